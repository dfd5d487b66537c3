/* meshlab-sharp's native library: its C ABI (every exported ms_ function), its options
 * and the constants of the method, defined here once.
 *
 * Three users: the library itself (native/src); the Python package, which loads the
 * library with ctypes (meshlab_sharp/_kernels.py) and reads the MS_ constants below from
 * this file (meshlab_sharp/_header.py); and the MeshLab plugin
 * (meshlab_plugin_cpp/src/filter_sharp_features.cpp), which links the same library
 * and calls the same functions. Plain C99: no Python, Qt, MeshLab or vcg types.
 *
 * Conventions: points are (n, 3) row-major doubles; "tree positions" index the points
 * in kd-tree order (ms_kdtree_build), "cleaned indices" the points as given; every
 * function that takes [begin, end) works on that chunk only, so that callers run chunks
 * on threads (nothing is shared but read-only input and disjoint output rows).
 */
#ifndef MESHLAB_SHARP_H
#define MESHLAB_SHARP_H

#include <stdint.h>

/* ---------------------------------------------------------------- constants
 * One `#define MS_NAME value` a line: a number, a quotient of two numbers in
 * parentheses, or a brace list of integers or of floating-point numbers. meshlab_sharp/_header.py parses exactly
 * these forms; the Python names drop the MS_ prefix. */

/* Default scales: k nearest neighbours on a point cloud, k-rings on a mesh. */
#define MS_DEFAULT_KNN_SCALES {12, 16, 20, 24, 28, 32, 36, 40}
#define MS_DEFAULT_RING_SCALES {1, 2, 3, 4}
/* The smallest scales (k of a cloud, ring of a mesh) and the most scales a detection
 * takes (pipeline.MAX_SCALES). */
#define MS_MIN_KNN_SCALE 2
#define MS_MIN_RING_SCALE 1
#define MS_MAX_SCALES 64
/* The largest scales, refused before any work (ms_detect, the command line): k nearest
 * neighbours (lists of k neighbours per point and scale) and rings (a k-ring's
 * neighbourhoods grow with k squared: ring 32 of a 25,000-vertex mesh takes about 20 s). */
#define MS_MAX_KNN_SCALE 512
#define MS_MAX_RING_SCALE 32
/* Default options, as indices into the lists the plugin's enums and Python share:
 * modes 0 paper, 1 robust (pipeline.MODES); weightings 0 gaussian, 1 none
 * (normals.WEIGHTINGS). */
#define MS_DEFAULT_MODE 1
#define MS_DEFAULT_WEIGHTING 0
/* Histogram bins of Otsu's threshold (threshold.BINS). */
#define MS_BINS 256
/* A scale whose projected distances span at most this fraction of the bounding-box
 * diagonal is flat (threshold.FLAT_TOLERANCE). */
#define MS_FLAT_TOLERANCE 1e-6
/* A face-average normal shorter than this is no normal (normals.ZERO_NORMAL). */
#define MS_ZERO_NORMAL 1e-12
/* The PCA normal where the covariance's smallest eigenvalue is not single (a
 * neighbourhood as symmetric as a grid's): the eigenvector is no longer one line, and
 * every path takes the same one in its eigenspace (normals.smallest_eigenvectors). With
 * p = sqrt(tr((A - q I)^2) / 6), q = tr(A) / 3 and r = det((A - q I) / p) / 2 (the
 * closed form's angle acos(r) / 3): triple where p <= EIG_TRIPLE_ROOT * |q|, the unit
 * vector EIG_TIE_DIRECTION itself; else double where 1 - r <= EIG_DOUBLE_ROOT (the two
 * smallest eigenvalues within about 1.6e-4 p; r is that accurate for p > EIG_TRIPLE_ROOT
 * |q|), EIG_TIE_DIRECTION less its part along the largest eigenvalue's eigenvector,
 * normalised; else a diagonal matrix's smallest entry's axis (the first of equals). The
 * direction (cos 72, 1/2, cos 36 degrees) is on no line of a grid's symmetries. */
#define MS_EIG_TRIPLE_ROOT 1e-5
#define MS_EIG_DOUBLE_ROOT 1e-8
#define MS_EIG_TIE_DIRECTION {0.30901699437494745, 0.5, 0.8090169943749475}
/* A cloud's point further from its median than FAR_SPREADS of its spreads (the largest
 * interquartile range of a coordinate), both measured on at most FAR_SAMPLE points evenly
 * spread through it, is far: dropped before the unit is chosen (neighbourhoods.far_points). */
#define MS_FAR_SPREADS 1099511627776.0
#define MS_FAR_SAMPLE 65536
/* Coordinates whose largest magnitude lies outside [2^-100, 2^100) are scaled by a
 * power of two first (neighbourhoods.UNIT_RANGE). */
#define MS_UNIT_RANGE 100
/* Robust mode (robust.py, creases.py; docs/method.md). */
#define MS_CREASE_ANGLE 20.0
/* Robust mode's threshold floor (robust.R_MIN): r on a straight edge turning by
 * MS_CREASE_ANGLE with a disc-shaped neighbourhood, (2 / pi) sin(MS_CREASE_ANGLE / 2),
 * to the nearest double. */
#define MS_R_MIN 0.11054786333836651
#define MS_NOISE_FACTOR (4.0 / 0.3186)
#define MS_NOISE_KNN 7
#define MS_NOISE_TOLERATED 0.15
#define MS_NOISE_MAX_FACTOR 3.0
/* On a cloud whose noise ratio exceeds MS_NOISE_QUIET, the largest scale's threshold is
 * at least this many times the median of its relative distances (robust.scale_floor,
 * ms_noise_floor): the noise that lifts a point's r at one scale lifts it at every
 * scale, and on a part with few edges Otsu's split lies below R_MIN, so 13-15 % of a
 * noisy cylinder's points passed the floor at every scale. */
#define MS_NOISE_FLOOR 3.0
/* ... but never above this (about the r of an edge turning by 40 degrees, twice the
 * crease angle): where the largest scale spans much of a small cloud, most points see
 * an edge and the median is no longer the flat points' noise. */
#define MS_NOISE_FLOOR_MAX 0.22
/* At most this median noise ratio, a cloud is thresholded at the floor alone
 * (ms_otsu_splits). */
#define MS_NOISE_QUIET 0.05
/* The sheet filter (robust.sheet_mask): gap in spacings, fewest points and kept share. */
#define MS_SHEET_GAP 0.4
#define MS_SHEET_MIN 6
#define MS_SHEET_OWN 0.5
/* Its second rule (where the first drops none): the column around the point (tangential
 * radius in spacings), the gap in spacings there, and the widest span, in spacings, of
 * the heights it drops on one side. */
#define MS_SHEET_COLUMN 1.1
#define MS_SHEET_COLUMN_GAP 0.75
#define MS_SHEET_FAR_SPAN 1.25
/* Its second pass (where the rules drop none): the rules again along the normal of the
 * neighbours within this many spacings of the point's plane, where that normal turns
 * from the list's by at most about 10 degrees (the cosine). */
#define MS_SHEET_TRIM 1.3
#define MS_SHEET_TRIM_COS 0.985
/* Isolation (robust.isolated_points): a point is also isolated when its MS_ISOLATED_NTH-th
 * nearest lies more than MS_ISOLATED_SPREAD times farther than the MS_ISOLATED_REF-th
 * nearest of its own kmax-th neighbour: its first few neighbours are not the surface's
 * spacing away (a stray pair or triple off the surface), while its kmax-th is. */
