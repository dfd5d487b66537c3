/* The feature curves of meshlab-sharp's native library: their C ABI and their
 * constants, defined here once.
 *
 * Users: the library's curves (native/src/curves.cpp, C++ behind this C ABI); the
 * Python package, which loads the library with ctypes (meshlab_sharp/curves/_native.py)
 * and reads the MS_CURVE_ constants below from this file (meshlab_sharp/_header.py, no
 * compiler needed), for its numpy reference (meshlab_sharp/reference/curves: graph.py,
 * trace.py, extract.py, refine.py) and its classification (meshlab_sharp/curves/fit.py);
 * and the MeshLab plugin, which compiles the same sources. What each constant does and
 * why it has its value is documented beside its Python name (the name without the
 * MS_CURVE_ prefix) in the module named above its group. Lengths are in point spacings,
 * angles in degrees.
 *
 * One `#define MS_CURVE_NAME value` a line: a number, an earlier MS_CURVE_ name, a
 * product or quotient of two floating-point numbers or earlier names in parentheses, or
 * a brace list of integers or of floating-point numbers; _header.py parses exactly these
 * forms. */
#ifndef MESHLAB_SHARP_CURVES_H
#define MESHLAB_SHARP_CURVES_H

/* graph.py: linking the feature points, the skeleton's spurs. */
#define MS_CURVE_LINK_NEIGHBOURS 8
#define MS_CURVE_LINK_RADIUS 2.5
#define MS_CURVE_SPUR_LENGTH 4.0
#define MS_CURVE_MESH_FLAT_WEIGHT 0.05
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
#define MS_CURVE_MIN_ADVANCE 0.3
/* Vertices on each side. */
#define MS_CURVE_LINE_FIT_HALF 2
#define MS_CURVE_RAW_TANGENT_WINDOW (2.0 * MS_CURVE_TANGENT_WINDOW)
#define MS_CURVE_SNAP 0.75
#define MS_CURVE_MAX_CORNER_CONDITION 1e6

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

/* fit.py: line, arc or free-form (Python only: the library does not classify). */
#define MS_CURVE_FIT_TOLERANCE 0.5
#define MS_CURVE_FIT_MAX 4.0
#define MS_CURVE_MAX_RADIUS_RATIO 20.0

/* ---------------------------------------------------------------- the C ABI */

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

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
 * Each is called on many values at once. The Python package passes numpy's, so that the
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
 * hi y, hi z}, the bounding box of the whole cloud when the vertices are only the part
 * of it near the features (out of core), or NULL (the vertices' box; ignored on a
 * mesh); math: the elementwise functions to use, or NULL (the C library's). On
 * MS_CURVES_OK *out holds the result (free it with ms_curves_free); on an
 * error *out is NULL. MS_CURVES_EINVAL: n < 0, m < 0, out NULL, vertices, feature or
 * (m > 0) faces NULL, face_bytes not 4 or 8, a mesh (m > 0) of more than 2^31
 * vertices, or a face index outside [0, n). */
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

#ifdef __cplusplus
}
#endif

#endif
