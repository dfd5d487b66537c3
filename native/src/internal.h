/* The native library's private declarations: what its files share and do not export.
 *
 * Built with -O3 -ffp-contract=off -fno-math-errno -std=c99 (native/CMakeLists.txt and
 * setup.py): no fused multiply-add the code does not write, every product and sum rounded
 * as numpy rounds it, in the order docs/contributing.md pins down; the cloud
 * pass's PCA (pca.c's lanes) writes its fused multiply-adds (fma()) and its own exp, acos
 * and cos, the same bits on every machine (see that page). The library is plain C: loaded
 * with ctypes by the Python package (no Python headers; ctypes releases the GIL during a
 * call, so Python threads run chunks of points on every core) and linked into the MeshLab
 * plugin (std::thread over the same chunks).
 */
#ifndef MESHLAB_SHARP_INTERNAL_H
#define MESHLAB_SHARP_INTERNAL_H

#include "meshlab_sharp.h"

#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#ifdef __SSE2__
#include <emmintrin.h>
#endif
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
/* AVX2 code paths, compiled whatever -m flags the build has, chosen at run time */
#define HAVE_AVX2_PATH 1
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* Functions one file of the library defines for the others: not exported. */
#if defined(__GNUC__)
#define MS_INTERNAL __attribute__((visibility("hidden")))
#else
#define MS_INTERNAL
#endif

/* Whether to take the AVX2 paths (the kNN's block scan, the sheet test's lanes, the
 * PCA's 4 lanes with fused multiply-adds): the CPU has AVX2, FMA and POPCNT, and the
 * environment does not set MESHLAB_SHARP_NO_AVX2. Every path gives the same bits
 * without them (the tests compare both). */
static inline int use_avx2(void) {
#ifdef HAVE_AVX2_PATH
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") &&
           __builtin_cpu_supports("popcnt") && getenv("MESHLAB_SHARP_NO_AVX2") == NULL;
#else
    return 0;
#endif
}

/* ------------------------------------------------------------------ pca.c */

/* The cloud pass's scales side by side: PCA_LANES at a time (pca_lanes). */
#define PCA_LANES 4
typedef void (*pca_lanes_fn)(const double *, const double *, const int64_t *, const double *,
                             const double *, int, int, double *, double *);

/* Unit eigenvector of the smallest eigenvalue of [[a, b, c], [b, d, e], [c, e, f]]. */
MS_INTERNAL void smallest_eigvec(double a, double b, double c, double d, double e, double f,
                                 double *out);
/* The (weighted) scatter of the offsets q (m, 3) about mean, into c (6). */
MS_INTERNAL void scatter(const double *q, int64_t m, const double *mean, const double *w,
                         double *c);
/* Normal and projected distance of one neighbourhood (offsets q, squared lengths d2). */
MS_INTERNAL double neighbourhood_pdis(const double *q, const double *d2, int64_t m,
                                      const double *mean, double h2, int gaussian,
                                      const double *fixed, double *normal, double *mu);
/* The PCA normals of up to PCA_LANES scales at once: AVX2 + FMA when use_avx2(). */
MS_INTERNAL pca_lanes_fn pca_lanes(void);
/* The normals of the scales [s0, s1) of one point, PCA_LANES at a time. */
MS_INTERNAL void pca_scales(pca_lanes_fn pca, const double *q, const double *d2,
                            const int64_t *mk, const double *smean, const double *sh2, int s0,
                            int s1, int gaussian, double *ws, double *snrm);
/* The means and the largest squared distances of the prefixes mk of one list. */
MS_INTERNAL void scale_means(const double *q, const double *d2, const int64_t *mk, int nscales,
                             double *smean, double *sh2);

/* ------------------------------------------------------------------ local_scale.c */

/* numpy's pairwise summation of a[0], a[stride], ... (n terms). */
MS_INTERNAL double pairwise_sum(const double *a, int64_t n, int64_t stride);
/* The local scales of every prefix of one list (local_scale_prefixes_body), compiled
 * for AVX2 when avx2. */
MS_INTERNAL void local_scale_prefixes_on(const double *v, const int64_t *ks, int nscales,
                                         double *ell, double *off, int avx2);