#define MS_ISOLATED_NTH 3
#define MS_ISOLATED_REF 10
#define MS_ISOLATED_SPREAD 2.5
#define MS_THIN_CONE_COS 0.5
/* On a noisy cloud (noise ratio above MS_NOISE_QUIET) thinning's cone is wider (about 63
 * degrees; support keeps MS_THIN_CONE_COS): noise tilts the offsets between a line's own
 * points, which then count as across it and thin the line to gaps (ms_thin_cone). */
#define MS_THIN_CONE_COS_NOISY 0.45
/* Thinning also compares a point with the higher-ranked features of its list that lie to
 * the side of its line by more than this fraction of the list's reach (the distance to
 * its farthest member), whatever their angle (robust.thin_side): the band of candidates
 * along an edge is 1.3-1.5 spacings wide, and a second point of it kept 1-1.5 spacings
 * from the edge, ahead or behind along the line, lies outside the cone. On meshes and
 * quiet clouds MS_THIN_SIDE (below it the rims of a wall 2 spacings thick, about 1.3
 * spacings apart in their bands, thin each other), on noisy clouds MS_THIN_SIDE_NOISY
 * (below it a noisy line thins to gaps). */
#define MS_THIN_SIDE 0.7
#define MS_THIN_SIDE_NOISY 0.65
/* After thinning, a cloud's feature point is dropped when it lies beside the line through
 * the higher-ranked features of its comparison list (at least MS_LINE_MIN of them) by
 * more than MS_LINE_OFFSET local units, and those features lie on one line: their mean
 * squared distance to it below (MS_LINE_SPREAD units)^2. The unit is the mean distance to
 * the MS_LINE_UNIT nearest, so it follows the cloud's local density (robust.line_test).
 * Not where the ranking is smoothed (ms_ranking_smoothed): there the points beside a line
 * already rank below it, and the smoothed ranking of a row beside it can outrank the line.
 * The point's foot on the line must lie among theirs, with some of them at least
 * MS_LINE_REACH units ahead of it and some as far behind: past a line's end nothing is
 * extrapolated, and at a corner the stronger points of the other edges, a short bent
 * row, do not make a line.
 * The band of candidates along an edge leaves points 1-1.5 spacings beside it whose own
 * line direction, tilted by noise, keeps the stronger edge points outside thinning's cone
 * and side rule; two rims or two edges side by side spread the stronger points over two
 * lines, and on a quiet cloud a point that is not a candidate, or ranks below, between the
 * point and the line blocks as in thinning. */
#define MS_LINE_OFFSET 0.6
#define MS_LINE_SPREAD 0.4
#define MS_LINE_MIN 3
#define MS_LINE_UNIT 6
#define MS_LINE_REACH 0.75
#define MS_THIN_KNN 12
#define MS_THIN_RING 2
#define MS_SUPPORT_KNN 16
#define MS_SUPPORT_MIN 2
/* On a cloud thresholded at the floor alone (noise ratio at most MS_NOISE_QUIET), a
 * candidate whose score (the mean o / l over the scales) is below this needs no support
 * (reference.detect.support_exempt): the candidates of weak edges come only here and
 * there. */
#define MS_SUPPORT_FREE_SCORE 0.22
/* On such a cloud, a point that is not a candidate at every scale but whose score lies in
 * [MS_ACUTE_SCORE, MS_ACUTE_SCORE_MAX) and that lies between two candidates of its
 * thinning list, (p_j - p_i) . (p_l - p_i) < 0 (robust.acute_tips), is a candidate too:
 * the tip of an acute edge, where the PCA normal turns perpendicular to the wedge's
 * mid-plane and r is small while o / l peaks; the candidates lie on the two faces beside
 * it, ahead and behind along the edge. Outliers that are not isolated score above the
 * cap (0.8-0.96). */
#define MS_ACUTE_SCORE 0.5
#define MS_ACUTE_SCORE_MAX 0.8
/* Points per chunk handed to a thread (_kernels.CHUNK). */
#define MS_CHUNK 8192
/* Most points in a leaf of the kd-tree (_kernels.KD_LEAF). */
#define MS_KD_LEAF 16
/* The kd-tree is built in two steps: its top MS_KD_TOP levels, then the 2^MS_KD_TOP
 * subtrees below them, each on its own (threads). */
#define MS_KD_TOP 3
/* A mesh is renumbered (ms_bfs_renumber: by detect right after cleaning, by the ring pass
 * of a caller that did not) when more than half of up to MS_SCATTER_SAMPLES vertices
 * evenly spread lie more than MS_SCATTERED_GAP positions from their first neighbour. */
#define MS_SCATTERED_GAP 16384
#define MS_SCATTER_SAMPLES 4096

/* ---------------------------------------------------------------- the feature curves
 * The constants of the feature curves: the Python package's curves modules
 * (meshlab_sharp/curves: graph.py, trace.py, extract.py, refine.py, fit.py) read them
 * (meshlab_sharp/_header.py), and the library's curves (native/src/curves.cpp) use the
 * macros. What each constant does and why it has its value is documented beside its
 * Python name (the name without the MS_CURVE_ prefix) in the module named above its
 * group. Lengths are in point spacings, angles in degrees. One `#define MS_CURVE_NAME
 * value` a line: a number, an earlier MS_CURVE_ name, a product or quotient of two
 * floating-point numbers or earlier names in parentheses, or a brace list of integers
 * or of floating-point numbers. */

/* graph.py: linking the feature points, the skeleton's spurs. */
#define MS_CURVE_LINK_NEIGHBOURS 8
#define MS_CURVE_LINK_RADIUS 2.5
#define MS_CURVE_SPUR_LENGTH 4.0
#define MS_CURVE_MESH_FLAT_WEIGHT 0.05
#define MS_CURVE_BRIDGE_BACK 3
#define MS_CURVE_BRIDGE_REACH 3.0
#define MS_CURVE_BRIDGE_ANGLE 30.0
#define MS_CURVE_IRREGULAR_BRIDGE_REACH 4.0
#define MS_CURVE_IRREGULAR_BRIDGE_ANGLE 60.0
#define MS_CURVE_PRUNE_ROUNDS 4

/* trace.py: turns, tangents, joining the ends. */
#define MS_CURVE_CORNER_TURN 35.0
#define MS_CURVE_TURN_INNER 0.5
#define MS_CURVE_TURN_OUTER 2.0
#define MS_CURVE_TURN_SCALES {1.0, 2.0, 4.0, 8.0}
#define MS_CURVE_MIN_TURN_SCALES 2
#define MS_CURVE_TANGENT_WINDOW 2.0
#define MS_CURVE_GAP_LENGTH 4.0
#define MS_CURVE_SHORTEST_CUT (2.0 * MS_CURVE_GAP_LENGTH)
/* In multiples of MS_CURVE_GAP_LENGTH. */
#define MS_CURVE_LOOP_LENGTH 3.0
#define MS_CURVE_LONG_GAP 12.0
/* An index into MS_CURVE_TURN_SCALES. */
#define MS_CURVE_CORNER_SCALE 2
#define MS_CURVE_LATERAL_OFFSET 2.0

/* extract.py: which curves are kept, the cloud curves' refinement and corners. */
#define MS_CURVE_MIN_CURVE_LENGTH MS_CURVE_GAP_LENGTH
#define MS_CURVE_SPUR_PIECE (2.0 * MS_CURVE_GAP_LENGTH)
#define MS_CURVE_MAX_FLAT_SHARE 0.5
#define MS_CURVE_CELL_SPACINGS 4.0
#define MS_CURVE_DENSITY_NEIGHBOURS 8
#define MS_CURVE_DENSITY_SCALE 0.45
#define MS_CURVE_MAX_LOCAL_SPACING 2.0
#define MS_CURVE_EARLY_DROP 0.75
#define MS_CURVE_MIN_ADVANCE 0.3
/* Vertices on each side. */
#define MS_CURVE_LINE_FIT_HALF 2
#define MS_CURVE_RAW_TANGENT_WINDOW (2.0 * MS_CURVE_TANGENT_WINDOW)
#define MS_CURVE_SNAP 0.75
#define MS_CURVE_MAX_CORNER_CONDITION 1e6
#define MS_CURVE_CORNER_OFFSET 1.5