/* local_scale_prefixes' values v (m, 4) of the offsets q (m, 3): |q_j|, then q_j. */
MS_INTERNAL void local_scale_values(const double *q, const double *d2, int64_t m, double *v,
                                    int avx2);
/* robust.noise_scale_factor's ratio at one point. */
MS_INTERNAL double noise_ratio(const double *q, int64_t k);

/* The sum of a segment as numpy's add.reduceat computes it: the first term plus the
 * pairwise sum of the others. */
static inline double segment_sum(const double *a, int64_t n, int64_t stride) {
    if (n == 0) return 0.0;
    return n == 1 ? a[0] : a[0] + pairwise_sum(a + stride, n - 1, stride);
}

/* local_scale_one for the prefixes of one neighbour list at every scale: v holds, for
 * each neighbour j < max(ks), the 4 values |q_j|, then the x, y and z of q_j (v[4 j + t]);
 * scale s (ks increasing) writes ell[s] and off[s]. The same sums as segment_sum, but
 * the 8 partial sums that pairwise_sum keeps over whole blocks of 8 are shared by the
 * prefixes (the same numbers, added in the same order), and so are the terms past the
 * last whole block where two scales end in the same block (the larger's sum goes on from
 * the smaller's): O(max(ks)) per point instead of O(sum of ks) for lists of up to 129
 * points. The 4 sums go side by side (t innermost: the compiler pairs them in SIMD
 * lanes, each lane the scalar arithmetic). */
static inline __attribute__((always_inline)) void local_scale_prefixes_body(
    const double *v, const int64_t *ks, int nscales, double *ell, double *off) {
    /* terms 1..i of each sum in r, i a multiple of 8: the first 8 copied when some list
     * has them (clearing r first cost 2 % of the ring pass's time); else r is unused,
     * cleared so that the compiler sees it set */
    double r[8][4];
    int64_t i = 0;
    if (ks[nscales - 1] > 8) {
        memcpy(r, v + 4, sizeof r);
        i = 8;
    } else {
        memset(r, 0, sizeof r);
    }
    double res[4] = {0.0}; /* the previous scale's pairwise sum: r's blocks up to rb, then */
    int64_t rb = 0, ru = 0; /* the terms rb + 1 .. ru one by one (rb = 0: none kept) */
    for (int s = 0; s < nscales; s++) {
        int64_t m = ks[s], nn = m - 1;
        double sum[4];
        if (nn >= 8 && nn <= 128) {
            int64_t nb = nn - nn % 8;
            for (; i < nb; i += 8) {
                for (int j = 0; j < 8; j++)
                    for (int t = 0; t < 4; t++) r[j][t] += v[4 * (1 + i + j) + t];
            }
            int64_t u = ru;
            if (nb != rb || ru > nn) {
                for (int t = 0; t < 4; t++)
                    res[t] = ((r[0][t] + r[1][t]) + (r[2][t] + r[3][t])) +
                             ((r[4][t] + r[5][t]) + (r[6][t] + r[7][t]));
                u = nb;
            }
            for (; u < nn; u++)
                for (int t = 0; t < 4; t++) res[t] += v[4 * (1 + u) + t];
            rb = nb;
            ru = nn;
            for (int t = 0; t < 4; t++) sum[t] = v[t] + res[t];
        } else if (m >= 1 && nn < 8) {
            /* segment_sum's short form (the first term plus the others in order from
             * -0.0; m = 1: plus -0.0, which changes no double), the 4 sums side by side:
             * a 1-ring's 7 points, without 4 calls */
            for (int t = 0; t < 4; t++) sum[t] = -0.0;
            for (int64_t u = 1; u <= nn; u++)
                for (int t = 0; t < 4; t++) sum[t] += v[4 * u + t];
            for (int t = 0; t < 4; t++) sum[t] = v[t] + sum[t];
        } else {
            for (int t = 0; t < 4; t++) sum[t] = segment_sum(v + t, m, 4);
        }
        if (m == 0) {
            ell[s] = 0.0;
            off[s] = 0.0;
            continue;
        }
        double c = (double)m, mean[4]; /* 4 divisions side by side */
        for (int t = 0; t < 4; t++) mean[t] = sum[t] / c;
        ell[s] = mean[0];
        off[s] = sqrt(mean[1] * mean[1] + mean[2] * mean[2] + mean[3] * mean[3]);
    }
}

/* ------------------------------------------------------------------ sheet.c */

/* robust.sheet_mask's parameters (cloud_out_t's sheet_*), and whether to take the AVX2
 * paths (use_avx2). */
typedef struct {
    double gap;
    int64_t minimum;
    double own, column, column_gap, far_span, trim, trim_cos;
    int avx2;
} sheet_params_t;

/* The sheet filter of one list: keep[j] for its k neighbours; returns how many it drops. */
MS_INTERNAL int64_t sheet_keep(const double *q, const double *d2, int64_t k, const double *nrm,
                               const sheet_params_t *sp, double *hs, int64_t *order,
                               char *keep);
/* The sheet filter's parameters from a pass's outputs. */
MS_INTERNAL sheet_params_t sheet_params(const cloud_out_t *out);

/* ------------------------------------------------------------------ thresholds */

/* Bin of a value in [0, 1] (threshold.c): min(floor(v * MS_BINS), MS_BINS - 1), 0 below 0. */
MS_INTERNAL int64_t ms_value_bin(double v);
/* Otsu's threshold t / MS_BINS from the MS_BINS counts of a histogram; 1.0 when no split
 * has points on both sides. */
MS_INTERNAL double ms_otsu_split(const int64_t *counts);
/* The span of min-max normalisation over [lo, hi], -1 (flat: every value 0) when it is
 * not above flat_span. */
MS_INTERNAL double ms_normal_span(double lo, double hi, double flat_span);

/* ------------------------------------------------------------------ meshes */

/* cross(p1 - p0, p2 - p0) of the triangle (i0, i1, i2) into c; returns its length, the
 * square root of the sum of squares (vcg's DoubleArea of the face). */
static inline double face_cross(const double *p, int64_t i0, int64_t i1, int64_t i2, double *c) {
    const double *p0 = p + 3 * i0, *p1 = p + 3 * i1, *p2 = p + 3 * i2;
    double a0 = p1[0] - p0[0], a1 = p1[1] - p0[1], a2 = p1[2] - p0[2];
    double b0 = p2[0] - p0[0], b1 = p2[1] - p0[1], b2 = p2[2] - p0[2];
    c[0] = a1 * b2 - a2 * b1; c[1] = a2 * b0 - a0 * b2; c[2] = a0 * b1 - a1 * b0;
    return sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
}

/* Unit normal of face f into u: cross(p1 - p0, p2 - p0) / |.| (a zero cross product stays
 * zero), numpy's arithmetic in creases.dihedral_angles and normals.face_average_normals. */
static inline void face_normal(const double *p, const int64_t *faces, int64_t f, double *u) {
    double c[3];
    double len = face_cross(p, faces[3 * f], faces[3 * f + 1], faces[3 * f + 2], c);
    double dv = len > 0 ? len : 1.0;
    u[0] = c[0] / dv; u[1] = c[1] / dv; u[2] = c[2] / dv;
}

/* Whether a face with corners c0, c1, c2, along its winding, goes from its corner lo
 * straight to its corner hi (1) or from hi to lo (0). The two faces of an edge of a
 * consistently wound mesh go opposite ways along it; where they go the same way one of
 * them is wound the other way round (edge_dot). */
static inline int corners_walk_up(int64_t c0, int64_t c1, int64_t c2, int64_t lo, int64_t hi) {
    const int64_t c[3] = {c0, c1, c2};
    const int at = c0 == lo ? 0 : c1 == lo ? 1 : 2;
    return c[(at + 1) % 3] == hi;
}

/* The dot product of the unit normals u and w of an edge's two faces as the two would be
 * wound alike, whatever the winding of either: negated where they go the same way along
 * the edge (same_way: corners_walk_up equal for both), the dihedral angle's cosine of
 * creases.dihedral_angles. */
static inline double edge_dot(const double *u, const double *w, int same_way) {
    const double d = u[0] * w[0] + u[1] * w[1] + u[2] * w[2];
    return same_way ? -d : d;
}

#ifdef __cplusplus
}
#endif

#endif