/* refine.py: the two arms' lines across a cloud curve. */
#define MS_CURVE_REFINE_NEIGHBOURS 40
#define MS_CURVE_SLAB 1.0
#define MS_CURVE_ARM_ITERATIONS 3
/* A total weight. */
#define MS_CURVE_MIN_ARM_POINTS 3.0
#define MS_CURVE_MAX_SHIFT 3.0
#define MS_CURVE_MIN_ARM_ANGLE 20.0
#define MS_CURVE_MAX_ARM_RMS 0.5
#define MS_CURVE_ZERO_OFFSET 1e-12
#define MS_CURVE_FRAME_SWITCH 0.9
#define MS_CURVE_OTHER_EDGE 3.0
/* The grid of cells around the features: the largest cell coordinate, and (in the numpy
 * reference) the most cells numbered by one int64 key (2^62). */
#define MS_CURVE_MAX_CELL 4611686018427387904.0
#define MS_CURVE_OTHER_EDGE_MARGIN 0.5
#define MS_CURVE_THIN_WALL 1.0
#define MS_CURVE_WALL_APART (2.0 * MS_CURVE_THIN_WALL)
#define MS_CURVE_WALL_GAP 2.0

/* fit.py: line, arc or free-form (Python only: the plugin does not classify). */
#define MS_CURVE_FIT_TOLERANCE 0.5
#define MS_CURVE_FIT_MAX 4.0
#define MS_CURVE_MAX_RADIUS_RATIO 20.0

#ifdef __cplusplus
extern "C" {
#endif

/* The C ABI is the libraries' face: exported even where the rest is compiled with hidden
 * visibility (the C++ sources of the Python package's libraries). */
#if defined(__GNUC__)
#pragma GCC visibility push(default)
#endif

/* What one pass of ms_cloud_pdis writes (each pointer may be NULL), per cleaned index
 * oi = orig[i] (with tree_order = 1 or 2: per tree position oi = i, the caller then moving
 * the rows to cleaned order: sequential writes, several times faster on a shuffled cloud;
 * the values are cleaned indices either way, but near[oi] and kth_idx[oi] with
 * tree_order = 2: tree positions, for ms_isolated_tree), s the scale's position
 * in ks:
 *   pdis[s * n + oi]          projected distance; normals[(s * n + oi) * 3] its normal;
 *   idx[oi * kmax + j]        the neighbour indices (kNN table);
 *   relative[s * n + oi]      robust mode's relative distance r = min(pdis / l, 1) (0
 *                             if l = 0; l = robust.local_scale in numpy's summation
 *                             order), and score[oi] its ranking: the sum over the scales
 *                             in order of min(o / l, 1) / nscales (RelativeRule's);
 *   noise[oi]                 reference.detect.noise_scale_factor's ratio over the
 *                             noise_k nearest;
 *   sheet_gap > 0             robust.sheet_mask (sheet_gap, sheet_min, sheet_own,
 *                             sheet_column, sheet_column_gap, sheet_far_span,
 *                             sheet_trim, sheet_trim_cos; rule 2 off when
 *                             sheet_column <= 0, the second pass when sheet_trim <= 0)
 *                             first
 *                             (normal: the weighted PCA normal of the kmax nearest):
 *                             every scale's neighbourhood, and the noise's, is then the
 *                             kept points among its neighbours;
 *   near[oi]                  the nearest other point (column 1 of the kNN table);
 *   kth_d2[oi], kth_idx[oi]   squared distance and index of the kmax-th neighbour;
 *   nth_d2[oi], ref_d2[oi]    squared distances of the neighbours in columns
 *                             min(isolated_nth, kmax - 1) and
 *                             min(isolated_ref, kmax - 1) of the kNN table (both
 *                             given or neither, as kth_d2 and kth_idx;
 *                             robust.isolated_points: MS_ISOLATED_NTH and
 *                             MS_ISOLATED_REF). */
typedef struct {
    double *pdis, *normals;
    int64_t *idx;
    double *relative, *score, *noise;
    int64_t noise_k;
    int32_t *near; /* n < 2**31 (_kernels.cloud_projected_distances checks) */
    double *kth_d2;
    int32_t *kth_idx;
    double *nth_d2, *ref_d2;
    int64_t isolated_nth, isolated_ref;
    double sheet_gap;
    int64_t sheet_min;
    double sheet_own;
    double sheet_column, sheet_column_gap, sheet_far_span, sheet_trim, sheet_trim_cos;
    int64_t tree_order;
} cloud_out_t;

/* The balanced kd-tree of p (n, 3), leaves at `depth` (ceil(log2(n / MS_KD_LEAF)), at
 * least 0): the points in tree order into tp (n, 3), their cleaned indices into torig
 * (n), the tight boxes (lo xyz, hi xyz) of the 2^(depth + 1) - 1 nodes into box. */
void ms_kdtree_build(const double *p, int64_t n, int depth, double *tp, int64_t *torig,
                     double *box);

/* ms_kdtree_build in steps, the same tree (callers run each step's ranges on threads):
 * with tp a copy of p and torig[i] = i, for each level l < t = min(depth, MS_KD_TOP) in
 * turn the splits of its nodes u in [first, last) of the 2^l (ms_kdtree_build_level),
 * then the subtrees of the nodes u in [first, last) of the 2^t at depth t
 * (ms_kdtree_build_subtrees; disjoint ranges of tp, torig and box). */
void ms_kdtree_build_level(double *tp, int64_t *torig, int64_t n, int depth, int level,
                           int64_t first, int64_t last, double *box);
void ms_kdtree_build_subtrees(double *tp, int64_t *torig, int64_t n, int depth, int64_t first,
                              int64_t last, double *box);

/* Unit eigenvector of the smallest eigenvalue of each symmetric matrix cov (c, 6) given
 * as a00 a01 a02 a11 a12 a22, into out (c, 3). */
void ms_eigvecs(const double *cov, int64_t c, double *out);

/* kNN of tree positions [begin, end) at k = max(ks) (ks: nscales increasing scales),
 * then what out asks for (cloud_out_t). p, orig, box, depth: the tree. Returns 0, or
 * -1 out of memory. */
int ms_cloud_pdis(const double *p, const int64_t *orig, int64_t n, const double *box, int depth,
                  const int64_t *ks, int nscales, int gaussian, int64_t begin, int64_t end,
                  const cloud_out_t *out);

/* Rows [begin, end) of src (n rows of `bytes` bytes each, tree order) to their cleaned
 * positions in dst: row i to row orig[i]. */
void ms_scatter_rows(const int64_t *orig, const void *src, int64_t bytes, int64_t begin,
                     int64_t end, void *dst);

/* robust.isolated_points from a pass's statistics near, kth_d2, kth_idx, nth_d2, ref_d2
 * (n, cleaned order) for the points [begin, end) of p (n, 3): out[i] = 1 when i is not
 * among the kmax nearest of near[i] ((|p_i - p_near[i]|^2, i) after that point's kmax-th
 * neighbour in the lists' order), or when nth_d2[i] > spread^2 * ref_d2[kth_idx[i]]
 * (robust.isolated_points: spread MS_ISOLATED_SPREAD). */
void ms_isolated(const double *p, const int32_t *near, const double *kth_d2,
                 const int32_t *kth_idx, const double *nth_d2, const double *ref_d2,
                 double spread, int64_t begin, int64_t end, uint8_t *out);

/* robust.sheet_mask, bit for bit, of the rows [begin, end) of the kNN lists idx (n, k)
 * (the point itself first) of the points p (n, 3) with their normals nrm (n, 3) and the
 * parameters params' sheet_* (cloud_out_t; sheet_gap > 0): keep[i * k + j] 1 where the
 * filter keeps idx[i * k + j]. The pass's filter (what ms_cloud_pdis runs with
 * sheet_gap > 0) on given lists. Returns 0, or -1 out of memory. */
int ms_sheet_mask(const double *p, const int64_t *idx, int64_t k, const double *nrm,
                  const cloud_out_t *params, int64_t begin, int64_t end, char *keep);

/* ms_isolated from a tree_order = 2 pass's statistics (per tree position t; near[t] and
 * kth_idx[t] tree positions) for the tree positions [begin, end): tp (n, 3) the points in
 * tree order, orig their cleaned indices; out[t] per tree position. */
void ms_isolated_tree(const double *tp, const int64_t *orig, const int32_t *near,
                      const double *kth_d2, const int32_t *kth_idx, const double *nth_d2,
                      const double *ref_d2, double spread, int64_t begin, int64_t end,
                      uint8_t *out);

/* Counts of v[begin, end) added to counts (32769): +0.0 in counts[0], the others by the
 * top 16 bits b of their bit patterns in counts[b + 1] (the values >= +0.0 and NaN, in
 * their order); returns how many have the sign bit set (left out). robust mode's noise
 * median (_kernels.lower_median). */
int64_t ms_bit_histogram(const double *v, int64_t begin, int64_t end, int64_t *counts);

/* For r in [begin, end): the k nearest of the point at tree position pos[r] into
 * out_idx[r * k ...], cleaned indices sorted by (squared distance, index): the search
 * of ms_cloud_pdis (a leaf's block of nearby points, shared by the rows in that leaf,
 * pruned by the previous row's k-th distance), fastest with pos increasing. Returns
 * 0, or -1 out of memory. */
int ms_knn_rows(const double *p, const int64_t *orig, int64_t n, const double *box, int depth,
                const int64_t *pos, int64_t k, int64_t begin, int64_t end, int64_t *out_idx);

/* robust.local_scale over CSR lists (indptr, indices int32, or int64 when wide) of the
 * points [begin, end): mean distance out_ell[i] and centroid distance out_off[i], in
 * numpy's summation order. Returns 0, or -1 out of memory. */
int ms_local_scale_csr(const double *p, const int64_t *indptr, const void *indices, int wide,
                       int64_t begin, int64_t end, double *out_ell, double *out_off);

/* 1-ring adjacency of a triangle mesh, CSR: ptr (n + 1), idx (room for 6 m; ptr[n] used),
 * each vertex's neighbours in the order its faces list them, each once. Returns 0, -1 out
 * of memory, or -2 when a face index lies outside [0, n). */
int ms_adjacency(const int64_t *faces, int64_t m, int64_t n, int64_t *ptr, int32_t *idx);

/* Whether a mesh's vertex order lacks locality (the rule above): 1 or 0. ptr (n + 1),
 * adj: ms_adjacency's lists. */
int ms_scattered(const int64_t *ptr, const int32_t *adj, int64_t n);

/* ms_scattered's answer for the faces (m, 3) mapped through remap (NULL: as they are)
 * into [0, n), from the faces alone, before the adjacency is built: 1 or 0. */
int ms_scattered_faces(const int64_t *faces, int64_t m, const int64_t *remap, int64_t n);

/* The mesh (p (n, 3), fixed (n, 3) or NULL, adjacency (ptr, adj)) with its vertices
 * renumbered in breadth-first order (each component from its lowest vertex not yet met)
 * for the ring pass's locality: order[k] the vertex numbered k, rank its inverse (both
 * (n,)), the lists (out_ptr (n + 1), out_adj as adj), row k old row order[k] mapped
 * through rank in the same order (a search over them meets the same vertices in the same
 * order), and out_p (out_fixed when fixed is not NULL) the rows in the new order. */
void ms_bfs_renumber(const int64_t *ptr, const int32_t *adj, int64_t n, const double *p,
                     const double *fixed, int32_t *order, int32_t *rank, int64_t *out_ptr,
                     int32_t *out_adj, double *out_p, double *out_fixed);

/* shifted[w] = 1 where vertex w + 1's list in (ptr, adj) is w's with each neighbour plus
 * one (the same length), else 0, for w in [begin, end) of the n vertices (w = n - 1: 0):
 * a grid-numbered mesh's vertices, whose rings ms_ring_pdis takes from the previous
 * vertex's. */
void ms_shifted_lists(const int64_t *ptr, const int32_t *adj, int64_t n, int64_t begin,
                      int64_t end, uint8_t *shifted);

/* k-rings by breadth-first search over (ptr, adj) for the vertices [begin, end) and the
 * projected distance at every ring of rings (nscales increasing) into
 * out_pdis[s * n + i] when not NULL, normals into out_normals when not NULL. fixed: (n, 3)
 * normals, a zero row meaning PCA, or NULL. Each ring is listed in the search's order
 * (RingNeighbourhoods.at). With out_relative and out_score not NULL, robust mode's
 * RelativeRule over the same rings (local scales in numpy's summation order): the
 * relative distances (nscales, n) and the score (n). stamp: (n,) int32 scratch of the
 * calling thread, all -1 before its first call. dest (n,) or NULL: vertex i's results go
 * to column dest[i] (ms_bfs_renumber's order). shifted (n,): ms_shifted_lists' flags over
 * (ptr, adj), where vertex i's search is vertex i - 1's plus one (no search), or NULL
 * (every vertex searched); the same outputs either way. Returns 0, or -1 out of memory. */
int ms_ring_pdis(const double *p, int64_t n, const int64_t *ptr, const int32_t *adj,
                 const double *fixed, const int64_t *rings, int nscales, int gaussian,
                 int64_t begin, int64_t end, int32_t *stamp, const int32_t *dest,
                 const uint8_t *shifted, double *out_pdis, double *out_normals,
                 double *out_relative, double *out_score);

/* The rings of the vertices rows[r] (r < m), breadth-first over (ptr, adj) as
 * ms_ring_pdis lists them (ring k a prefix of ring k + 1): the length of ring rings[s]
 * (nrings increasing) into out_len[s * m + r], and when out_idx is not NULL the last
 * ring's members from out_idx[out_start[r]] on. stamp: (n,) int32 scratch, all -1 on
 * entry (and on return). Returns 0, or -1 out of memory. */
int ms_ring_lists(const int64_t *ptr, const int32_t *adj, const int64_t *rows, int64_t m,
                  const int64_t *rings, int nrings, int32_t *stamp, int64_t *out_len,
                  const int64_t *out_start, int32_t *out_idx);

/* The faces (m, 3) wound as their neighbours are: flip[f] (m) 1 where face f is wound the
 * other way round from the lowest face of its part (the faces joined through edges with
 * exactly two faces, both faces of such an edge counted as one way round when they go
 * opposite ways along it), else 0. A part with no consistent winding (non-orientable: a
 * Moebius strip) keeps its faces' (0). Returns the number of faces in such parts, or -1
 * out of memory (or m >= 2^31). */
int64_t ms_face_windings(const int64_t *faces, int64_t m, int64_t n, uint8_t *flip);
/* ms_face_windings over the faces' incidence (ptr (n + 1), inc (3 m): ms_vertex_faces' of
 * the same faces), which it only reads: the same turns, without building it again. */
int64_t ms_face_windings_at(const int64_t *faces, int64_t m, int64_t n, const int64_t *ptr,
                            const int32_t *inc, uint8_t *flip);

/* Face-average vertex normals (unit, or zero when shorter than `zero`) into acc (n, 3),
 * zero on entry; faces (m, 3), each face's normal turned where ms_face_windings turns the
 * face: the same normals' lines whatever the faces' winding. Returns ms_face_windings'
 * count of faces left as they are wound, or -1 out of memory. */
int64_t ms_face_average_normals(const double *p, int64_t n, const int64_t *faces, int64_t m,
                                double zero, double *acc);
/* ms_face_average_normals with the faces' turns given: turned (m), ms_face_windings'
 * flip, or NULL (found inside; the same normals). Returns 0 (turned given), else
 * ms_face_average_normals'. A caller that holds the faces' incidence finds the turns
 * with ms_face_windings_at, and may find them before building what the normals' sum
 * runs beside (the windings' memory freed first). */
int64_t ms_face_average_normals_at(const double *p, int64_t n, const int64_t *faces, int64_t m,
                                   const uint8_t *turned, double zero, double *acc);

/* The edges (a, b), a < b, with exactly two faces, sorted, into out_edges (room for
 * (3 m + 1) / 2 rows: 3 m int64, the sort keys' scratch first), and the dot products of their faces' unit normals (cross(p1 - p0,
 * p2 - p0) / |.| of the points p), the lower face first, into out_dot (creases.dihedral_angles);
 * negated where the two faces go the same way along the edge (wound opposite ways round),
 * so that the dot product does not depend on the faces' winding. n * m < 2^63.
 * Returns the count, or -1 out of memory. */
int64_t ms_two_face_edges(const double *p, const int64_t *faces, int64_t m, int64_t n,
                          int64_t *out_edges, double *out_dot);

/* creases.sharp_vertices in less memory than ms_two_face_edges (no sort keys, no edge
 * list). ms_vertex_faces: each vertex's faces, in face order, as CSR ptr (n + 1), inc
 * (3 m; m < 2^31); returns 0 or -1 out of memory. ms_crease_dots: the dot products u . v
 * of the unit normals of the two faces of every edge with exactly two faces (negated as
 * in ms_two_face_edges: independent of the winding; the same
 * values as ms_two_face_edges', in another order: the lower vertex increasing, then its
 * faces in order), those not >= 1 ("turned") into dot (room for (3 m + 1) / 2), where
 * each vertex's turned edges start into estart (n + 1), and the number of the others
 * (flat: their angle acos(min(u . v, 1)) is exactly 0) into *flat; returns the number of
 * turned edges. ms_crease_mask: the same turned edges; both vertices of each edge whose
 * angle[e] > threshold marked 1 in mask (n, zeroed by the caller). */
int ms_vertex_faces(const int64_t *faces, int64_t m, int64_t n, int64_t *ptr, int32_t *inc);
int64_t ms_crease_dots(const double *p, const int64_t *faces, int64_t n, const int64_t *ptr,
                       const int32_t *inc, double *dot, int64_t *estart, int64_t *flat);
void ms_crease_mask(const double *p, const int64_t *faces, int64_t n, const int64_t *ptr,
                    const int32_t *inc, const int64_t *estart, const double *angle, double threshold,
                    uint8_t *mask);

/* Merge exactly equal points (==, so -0.0 equals 0.0) into their first occurrence, on one
 * thread (cleaning and _kernels.merge_duplicates). table: (tmask + 1) uint64 scratch,
 * tmask + 1 a power of two >= 2 n and <= 2^32; n < 2^31. from_input (n, all 0 at
 * first): cleaned index of each input point; to_input (n, first m used) or NULL: input
 * index of each cleaned point; out (room for n rows) or NULL: the cleaned points (m, 3)
 * when some points merge, untouched when none does. Returns m. */
int64_t ms_dedup(const double *p, int64_t n, uint64_t *table, int64_t tmask,
                 int64_t *from_input, int64_t *to_input, double *out);

/* Cleaning's faces in one pass (cleaning.clean): each face of faces (m, 3) (indices of
 * the input points, mapped through from_input when not NULL) whose double area on p,
 * |(p1 - p0) x (p2 - p0)| as vcg's DoubleArea computes it, is > 0, in order, into out (room for m rows; may be faces
 * itself when from_input is NULL), its vertices marked 1 in used (zeroed by the caller).
 * Returns the number of faces kept. */
int64_t ms_keep_faces(const double *p, const int64_t *faces, int64_t m, const int64_t *from_input,
                      int64_t *out, uint8_t *used);

/* Robust mode's finishing steps (reference.detect.RobustSetup.finish; reference/robust.py
 * is the numpy reference), over candidate slots r in [begin, end): the point rows[r]
 * (cleaned index) and its lists in an ms_lists_t; below i = rows[r]. f0, f1, f2,
 * between: (n) masks, one byte a point; e (c, 3) and out (c) per slot; f1, f2 and rank
 * are written at the rows only (the caller sets the rest).
 * Slot r's list: the members idx[first ...], len of them, first = start[r] (start NULL:
 * r * stride), len = len[r] (len NULL: k); idx int64 when wide, else int32. The lists of
 * the steps may be views of one table (the k nearest at several k: one stride, several
 * k) or of one CSR list (a mesh's rings: one start, several len). */
typedef struct {
    const void *idx;
    int64_t wide;
    const int64_t *start;
    int64_t stride;
    const int64_t *len;
    int64_t k;
} ms_lists_t;

/* ms_line_test's rules (robust.line_test): the offset, spread and reach in local units,
 * the fewest stronger features that make a line, and how many nearest set the unit. */
typedef struct {
    double offset;
    double spread;
    double reach;
    int64_t minimum;
    int64_t unit;
} ms_line_rules_t;

/* robust.line_directions: e[r] (3) = the unit eigenvector of the largest eigenvalue of
 * C = sum_j (q_j - qbar)(q_j - qbar)^T, q_j = p_j - p_i, over the j of direction's list
 * with f0[j] (numpy's sums and lower triangle; the 3x3 solver of the normals, on -C:
 * within about 1e-16 of numpy's eigh, up to sign). Returns 0, or -1 out of memory.
 * ms_supported (robust.supported): f1[i] = at least `minimum` points j != i of around's
 * list with f0[j] and p_j - p_i along the line (not |d . e| < cone |d|), or (score not
 * NULL) score[i] < free_below (reference.detect.support_exempt). ms_smoothed_ranking
 * (robust.smoothed_ranking): rank[i] = the mean of score over the first `window` of
 * compare's list (added in order to 0.0), when it is not empty; the other entries of
 * rank are the caller's. ms_thin (robust.thin; f1 complete first): f2[i] = f1[i] and no
 * j != i of compare's list with f1[j], rank[j] > rank[i] and d = p_j - p_i across the line
 * (|d . e| < cone |d|) or beside it (|d|^2 - (d . e)^2 > (side * side) |p_l - p_i|^2, l
 * the list's farthest member), unless (between not NULL) a point m of the list with between[m]
 * or rank[m] < rank[i] lies between: (p_m - p_i) . (p_m - p_j) < 0. ms_acute_tips
 * (robust.acute_tips): out[r] = some j != l of the list, both f0 and not i, with
 * (p_j - p_i) . (p_l - p_i) < 0. ms_line_test (robust.line_test; f2 complete first; the
 * rules' offset, spread, reach, minimum and unit are MS_LINE_OFFSET, MS_LINE_SPREAD,
 * MS_LINE_REACH, MS_LINE_MIN and MS_LINE_UNIT in ms_detect): f3[i] = f2[i], unless the
 * m >= minimum points j != i of compare's list with f2[j] and rank[j] > rank[i] (q_j =
 * p_j - p_i, in list order) have, with qbar and e as ms_line_directions forms them over
 * those j, a mean of |r_j|^2 - (r_j . e)^2, r_j = q_j - qbar (add.reduceat's sum,
 * divided by m), below (spread u)^2 while g = qbar - (qbar . e) e has |g|^2 > (offset
 * u)^2 (u: the mean of |q| over the next min(unit, len - 1) members after i, added in
 * order to 0.0), and some r_j . e > -(qbar . e) + reach u and some r_j . e < -(qbar .
 * e) - reach u (p_i's foot lies among theirs): then f3[i] = 0, unless (between not
 * NULL) a point m of the list with between[m] or rank[m] < rank[i] has (p_m - p_i) .
 * (p_m - (p_i + g)) < 0. Returns 0, or -1 out of memory. Sums over x, y, z in that
 * order, as numpy's. */
int ms_line_directions(const double *p, const uint8_t *f0, const int64_t *rows,
                       const ms_lists_t *direction, int64_t begin, int64_t end, double *e);
void ms_supported(const double *p, const uint8_t *f0, const int64_t *rows, const double *e,
                  const ms_lists_t *around, double cone, int64_t minimum, const double *score,
                  double free_below, int64_t begin, int64_t end, uint8_t *f1);
void ms_smoothed_ranking(const double *score, const int64_t *rows, const ms_lists_t *compare,
                         int64_t window, int64_t begin, int64_t end, double *rank);
void ms_thin(const double *p, const uint8_t *f1, const int64_t *rows, const double *e,
             const ms_lists_t *compare, const double *rank, double cone, double side,
             const uint8_t *between, int64_t begin, int64_t end, uint8_t *f2);
int ms_line_test(const double *p, const uint8_t *f2, const int64_t *rows,
                 const ms_lists_t *compare, const double *rank, const ms_line_rules_t *rules,
                 const uint8_t *between, int64_t begin, int64_t end, uint8_t *f3);
void ms_acute_tips(const double *p, const uint8_t *f0, const int64_t *rows,
                   const ms_lists_t *lists, int64_t begin, int64_t end, uint8_t *out);

/* Robust mode's rules on a cloud's noise ratio `noise` (the lower median of the pass's
 * per-point ratios; 0 on a mesh, mesh = 1), the one definition of each (robust.py binds
 * them). ms_noise_factor: the scales' growth, min(max(1, (noise / MS_NOISE_TOLERATED)^2),
 * MS_NOISE_MAX_FACTOR); ms_scale_growth: that factor for a cloud of n points (isolated
 * ones left out) at largest scale top, at most n / top (the largest grown scale stays
 * within the cloud; above 1, the scales grow). ms_grown_scale: k * factor rounded half up.
 * ms_thin_knn: thinning's comparison list on a cloud, MS_THIN_KNN grown by `growth` (1:
 * not grown). ms_quiet_cloud: a cloud whose noise is at most MS_NOISE_QUIET, thresholded
 * at the floor alone; ms_otsu_splits its negation. ms_thin_cone: thinning's cone,
 * MS_THIN_CONE_COS_NOISY on a noisy cloud, else MS_THIN_CONE_COS; ms_thin_side its side
 * rule, MS_THIN_SIDE_NOISY on a noisy cloud, else MS_THIN_SIDE. ms_ranking_smoothed:
 * thinning ranks by ms_smoothed_ranking, on a cloud whose noise grew the scales to the
 * cap. ms_support_free_score: 1 and *score = MS_SUPPORT_FREE_SCORE on a quiet cloud (a
 * candidate scoring below it needs no support), else 0 (*score untouched). */
double ms_noise_factor(double noise);
double ms_scale_growth(double noise, int64_t n, int top);
int ms_grown_scale(int k, double factor);
int ms_thin_knn(double growth);
int ms_quiet_cloud(int mesh, double noise);
int ms_otsu_splits(int mesh, double noise);
double ms_thin_cone(int mesh, double noise);
double ms_thin_side(int mesh, double noise);
int ms_ranking_smoothed(int mesh, double noise);
int ms_support_free_score(int mesh, double noise, double *score);
/* ms_scale_floor (robust.scale_floor): the floor of a scale's threshold, MS_R_MIN; on the
 * largest scale (last) of a cloud that is not quiet (ms_quiet_cloud), at least
 * ms_noise_floor(counts) of that scale's histogram (MS_BINS; not read otherwise). */
double ms_scale_floor(const int64_t *counts, int last, int mesh, double noise);

/* Robust mode's decisions once the first pass has measured the noise (ms_robust_plan,
 * stages.c): every branch of the sequence after that pass, taken from the rules above,
 * in one place. ms_detect's cloud sequence (detect.cpp) and the out-of-core tiles
 * (meshlab_sharp.tiles) both run what it says; the numpy reference states the same
 * decisions (meshlab_sharp.reference.robust.robust_plan). */
typedef struct {
    int mesh;                  /* the input: a mesh (1) or a cloud (0) */
    double noise;              /* the cloud's noise ratio (0 on a mesh) */
    int n_scales;              /* s, the scales' count */
    int scales[MS_MAX_SCALES]; /* the scales the detection runs at (grown when grown) */
    double growth;             /* how much the noise grew the scales (ms_scale_growth; 1: not) */
    int grown;                 /* growth > 1: the scales grew, and a pass at them follows */
    int otsu;                  /* Otsu's split raises the thresholds (ms_otsu_splits) */
    int noise_floor;           /* the largest scale's floor reads its histogram (ms_scale_floor) */
    int acute_tests;           /* acute tips are looked for (ms_stage_acute_tests) */
    int support_knn;           /* support's list: the MS_SUPPORT_KNN nearest (a mesh's
                                  MS_THIN_RING-ring), at most the largest scale */
    int compare_knn;           /* thinning's and acute tips' comparison list: ms_thin_knn(growth)
                                  nearest (a mesh's MS_THIN_RING-ring), at most the largest scale */
    int ranking_smoothed;      /* thinning ranks by ms_smoothed_ranking (ms_ranking_smoothed) */
    int support_exempt;        /* candidates scoring below free_below need no support */
    double free_below;         /* ms_support_free_score's score (0 when not support_exempt) */
    double thin_cone;          /* thinning's cone (ms_thin_cone) */
    double thin_side;          /* thinning's side rule (ms_thin_side) */
    int thin_between;          /* thinning is blocked by the points that are not candidates
                                  (a quiet cloud: reference.detect.thin_blockers) */
    int curved_dropped;        /* candidates on a curved surface are dropped (a mesh:
                                  ms_stage_curved) */
    int thin_line;             /* thinning's line test follows (ms_line_test): a cloud whose
                                  ranking is not smoothed */
} ms_robust_plan_t;
/* ms_robust_plan: the plan for an input of `mesh`, noise ratio `noise`, n_kept points (the
 * isolated ones left out) and the s given scales (increasing, s <= MS_MAX_SCALES; a cloud's
 * scales grow by ms_scale_growth(noise, n_kept, largest scale), a mesh's do not). Returns 0,
 * or -1 when s is out of range. ms_plan_thresholds: each scale's threshold (s) from its
 * summed MS_BINS-bin histogram counts (s, MS_BINS; read only with plan->otsu): with the
 * plan's floor of that scale (ms_scale_floor), ms_stage_threshold. */
int ms_robust_plan(double noise, int64_t n_kept, const int *scales, int s, int mesh,
                   ms_robust_plan_t *plan);
void ms_plan_thresholds(const ms_robust_plan_t *plan, const int64_t *counts, double *thresholds);

/* The pointwise stages of a cloud's sequence (stages.c), over the points [begin, end):
 * ms_detect runs them over every point, the out-of-core path over each tile's points and
 * sums their partials. ms_flat_span: paper mode's flat span, MS_FLAT_TOLERANCE times the
 * diagonal of the bounding box whose sides are extent (3; ms_extent's). Point i's value at
 * scale s (s < MS_MAX_SCALES of them) is x[i * point_stride + s * scale_stride]; with lo
 * not NULL, min-max normalised as ms_scale_vote normalises it with the global lo[s], hi[s]
 * (s each) and flat_span. ms_stage_histograms: adds each scale's MS_BINS-bin histogram
 * (ms_scale_vote's bins) to counts (s, MS_BINS). ms_stage_threshold: a scale's threshold
 * from its summed histogram, max(Otsu's split, floor_) with `otsu`, floor_ without
 * (ms_scale_vote's T). ms_stage_decide: with the global thresholds (s), the votes v >= T
 * of each point: feature (all s), strength (votes / s), each scale's candidates added
 * to counts (s), and v into out (x's layout) when out is not NULL.
 * ms_stage_acute_tests (reference.detect.acute_tests): on a quiet cloud (ms_quiet_cloud),
 * tested[i] = not feature[i] and score[i] in [MS_ACUTE_SCORE, MS_ACUTE_SCORE_MAX); returns
 * how many (0, tested untouched, otherwise).
 * ms_stage_curved (robust.stage_curved): a mesh's candidates whose relative distance
 * grows with the ring at least as the square root of the ring, feature[i] = 0 where
 * feature[i] and first[i] * first[i] * s_last < last[i] * last[i] * s_first (first and
 * last: the relative distances at the smallest ring s_first and the largest s_last);
 * returns how many. A crease is a wedge, the same at every size: its relative distance
 * does not grow; a smooth surface's grows in proportion to the ring's radius, which is
 * in proportion to the ring. */
double ms_flat_span(const double *extent);
void ms_stage_histograms(const double *x, int64_t point_stride, int64_t scale_stride, int s,
                         int64_t begin, int64_t end, const double *lo, const double *hi,
                         double flat_span, int64_t *counts);
double ms_stage_threshold(const int64_t *counts, int otsu, double floor_);
void ms_stage_decide(const double *x, int64_t point_stride, int64_t scale_stride, int s,
                     int64_t begin, int64_t end, const double *lo, const double *hi,
                     double flat_span, const double *thresholds, uint8_t *feature,
                     double *strength, int64_t *counts, double *out);
int64_t ms_stage_acute_tests(const double *score, const uint8_t *feature, int64_t begin,
                             int64_t end, int mesh, double noise, uint8_t *tested);
int64_t ms_stage_curved(const double *first, const double *last, int64_t begin, int64_t end,
                        int s_first, int s_last, uint8_t *feature);
/* ms_isolated's test of the rows [begin, end) whose values are gathered per row (a tile's
 * points, their nearest anywhere in the cloud): out[r] = 1 when the point a[r] (3; index
 * idx[r] in the lists' order) is not among the kmax nearest of its nearest b[r] (3), whose
 * kmax-th neighbour has squared distance kth_d2[r] and index kth_idx[r], or when its
 * nth_d2[r] > spread^2 * far_d2[r] (the ref_d2 of its own kmax-th neighbour). */
void ms_stage_isolated(const double *a, const double *b, const double *kth_d2,
                       const int64_t *kth_idx, const int64_t *idx, const double *nth_d2,
                       const double *far_d2, double spread, int64_t begin, int64_t end,
                       uint8_t *out);

/* Thresholds, the global steps of every path (docs/contributing.md,
 * "Normalisation and Otsu"; threshold.py is the numpy reference).
 * ms_extent: max - min of each coordinate of the finite points p (n, 3) into out (3)
 * (numpy's ptp of each column; 0 when n = 0), for the flat rule's bounding box.
 * ms_scale_vote: one scale's decision over x (n). With `normalise`, v is the min-max
 * normalised x, all 0 when max - min <= flat_span (threshold.normalise); else v = x (in
 * [0, 1]). The threshold is T = max(Otsu's split of the MS_BINS-bin histogram of v (bin
 * min(floor(v * MS_BINS), MS_BINS - 1); the split's integer form of the notes, the first
 * largest wins; 1.0 when no split has points on both sides), floor_) with `otsu`, floor_
 * without (no histogram; reference.detect.robust_threshold); then votes[i] += v[i] >= T,
 * the number of such points into *count, and v into out when out is not NULL. Returns T.
 * ms_noise_floor: the least of MS_NOISE_FLOOR * (b + 1) / MS_BINS, b the bin of the
 * lower median of the MS_BINS counts (the first bin whose cumulative count exceeds
 * (total - 1) / 2), and MS_NOISE_FLOOR_MAX; 0 when every count is 0
 * (ms_scale_floor). */
void ms_extent(const double *p, int64_t n, double *out);
double ms_noise_floor(const int64_t *counts);
double ms_scale_vote(const double *x, int64_t n, int normalise, double flat_span, int otsu,
                     double floor_, double *out, int64_t *votes, int64_t *count);

/* The whole detection (detect_api.cpp, the sequence of both modes in detect.cpp): what
 * meshlab_sharp.detect computes for an in-memory input, and what the MeshLab plugin runs.
 *
 * Status codes of ms_detect and ms_parse_scales: success, out of memory, unusable input or
 * options (the message is meant for the user), a defect (the message says what failed). */
#define MS_OK 0
#define MS_ENOMEM (-1)
#define MS_EINPUT (-2)
#define MS_EINTERNAL (-3)

/* Progress: percent done (0 to 100) and a message such as "Sharp features: neighbours and
 * projected distances 45%", with the caller's ctx; called by the thread that called
 * ms_detect only, never concurrently. Its result is ignored. */
typedef int (*ms_progress_fn)(int percent, const char *message, void *ctx);

/* Options of ms_detect; ms_detect_defaults fills in the defaults given here. */
typedef struct {
    int mode;                        /* 0: paper, 1: robust (MS_DEFAULT_MODE) */
    int weighting;                   /* 0: Gaussian, 1: none, plain PCA (MS_DEFAULT_WEIGHTING) */
    int as_points;                   /* 1: ignore the faces (k nearest neighbours); 0 */
    int threads;                     /* threads of the run; 0: one per core the process may use */
    int n_knn_scales;                /* point clouds: 1 to MS_MAX_SCALES scales k, ascending, */
    int knn_scales[MS_MAX_SCALES];   /* each >= MS_MIN_KNN_SCALE (MS_DEFAULT_KNN_SCALES) */
    int n_ring_scales;               /* meshes: 1 to MS_MAX_SCALES rings, ascending, */
    int ring_scales[MS_MAX_SCALES];  /* each >= MS_MIN_RING_SCALE (MS_DEFAULT_RING_SCALES) */
    int details;                     /* 1: keep the per-scale distances and normals
                                        (ms_detection_details); 0 */
} ms_detect_options;

/* A detection's results, owned by the library (ms_detection_free). */
typedef struct ms_detection ms_detection;

/* What ms_detection_counts writes into out (MS_DETECTION_COUNTS values), at these
 * positions: input vertices n; distinct points processed; features; scales used (robust
 * mode grows a noisy cloud's, not their number); 1 when processed as a mesh (k-rings), 0
 * as points (kNN); 1 when every scale is flat (all points on one plane); stages timed
 * (ms_detection_timing). */
#define MS_COUNT_INPUT 0
#define MS_COUNT_CLEAN 1
#define MS_COUNT_FEATURES 2
#define MS_COUNT_SCALES 3
#define MS_COUNT_MESH 4
#define MS_COUNT_ALL_FLAT 5
#define MS_COUNT_TIMINGS 6
#define MS_DETECTION_COUNTS 7

void ms_detect_defaults(ms_detect_options *opt);
/* Detect the sharp features of the n vertices xyz (n, 3) and, unless faces is NULL, m is 0
 * or opt->as_points, of the mesh of the m triangles faces (m, 3) (0-based indices below
 * n); opt NULL: the defaults. The scales it uses (rings of a mesh, k of points) above
 * MS_MAX_RING_SCALE or MS_MAX_KNN_SCALE are MS_EINPUT ("rings must be <= 32, got 40").
 * On MS_OK *out holds the results; otherwise *out is NULL and err (errlen bytes,
 * NUL-terminated, may be NULL) the message. */
int ms_detect(const double *xyz, int64_t n, const int64_t *faces, int64_t m,
              const ms_detect_options *opt, ms_progress_fn progress, void *progress_ctx,
              ms_detection **out, char *err, int errlen);
void ms_detection_counts(const ms_detection *d, int64_t *out);
/* Per input vertex, in input order (each pointer may be NULL): strength (n) the fraction
 * of scales at which it was a candidate (1 on robust mode's sharp mesh edges), feature
 * (n) 1 for a feature, kept (n) 1 when it took part (not a dropped or isolated point). */
void ms_detection_vertices(const ms_detection *d, double *strength, uint8_t *feature,
                           uint8_t *kept);
/* Per scale used (MS_COUNT_SCALES of them; each pointer may be NULL): the scale, its
 * threshold and its number of candidates. */
void ms_detection_scales(const ms_detection *d, int *scales, double *thresholds,
                         int64_t *candidates);
/* Stage i's name (into name, cap bytes, NUL-terminated) and seconds, in order ("" and 0
 * for an i out of range). */
void ms_detection_timing(const ms_detection *d, int i, char *name, int cap, double *seconds);
/* With opt->details, per scale used and input vertex, in input order (each pointer may be
 * NULL; NaN where the vertex took no part): distances (MS_COUNT_SCALES, n) the values the
 * scale's threshold split (the normalised projected distances; in robust mode the
 * relative ones), normals (MS_COUNT_SCALES, n, 3) the unit normals they were measured
 * along. Returns 1, or 0 (nothing written) when the detection kept no details. */
int ms_detection_details(const ms_detection *d, double *distances, double *normals);
void ms_detection_free(ms_detection *d);

/* The scales grammar of the command line (meshlab_sharp.cli.parse_scales): a list
 * "12,16,20" (commas) or "12 16 20" (ASCII white space), never both, or an inclusive
 * range "12:40:4" ("1:4" steps by 1); each number an optional sign and digits, white space
 * around it allowed, at most 2^31 - 1 in magnitude; at most MS_MAX_SCALES; sorted, repeats
 * dropped, each >= minimum. Writes at most cap scales into out and returns their number,
 * or MS_EINPUT with the message in err (errlen bytes, may be NULL). */
int ms_parse_scales(const char *text, int minimum, int *out, int cap, char *err, int errlen);
/* The scales as ms_parse_scales reads them back, "12 16 20", into out (cap bytes,
 * NUL-terminated, cut to fit); returns the length of the whole text. */
int ms_format_scales(const int *scales, int count, char *out, int cap);

/* Feature curves (native/src/curves.cpp: the steps of the numpy reference
 * meshlab_sharp/reference/curves, line for line; the MS_CURVE_ constants above). */

/* Status codes of ms_curves_extract. */
enum {
	MS_CURVES_OK = 0,
	MS_CURVES_ENOMEM = -1, /* out of memory */
	MS_CURVES_EINVAL = -2  /* bad input: see ms_curves_extract */
};

/* Elementwise math over n doubles: out[i] = f(x[i]), or f(y[i], x[i]). */
typedef void (*ms_curves_fn1)(const double *x, double *out, int64_t n);
typedef void (*ms_curves_fn2)(const double *y, const double *x, double *out, int64_t n);

/* The three functions of the curves whose last bits differ between math libraries:
 * exp (the refinement's weights), acos (turn angles) and atan2 (the arms' directions).
 * Each is called on many values at once, from several threads at once. The Python package passes numpy's, so that the
 * library reproduces its numpy reference bit for bit; NULL: the C library's. */
typedef struct ms_curves_math {
	ms_curves_fn1 exp;
	ms_curves_fn1 acos;
	ms_curves_fn2 atan2;
} ms_curves_math;

/* The curves and corners of one extraction (opaque). */
typedef struct ms_curves ms_curves;

/* The feature curves of a detection (meshlab_sharp.curves.extract_curves).
 * vertices: (n, 3) row-major doubles, the input in input order; feature: (n,) 0/1, the
 * detected features; valid: (n,) 0/1, the points that took part in detection, or NULL
 * (all); faces: (m, 3) row-major indices into the vertices, int32 (face_bytes 4) or
 * int64 (face_bytes 8), or NULL (m 0) for a cloud; bounds: {lo x, lo y, lo z, hi x,
 * hi y, hi z}, the bounding box of the whole cloud's valid points when the vertices are
 * only the part of it near the features (out of core), or NULL (the valid vertices' box;
 * ignored on a mesh); math: the elementwise functions to use, or NULL (the C library's).
 * The vertices that are not valid are never read on a cloud: they may lie anywhere. On
 * MS_CURVES_OK *out holds the result (free it with ms_curves_free); on an
 * error *out is NULL. MS_CURVES_EINVAL: n < 0, m < 0, out NULL, vertices, feature or
 * (m > 0) faces NULL, face_bytes not 4 or 8, a mesh (m > 0) of more than 2^31
 * vertices, a face index outside [0, n), or a NaN or infinite coordinate of a valid
 * vertex (of any vertex of a mesh). */
int ms_curves_extract(const double *vertices, const uint8_t *feature, const uint8_t *valid,
                      int64_t n, const void *faces, int face_bytes, int64_t m,
                      const double *bounds, const ms_curves_math *math, ms_curves **out);

/* Curves, their vertices in all, corners; and the spacing the steps are measured in
 * (0 when there is no curve to measure). */
int64_t ms_curves_count(const ms_curves *c);
int64_t ms_curves_vertex_count(const ms_curves *c);
int64_t ms_curves_corner_count(const ms_curves *c);
double ms_curves_spacing(const ms_curves *c);

/* The curves, in their order (by first vertex, last vertex, length), into
 * caller-allocated arrays: sizes (count,) vertices per curve; closed (count,) 0/1
 * (a loop: its last vertex connects to its first, which is not repeated); lengths
 * (count,) polyline lengths (the closing segment included); points (vertex_count, 3)
 * and indices (vertex_count,) the vertices of one curve after the other, with the input
 * vertex each came from. */
void ms_curves_copy(const ms_curves *c, int64_t *sizes, uint8_t *closed, double *lengths,
                    double *points, int64_t *indices);

/* The corners, in coordinate order: points (corner_count, 3) and indices
 * (corner_count,), the input vertex of each. */
void ms_curves_copy_corners(const ms_curves *c, double *points, int64_t *indices);

void ms_curves_free(ms_curves *c);

#if defined(__GNUC__)
#pragma GCC visibility pop
#endif

#ifdef __cplusplus
}
#endif

#endif
