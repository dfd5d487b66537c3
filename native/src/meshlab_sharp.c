/* Compiled kernels of meshlab-sharp: kd-tree kNN, k-rings, weighted PCA normals and
 * projected distances, face-average normals, duplicate merging.
 *
 * A plain C library, its ABI and the method's constants declared in _ckernels.h: loaded
 * with ctypes by the Python package (meshlab_sharp/_kernels.py; no Python headers are
 * needed to build it, and ctypes releases the GIL during a call, so Python threads run
 * chunks of points on every core) and compiled into the MeshLab plugin
 * (meshlab_plugin_cpp/src/sharp_core.cpp, std::thread over the same chunks). Built by setuptools (setup.py) with
 * -ffp-contract=off: no fused multiply-add the code does not write, every product and
 * sum rounded as numpy rounds it, in the order docs/implementation-notes.md pins down;
 * the cloud pass's PCA (pca_lanes) writes its fused multiply-adds (fma()) and its own
 * exp, acos and cos, the same bits on every machine (see that page).
 */
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

/* Whether to take the AVX2 paths (the kNN's block scan, the sheet test's lanes, the
 * PCA's 4 lanes with fused multiply-adds): the CPU has AVX2, FMA and POPCNT, and the
 * environment does not set MESHLAB_SHARP_NO_AVX2. Every path gives the same bits
 * without them (the tests compare both). */
static int use_avx2(void) {
#ifdef HAVE_AVX2_PATH
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") &&
           __builtin_cpu_supports("popcnt") && getenv("MESHLAB_SHARP_NO_AVX2") == NULL;
#else
    return 0;
#endif
}

#if defined(__x86_64__) && defined(__GLIBC__) && defined(MS_LIBMVEC)
#include <emmintrin.h>
/* glibc's libmvec: exp of two doubles at once (SSE2, any x86-64), within 1 ulp of
 * exp(); about 2.5x faster than two calls of exp() here. */
__m128d _ZGVbN2v_exp(__m128d);
#define HAVE_VEXP 1
#endif

/* mu[j] = exp(-d2[j] / h2), j < m */
static void gaussian_weights(const double *d2, int64_t m, double h2, double *mu) {
    int64_t j = 0;
#ifdef HAVE_VEXP
    __m128d hh = _mm_set1_pd(h2), zero = _mm_setzero_pd();
    for (; j + 2 <= m; j += 2) {
        __m128d a = _mm_div_pd(_mm_sub_pd(zero, _mm_loadu_pd(d2 + j)), hh);
        _mm_storeu_pd(mu + j, _ZGVbN2v_exp(a));
    }
#endif
    for (; j < m; j++) mu[j] = exp(-d2[j] / h2);
}

/* ------------------------------------------------------------------ 3x3 eigenvector */

/* Unit eigenvector of the smallest eigenvalue of the symmetric matrix
 * [[a, b, c], [b, d, e], [c, e, f]]: eigenvalue in closed form (trigonometric), vector
 * as the largest cross product of two rows of A - lambda I. Agrees with LAPACK's
 * dsyevd to about 1e-16 when the smallest eigenvalue is well separated (error ~
 * eps * |A| / gap, as for LAPACK itself). */
static void smallest_eigvec(double a, double b, double c, double d, double e, double f,
                            double *out) {
    double p1 = b * b + c * c + e * e;
    double scale = fabs(a) + fabs(b) + fabs(c) + fabs(d) + fabs(e) + fabs(f);
    if (scale == 0.0) {
        out[0] = 1.0; out[1] = 0.0; out[2] = 0.0;
        return;
    }
    if (p1 == 0.0) {
        int k = 0;
        if (d < a) k = 1;
        if (f < (k == 0 ? a : d)) k = 2;
        out[0] = k == 0; out[1] = k == 1; out[2] = k == 2;
        return;
    }
    /* scale by a power of two (exact) to O(1), for range safety: s = 2^-e with scale =
     * f 2^e, f in [0.5, 1) (frexp), built from the exponent bits when s is normal */
    double s;
    uint64_t bits;
    memcpy(&bits, &scale, sizeof bits);
    int64_t biased = (int64_t)(bits >> 52); /* scale > 0: no sign bit */
    if (biased >= 1 && biased <= 2044) {
        bits = (uint64_t)(2045 - biased) << 52;
        memcpy(&s, &bits, sizeof s);
    } else {
        int ex;
        frexp(scale, &ex);
        s = ldexp(1.0, -ex);
    }
    a *= s; b *= s; c *= s; d *= s; e *= s; f *= s;
    p1 = b * b + c * c + e * e;
    double q = (a + d + f) / 3.0;
    double p2 = (a - q) * (a - q) + (d - q) * (d - q) + (f - q) * (f - q) + 2.0 * p1;
    double p = sqrt(p2 / 6.0);
    double ip = 1.0 / p;
    double B00 = (a - q) * ip, B11 = (d - q) * ip, B22 = (f - q) * ip;
    double B01 = b * ip, B02 = c * ip, B12 = e * ip;
    double r = 0.5 * (B00 * (B11 * B22 - B12 * B12) - B01 * (B01 * B22 - B12 * B02) +
                      B02 * (B01 * B12 - B11 * B02));
    if (r < -1.0) r = -1.0;
    if (r > 1.0) r = 1.0;
    double phi = acos(r) / 3.0;
    double lam = q + 2.0 * p * cos(phi + 2.0943951023931954923);
    double r0[3] = {a - lam, b, c}, r1[3] = {b, d - lam, e}, r2[3] = {c, e, f - lam};
    double x[3][3];
    x[0][0] = r0[1] * r1[2] - r0[2] * r1[1];
    x[0][1] = r0[2] * r1[0] - r0[0] * r1[2];
    x[0][2] = r0[0] * r1[1] - r0[1] * r1[0];
    x[1][0] = r0[1] * r2[2] - r0[2] * r2[1];
    x[1][1] = r0[2] * r2[0] - r0[0] * r2[2];
    x[1][2] = r0[0] * r2[1] - r0[1] * r2[0];
    x[2][0] = r1[1] * r2[2] - r1[2] * r2[1];
    x[2][1] = r1[2] * r2[0] - r1[0] * r2[2];
    x[2][2] = r1[0] * r2[1] - r1[1] * r2[0];
    double best = -1.0;
    int bi = 0;
    for (int i = 0; i < 3; i++) {
        double nn = x[i][0] * x[i][0] + x[i][1] * x[i][1] + x[i][2] * x[i][2];
        if (nn > best) { best = nn; bi = i; }
    }
    double v0, v1, v2;
    if (!(best > 0.0)) {
        v0 = 1.0; v1 = 0.0; v2 = 0.0;
    } else {
        double inv = 1.0 / sqrt(best);
        v0 = x[bi][0] * inv; v1 = x[bi][1] * inv; v2 = x[bi][2] * inv;
    }
    out[0] = v0; out[1] = v1; out[2] = v2;
}

/* Batch version (for tests): cov (c, 6) as a00 a01 a02 a11 a12 a22. */
void ms_eigvecs(const double *cov, int64_t c, double *out) {
    for (int64_t i = 0; i < c; i++) {
        const double *m = cov + 6 * i;
        smallest_eigvec(m[0], m[1], m[2], m[3], m[4], m[5], out + 3 * i);
    }
}

/* ------------------------------------------------------------------ per-point arithmetic */

/* The scatter sum_j w_j (q_j - mean)(q_j - mean)^T of the offsets q (m, 3), weights w
 * (m) or NULL (all 1), into c as c00 c01 c02 c11 c12 c22: each entry summed over j in
 * order from 0, of the products (w_j r_a) r_b, r = q_j - mean. */
static inline void scatter(const double *q, int64_t m, const double *mean, const double *w,
                           double *c) {
#ifdef __SSE2__
    /* two entries a lane: (c00, c01), (c02, c11), (c12, c22) */
    __m128d a0 = _mm_setzero_pd(), a1 = a0, a2 = a0;
    __m128d mxy = _mm_loadu_pd(mean), mzz = _mm_set1_pd(mean[2]);
    for (int64_t j = 0; j < m; j++) {
        __m128d r = _mm_sub_pd(_mm_loadu_pd(q + 3 * j), mxy);         /* rx ry */
        __m128d rz = _mm_sub_pd(_mm_set1_pd(q[3 * j + 2]), mzz);      /* rz rz */
        __m128d wj = _mm_set1_pd(w ? w[j] : 1.0);
        __m128d s = _mm_mul_pd(wj, r), sz = _mm_mul_pd(wj, rz);       /* mx my, mz mz */
        a0 = _mm_add_pd(a0, _mm_mul_pd(_mm_unpacklo_pd(s, s), r));   /* mx rx, mx ry */
        a1 = _mm_add_pd(a1, _mm_mul_pd(s, _mm_shuffle_pd(rz, r, 2))); /* mx rz, my ry */
        a2 = _mm_add_pd(a2, _mm_mul_pd(_mm_shuffle_pd(s, sz, 1), rz)); /* my rz, mz rz */
    }
    _mm_storeu_pd(c, a0);
    _mm_storeu_pd(c + 2, a1);
    _mm_storeu_pd(c + 4, a2);
#else
    double c00 = 0, c01 = 0, c02 = 0, c11 = 0, c12 = 0, c22 = 0;
    for (int64_t j = 0; j < m; j++) {
        double rx = q[3 * j] - mean[0], ry = q[3 * j + 1] - mean[1], rz = q[3 * j + 2] - mean[2];
        double wj = w ? w[j] : 1.0;
        double mx = wj * rx, my = wj * ry, mz = wj * rz;
        c00 += mx * rx; c01 += mx * ry; c02 += mx * rz;
        c11 += my * ry; c12 += my * rz; c22 += mz * rz;
    }
    c[0] = c00; c[1] = c01; c[2] = c02; c[3] = c11; c[4] = c12; c[5] = c22;
#endif
}

/* Normal and projected distance of one neighbourhood given as offsets q (m, 3) from
 * the point and their squared lengths d2 (m); see docs/implementation-notes.md.
 * fixed: a fixed unit normal or NULL (PCA). h2 is max d2 (given). */
static inline double neighbourhood_pdis(const double *q, const double *d2, int64_t m,
                                        const double *mean, double h2, int gaussian,
                                        const double *fixed, double *normal, double *mu) {
    double nrm[3];
    if (fixed != NULL) {
        nrm[0] = fixed[0]; nrm[1] = fixed[1]; nrm[2] = fixed[2];
    } else {
        int w = gaussian && h2 > 0.0;
        if (w) gaussian_weights(d2, m, h2, mu);
        double c[6];
        scatter(q, m, mean, w ? mu : NULL, c);
        smallest_eigvec(c[0], c[1], c[2], c[3], c[4], c[5], nrm);
    }
    if (normal != NULL) {
        normal[0] = nrm[0]; normal[1] = nrm[1]; normal[2] = nrm[2];
    }
    return fabs(mean[0] * nrm[0] + mean[1] * nrm[1] + mean[2] * nrm[2]);
}

/* ------------------------------------------------------------------ four scales at once */

/* The PCA normals of up to four scales of one point side by side, one lane each (the
 * cloud pass's scales: the first m of the same offsets, m increasing), written once on
 * vectors of 4 doubles (the GCC / Clang vector extension) and compiled twice: with AVX2
 * and FMA (chosen at run time) and plain. Every operation in it is correctly rounded
 * (+, -, *, /, sqrt, and fma(), exact then rounded once, on every machine), so both
 * builds give the same bits; docs/implementation-notes.md says how this differs from
 * the numpy reference. */
#if defined(__GNUC__) && !defined(__clang__)
/* the helpers below pass vectors only inlined: no ABI to keep */
#pragma GCC diagnostic ignored "-Wpsabi"
#endif
typedef double v4d __attribute__((vector_size(32)));
typedef int64_t v4i __attribute__((vector_size(32)));
typedef uint64_t v4u __attribute__((vector_size(32)));
/* a v4d in memory at any 8-byte alignment (malloc's buffers) */
typedef double v4d_mem __attribute__((vector_size(32), aligned(8)));
#define PCA_LANES 4
#define LANES_INLINE static inline __attribute__((always_inline))

LANES_INLINE v4d v4_set1(double x) { return (v4d){x, x, x, x}; }

LANES_INLINE v4d v4_fma(v4d a, v4d b, v4d c) {
    return (v4d){fma(a[0], b[0], c[0]), fma(a[1], b[1], c[1]), fma(a[2], b[2], c[2]),
                 fma(a[3], b[3], c[3])};
}

LANES_INLINE v4d v4_sqrt(v4d a) { return (v4d){sqrt(a[0]), sqrt(a[1]), sqrt(a[2]), sqrt(a[3])}; }

/* a where the mask m is set (all ones), else b */
LANES_INLINE v4d v4_sel(v4i m, v4d a, v4d b) { return (v4d)((m & (v4i)a) | (~m & (v4i)b)); }

/* 1 / n!, n = 13 down to 2: exp's Taylor coefficients */
static const double exp_coef[12] = {
    1.0 / 6227020800.0, 1.0 / 479001600.0, 1.0 / 39916800.0, 1.0 / 3628800.0,
    1.0 / 362880.0,     1.0 / 40320.0,     1.0 / 5040.0,      1.0 / 720.0,
    1.0 / 120.0,        1.0 / 24.0,        1.0 / 6.0,         0.5};

/* exp(x) for x in [-708, 708] (other lanes: any bits), within about 1 ulp: x = k ln2 + r
 * (k rounded to nearest by the shifter 1.5 2^52, ln2 in two parts, |r| <= ln2 / 2),
 * exp(r) by its Taylor polynomial of degree 13 (truncation below 1e-17; Horner's rule
 * in fused multiply-adds), times 2^k added to the exponent bits. */
LANES_INLINE v4d v4_exp(v4d x) {
    const v4d shifter = v4_set1(0x1.8p52);
    v4d t = v4_fma(x, v4_set1(0x1.71547652b82fep0), shifter); /* k + shifter */
    v4d k = t - shifter;
    v4d r = v4_fma(k, v4_set1(-0x1.62e42fefa3800p-1), x);
    r = v4_fma(k, v4_set1(-0x1.ef35793c76730p-45), r);
    v4d p = v4_set1(exp_coef[0]);
#pragma GCC unroll 12
    for (int i = 1; i < 12; i++) p = v4_fma(p, r, v4_set1(exp_coef[i]));
    p = v4_fma(p, r, v4_set1(1.0));
    p = v4_fma(p, r, v4_set1(1.0));
    return (v4d)((v4u)p + ((v4u)t << 52)); /* k in t's low bits, the shifter's are 0 */
}

/* asin(s) = s + s z P(z) / Q(z), z = s^2 <= 1/4: fdlibm's rational (e_asin.c), P and Q
 * from their highest coefficient (Q's constant term 1) */
static const double asin_p[6] = {3.47933107596021167570e-05, 7.91534994289814532176e-04,
                                 -4.00555345006794114027e-02, 2.01212532134862925881e-01,
                                 -3.25565818622400915405e-01, 1.66666666666666657415e-01};
static const double asin_q[4] = {7.70381505559019352791e-02, -6.88283971605453293030e-01,
                                 2.02094576023350569471e+00, -2.40339491173441421878e+00};
/* (-1)^n / (2n)!, n = 9 down to 1: cos's Taylor coefficients */
static const double cos_coef[9] = {-1.0 / 6402373705728000.0, 1.0 / 20922789888000.0,
                                   -1.0 / 87178291200.0, 1.0 / 479001600.0, -1.0 / 3628800.0,
                                   1.0 / 40320.0, -1.0 / 720.0, 1.0 / 24.0, -0.5};

/* cos(acos(x) / 3 + 2 pi / 3), x clamped to [-1, 1] (NaN kept): the cosine of the
 * smallest eigenvalue's angle, in [-1, -1/2], within 3e-16. acos(x) from asin: of x when
 * |x| <= 1/2, else of sqrt((1 - |x|) / 2); then u = (acos(x) - pi) / 3 in [-pi/3, 0] (pi
 * and pi/2 in two parts) and the value -cos(u) by its Taylor polynomial of degree 18
 * (truncation below 1e-18). */
LANES_INLINE v4d v4_cos_third_acos(v4d x) {
    const v4i sign = (v4i)v4_set1(-0.0);
    x = v4_sel(x < v4_set1(-1.0), v4_set1(-1.0), x);
    x = v4_sel(x > v4_set1(1.0), v4_set1(1.0), x);
    v4d ax = (v4d)((v4i)x & ~sign);
    v4i big = ax > v4_set1(0.5);
    v4d z = v4_sel(big, (1.0 - ax) * 0.5, x * x);
    v4d s = v4_sel(big, v4_sqrt(z), ax);
    v4d p = v4_set1(asin_p[0]), qd = v4_set1(asin_q[0]);
#pragma GCC unroll 6
    for (int i = 1; i < 6; i++) p = v4_fma(p, z, v4_set1(asin_p[i]));
#pragma GCC unroll 4
    for (int i = 1; i < 4; i++) qd = v4_fma(qd, z, v4_set1(asin_q[i]));
    qd = v4_fma(qd, z, v4_set1(1.0));
    v4d as = v4_fma(s * z, p / qd, s); /* asin(s) */
    /* acos(x) - pi: -pi/2 - asin(x) when |x| <= 1/2, else 2 asin(s) - pi (x > 0) or
     * -2 asin(s) (x < 0) */
    v4d asx = (v4d)((v4i)as | ((v4i)x & sign));
    v4d t_small = -(v4_set1(0x1.921fb54442d18p0) + (asx + v4_set1(0x1.1a62633145c07p-54)));
    v4d t_pos = (2.0 * as - v4_set1(0x1.921fb54442d18p1)) - v4_set1(0x1.1a62633145c07p-53);
    v4d t = v4_sel(big, v4_sel(x > 0.0, t_pos, -2.0 * as), t_small);
    v4d u = t / 3.0;
    v4d v = u * u;
    v4d c = v4_set1(cos_coef[0]);
#pragma GCC unroll 9
    for (int i = 1; i < 9; i++) c = v4_fma(c, v, v4_set1(cos_coef[i]));
    return -v4_fma(c, v, v4_set1(1.0));
}

/* The power of two smallest_eigvec scales each lane's matrix [[a, b, c], [b, d, e],
 * [c, e, f]] by, or 0 where smallest_eigvec takes another branch for it (zero matrix,
 * diagonal, a scale not built from the exponent bits). */
LANES_INLINE v4d v4_eig_scale(v4d a, v4d b, v4d c, v4d d, v4d e, v4d f) {
    const v4i magnitude = ~(v4i)v4_set1(-0.0);
    v4d p1 = b * b + c * c + e * e;
    v4d scale = (v4d)((v4i)a & magnitude) + (v4d)((v4i)b & magnitude) +
                (v4d)((v4i)c & magnitude) + (v4d)((v4i)d & magnitude) +
                (v4d)((v4i)e & magnitude) + (v4d)((v4i)f & magnitude);
    v4i biased = (v4i)((v4u)scale >> 52); /* a sign bit (NaN) makes it > 2044 */
    v4i ok = (scale != 0.0) & (p1 != 0.0) & (biased >= 1) & (biased <= 2044);
    return (v4d)(((v4u)(2045 - biased) << 52) & (v4u)ok);
}

/* The normals nrm (3 a lane) of lanes l < count: the PCA of the first m[l] offsets q
 * (m, 3) with squared lengths d2, mean mean[3 l ..], weighted by exp(-d2 / h2[l]) when
 * gaussian and h2[l] > 0 (else 1; v4_exp): the weighted scatter summed in order from
 * the first offset with fused multiply-adds, then smallest_eigvec's closed form (its
 * angle by v4_cos_third_acos). ws: room for 4 max(m) doubles (the weights). */
LANES_INLINE void pca_lanes_body(const double *q, const double *d2, const int64_t *m,
                                 const double *mean, const double *h2, int count, int gaussian,
                                 double *ws, double *nrm) {
    double mm[3][PCA_LANES] = {{0}}, hh[PCA_LANES] = {0};
    int64_t mi[PCA_LANES] = {0}, mmax = 0;
    for (int l = 0; l < count; l++) {
        for (int a = 0; a < 3; a++) mm[a][l] = mean[3 * l + a];
        hh[l] = gaussian && h2[l] > 0.0 ? -h2[l] : -INFINITY; /* exp(d2 / -inf) = 1 */
        mi[l] = m[l];
        if (m[l] > mmax) mmax = m[l];
    }
    v4d mx = {mm[0][0], mm[0][1], mm[0][2], mm[0][3]};
    v4d my = {mm[1][0], mm[1][1], mm[1][2], mm[1][3]};
    v4d mz = {mm[2][0], mm[2][1], mm[2][2], mm[2][3]};
    v4d vh2 = {hh[0], hh[1], hh[2], hh[3]}; /* -h2: d2 / -h2 = -(d2 / h2), to the bit */
    v4i vm = {mi[0], mi[1], mi[2], mi[3]};
    v4d c00 = v4_set1(0.0), c01 = c00, c02 = c00, c11 = c00, c12 = c00, c22 = c00;
    v4i vj = {0, 0, 0, 0};
    /* the weights first, then their sums (the same operations): each exp is a chain of
     * 16 dependent fused multiply-adds, and a loop of exps alone keeps more of them in
     * flight than one that also holds the sums (the pass's 8 scales: 0.68 against 0.84
     * us a point, docs/benchmark-history.md, "Session 11") */
    v4d_mem *w4 = (v4d_mem *)ws;
    for (int64_t j = 0; j < mmax; j++) w4[j] = v4_exp(d2[j] / vh2);
    for (int64_t j = 0; j < mmax; j++, vj += 1) {
        /* the weight, 0 past each lane's m (there the exponent may lie outside exp's
         * range: -d2 / h2 is in [-1, 0] only over the lane's own m offsets) */
        v4d w = (v4d)((v4i)w4[j] & (vj < vm));
        v4d rx = q[3 * j] - mx, ry = q[3 * j + 1] - my, rz = q[3 * j + 2] - mz;
        v4d sx = w * rx, sy = w * ry, sz = w * rz;
        c00 = v4_fma(sx, rx, c00);
        c01 = v4_fma(sx, ry, c01);
        c02 = v4_fma(sx, rz, c02);
        c11 = v4_fma(sy, ry, c11);
        c12 = v4_fma(sy, rz, c12);
        c22 = v4_fma(sz, rz, c22);
    }
    /* smallest_eigvec on each lane, its power-of-two scale first (a lane whose matrix
     * takes another branch there goes through smallest_eigvec itself, below) */
    v4d s = v4_eig_scale(c00, c01, c02, c11, c12, c22);
    v4d a = c00 * s, b = c01 * s, c = c02 * s, d = c11 * s, e = c12 * s, f = c22 * s;
    v4d p1 = b * b + c * c + e * e;
    v4d qq = (a + d + f) / 3.0;
    v4d aq = a - qq, dq = d - qq, fq = f - qq;
    v4d p = v4_sqrt((aq * aq + dq * dq + fq * fq + 2.0 * p1) / 6.0);
    v4d ip = 1.0 / p;
    v4d B00 = aq * ip, B11 = dq * ip, B22 = fq * ip, B01 = b * ip, B02 = c * ip, B12 = e * ip;
    v4d r = 0.5 * (B00 * (B11 * B22 - B12 * B12) - B01 * (B01 * B22 - B12 * B02) +
                   B02 * (B01 * B12 - B11 * B02));
    v4d lam = qq + 2.0 * p * v4_cos_third_acos(r);
    v4d r00 = a - lam, r11 = d - lam, r22 = f - lam;
    /* the cross products of the rows (r00, b, c), (b, r11, e), (c, e, r22), and the
     * longest (the first of equals) */
    v4d x[3][3] = {{b * e - c * r11, c * b - r00 * e, r00 * r11 - b * b},
                   {b * r22 - c * e, c * c - r00 * r22, r00 * e - b * c},
                   {r11 * r22 - e * e, e * c - b * r22, b * e - r11 * c}};
    v4d best = v4_set1(-1.0), v0 = x[0][0], v1 = x[0][1], v2 = x[0][2];
    for (int i = 0; i < 3; i++) {
        v4d nn = x[i][0] * x[i][0] + x[i][1] * x[i][1] + x[i][2] * x[i][2];
        v4i longer = nn > best;
        best = v4_sel(longer, nn, best);
        v0 = v4_sel(longer, x[i][0], v0);
        v1 = v4_sel(longer, x[i][1], v1);
        v2 = v4_sel(longer, x[i][2], v2);
    }
    v4i ok = best > 0.0;
    v4d inv = 1.0 / v4_sqrt(best);
    v0 = v4_sel(ok, v0 * inv, v4_set1(1.0));
    v1 = v4_sel(ok, v1 * inv, v4_set1(0.0));
    v2 = v4_sel(ok, v2 * inv, v4_set1(0.0));
    for (int l = 0; l < count; l++) {
        double *o = nrm + 3 * l;
        if (s[l] == 0.0) {
            smallest_eigvec(c00[l], c01[l], c02[l], c11[l], c12[l], c22[l], o);
        } else {
            o[0] = v0[l]; o[1] = v1[l]; o[2] = v2[l];
        }
    }
}

typedef void (*pca_lanes_fn)(const double *, const double *, const int64_t *, const double *,
                             const double *, int, int, double *, double *);

static void pca_lanes_plain(const double *q, const double *d2, const int64_t *m,
                            const double *mean, const double *h2, int count, int gaussian,
                            double *ws, double *nrm) {
    pca_lanes_body(q, d2, m, mean, h2, count, gaussian, ws, nrm);
}

#ifdef HAVE_AVX2_PATH
__attribute__((target("avx2,fma"))) static void pca_lanes_avx2(const double *q,
                                                               const double *d2,
                                                               const int64_t *m,
                                                               const double *mean,
                                                               const double *h2, int count,
                                                               int gaussian, double *ws,
                                                               double *nrm) {
    pca_lanes_body(q, d2, m, mean, h2, count, gaussian, ws, nrm);
}
#endif

/* The pca_lanes to use: AVX2 + FMA when use_avx2(); the same
 * bits either way (the tests compare both). */
static pca_lanes_fn pca_lanes(void) {
#ifdef HAVE_AVX2_PATH
    if (use_avx2()) return pca_lanes_avx2;
#endif
    return pca_lanes_plain;
}

/* The normals snrm (3 a scale) of the scales [s0, s1) of one point (mk, smean, sh2 as
 * scale_means gives them), PCA_LANES at a time; ws: room for PCA_LANES mk[s1 - 1]
 * doubles. */
static void pca_scales(pca_lanes_fn pca, const double *q, const double *d2, const int64_t *mk,
                       const double *smean, const double *sh2, int s0, int s1, int gaussian,
                       double *ws, double *snrm) {
    for (int s = s0; s < s1; s += PCA_LANES) {
        int count = s1 - s < PCA_LANES ? s1 - s : PCA_LANES;
        pca(q, d2, mk + s, smean + 3 * s, sh2 + s, count, gaussian, ws, snrm + 3 * s);
    }
}

/* Each scale's mean offset smean (3 a scale) and largest squared distance sh2 over the
 * first mk[s] offsets q with squared lengths d2 (mk increasing): one running sum, in
 * order from the first offset. */
static void scale_means(const double *q, const double *d2, const int64_t *mk, int nscales,
                        double *smean, double *sh2) {
    double sx = 0, sy = 0, sz = 0, h2 = 0;
    int64_t j = 0;
    for (int s = 0; s < nscales; s++) {
        int64_t m = mk[s];
        for (; j < m; j++) {
            sx += q[3 * j]; sy += q[3 * j + 1]; sz += q[3 * j + 2];
            if (d2[j] > h2) h2 = d2[j];
        }
        smean[3 * s] = sx / (double)m;
        smean[3 * s + 1] = sy / (double)m;
        smean[3 * s + 2] = sz / (double)m;
        sh2[s] = h2;
    }
}

/* ------------------------------------------------------------------ robust mode */

/* numpy's pairwise summation of a[0], a[stride], ... (n terms), as its add.reduce
 * inner loop computes it (numpy/_core/src/umath/loops_utils.h.src): fewer than 8
 * terms summed in order from -0.0; up to 128 in 8 interleaved partial sums, combined
 * as ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7)), then the remainder in order;
 * more split in two at a multiple of 8. */
static double pairwise_sum(const double *a, int64_t n, int64_t stride) {
    if (n < 8) {
        double res = -0.0;
        for (int64_t i = 0; i < n; i++) res += a[i * stride];
        return res;
    }
    if (n <= 128) {
        double r[8];
        for (int j = 0; j < 8; j++) r[j] = a[j * stride];
        int64_t i = 8;
        for (; i < n - (n % 8); i += 8) {
            for (int j = 0; j < 8; j++) r[j] += a[(i + j) * stride];
        }
        double res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for (; i < n; i++) res += a[i * stride];
        return res;
    }
    int64_t n2 = n / 2;
    n2 -= n2 % 8;
    return pairwise_sum(a, n2, stride) + pairwise_sum(a + n2 * stride, n - n2, stride);
}

/* The sum of a segment as numpy's add.reduceat computes it: the first term plus the
 * pairwise sum of the others. */
static inline double segment_sum(const double *a, int64_t n, int64_t stride) {
    if (n == 0) return 0.0;
    return n == 1 ? a[0] : a[0] + pairwise_sum(a + stride, n - 1, stride);
}

/* robust.local_scale of one neighbourhood: offsets q (m, 3) from the point, their
 * lengths dist (m): *ell = (sum dist) / m, *off = |(sum q) / m| (0, 0 when m = 0). */
static inline void local_scale_one(const double *q, const double *dist, int64_t m, double *ell,
                                   double *off) {
    if (m == 0) { *ell = 0.0; *off = 0.0; return; }
    double c = (double)m;
    *ell = segment_sum(dist, m, 1) / c;
    double cx = segment_sum(q, m, 3) / c, cy = segment_sum(q + 1, m, 3) / c,
           cz = segment_sum(q + 2, m, 3) / c;
    *off = sqrt(cx * cx + cy * cy + cz * cz);
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

/* local_scale_prefixes_body, for any x86-64 (or other) CPU. */
static void local_scale_prefixes(const double *v, const int64_t *ks, int nscales, double *ell,
                                 double *off) {
    local_scale_prefixes_body(v, ks, nscales, ell, off);
}

#ifdef HAVE_AVX2_PATH
/* The same compiled for AVX2: the 4 sums side by side in one register (additions only,
 * each lane the scalar arithmetic). */
__attribute__((target("avx2"))) static void local_scale_prefixes_avx2(const double *v,
                                                                      const int64_t *ks,
                                                                      int nscales, double *ell,
                                                                      double *off) {
    local_scale_prefixes_body(v, ks, nscales, ell, off);
}
#endif

/* local_scale_prefixes, compiled for AVX2 when avx2. */
static inline void local_scale_prefixes_on(const double *v, const int64_t *ks, int nscales,
                                           double *ell, double *off, int avx2) {
#ifdef HAVE_AVX2_PATH
    if (avx2) {
        local_scale_prefixes_avx2(v, ks, nscales, ell, off);
        return;
    }
#endif
    (void)avx2;
    local_scale_prefixes(v, ks, nscales, ell, off);
}

/* local_scale_prefixes' values v (m, 4) of the offsets q (m, 3) with squared lengths d2
 * (m): |q_j| = sqrt(d2_j), then q_j. */
static void local_scale_values_plain(const double *q, const double *d2, int64_t m, double *v) {
    for (int64_t j = 0; j < m; j++) {
        v[4 * j] = sqrt(d2[j]);
        v[4 * j + 1] = q[3 * j];
        v[4 * j + 2] = q[3 * j + 1];
        v[4 * j + 3] = q[3 * j + 2];
    }
}

#ifdef HAVE_AVX2_PATH
/* local_scale_values_plain with 4 square roots an instruction (AVX: correctly rounded,
 * as sqrt) and each row one load of q (from the previous row's z) and one store; the
 * last rows as one more block of 4 ending at row m - 1, over rows already written (the
 * same values again), when m - 1 is not a multiple of 4. */
__attribute__((target("avx2"))) static void local_scale_values_avx2(const double *q,
                                                                    const double *d2, int64_t m,
                                                                    double *v) {
    if (m < 5) {
        local_scale_values_plain(q, d2, m, v);
        return;
    }
    local_scale_values_plain(q, d2, 1, v);
    double r[4];
    for (int64_t j = 1; j < m; j += 4) {
        if (j + 4 > m) j = m - 4;
        _mm256_storeu_pd(r, _mm256_sqrt_pd(_mm256_loadu_pd(d2 + j)));
        for (int l = 0; l < 4; l++) {
            __m256d row = _mm256_loadu_pd(q + 3 * (j + l) - 1); /* z of the row before */
            _mm256_storeu_pd(v + 4 * (j + l), _mm256_blend_pd(row, _mm256_broadcast_sd(r + l), 1));
        }
    }
}
#endif

/* local_scale_values_plain, on 4 lanes when avx2. */
static inline void local_scale_values(const double *q, const double *d2, int64_t m, double *v,
                                      int avx2) {
#ifdef HAVE_AVX2_PATH
    if (avx2) {
        local_scale_values_avx2(q, d2, m, v);
        return;
    }
#endif
    (void)avx2;
    local_scale_values_plain(q, d2, m, v);
}

/* robust.local_scale over CSR lists (indptr, indices int32 or int64 when wide), points
 * [begin, end): out_ell, out_off (n). Returns 0, or -1 out of memory. */
int ms_local_scale_csr(const double *p, const int64_t *indptr, const void *indices, int wide,
                       int64_t begin, int64_t end, double *out_ell, double *out_off) {
    int64_t cap = 0;
    double *q = NULL, *dist = NULL;
    for (int64_t i = begin; i < end; i++) {
        int64_t s = indptr[i], m = indptr[i + 1] - s;
        if (m > cap) {
            cap = m > 2 * cap ? m : 2 * cap;
            free(q); free(dist);
            q = (double *)malloc((size_t)cap * 3 * sizeof(double));
            dist = (double *)malloc((size_t)cap * sizeof(double));
            if (!q || !dist) { free(q); free(dist); return -1; }
        }
        const double *pi = p + 3 * i;
        for (int64_t j = 0; j < m; j++) {
            int64_t v = wide ? ((const int64_t *)indices)[s + j] : ((const int32_t *)indices)[s + j];
            const double *pj = p + 3 * v;
            double x = pj[0] - pi[0], y = pj[1] - pi[1], z = pj[2] - pi[2];
            q[3 * j] = x; q[3 * j + 1] = y; q[3 * j + 2] = z;
            dist[j] = sqrt(x * x + y * y + z * z);
        }
        local_scale_one(q, dist, m, out_ell + i, out_off + i);
    }
    free(q);
    free(dist);
    return 0;
}

/* robust.noise_scale_factor's ratio at one point: offsets q (k, 3) of its k nearest
 * (itself first, then its nearest neighbour): |d . n| / |d| with d = q[1] and n the
 * unweighted PCA normal of the k offsets (0 when |d| = 0). */
static double noise_ratio(const double *q, int64_t k) {
    double sx = 0, sy = 0, sz = 0;
    for (int64_t j = 0; j < k; j++) { sx += q[3 * j]; sy += q[3 * j + 1]; sz += q[3 * j + 2]; }
    double mean[3] = {sx / (double)k, sy / (double)k, sz / (double)k}, c[6], nrm[3];
    scatter(q, k, mean, NULL, c);
    smallest_eigvec(c[0], c[1], c[2], c[3], c[4], c[5], nrm);
    const double *d = q + 3;
    double length = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    double across = fabs(d[0] * nrm[0] + d[1] * nrm[1] + d[2] * nrm[2]);
    return length > 0 ? across / length : 0.0;
}

/* robust.sheet_mask's parameters (cloud_out_t's sheet_*), and whether to take the AVX2
 * paths (use_avx2). */
typedef struct {
    double gap;
    int64_t minimum;
    double own, column, column_gap, far_span, trim, trim_cos;
    int avx2;
} sheet_params_t;

/* The kept range [lo, hi] of heights from one increasingly sorted list hs (k), z of
 * them below 0 (hs[z] is the point's own height 0), a gap being a step > g: above 0,
 * hi is the first gap's near end (rule 1, column = 0) or, when it is the only gap above
 * z, its middle (rule 2, column = 1), else +inf; likewise lo below 0, else -inf. */
static void sheet_cuts(const double *hs, int64_t k, int64_t z, double g, int column,
                       double *lo, double *hi) {
    /* up: the first gap's lower end above z, down: the first gap's upper end below z
     * (read only where there is a gap on that side), counted on the way */
    int64_t up = z, down = z, gaps_up = 0, gaps_down = 0;
    for (int64_t j = z; j + 1 < k; j++) {
        int gap = hs[j + 1] - hs[j] > g;
        up = gaps_up == 0 ? j : up;
        gaps_up += gap;
    }
    for (int64_t j = z; j > 0; j--) {
        int gap = hs[j] - hs[j - 1] > g;
        down = gaps_down == 0 ? j : down;
        gaps_down += gap;
    }
    if (column) {
        *hi = gaps_up != 1 ? INFINITY : 0.5 * (hs[up] + hs[up + 1]);
        *lo = gaps_down != 1 ? -INFINITY : 0.5 * (hs[down - 1] + hs[down]);
    } else {
        *hi = gaps_up == 0 ? INFINITY : hs[up];
        *lo = gaps_down == 0 ? -INFINITY : hs[down];
    }
}

/* Insertion sort of hs (k) in place, order (k) beside it: order[u] is the position before
 * the sort of the height that ends at u. Returns how many are < 0. */
static int64_t sort_heights(double *hs, int64_t *order, int64_t k) {
    int64_t z = 0;
    for (int64_t j = 0; j < k; j++) {
        double x = hs[j];
        z += x < 0;
        int64_t u = j;
        while (u > 0 && hs[u - 1] > x) {
            hs[u] = hs[u - 1];
            order[u] = order[u - 1];
            u--;
        }
        hs[u] = x;
        order[u] = j;
    }
    return z;
}

#ifdef HAVE_AVX2_PATH
/* Most heights sort_heights_avx2 sorts by ranks (a kNN list's length up to 2 blocks of
 * 32: the default scales' 40); longer lists go to sort_heights. */
#define RANK_SORT_MAX 64

/* The ranks' comparisons of one height y = hs[i] with the 4 heights x of a block
 * starting at j0: y <= x in the lanes j > i (ties count), y < x in the others. */
__attribute__((target("avx2"))) static inline __m256d rank_cmp(__m256d y, __m256d x,
                                                               int64_t i, int64_t j0) {
    if (i < j0) return _mm256_cmp_pd(y, x, _CMP_LE_OQ);
    if (i >= j0 + 4) return _mm256_cmp_pd(y, x, _CMP_LT_OQ);
    __m256i after = _mm256_cmpgt_epi64(_mm256_setr_epi64x(0, 1, 2, 3), _mm256_set1_epi64x(i - j0));
    return _mm256_blendv_pd(_mm256_cmp_pd(y, x, _CMP_LT_OQ), _mm256_cmp_pd(y, x, _CMP_LE_OQ),
                            _mm256_castsi256_pd(after));
}

/* sort_heights by ranks, 8 heights at a time (AVX2, two blocks of 4): hs[j] goes to its
 * rank, the number of hs[i] < hs[j] plus the number of i < j with hs[i] == hs[j]: where
 * the (stable) insertion sort puts it, so the array is the same, bit for bit (-0.0 and
 * 0.0 included). Branch-free but for the loop; sort_heights itself when some height is
 * NaN (no order) or k > RANK_SORT_MAX. */
__attribute__((target("avx2"))) static int64_t sort_heights_avx2(double *hs, int64_t *order,
                                                                 int64_t k) {
    if (k > RANK_SORT_MAX) return sort_heights(hs, order, k);
    double v[RANK_SORT_MAX + 8];
    int64_t z = 0, rank[8];
    int nan = 0;
    for (int64_t j = 0; j < k; j++) {
        v[j] = hs[j];
        z += v[j] < 0;
        nan |= v[j] != v[j];
    }
    if (nan) return sort_heights(hs, order, k);
    for (int64_t j = k; j < k + 8; j++) v[j] = 0.0;
    for (int64_t j0 = 0; j0 < k; j0 += 8) {
        __m256d x0 = _mm256_loadu_pd(v + j0), x1 = _mm256_loadu_pd(v + j0 + 4);
        __m256i acc0 = _mm256_setzero_si256(), acc1 = _mm256_setzero_si256();
        int64_t i = 0;
        for (; i < j0; i++) { /* before both blocks */
            __m256d y = _mm256_broadcast_sd(v + i);
            acc0 = _mm256_sub_epi64(acc0, _mm256_castpd_si256(_mm256_cmp_pd(y, x0, _CMP_LE_OQ)));
            acc1 = _mm256_sub_epi64(acc1, _mm256_castpd_si256(_mm256_cmp_pd(y, x1, _CMP_LE_OQ)));
        }
        int64_t mid = j0 + 8 < k ? j0 + 8 : k;
        for (; i < mid; i++) { /* inside them */
            __m256d y = _mm256_broadcast_sd(v + i);
            acc0 = _mm256_sub_epi64(acc0, _mm256_castpd_si256(rank_cmp(y, x0, i, j0)));
            acc1 = _mm256_sub_epi64(acc1, _mm256_castpd_si256(rank_cmp(y, x1, i, j0 + 4)));
        }
        for (; i < k; i++) { /* after both */
            __m256d y = _mm256_broadcast_sd(v + i);
            acc0 = _mm256_sub_epi64(acc0, _mm256_castpd_si256(_mm256_cmp_pd(y, x0, _CMP_LT_OQ)));
            acc1 = _mm256_sub_epi64(acc1, _mm256_castpd_si256(_mm256_cmp_pd(y, x1, _CMP_LT_OQ)));
        }
        _mm256_storeu_si256((__m256i *)rank, acc0);
        _mm256_storeu_si256((__m256i *)(rank + 4), acc1);
        for (int l = 0; l < 8 && j0 + l < k; l++) {
            hs[rank[l]] = v[j0 + l];
            order[rank[l]] = j0 + l;
        }
    }
    return z;
}
#endif

/* sort_heights, by ranks when avx2. */
static inline int64_t sorted_heights(double *hs, int64_t *order, int64_t k, int avx2) {
#ifdef HAVE_AVX2_PATH
    if (avx2) return sort_heights_avx2(hs, order, k);
#endif
    (void)avx2;
    return sort_heights(hs, order, k);
}

/* The column's heights sorted, from all the heights h (k) sorted: hs (k) and order as
 * sort_heights leaves them, z of them < 0, none NaN. The heights of the column's points
 * (d2_j - h_j^2 <= c2) keep their order, the others read as 0.0: the column's negative
 * heights, then those zeros, then its other heights, in place. These are the values that
 * sorting the column's heights gives, in order; equal values (0.0 and -0.0 among them)
 * may come in another order, which sheet_cuts' cuts do not see (a difference, a
 * midpoint or a bound of equal values compares the same). Returns how many are < 0. */
static int64_t column_heights(double *hs, const int64_t *order, const double *h,
                              const double *d2, int64_t k, int64_t z, double c2) {
    int64_t below = 0, above = k;
    for (int64_t u = 0; u < z; u++) {
        int64_t j = order[u];
        if (d2[j] - h[j] * h[j] <= c2) hs[below++] = hs[u];
    }
    for (int64_t u = k - 1; u >= z; u--) {
        int64_t j = order[u];
        if (d2[j] - h[j] * h[j] <= c2) hs[--above] = hs[u];
    }
    for (int64_t u = below; u < above; u++) hs[u] = 0.0;
    return below;
}

/* h[j] = q_j . nrm for the offsets q (k, 3), summed as (x n0 + y n1) + z n2; *lo and *hi
 * their smallest and largest (when none is NaN); returns whether some h[j] is NaN. */
static int sheet_heights(const double *q, int64_t k, const double *nrm, double *h, double *lo,
                         double *hi) {
    double hmin = INFINITY, hmax = -INFINITY;
    int nan = 0;
    for (int64_t j = 0; j < k; j++) {
        double v = q[3 * j] * nrm[0] + q[3 * j + 1] * nrm[1] + q[3 * j + 2] * nrm[2];
        h[j] = v;
        nan |= v != v;
        if (v < hmin) hmin = v;
        if (v > hmax) hmax = v;
    }
    *lo = hmin;
    *hi = hmax;
    return nan;
}

#ifdef HAVE_AVX2_PATH
/* sheet_heights on 4 lanes (AVX2: the same products and sums, no fused multiply-add):
 * 4 offsets (12 coordinates, 3 loads) transposed to their x, y and z. */
__attribute__((target("avx2"))) static int sheet_heights_avx2(const double *q, int64_t k,
                                                              const double *nrm, double *h,
                                                              double *lo, double *hi) {
    __m256d n0 = _mm256_set1_pd(nrm[0]), n1 = _mm256_set1_pd(nrm[1]), n2 = _mm256_set1_pd(nrm[2]);
    __m256d vmin = _mm256_set1_pd(INFINITY), vmax = _mm256_set1_pd(-INFINITY);
    __m256d vnan = _mm256_setzero_pd();
    int64_t j = 0;
    for (; j + 4 <= k; j += 4) {
        const double *r = q + 3 * j;
        __m256d a = _mm256_loadu_pd(r), b = _mm256_loadu_pd(r + 4), c = _mm256_loadu_pd(r + 8);
        __m256d xy = _mm256_blend_pd(a, b, 12);           /* x0 y0 x2 y2 */
        __m256d zx = _mm256_permute2f128_pd(a, c, 0x21);  /* z0 x1 z2 x3 */
        __m256d yz = _mm256_blend_pd(b, c, 12);           /* y1 z1 y3 z3 */
        __m256d x = _mm256_blend_pd(xy, zx, 10), y = _mm256_shuffle_pd(xy, yz, 5),
                z = _mm256_blend_pd(zx, yz, 10);
        __m256d v = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(x, n0), _mm256_mul_pd(y, n1)),
                                  _mm256_mul_pd(z, n2));
        _mm256_storeu_pd(h + j, v);
        vnan = _mm256_or_pd(vnan, _mm256_cmp_pd(v, v, _CMP_UNORD_Q));
        vmin = _mm256_min_pd(vmin, v);
        vmax = _mm256_max_pd(vmax, v);
    }
    double m4[4], x4[4], hmin, hmax;
    _mm256_storeu_pd(m4, vmin);
    _mm256_storeu_pd(x4, vmax);
    int nan = _mm256_movemask_pd(vnan) != 0;
    nan |= sheet_heights(q + 3 * j, k - j, nrm, h + j, &hmin, &hmax);
    for (int l = 0; l < 4; l++) {
        if (m4[l] < hmin) hmin = m4[l];
        if (x4[l] > hmax) hmax = x4[l];
    }
    *lo = hmin;
    *hi = hmax;
    return nan;
}
#endif

/* sheet_heights, on 4 lanes when avx2. */
static inline int heights_of(const double *q, int64_t k, const double *nrm, double *h,
                             double *lo, double *hi, int avx2) {
#ifdef HAVE_AVX2_PATH
    if (avx2) return sheet_heights_avx2(q, k, nrm, h, lo, hi);
#endif
    (void)avx2;
    return sheet_heights(q, k, nrm, h, lo, hi);
}

/* sheet_apply's tally of one list: how many heights are dropped, and the range of those
 * below lo and of those above hi (empty: lo = inf, hi = -inf). */
typedef struct {
    int64_t dropped;
    double blo, bhi, alo, ahi;
} sheet_tally_t;

/* keep[j] = lo <= h[j] <= hi for j in [j0, k), into the tally t. */
static void sheet_marks(const double *h, int64_t j0, int64_t k, double lo, double hi,
                        char *keep, sheet_tally_t *t) {
    for (int64_t j = j0; j < k; j++) {
        double v = h[j];
        keep[j] = v >= lo && v <= hi;
        t->dropped += !keep[j];
        if (v < lo) { if (v < t->blo) t->blo = v; if (v > t->bhi) t->bhi = v; }
        if (v > hi) { if (v < t->alo) t->alo = v; if (v > t->ahi) t->ahi = v; }
    }
}

#ifdef HAVE_AVX2_PATH
/* sheet_marks from j = 0 on 4 lanes (AVX2), then the rest: the same marks, count and
 * ranges (where equal values of either sign of zero are a range's end, either sign may
 * be it: the range's test in sheet_apply sees no difference). */
__attribute__((target("avx2,popcnt"))) static void sheet_marks_avx2(const double *h, int64_t k,
                                                             double lo, double hi, char *keep,
                                                             sheet_tally_t *t) {
    const __m256d vlo = _mm256_set1_pd(lo), vhi = _mm256_set1_pd(hi);
    const __m256d inf = _mm256_set1_pd(INFINITY), ninf = _mm256_set1_pd(-INFINITY);
    __m256d blo = inf, bhi = ninf, alo = inf, ahi = ninf;
    int64_t j = 0, kept = 0;
    for (; j + 4 <= k; j += 4) {
        __m256d v = _mm256_loadu_pd(h + j);
        __m256d below = _mm256_cmp_pd(v, vlo, _CMP_LT_OQ), above = _mm256_cmp_pd(v, vhi, _CMP_GT_OQ);
        unsigned in = (unsigned)_mm256_movemask_pd(_mm256_and_pd(
            _mm256_cmp_pd(v, vlo, _CMP_GE_OQ), _mm256_cmp_pd(v, vhi, _CMP_LE_OQ)));
        uint32_t bytes = (in * 0x204081u) & 0x01010101u; /* bit l to byte l */
        memcpy(keep + j, &bytes, 4);
        kept += __builtin_popcount(in);
        blo = _mm256_min_pd(blo, _mm256_blendv_pd(inf, v, below));
        bhi = _mm256_max_pd(bhi, _mm256_blendv_pd(ninf, v, below));
        alo = _mm256_min_pd(alo, _mm256_blendv_pd(inf, v, above));
        ahi = _mm256_max_pd(ahi, _mm256_blendv_pd(ninf, v, above));
    }
    double r[4][4];
    _mm256_storeu_pd(r[0], blo);
    _mm256_storeu_pd(r[1], bhi);
    _mm256_storeu_pd(r[2], alo);
    _mm256_storeu_pd(r[3], ahi);
    t->dropped += j - kept;
    for (int l = 0; l < 4; l++) {
        if (r[0][l] < t->blo) t->blo = r[0][l];
        if (r[1][l] > t->bhi) t->bhi = r[1][l];
        if (r[2][l] < t->alo) t->alo = r[2][l];
        if (r[3][l] > t->ahi) t->ahi = r[3][l];
    }
    sheet_marks(h, j, k, lo, hi, keep, t);
}
#endif

/* keep[j] = lo <= h[j] <= hi (on 4 lanes when avx2); returns the number dropped, or 0
 * (every keep[j] 1) when fewer than minimum would be, the kept would be fewer than own
 * times the dropped, or the dropped heights on one side span more than span. */
static int64_t sheet_apply(const double *h, int64_t k, double lo, double hi, int64_t minimum,
                           double own, double span, char *keep, int avx2) {
    sheet_tally_t t = {0, INFINITY, -INFINITY, INFINITY, -INFINITY};
#ifdef HAVE_AVX2_PATH
    if (avx2)
        sheet_marks_avx2(h, k, lo, hi, keep, &t);
    else
#endif
        sheet_marks(h, 0, k, lo, hi, keep, &t);
    (void)avx2;
    int64_t dropped = t.dropped;
    if (dropped < minimum || (double)(k - dropped) < own * (double)dropped ||
        (t.bhi >= t.blo && t.bhi - t.blo > span) || (t.ahi >= t.alo && t.ahi - t.alo > span)) {
        for (int64_t j = 0; j < k; j++) keep[j] = 1;
        return 0;
    }
    return dropped;
}

/* The set of buckets floor((v[j] - lo) * s) of the values v (k), each in [0, 63): bit b
 * set when some value falls in bucket b. */
static uint64_t bucket_bits(const double *v, int64_t k, double lo, double s) {
    uint64_t seen = 0;
    for (int64_t j = 0; j < k; j++) seen |= (uint64_t)1 << (int)((v[j] - lo) * s);
    return seen;
}

#ifdef HAVE_AVX2_PATH
/* bucket_bits on 4 lanes (AVX2: the same difference, product and truncation). */
__attribute__((target("avx2"))) static uint64_t bucket_bits_avx2(const double *v, int64_t k,
                                                                 double lo, double s) {
    const __m256d vlo = _mm256_set1_pd(lo), vs = _mm256_set1_pd(s);
    const __m256i one = _mm256_set1_epi64x(1);
    __m256i seen = _mm256_setzero_si256();
    int64_t j = 0;
    for (; j + 4 <= k; j += 4) {
        __m128i b = _mm256_cvttpd_epi32(_mm256_mul_pd(_mm256_sub_pd(_mm256_loadu_pd(v + j), vlo), vs));
        seen = _mm256_or_si256(seen, _mm256_sllv_epi64(one, _mm256_cvtepi32_epi64(b)));
    }
    __m128i half = _mm_or_si128(_mm256_castsi256_si128(seen), _mm256_extracti128_si256(seen, 1));
    return (uint64_t)_mm_cvtsi128_si64(_mm_or_si128(half, _mm_unpackhi_epi64(half, half))) |
           bucket_bits(v + j, k - j, lo, s);
}
#endif

/* bucket_bits, on 4 lanes when avx2. */
static inline uint64_t bucket_bits_on(const double *v, int64_t k, double lo, double s, int avx2) {
#ifdef HAVE_AVX2_PATH
    if (avx2) return bucket_bits_avx2(v, k, lo, s);
#endif
    (void)avx2;
    return bucket_bits(v, k, lo, s);
}

/* Whether no step between consecutive sorted values of v (k, none NaN; lo and hi their
 * smallest and largest) exceeds g, shown without sorting them (0: one may). A value x
 * goes to bucket b(x) = floor((x - lo) * s), s = 1 / (0.18 g) rounded (a bucket about
 * 0.18 g wide), b(hi) at most 62. b is monotone (each rounded operation is), so two
 * consecutive sorted values lie in buckets with none occupied between them (a value in
 * one would lie between them); when no 4 buckets in a row below b(hi) are empty, theirs
 * are at most 4 apart, and the values differ by less than 5 buckets: exactly, the rounded
 * (x - lo) * s is off by under 64 * 2^-52 buckets, so by less than 0.9 g (1 + 1e-14),
 * and their rounded difference is at most g (rounding is monotone, g a double). With more
 * buckets, or 0.18 g not a normal double (NaN, 0, subnormal: s is not its inverse then):
 * whether hi - lo <= g (no step's rounded difference exceeds that). */
static int no_gap(const double *v, int64_t k, double lo, double hi, double g, int avx2) {
    double w = 0.18 * g, s = 1.0 / w, t = (hi - lo) * s;
    if (!(w >= DBL_MIN && t < 63.0)) return hi - lo <= g;
    uint64_t seen = bucket_bits_on(v, k, lo, s, avx2);
    uint64_t near = seen | seen << 1; /* the buckets at most 3 above an occupied one */
    near |= near << 2;
    uint64_t all = ((uint64_t)2 << (int)t) - 1; /* buckets 0 .. b(hi) */
    return (near & all) == all;
}

/* The column's heights, unsorted: hs[j] = h[j] where d2[j] - h[j]^2 <= c2, else 0.0,
 * for the heights h (k) and squared lengths d2 (k); *lo and *hi their smallest and
 * largest (when none is NaN). */
static void column_values(const double *h, const double *d2, int64_t k, double c2, double *hs,
                          double *lo, double *hi) {
    double vmin = INFINITY, vmax = -INFINITY;
    for (int64_t j = 0; j < k; j++) {
        double v = d2[j] - h[j] * h[j] <= c2 ? h[j] : 0.0;
        hs[j] = v;
        if (v < vmin) vmin = v;
        if (v > vmax) vmax = v;
    }
    *lo = vmin;
    *hi = vmax;
}

/* Rules 1 and 2 of robust.sheet_mask on the heights h (k) of one list, squared lengths
 * d2 (k), spacing a (lo, hi their smallest and largest, nan whether some is NaN, as
 * heights_of gives them); hs (k) scratch; keep (k) all 1 on entry. Writes keep[j] and returns
 * the number dropped (0: every keep[j] is 1). Rule 1, the whole list: a gap is a step >
 * sheet_gap * a between consecutive sorted h; above 0 (the point's own h) the points
 * beyond the first gap are dropped (whatever lies beyond them); likewise below; not when
 * fewer than sheet_min would be, or the kept would be fewer than sheet_own times the
 * dropped. Rule 2, when rule 1 drops none: the same with the heights of the points of
 * the column (tangential distance t_j, t_j^2 = d2_j - h_j^2, at most sheet_column * a;
 * the others' heights read as 0), gaps > sheet_column_gap * a, a side cut only when its
 * gap is the only one on that side, the cuts in the middle of the gaps, and not when the
 * dropped heights on one side span more than sheet_far_span * a; the column's heights
 * sorted from the list's (column_heights) when rule 1 sorted them and none is NaN. A
 * rule that no_gap shows to have no gap drops none, and its heights are not sorted (most
 * lists past sheet_keep's first test: the points near a crease, heights spread out
 * without a gap). order (k) scratch. */
static int64_t sheet_rules(const double *h, double lo, double hi, int nan, const double *d2,
                           int64_t k, double a, const sheet_params_t *sp, double *hs,
                           int64_t *order, char *keep) {
    double c = sp->column * a, c2 = c * c;
    int64_t z;
    if (!nan && no_gap(h, k, lo, hi, sp->gap * a, sp->avx2)) { /* rule 1 drops none */
        if (sp->column <= 0.0) return 0;
        column_values(h, d2, k, c2, hs, &lo, &hi);
        if (no_gap(hs, k, lo, hi, sp->column_gap * a, sp->avx2)) return 0;
        z = sorted_heights(hs, order, k, sp->avx2);
    } else {
        memcpy(hs, h, (size_t)k * sizeof(double));
        z = sorted_heights(hs, order, k, sp->avx2);
        sheet_cuts(hs, k, z, sp->gap * a, 0, &lo, &hi);
        int64_t dropped = sheet_apply(h, k, lo, hi, sp->minimum, sp->own, INFINITY, keep,
                                      sp->avx2);
        if (dropped > 0 || sp->column <= 0.0) return dropped;
        if (nan) {
            column_values(h, d2, k, c2, hs, &lo, &hi);
            z = sorted_heights(hs, order, k, sp->avx2);
        } else {
            z = column_heights(hs, order, h, d2, k, z, c2);
        }
    }
    sheet_cuts(hs, k, z, sp->column_gap * a, 1, &lo, &hi);
    return sheet_apply(h, k, lo, hi, sp->minimum, sp->own, sp->far_span * a, keep,
                       sp->avx2);
}

/* robust.sheet_mask of one kNN list: offsets q (k, 3) from the point (itself first),
 * squared lengths d2 (k), the list's normal nrm, the parameters sp; hs (2 k) and order
 * (k) scratch.
 * Writes keep[j] (1: kept) and returns the number of neighbours dropped (0: every
 * keep[j] is 1). h_j = q_j . n; a = the mean length of q_1 .. q_m, m = min(6, k - 1),
 * summed in order; sheet_rules on those heights. Pass 2, when they drop none, some
 * |h_j| > sheet_trim * a and at least 3 are not: sheet_rules again on the heights along
 * the unweighted PCA normal n2 (smallest_eigvec of the scatter, sums in order) of the
 * q_j with |h_j| <= sheet_trim * a, when |n2 . n| >= sheet_trim_cos. */
static int64_t sheet_keep(const double *q, const double *d2, int64_t k, const double *nrm,
                          const sheet_params_t *sp, double *hs, int64_t *order, char *keep) {
    for (int64_t j = 0; j < k; j++) keep[j] = 1;
    int64_t m = k - 1 < 6 ? k - 1 : 6;
    if (m < 1) return 0;
    double a = sqrt(d2[1]);
    for (int64_t j = 2; j <= m; j++) a += sqrt(d2[j]);
    a /= (double)m;
    double g = sp->gap * a, g2 = sp->column_gap * a, t = sp->trim * a;
    /* No step between consecutive sorted heights, of the whole list or of the column,
     * exceeds (max h) - (min h) as rounded (rounding is monotone), and no |h_j| does
     * (0 is among them): when that is at most both gaps and the trim there is none, no
     * second pass, and every neighbour is kept (most points: a smooth surface), without
     * sorting. */
    double *h = hs + k, hmin, hmax;
    int nan = heights_of(q, k, nrm, h, &hmin, &hmax, sp->avx2);
    if (!nan && hmax - hmin <= g && (sp->column <= 0.0 || hmax - hmin <= g2) &&
        (sp->trim <= 0.0 || hmax - hmin <= t))
        return 0;
    int64_t dropped = sheet_rules(h, hmin, hmax, nan, d2, k, a, sp, hs, order, keep);
    if (dropped > 0 || sp->trim <= 0.0) return dropped;
    double sx = 0.0, sy = 0.0, sz = 0.0;
    int64_t count = 0;
    for (int64_t j = 0; j < k; j++) {
        if (!(fabs(h[j]) <= t)) continue;
        sx += q[3 * j]; sy += q[3 * j + 1]; sz += q[3 * j + 2];
        count++;
    }
    if (count < 3 || count == k) return 0;
    double mx = sx / (double)count, my = sy / (double)count, mz = sz / (double)count;
    double c[6] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0}, n2[3];
    for (int64_t j = 0; j < k; j++) {
        if (!(fabs(h[j]) <= t)) continue;
        double x = q[3 * j] - mx, y = q[3 * j + 1] - my, z = q[3 * j + 2] - mz;
        c[0] += x * x; c[1] += x * y; c[2] += x * z;
        c[3] += y * y; c[4] += y * z; c[5] += z * z;
    }
    smallest_eigvec(c[0], c[1], c[2], c[3], c[4], c[5], n2);
    if (!(fabs(n2[0] * nrm[0] + n2[1] * nrm[1] + n2[2] * nrm[2]) >= sp->trim_cos)) return 0;
    nan = heights_of(q, k, n2, h, &hmin, &hmax, sp->avx2);
    return sheet_rules(h, hmin, hmax, nan, d2, k, a, sp, hs, order, keep);
}

/* The sheet filter's parameters from a pass's cloud_out_t. */
static sheet_params_t sheet_params(const cloud_out_t *out) {
    sheet_params_t sp = {out->sheet_gap, out->sheet_min, out->sheet_own, out->sheet_column,
                         out->sheet_column_gap, out->sheet_far_span, out->sheet_trim,
                         out->sheet_trim_cos, use_avx2()};
    return sp;
}

int ms_sheet_mask(const double *p, const int64_t *idx, int64_t k, const double *nrm,
                  const cloud_out_t *params, int64_t begin, int64_t end, char *keep) {
    const sheet_params_t sp = sheet_params(params);
    double *q = (double *)malloc((size_t)k * 3 * sizeof(double));
    double *d2 = (double *)malloc((size_t)k * sizeof(double));
    double *hs = (double *)malloc((size_t)k * 2 * sizeof(double));
    int64_t *order = (int64_t *)malloc((size_t)k * sizeof(int64_t));
    int rc = q && d2 && hs && order ? 0 : -1;
    for (int64_t i = begin; i < end && rc == 0; i++) {
        const double *pi = p + 3 * i;
        for (int64_t j = 0; j < k; j++) {
            const double *pj = p + 3 * idx[i * k + j];
            double x = pj[0] - pi[0], y = pj[1] - pi[1], z = pj[2] - pi[2];
            q[3 * j] = x; q[3 * j + 1] = y; q[3 * j + 2] = z;
            d2[j] = x * x + y * y + z * z;
        }
        sheet_keep(q, d2, k, nrm + 3 * i, &sp, hs, order, keep + i * k);
    }
    free(q);
    free(d2);
    free(hs);
    free(order);
    return rc;
}

/* ------------------------------------------------------------------ kd-tree */

/* A balanced kd-tree stored implicitly: node 0 is the root, the children of node t are
 * 2t + 1 and 2t + 2, a node holding the points [s, e) of the tree order splits them at
 * s + (e - s) / 2 (the median along the widest side of its bounding box), and every
 * leaf is at the same depth. Median splits keep the depth at log2(n / KD_LEAF) and the
 * leaves balanced whatever the spatial distribution: a far outlier, distant clusters,
 * points on a line or a plane. box holds each node's tight bounding box (lo xyz, hi
 * xyz), which bounds the squared distance of its points from below exactly (see
 * box_dist2), so the search is exact: the k nearest by (squared distance, index). */

/* Points x (n, 3) with their indices idx (n), permuted together. */
static inline void point_swap(double *x, int64_t *idx, int64_t i, int64_t j) {
    double t0 = x[3 * i], t1 = x[3 * i + 1], t2 = x[3 * i + 2];
    x[3 * i] = x[3 * j]; x[3 * i + 1] = x[3 * j + 1]; x[3 * i + 2] = x[3 * j + 2];
    x[3 * j] = t0; x[3 * j + 1] = t1; x[3 * j + 2] = t2;
    int64_t t = idx[i];
    idx[i] = idx[j];
    idx[j] = t;
}

static inline uint64_t xorshift64(uint64_t *s) {
    uint64_t x = *s;
    x ^= x << 13;
    x ^= x >> 7;
    x ^= x << 17;
    *s = x;
    return x;
}

/* Ranges of at least SELECT_SAMPLED points take select_pivot's pivot from a sorted
 * sample of SELECT_SAMPLE pseudo-random points. */
#define SELECT_SAMPLED 512
#define SELECT_SAMPLE 31

/* select_axis' pivot along axis a for the points [lo, lo + span), where the one of rank
 * m is wanted: with a large span, the sample point whose rank in the sample is where
 * m's is in the range (near the target value, so that the partition leaves few points
 * on m's side: after the first partition m is far from its range's middle, and a median
 * of three pivot then cut off little: 6 % fewer instructions, 10 % less time, building
 * the tree of 1M points); else the median of three. */
static double select_pivot(const double *x, int64_t lo, uint64_t span, int64_t m, int a,
                           uint64_t *rng) {
    if (span >= SELECT_SAMPLED) {
        double v[SELECT_SAMPLE];
        for (int u = 0; u < SELECT_SAMPLE; u++) { /* insertion sort as they come */
            double w = x[3 * (lo + (int64_t)(xorshift64(rng) % span)) + a];
            int t = u;
            for (; t > 0 && w < v[t - 1]; t--) v[t] = v[t - 1];
            v[t] = w;
        }
        return v[(int64_t)((double)(m - lo) / (double)span * SELECT_SAMPLE)];
    }
    double v0 = x[3 * (lo + (int64_t)(xorshift64(rng) % span)) + a];
    double v1 = x[3 * (lo + (int64_t)(xorshift64(rng) % span)) + a];
    double v2 = x[3 * (lo + (int64_t)(xorshift64(rng) % span)) + a];
    return v0 < v1 ? (v1 < v2 ? v1 : (v0 < v2 ? v2 : v0)) : (v0 < v2 ? v0 : (v1 < v2 ? v2 : v1));
}

/* Reorder the points [0, n) so that point m is the one of rank m along axis a, with
 * smaller or equal ones before it and larger or equal ones after (quickselect, pivot
 * select_pivot's: expected O(n) whatever the input order). */
static void select_axis(double *x, int64_t *idx, int64_t n, int64_t m, int a, uint64_t *rng) {
    int64_t lo = 0, hi = n - 1;
    while (hi - lo >= 16) {
        uint64_t span = (uint64_t)(hi - lo + 1);
        double pivot = select_pivot(x, lo, span, m, a, rng);
        int64_t i = lo, j = hi;
        while (i <= j) {
            while (x[3 * i + a] < pivot) i++;
            while (pivot < x[3 * j + a]) j--;
            if (i <= j) { point_swap(x, idx, i, j); i++; j--; }
        }
        if (m <= j) hi = j;
        else if (m >= i) lo = i;
        else return;
    }
    for (int64_t i = lo + 1; i <= hi; i++) {
        for (int64_t j = i; j > lo && x[3 * j + a] < x[3 * (j - 1) + a]; j--) {
            point_swap(x, idx, j, j - 1);
        }
    }
}

/* One split of build_node: the box of node t (at depth d) into box when d <= depth, and
 * the points [s, e) split at their median along the widest side of that box; returns
 * the split s + (e - s) / 2, or -1 when fewer than 2 points. */
static int64_t split_node(double *x, int64_t *idx, int64_t s, int64_t e, int64_t t, int d,
                          int depth, double *box, uint64_t *rng) {
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
#ifdef __SSE2__
    /* (x, y) on two lanes and z: min(v, lo) keeps lo when v is not below it (an equal
     * value of the other sign, NaN), as the loop below does */
    __m128d lxy = _mm_loadu_pd(lo), hxy = _mm_loadu_pd(hi);
    __m128d lz = _mm_load_sd(lo + 2), hz = _mm_load_sd(hi + 2);
    for (int64_t j = s; j < e; j++) {
        __m128d vxy = _mm_loadu_pd(x + 3 * j), vz = _mm_load_sd(x + 3 * j + 2);
        lxy = _mm_min_pd(vxy, lxy);
        hxy = _mm_max_pd(vxy, hxy);
        lz = _mm_min_sd(vz, lz);
        hz = _mm_max_sd(vz, hz);
    }
    _mm_storeu_pd(lo, lxy);
    _mm_storeu_pd(hi, hxy);
    _mm_store_sd(lo + 2, lz);
    _mm_store_sd(hi + 2, hz);
#else
    for (int64_t j = s; j < e; j++) {
        for (int a = 0; a < 3; a++) {
            double v = x[3 * j + a];
            if (v < lo[a]) lo[a] = v;
            if (v > hi[a]) hi[a] = v;
        }
    }
#endif
    if (d <= depth) {
        double *b = box + 6 * t;
        b[0] = lo[0]; b[1] = lo[1]; b[2] = lo[2];
        b[3] = hi[0]; b[4] = hi[1]; b[5] = hi[2];
    }
    if (e - s < 2) return -1;
    int a = 0;
    for (int c = 1; c < 3; c++) {
        if (hi[c] - lo[c] > hi[a] - lo[a]) a = c;
    }
    int64_t m = s + (e - s) / 2;
    select_axis(x + 3 * s, idx + s, e - s, m - s, a, rng);
    return m;
}

/* Split the points [s, e) of node t (depth d) recursively (split_node) down to the
 * leaves, and each leaf once more into its two halves, so that the tree order roughly
 * orders the points inside a leaf too (consecutive points near each other: see
 * ms_cloud_pdis). Splitting on down to single points cost 18 % of the build's
 * instructions and saved 0.1 % of the pass's (200k-point cloud). The boxes of the
 * nodes down to `depth` go into box. The nodes at depth `stop` are left as they are
 * (ms_kdtree_build_subtrees; stop < 0: none). */
static void build_node(double *x, int64_t *idx, int64_t s, int64_t e, int64_t t, int d,
                       int depth, int stop, double *box, uint64_t *rng) {
    if (d == stop || d > depth) return;
    int64_t m = split_node(x, idx, s, e, t, d, depth, box, rng);
    if (m < 0) return;
    build_node(x, idx, s, m, 2 * t + 1, d + 1, depth, stop, box, rng);
    build_node(x, idx, m, e, 2 * t + 2, d + 1, depth, stop, box, rng);
}

/* The depth at which the top levels stop: min(depth, MS_KD_TOP). */
static int top_levels(int depth) { return depth < MS_KD_TOP ? depth : MS_KD_TOP; }

/* The points [*s, *e) of the node u (of the 2^d) at depth d: its median halves. */
static void node_span(int64_t n, int64_t u, int d, int64_t *s, int64_t *e) {
    *s = 0;
    *e = n;
    for (int b = d - 1; b >= 0; b--) {
        int64_t m = *s + (*e - *s) / 2;
        if ((u >> b) & 1) *s = m;
        else *e = m;
    }
}

void ms_kdtree_build_level(double *tp, int64_t *torig, int64_t n, int depth, int level,
                           int64_t first, int64_t last, double *box) {
    for (int64_t u = first; u < last; u++) {
        int64_t s, e, t = ((int64_t)1 << level) - 1 + u;
        node_span(n, u, level, &s, &e);
        uint64_t rng = 0x9e3779b97f4a7c15ULL ^ (0x94d049bb133111ebULL * (uint64_t)(t + 1));
        split_node(tp, torig, s, e, t, level, depth, box, &rng);
    }
}

/* The top levels of ms_kdtree_build on one thread (tp, torig filled from p). */
static void kdtree_build_top(const double *p, int64_t n, int depth, double *tp, int64_t *torig,
                             double *box) {
    memcpy(tp, p, (size_t)n * 3 * sizeof(double));
    for (int64_t i = 0; i < n; i++) torig[i] = i;
    for (int level = 0; level < top_levels(depth); level++) {
        ms_kdtree_build_level(tp, torig, n, depth, level, 0, (int64_t)1 << level, box);
    }
}

void ms_kdtree_build_subtrees(double *tp, int64_t *torig, int64_t n, int depth, int64_t first,
                              int64_t last, double *box) {
    int top = top_levels(depth);
    for (int64_t u = first; u < last; u++) {
        int64_t s, e; /* the points of node u at depth top */
        node_span(n, u, top, &s, &e);
        uint64_t rng = 0x9e3779b97f4a7c15ULL ^ (0xbf58476d1ce4e5b9ULL * (uint64_t)(u + 1));
        build_node(tp, torig, s, e, ((int64_t)1 << top) - 1 + u, top, depth, -1, box, &rng);
    }
}

void ms_kdtree_build(const double *p, int64_t n, int depth, double *tp, int64_t *torig,
                     double *box) {
    kdtree_build_top(p, n, depth, tp, torig, box);
    ms_kdtree_build_subtrees(tp, torig, n, depth, 0, (int64_t)1 << top_levels(depth), box);
}

typedef struct {
    double d2;
    int64_t idx; /* cleaned index (tie rule) */
    int64_t pos; /* tree position (coordinates) */
} cand_t;

static inline int cand_lt(const cand_t *x, const cand_t *y) {
    return x->d2 < y->d2 || (x->d2 == y->d2 && x->idx < y->idx);
}

static void insertion_sort(cand_t *a, int64_t n) {
    for (int64_t i = 1; i < n; i++) {
        cand_t t = a[i];
        int64_t j = i - 1;
        while (j >= 0 && cand_lt(&t, &a[j])) { a[j + 1] = a[j]; j--; }
        a[j + 1] = t;
    }
}

/* Put the k smallest of a[0..n) (by (d2, idx)) in a[0..k), sorted. */
static void select_sorted(cand_t *a, int64_t n, int64_t k) {
    int64_t lo = 0, hi = n - 1, kk = k - 1;
    while (hi - lo >= 16) {
        int64_t mid = lo + (hi - lo) / 2;
        cand_t t;
        if (cand_lt(&a[mid], &a[lo])) { t = a[mid]; a[mid] = a[lo]; a[lo] = t; }
        if (cand_lt(&a[hi], &a[lo])) { t = a[hi]; a[hi] = a[lo]; a[lo] = t; }
        if (cand_lt(&a[hi], &a[mid])) { t = a[hi]; a[hi] = a[mid]; a[mid] = t; }
        cand_t pivot = a[mid];
        int64_t i = lo, j = hi;
        while (i <= j) {
            while (cand_lt(&a[i], &pivot)) i++;
            while (cand_lt(&pivot, &a[j])) j--;
            if (i <= j) { t = a[i]; a[i] = a[j]; a[j] = t; i++; j--; }
        }
        if (kk <= j) hi = j;
        else if (kk >= i) lo = i;
        else break;
    }
    if (hi > lo) insertion_sort(a + lo, hi - lo + 1);
    insertion_sort(a, k);
}

/* The k best candidates seen by one query, a max-heap by (d2, idx); until it holds k,
 * only candidates with d2 <= tau (an upper bound of the k-th squared distance) enter. */
typedef struct {
    cand_t *c;
    int64_t n, k;
    double tau;
} heap_t;

static inline double heap_bound(const heap_t *h) { return h->n < h->k ? h->tau : h->c[0].d2; }

static void sift_down(cand_t *c, int64_t n, int64_t i) {
    cand_t t = c[i];
    while (1) {
        int64_t l = 2 * i + 1;
        if (l >= n) break;
        if (l + 1 < n && cand_lt(&c[l], &c[l + 1])) l++;
        if (!cand_lt(&t, &c[l])) break;
        c[i] = c[l];
        i = l;
    }
    c[i] = t;
}

static inline void heap_offer(heap_t *h, double d2, int64_t idx, int64_t pos) {
    cand_t x = {d2, idx, pos};
    if (h->n < h->k) {
        int64_t i = h->n++;
        while (i > 0) {
            int64_t up = (i - 1) / 2;
            if (!cand_lt(&h->c[up], &x)) break;
            h->c[i] = h->c[up];
            i = up;
        }
        h->c[i] = x;
    } else if (cand_lt(&x, &h->c[0])) {
        h->c[0] = x;
        sift_down(h->c, h->n, 0);
    }
}

typedef struct {
    const double *p;
    const int64_t *orig;
    const double *box;
    int64_t n;
    int depth;
} tree_t;

/* Squared distance between boxes a and b (a point is a box with lo = hi), computed as
 * the squared distance of two points is (axes summed in order): never larger than that
 * of a point of a and a point of b, since IEEE rounding is monotone (the difference of
 * the coordinates is at least the gap between the boxes on each axis). */
static inline double box_dist2(const double *a, const double *b) {
    double g[3];
    for (int i = 0; i < 3; i++) {
        g[i] = b[3 + i] < a[i] ? a[i] - b[3 + i] : (a[3 + i] < b[i] ? b[i] - a[3 + i] : 0.0);
    }
    return g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
}

/* Heap search of q (as a box qq: lo = hi = q), nearer child first. */
static void search(const tree_t *T, const double *qq, int64_t t, int64_t s, int64_t e, int d,
                   heap_t *h) {
    if (d == T->depth) {
        for (int64_t j = s; j < e; j++) {
            const double *pj = T->p + 3 * j;
            double dx = pj[0] - qq[0], dy = pj[1] - qq[1], dz = pj[2] - qq[2];
            double d2 = dx * dx + dy * dy + dz * dz;
            if (d2 <= heap_bound(h)) heap_offer(h, d2, T->orig[j], j);
        }
        return;
    }
    int64_t m = s + (e - s) / 2;
    int64_t l = 2 * t + 1, r = 2 * t + 2;
    double dl = box_dist2(T->box + 6 * l, qq), dr = box_dist2(T->box + 6 * r, qq);
    if (dl <= dr) {
        if (dl <= heap_bound(h)) search(T, qq, l, s, m, d + 1, h);
        if (dr <= heap_bound(h)) search(T, qq, r, m, e, d + 1, h);
    } else {
        if (dr <= heap_bound(h)) search(T, qq, r, m, e, d + 1, h);
        if (dl <= heap_bound(h)) search(T, qq, l, s, m, d + 1, h);
    }
}

/* The k nearest of q into h->c[0..k), sorted by (d2, idx); tau an upper bound of the
 * k-th squared distance (INFINITY if none is known). */
static void knn_search(const tree_t *T, const double *q, int64_t k, double tau, heap_t *h) {
    double qq[6] = {q[0], q[1], q[2], q[0], q[1], q[2]};
    h->k = k;
    h->n = 0;
    h->tau = tau;
    search(T, qq, 0, 0, T->n, 0, h);
    if (h->n < k) { /* tau too small: cannot happen, costs nothing to check */
        h->n = 0;
        h->tau = INFINITY;
        search(T, qq, 0, 0, T->n, 0, h);
    }
    for (int64_t m = h->n; m > 1; m--) {
        cand_t t = h->c[0];
        h->c[0] = h->c[m - 1];
        h->c[m - 1] = t;
        sift_down(h->c, m - 1, 0);
    }
}

/* An upper bound of the squared k-th distance of the point pi, from the k-th distance
 * prev_r of the point prev_p (triangle inequality, with room for rounding); INFINITY
 * when prev_r < 0 (no previous point). */
static inline double kth_bound(const double *pi, const double *prev_p, double prev_r) {
    if (prev_r < 0.0) return INFINITY;
    double ex = pi[0] - prev_p[0], ey = pi[1] - prev_p[1], ez = pi[2] - prev_p[2];
    double t = prev_r + sqrt(ex * ex + ey * ey + ez * ez);
    return t * t * (1.0 + 1e-9) + 1e-300;
}

/* The points of a node's neighbourhood, as arrays, leaf by leaf: the points of leaf l in
 * the slots [start[l], start[l + 1]), padded to a multiple of 4 with NaN coordinates
 * (never within any bound), and its box in lb[0..6)[l] (lo x, y, z, hi x, y, z; rows
 * padded to a multiple of 4 with empty boxes, lo = +inf and hi = -inf). Room for `cap`
 * slots and cap / 4 + 1 leaves. */
typedef struct {
    double *x, *y, *z, *d2;
    int64_t *idx, *pos;
    double *lb[6];
    int32_t *start;
    int64_t n, nl, cap;
} block_t;

static int block_alloc(block_t *b, int64_t cap) {
    int64_t lcap = cap / 4 + 8;
    b->cap = cap;
    double **dp[4] = {&b->x, &b->y, &b->z, &b->d2};
    for (int t = 0; t < 4; t++) *dp[t] = (double *)malloc((size_t)cap * sizeof(double));
    b->idx = (int64_t *)malloc((size_t)cap * sizeof(int64_t));
    b->pos = (int64_t *)malloc((size_t)cap * sizeof(int64_t));
    for (int a = 0; a < 6; a++) b->lb[a] = (double *)malloc((size_t)lcap * sizeof(double));
    b->start = (int32_t *)malloc((size_t)lcap * sizeof(int32_t));
    int ok = b->x && b->y && b->z && b->d2 && b->idx && b->pos && b->start;
    for (int a = 0; a < 6; a++) ok = ok && b->lb[a];
    return ok ? 0 : -1;
}

static void block_free(block_t *b) {
    free(b->x); free(b->y); free(b->z); free(b->d2);
    free(b->idx); free(b->pos);
    for (int a = 0; a < 6; a++) free(b->lb[a]);
    free(b->start);
}

/* Append to b the points of the leaves whose box lies within squared distance r2 of
 * box lb, unless more than b->cap slots: returns 0, or 1 (over). Every point left out
 * is farther than r2 from every point in lb. */
static int gather(const tree_t *T, const double *lb, double r2, int64_t t, int64_t s,
                  int64_t e, int d, block_t *b) {
    if (box_dist2(T->box + 6 * t, lb) > r2) return 0;
    if (d < T->depth) {
        int64_t m = s + (e - s) / 2;
        int rc = gather(T, lb, r2, 2 * t + 1, s, m, d + 1, b);
        return rc ? rc : gather(T, lb, r2, 2 * t + 2, m, e, d + 1, b);
    }
    int64_t u = b->n, end = u + ((e - s + 3) & ~(int64_t)3);
    if (e <= s) return 0;
    if (end > b->cap) return 1;
    for (int64_t j = s; j < e; j++, u++) {
        b->x[u] = T->p[3 * j];
        b->y[u] = T->p[3 * j + 1];
        b->z[u] = T->p[3 * j + 2];
        b->idx[u] = T->orig[j];
        b->pos[u] = j;
    }
    for (; u < end; u++) {
        b->x[u] = b->y[u] = b->z[u] = NAN;
        b->idx[u] = b->pos[u] = 0;
    }
    for (int a = 0; a < 6; a++) b->lb[a][b->nl] = T->box[6 * t + a];
    b->start[b->nl++] = (int32_t)b->n;
    b->start[b->nl] = (int32_t)end;
    b->n = end;
    return 0;
}

/* The block of the leaf box lb at squared radius r2 (gather), its box rows padded:
 * returns 0, or 1 (over b->cap slots). */
static int gather_block(const tree_t *T, const double *lb, double r2, block_t *b) {
    b->n = 0;
    b->nl = 0;
    b->start[0] = 0;
    int rc = gather(T, lb, r2, 0, 0, T->n, 0, b);
    for (int64_t l = b->nl; l < ((b->nl + 3) & ~(int64_t)3); l++) {
        for (int a = 0; a < 3; a++) b->lb[a][l] = INFINITY;
        for (int a = 3; a < 6; a++) b->lb[a][l] = -INFINITY;
    }
    return rc;
}

/* Lower bound of the squared distance of (px, py, pz) to the points of box l of b: the
 * gaps max(lo - p, p - hi, 0) on each axis, squared and summed in order (as box_dist2,
 * never above a point's d2). */
static inline double leaf_gap2(const block_t *b, int64_t l, double px, double py, double pz) {
    double p[3] = {px, py, pz}, s = 0.0;
    for (int a = 0; a < 3; a++) {
        double lo = b->lb[a][l] - p[a], hi = p[a] - b->lb[3 + a][l];
        double g = lo > hi ? lo : hi;
        g = g > 0.0 ? g : 0.0;
        s += g * g;
    }
    return s;
}

/* The squared distances b->d2[j] from (px, py, pz) of the points of the block's leaves
 * whose box is within limit2, and the entries j with d2 <= limit2 into sel (room for
 * b->n + 3), leaf by leaf: returns their number. dx * dx + dy * dy + dz * dz summed in
 * that order, every lane as the scalar. key: unused (see block_scan_avx2). */
static int64_t block_scan(const block_t *b, double px, double py, double pz, double limit2,
                          int32_t *sel, float *key) {
    (void)key;
    int64_t m = 0;
    double *bd = b->d2;
    for (int64_t l = 0; l < b->nl; l++) {
        if (leaf_gap2(b, l, px, py, pz) > limit2) continue;
        for (int64_t j = b->start[l]; j < b->start[l + 1]; j++) { /* branch-free */
            double dx = b->x[j] - px, dy = b->y[j] - py, dz = b->z[j] - pz;
            bd[j] = dx * dx + dy * dy + dz * dz;
            sel[m] = (int32_t)j;
            m += bd[j] <= limit2;
        }
    }
    return m;
}

#ifdef HAVE_AVX2_PATH
/* block_scan on 4 lanes (AVX2, no fused multiply-add: the same roundings), 4 leaf boxes
 * at a time; the entries kept written branch-free, 4 at a time from a table of the 16
 * masks, and beside them their d2 rounded to float in key (for rank_select_avx2). */
/* scan_pick[mask]: the lanes set in mask, in order (then 0s) */
static const int32_t scan_pick[16][4] = {
    {0, 0, 0, 0}, {0, 0, 0, 0}, {1, 0, 0, 0}, {0, 1, 0, 0},
    {2, 0, 0, 0}, {0, 2, 0, 0}, {1, 2, 0, 0}, {0, 1, 2, 0},
    {3, 0, 0, 0}, {0, 3, 0, 0}, {1, 3, 0, 0}, {0, 1, 3, 0},
    {2, 3, 0, 0}, {0, 2, 3, 0}, {1, 2, 3, 0}, {0, 1, 2, 3}};

__attribute__((target("avx2,popcnt,bmi"))) static int64_t block_scan_avx2(
    const block_t *b, double px, double py, double pz, double limit2, int32_t *sel, float *key) {
    int64_t m = 0, nl = b->nl;
    const double *x = b->x, *y = b->y, *z = b->z;
    double *const *lb = b->lb;
    const int32_t *start = b->start;
    double *bd = b->d2;
    __m256d vx = _mm256_set1_pd(px), vy = _mm256_set1_pd(py), vz = _mm256_set1_pd(pz);
    __m256d lim = _mm256_set1_pd(limit2), zero = _mm256_setzero_pd();
    for (int64_t l0 = 0; l0 < nl; l0 += 4) {
        __m256d gx = _mm256_max_pd(_mm256_max_pd(_mm256_sub_pd(_mm256_loadu_pd(lb[0] + l0), vx),
                                                 _mm256_sub_pd(vx, _mm256_loadu_pd(lb[3] + l0))),
                                   zero);
        __m256d gy = _mm256_max_pd(_mm256_max_pd(_mm256_sub_pd(_mm256_loadu_pd(lb[1] + l0), vy),
                                                 _mm256_sub_pd(vy, _mm256_loadu_pd(lb[4] + l0))),
                                   zero);
        __m256d gz = _mm256_max_pd(_mm256_max_pd(_mm256_sub_pd(_mm256_loadu_pd(lb[2] + l0), vz),
                                                 _mm256_sub_pd(vz, _mm256_loadu_pd(lb[5] + l0))),
                                   zero);
        __m256d g = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(gx, gx), _mm256_mul_pd(gy, gy)),
                                  _mm256_mul_pd(gz, gz));
        unsigned near = (unsigned)_mm256_movemask_pd(_mm256_cmp_pd(g, lim, _CMP_LE_OQ));
        while (near) {
            int64_t l = l0 + __builtin_ctz(near), end = start[l + 1];
            near &= near - 1;
            __m128i at = _mm_set1_epi32(start[l]);
            for (int64_t j = start[l]; j < end; j += 4) {
                __m256d dx = _mm256_sub_pd(_mm256_loadu_pd(x + j), vx);
                __m256d dy = _mm256_sub_pd(_mm256_loadu_pd(y + j), vy);
                __m256d dz = _mm256_sub_pd(_mm256_loadu_pd(z + j), vz);
                __m256d d = _mm256_add_pd(
                    _mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)),
                    _mm256_mul_pd(dz, dz));
                _mm256_storeu_pd(bd + j, d);
                int mask = _mm256_movemask_pd(_mm256_cmp_pd(d, lim, _CMP_LE_OQ));
                __m128i pick = _mm_loadu_si128((const __m128i *)scan_pick[mask]);
                _mm_storeu_si128((__m128i *)(sel + m), _mm_add_epi32(pick, at));
                _mm_storeu_ps(key + m, _mm_permutevar_ps(_mm256_cvtpd_ps(d), pick));
                m += __builtin_popcount((unsigned)mask);
                at = _mm_add_epi32(at, _mm_set1_epi32(4));
            }
        }
    }
    return m;
}

/* The ranks of key[j0 .. j0 + 8 nv) among key[0..m) (nv <= 4), as minus the sum of the
 * comparisons' all-ones lanes. */
#define RANK_ADD(a, ki, kj) \
    a = _mm256_add_epi32(a, _mm256_castps_si256(_mm256_cmp_ps(ki, kj, _CMP_LT_OQ)))
__attribute__((target("avx2"))) static inline __attribute__((always_inline)) void rank_lanes(
    const float *key, int64_t m, int64_t j0, int nv, int32_t *rank) {
    __m256 k0 = _mm256_loadu_ps(key + j0), k1 = _mm256_loadu_ps(key + j0 + 8);
    __m256 k2 = _mm256_loadu_ps(key + j0 + 16), k3 = _mm256_loadu_ps(key + j0 + 24);
    __m256i a0 = _mm256_setzero_si256(), a1 = a0, a2 = a0, a3 = a0;
    for (int64_t i = 0; i < m; i += 2) { /* key[m] is +inf: below none */
        __m256 ki = _mm256_broadcast_ss(key + i), kn = _mm256_broadcast_ss(key + i + 1);
        RANK_ADD(a0, ki, k0);
        RANK_ADD(a0, kn, k0);
        if (nv > 1) { RANK_ADD(a1, ki, k1); RANK_ADD(a1, kn, k1); }
        if (nv > 2) { RANK_ADD(a2, ki, k2); RANK_ADD(a2, kn, k2); }
        if (nv > 3) { RANK_ADD(a3, ki, k3); RANK_ADD(a3, kn, k3); }
    }
    __m256i acc[4] = {a0, a1, a2, a3};
    for (int v = 0; v < nv; v++) {
        _mm256_storeu_si256((__m256i *)(rank + j0 + 8 * v),
                            _mm256_sub_epi32(_mm256_setzero_si256(), acc[v]));
    }
}
#undef RANK_ADD

/* The m candidates sel (their d2 in b->d2, rounded to float in key: room for m + 32)
 * put at their ranks in out (room for m): the rank of j is #{i : key[i] < key[j]}, 32
 * keys at a time and branch-free. Returns 1, or 0 when two keys are equal (a tie in d2,
 * or d2 closer than a float's precision: the ranks repeat, and their sum falls below
 * m (m - 1) / 2): then out is to be filled another way. Distinct keys order the d2 as
 * they do (rounding to float is nondecreasing), so no index is needed. */
__attribute__((target("avx2"))) static int rank_select_avx2(const block_t *b, const int32_t *sel,
                                                            float *key, int64_t m, cand_t *out,
                                                            int32_t *rank) {
    for (int64_t j = m; j < m + 32; j++) key[j] = INFINITY;
    for (int64_t j0 = 0; j0 < m; j0 += 32) {
        int64_t left = m - j0;
        if (left > 24) rank_lanes(key, m, j0, 4, rank);
        else if (left > 16) rank_lanes(key, m, j0, 3, rank);
        else if (left > 8) rank_lanes(key, m, j0, 2, rank);
        else rank_lanes(key, m, j0, 1, rank);
    }
    int64_t sum = 0;
    for (int64_t j = 0; j < m; j++) {
        int32_t r = rank[j], s = sel[j];
        sum += r;
        out[r].d2 = b->d2[s];
        out[r].idx = b->idx[s];
        out[r].pos = b->pos[s];
    }
    return sum == m * (m - 1) / 2;
}
#endif

typedef int64_t (*block_scan_fn)(const block_t *, double, double, double, double, int32_t *,
                                 float *);

/* The block_scan to use: the AVX2 one when use_avx2. */
static block_scan_fn block_scanner(void) {
#ifdef HAVE_AVX2_PATH
    if (use_avx2()) return block_scan_avx2;
#endif
    return block_scan;
}

/* Buckets of nearest_of_block's counting sort. */
#define NEAR_BUCKETS 64

/* The k nearest of the m candidates sel (block entries whose squared distance bd[sel[t]]
 * is at most limit2, m >= k) into out[0..k), sorted by (d2, idx); out has room for m,
 * bucket for m, count for NEAR_BUCKETS + 1. A counting sort on the bucket
 * floor(d2 * NEAR_BUCKETS / limit2) (nondecreasing in d2: a candidate of a later bucket
 * is strictly farther), then an insertion sort of the candidates of the buckets up to
 * the one that reaches k (only the members of one bucket are out of order; on a
 * surface, d2 is about uniform over [0, limit2]). Many candidates in those buckets (ties,
 * a crowded bucket): a selection of every candidate instead. */
static void nearest_of_block(const block_t *b, const double *bd, const int32_t *sel, int64_t m,
                             int64_t k, double limit2, cand_t *out, uint8_t *bucket,
                             int32_t *count) {
    double scale = NEAR_BUCKETS / limit2;
    int64_t total = m;
    if (scale > 0.0 && scale < INFINITY) {
        memset(count, 0, (NEAR_BUCKETS + 1) * sizeof(int32_t));
        for (int64_t t = 0; t < m; t++) {
            double x = bd[sel[t]] * scale;
            int c = x < NEAR_BUCKETS - 1 ? (int)x : NEAR_BUCKETS - 1;
            bucket[t] = (uint8_t)c;
            count[c + 1]++;
        }
        int last = 0;
        while (count[last + 1] < k) { /* buckets [0, last] hold at least k */
            last++;
            count[last + 1] += count[last];
        }
        total = count[last + 1];
        if (total <= 2 * k + 16) {
            for (int64_t t = 0; t < m; t++) {
                if (bucket[t] > last) continue;
                int32_t j = sel[t];
                cand_t *c = out + count[bucket[t]]++;
                c->d2 = bd[j]; c->idx = b->idx[j]; c->pos = b->pos[j];
            }
            insertion_sort(out, total);
            return;
        }
    }
    for (int64_t t = 0; t < m; t++) {
        int32_t j = sel[t];
        out[t].d2 = bd[j]; out[t].idx = b->idx[j]; out[t].pos = b->pos[j];
    }
    select_sorted(out, m, k);
}

/* The node at depth d holding tree position i, and its points [*s, *e). */
static int64_t node_of(const tree_t *T, int64_t i, int d, int64_t *s, int64_t *e) {
    int64_t t = 0;
    *s = 0;
    *e = T->n;
    for (int u = 0; u < d; u++) {
        int64_t m = *s + (*e - *s) / 2;
        if (i < m) { t = 2 * t + 1; *e = m; }
        else { t = 2 * t + 2; *s = m; }
    }
    return t;
}

/* Squared radius of a block, relative to the largest k-th squared distance of the
 * previous block's points (radius x 1.25). */
#define BLOCK_GROW 1.5625
/* A block serves the points of a node this many levels above the leaves (two leaves). */
#define BLOCK_UP 1
/* The first bound tried for a point: this times the previous point's k-th squared
 * distance (radius x 1.095), when below the proven one. */
#define KNN_GUESS 1.2

/* The exact kNN of points of the tree taken one after the other (in increasing tree
 * position: every one, or a few here and there), each answer into h.c[0..k), sorted by
 * (d2, idx).
 *
 * Points are taken node by node (the nodes BLOCK_UP levels above the leaves). The
 * points of the leaves within a radius r of the node's box are gathered once for all
 * its points (r: 1.25 times the largest k-th distance found in the previous node); a
 * point's k nearest are among them when at least k lie within r. The k-th distance of
 * the previous point plus the distance between the two bounds this point's k-th
 * distance (triangle inequality). A point first scans the block's leaves within a guess
 * (KNN_GUESS times the previous point's k-th squared distance, when below that bound),
 * then, when fewer than k points lie within the guess, the leaves within the bound: at
 * least k points within either hold the k nearest. The candidates are then ranked
 * (rank_select_avx2, or nearest_of_block's selection). Otherwise (the k-th distance
 * grew, or the block would exceed a few thousand points, as around a far outlier) the
 * point gets a heap search of the tree: O(log n) per point whatever the
 * spatial distribution. */
typedef struct {
    tree_t T;
    int64_t k;
    heap_t h;
    block_t blk;
    int32_t *sel, *rank;
    float *key;
    uint8_t *bucket;
    int32_t count[NEAR_BUCKETS + 1];
    block_scan_fn scan;
    int avx2, have_block;
    int64_t node_s, node_e; /* the points the block serves */
    double r2, node_max, prev_r, prev_k2, prev_p[3];
} knn_cursor_t;

/* Returns 0, or -1 out of memory (then knn_cursor_free it all the same). */
static int knn_cursor_init(knn_cursor_t *c, const tree_t *T, int64_t k) {
    memset(c, 0, sizeof *c);
    c->T = *T;
    c->k = k;
    int64_t limit = 64 * k + 1024; /* slots of a block */
    c->h.c = (cand_t *)malloc((size_t)limit * sizeof(cand_t));
    c->h.k = k;
    c->h.tau = INFINITY;
    c->sel = (int32_t *)malloc((size_t)(limit + 32) * sizeof(int32_t));
    c->rank = (int32_t *)malloc((size_t)(limit + 32) * sizeof(int32_t));
    c->key = (float *)malloc((size_t)(limit + 32) * sizeof(float));
    c->bucket = (uint8_t *)malloc((size_t)limit);
    c->scan = block_scanner();
    c->avx2 = use_avx2();
    c->r2 = -1.0;
    c->prev_r = -1.0;
    c->prev_k2 = -1.0;
    int rc = block_alloc(&c->blk, limit);
    return !rc && c->h.c && c->sel && c->rank && c->key && c->bucket ? 0 : -1;
}

static void knn_cursor_free(knn_cursor_t *c) {
    free(c->h.c);
    block_free(&c->blk);
    free(c->sel);
    free(c->rank);
    free(c->key);
    free(c->bucket);
}

/* The k nearest of the m >= k candidates c->sel (within limit2) into c->h.c[0..k). */
static void select_block(knn_cursor_t *c, int64_t m, double limit2) {
#ifdef HAVE_AVX2_PATH
    if (c->avx2 && rank_select_avx2(&c->blk, c->sel, c->key, m, c->h.c, c->rank)) return;
#endif
    nearest_of_block(&c->blk, c->blk.d2, c->sel, m, c->k, limit2, c->h.c, c->bucket, c->count);
}

/* The k nearest of the point at tree position i into c->h.c[0..k) (fastest with the
 * positions increasing). */
static void knn_cursor_next(knn_cursor_t *c, int64_t i) {
    const tree_t *T = &c->T;
    const double *pi = T->p + 3 * i;
    int64_t k = c->k;
    double tau = kth_bound(pi, c->prev_p, c->prev_r);
    if (i < c->node_s || i >= c->node_e) {
        int up = T->depth < BLOCK_UP ? T->depth : BLOCK_UP;
        int64_t t = node_of(T, i, T->depth - up, &c->node_s, &c->node_e);
        if (c->node_max > 0.0) c->r2 = c->node_max * BLOCK_GROW;
        c->node_max = 0.0;
        c->have_block = c->r2 >= 0.0 && gather_block(T, T->box + 6 * t, c->r2, &c->blk) == 0;
    }
    int found = 0;
    if (c->have_block && c->blk.n >= k) {
        double limit2 = tau < c->r2 ? tau : c->r2, guess = c->prev_k2 * KNN_GUESS;
        for (int pass = guess > 0.0 && guess < limit2 ? 0 : 1; pass < 2 && !found; pass++) {
            double bound = pass ? limit2 : guess;
            int64_t m = c->scan(&c->blk, pi[0], pi[1], pi[2], bound, c->sel, c->key);
            if (m >= k) {
                select_block(c, m, bound);
                found = 1;
            }
        }
    }
    if (!found) knn_search(T, pi, k, tau, &c->h);
    double kth = c->h.c[k - 1].d2;
    if (kth > c->node_max) c->node_max = kth;
    if (c->r2 < 0.0) c->r2 = kth * BLOCK_GROW; /* the first point */
    c->prev_r = sqrt(kth);
    c->prev_k2 = kth;
    c->prev_p[0] = pi[0]; c->prev_p[1] = pi[1]; c->prev_p[2] = pi[2];
}

/* cloud_out_t: what one pass over the points writes (_ckernels.h). */

/* kNN of tree positions [begin, end) at k = max(ks) (knn_cursor_t), then what out asks
 * for (see cloud_out_t). Returns 0, or -1 out of memory. */
/* The offsets q (k, 3) of one kNN list nb (k = mk[nscales - 1]) from the point pi, q_j =
 * p[nb[j].pos] - pi, their squared lengths d2 (k) = nb[j].d2, and on the way scale_means'
 * smean and sh2 of the prefixes mk (the same running sums, in the same order). */
static void offsets_means(const double *p, const double *pi, const cand_t *nb,
                          const int64_t *mk, int nscales, double *q, double *d2, double *smean,
                          double *sh2) {
    double sx = 0, sy = 0, sz = 0, h2 = 0;
    int64_t j = 0;
    for (int s = 0; s < nscales; s++) {
        int64_t m = mk[s];
        for (; j < m; j++) {
            const double *pj = p + 3 * nb[j].pos;
            double x = pj[0] - pi[0], y = pj[1] - pi[1], z = pj[2] - pi[2], dj = nb[j].d2;
            q[3 * j] = x; q[3 * j + 1] = y; q[3 * j + 2] = z;
            d2[j] = dj;
            sx += x; sy += y; sz += z;
            if (dj > h2) h2 = dj;
        }
        smean[3 * s] = sx / (double)m;
        smean[3 * s + 1] = sy / (double)m;
        smean[3 * s + 2] = sz / (double)m;
        sh2[s] = h2;
    }
}

#ifdef HAVE_AVX2_PATH
/* offsets_means with each offset's x, y, z in the lanes of one register (the 4th lane
 * 0, masked off p and smean; q has room for one more double): the same differences,
 * sums and quotients, lane by lane. */
__attribute__((target("avx2"))) static void offsets_means_avx2(const double *p,
                                                               const double *pi,
                                                               const cand_t *nb,
                                                               const int64_t *mk, int nscales,
                                                               double *q, double *d2,
                                                               double *smean, double *sh2) {
    const __m256i xyz = _mm256_setr_epi64x(-1, -1, -1, 0);
    __m256d vpi = _mm256_maskload_pd(pi, xyz), sum = _mm256_setzero_pd();
    double h2 = 0;
    int64_t j = 0;
    for (int s = 0; s < nscales; s++) {
        int64_t m = mk[s];
        for (; j < m; j++) {
            __m256d v = _mm256_sub_pd(_mm256_maskload_pd(p + 3 * nb[j].pos, xyz), vpi);
            double dj = nb[j].d2;
            _mm256_storeu_pd(q + 3 * j, v);
            d2[j] = dj;
            sum = _mm256_add_pd(sum, v);
            if (dj > h2) h2 = dj;
        }
        _mm256_maskstore_pd(smean + 3 * s, xyz, _mm256_div_pd(sum, _mm256_set1_pd((double)m)));
        sh2[s] = h2;
    }
}
#endif

/* offsets_means, on 4 lanes when avx2. */
static inline void offsets_means_on(const double *p, const double *pi, const cand_t *nb,
                                    const int64_t *mk, int nscales, double *q, double *d2,
                                    double *smean, double *sh2, int avx2) {
#ifdef HAVE_AVX2_PATH
    if (avx2) {
        offsets_means_avx2(p, pi, nb, mk, nscales, q, d2, smean, sh2);
        return;
    }
#endif
    (void)avx2;
    offsets_means(p, pi, nb, mk, nscales, q, d2, smean, sh2);
}

int ms_cloud_pdis(const double *p, const int64_t *orig, int64_t n, const double *box, int depth,
                  const int64_t *ks, int nscales, int gaussian, int64_t begin, int64_t end,
                  const cloud_out_t *out) {
    tree_t T = {p, orig, box, n, depth};
    int64_t kmax = ks[nscales - 1];
    knn_cursor_t cur;
    int cur_rc = knn_cursor_init(&cur, &T, kmax);
    const cand_t *nb = cur.h.c;
    double *q = (double *)malloc(((size_t)kmax * 3 + 1) * sizeof(double)); /* +1: see
                                                                                * offsets_means_avx2 */
    double *d2 = (double *)malloc((size_t)kmax * sizeof(double));
    pca_lanes_fn pca = pca_lanes();
    /* per scale: mean offset (3), normal (3), largest squared distance (1) */
    double *smean = (double *)malloc((size_t)nscales * 7 * sizeof(double));
    double *snrm = smean ? smean + 3 * nscales : NULL, *sh2 = smean ? smean + 6 * nscales : NULL;
    double *soa = (double *)malloc((size_t)kmax * 4 * sizeof(double));
    double *ws = (double *)malloc((size_t)kmax * PCA_LANES * sizeof(double)); /* weights */
    double *ell = (double *)malloc((size_t)nscales * 2 * sizeof(double)); /* l, then o */
    double *hs = (double *)malloc((size_t)kmax * 2 * sizeof(double));
    int64_t *order = (int64_t *)malloc((size_t)kmax * sizeof(int64_t));
    char *keep = (char *)malloc((size_t)kmax);
    const sheet_params_t sheet = sheet_params(out);
    int64_t *mk = (int64_t *)malloc((size_t)nscales * sizeof(int64_t));
    int rc = 0;
    if (cur_rc || !q || !d2 || !smean || !soa || !ws || !ell || !hs || !order || !keep || !mk) {
        rc = -1;
        goto done;
    }
    for (int64_t i = begin; i < end; i++) {
        const double *pi = p + 3 * i;
        knn_cursor_next(&cur, i);
        int64_t ci = orig[i], oi = out->tree_order ? i : ci; /* cleaned index, its row */
        if (out->idx != NULL) {
            for (int64_t j = 0; j < kmax; j++) out->idx[oi * kmax + j] = nb[j].idx;
        }
        if (out->near != NULL) { /* tree_order 2: a tree position (ms_isolated_tree) */
            const cand_t *c = kmax > 1 ? nb + 1 : NULL;
            out->near[oi] = (int32_t)(out->tree_order == 2 ? (c ? c->pos : i) : (c ? c->idx : ci));
        }
        if (out->kth_d2 != NULL) {
            out->kth_d2[oi] = nb[kmax - 1].d2;
            out->kth_idx[oi] = (int32_t)nb[kmax - 1].idx;
        }
        if (out->pdis == NULL && out->relative == NULL && out->noise == NULL) continue;
        for (int s = 0; s < nscales; s++) mk[s] = ks[s];
        offsets_means_on(p, pi, nb, mk, nscales, q, d2, smean, sh2, sheet.avx2);
        /* known: how many of the largest scales have their normal from the sheet filter's
         * PCA (the largest scale's, and the next one's computed beside it): their lists
         * are the same when the filter keeps every neighbour */
        int known = 0, means = 1; /* means: smean and sh2 hold the lists' */
        int pdis_wanted = out->pdis != NULL || out->relative != NULL;
        if (out->sheet_gap > 0.0) {
            /* the largest scale's normal for the filter, and the next ones' beside it */
            known = !pdis_wanted ? 1 : nscales < PCA_LANES ? nscales : PCA_LANES;
            pca_scales(pca, q, d2, mk, smean, sh2, nscales - known, nscales, gaussian, ws,
                       snrm);
            if (sheet_keep(q, d2, kmax, snrm + 3 * (nscales - 1), &sheet, hs, order, keep) > 0) {
                known = 0;
                means = 0;
                int64_t t = 0, s = 0;
                for (int64_t j = 0; j < kmax; j++) {
                    while (s < nscales && ks[s] == j) mk[s++] = t;
                    if (!keep[j]) continue;
                    q[3 * t] = q[3 * j]; q[3 * t + 1] = q[3 * j + 1]; q[3 * t + 2] = q[3 * j + 2];
                    d2[t] = d2[j];
                    t++;
                }
                while (s < nscales) mk[s++] = t;
            }
        }
        int64_t kk = mk[nscales - 1]; /* the list's length after the sheet filter */
        if (out->noise != NULL) {
            int64_t k0 = out->noise_k < kk ? out->noise_k : kk;
            out->noise[oi] = k0 >= 2 ? noise_ratio(q, k0) : 0.0;
        }
        if (out->relative != NULL) {
            local_scale_values(q, d2, kk, soa, sheet.avx2);
            local_scale_prefixes_on(soa, mk, nscales, ell, ell + nscales, sheet.avx2);
        }
        if (out->pdis == NULL && out->relative == NULL) continue;
        double score = 0.0;
        if (!means) scale_means(q, d2, mk, nscales, smean, sh2);
        /* the scales whose normals are still to do, PCA_LANES at a time */
        pca_scales(pca, q, d2, mk, smean, sh2, 0, nscales - known, gaussian, ws, snrm);
        for (int s = 0; s < nscales; s++) {
            const double *mean = smean + 3 * s, *nv = snrm + 3 * s;
            double pd = fabs(mean[0] * nv[0] + mean[1] * nv[1] + mean[2] * nv[2]);
            if (out->normals != NULL) {
                double *nrm = out->normals + 3 * (s * n + oi);
                nrm[0] = nv[0]; nrm[1] = nv[1]; nrm[2] = nv[2];
            }
            if (out->pdis != NULL) out->pdis[s * n + oi] = pd;
            if (out->relative != NULL) { /* min(x / l, 1) keeps a NaN, as np.minimum */
                double l = ell[s], r = l > 0 ? pd / l : 0.0, g = l > 0 ? ell[nscales + s] / l : 0.0;
                out->relative[s * n + oi] = r > 1.0 ? 1.0 : r;
                score += (g > 1.0 ? 1.0 : g) / (double)nscales;
            }
        }
        if (out->score != NULL) out->score[oi] = score;
    }
done:
    knn_cursor_free(&cur);
    free(q);
    free(d2);
    free(smean);
    free(soa);
    free(ws);
    free(ell);
    free(hs);
    free(order);
    free(keep);
    free(mk);
    return rc;
}

/* Rows [begin, end) of src (n rows of `bytes` bytes each, tree order) to their cleaned
 * positions in dst: row i to row orig[i] (the pass's tree_order outputs: rows of 8-byte
 * values, and the statistics' int32 indices). */
void ms_scatter_rows(const int64_t *orig, const void *src, int64_t bytes, int64_t begin,
                     int64_t end, void *dst) {
    if (bytes == 8) { /* one value a row: a plain copy, no memcpy call per row */
        const uint64_t *s = (const uint64_t *)src;
        uint64_t *d = (uint64_t *)dst;
        for (int64_t i = begin; i < end; i++) d[orig[i]] = s[i];
        return;
    }
    if (bytes == 4) {
        const uint32_t *s = (const uint32_t *)src;
        uint32_t *d = (uint32_t *)dst;
        for (int64_t i = begin; i < end; i++) d[orig[i]] = s[i];
        return;
    }
    const char *s = (const char *)src;
    char *d = (char *)dst;
    for (int64_t i = begin; i < end; i++) {
        memcpy(d + orig[i] * bytes, s + i * bytes, (size_t)bytes);
    }
}

/* Whether the point a (cleaned index i) is not among the kmax nearest of its nearest b,
 * whose kmax-th neighbour has squared distance kth and index kth_idx: (|a - b|^2, i)
 * comes after (kth, kth_idx) in the lists' order (squared distance, then index). */
static inline uint8_t isolated_one(const double *a, const double *b, double kth,
                                   int64_t kth_idx, int64_t i) {
    double dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
    double d2 = dx * dx + dy * dy + dz * dz;
    return !(d2 < kth || (d2 == kth && i <= kth_idx));
}

/* robust.isolated_points from a pass's statistics (cloud_out_t's near, kth_d2, kth_idx)
 * for the points [begin, end) of p (n, 3), cleaned order: out[i] = isolated_one of i and
 * j = near[i]. */
void ms_isolated(const double *p, const int32_t *near, const double *kth_d2,
                 const int32_t *kth_idx, int64_t begin, int64_t end, uint8_t *out) {
    for (int64_t i = begin; i < end; i++) {
        int64_t j = near[i];
        out[i] = isolated_one(p + 3 * i, p + 3 * j, kth_d2[j], kth_idx[j], i);
    }
}

/* ms_isolated from a tree_order pass's statistics, for the tree positions [begin, end):
 * tp (n, 3) the points in tree order, orig their cleaned indices, near[t] the tree
 * position of the nearest, out[t] per tree position. The nearest lies close by in the
 * tree: reads near the point's own, where cleaned order reads all over the cloud. */
void ms_isolated_tree(const double *tp, const int64_t *orig, const int32_t *near,
                      const double *kth_d2, const int32_t *kth_idx, int64_t begin, int64_t end,
                      uint8_t *out) {
    for (int64_t t = begin; t < end; t++) {
        int64_t u = near[t];
        out[t] = isolated_one(tp + 3 * t, tp + 3 * u, kth_d2[u], kth_idx[u], orig[t]);
    }
}

/* Counts of the values v[begin, end) added to counts (32769): +0.0 in counts[0], any
 * other value by the top 16 bits b of its IEEE 754 bit pattern in counts[b + 1]: from
 * +0.0 up to +inf and then NaN, the bins follow the values' order (np.partition's, NaN
 * last). Returns how many values have the sign bit set (negative, -0.0; left out). */
int64_t ms_bit_histogram(const double *v, int64_t begin, int64_t end, int64_t *counts) {
    int64_t negative = 0;
    for (int64_t i = begin; i < end; i++) {
        uint64_t bits;
        memcpy(&bits, v + i, sizeof bits);
        uint64_t sign = bits >> 63;
        negative += (int64_t)sign;
        counts[bits ? (bits >> 48) + 1 : 0] += !sign;
    }
    return negative;
}

/* For r in [begin, end): the k nearest of the point at tree position pos[r] into
 * out_idx[r * k ...] (cleaned indices sorted by (squared distance, index), the rows of
 * ms_cloud_pdis's kNN table), by the same knn_cursor_t: rows in increasing tree
 * position share their node's block and are pruned by the previous row's k-th
 * distance. Returns 0, or -1 out of memory. */
int ms_knn_rows(const double *p, const int64_t *orig, int64_t n, const double *box, int depth,
                const int64_t *pos, int64_t k, int64_t begin, int64_t end, int64_t *out_idx) {
    tree_t T = {p, orig, box, n, depth};
    knn_cursor_t cur;
    int rc = knn_cursor_init(&cur, &T, k);
    for (int64_t r = begin; r < end && rc == 0; r++) {
        knn_cursor_next(&cur, pos[r]);
        for (int64_t j = 0; j < k; j++) out_idx[r * k + j] = cur.h.c[j].idx;
    }
    knn_cursor_free(&cur);
    return rc;
}

/* ------------------------------------------------------------------ meshes */

/* 1-ring adjacency of a triangle mesh in CSR form: ptr (n + 1), idx (room for 6 m). Each
 * face adds both other corners to each of its corners, in face order; only the first
 * occurrence of a neighbour is kept (a breadth-first search over these lists meets the
 * vertices in the order it meets them over the lists with repeats, at half the reads).
 * Returns 0, -1 out of memory, or -2 when a face index lies outside [0, n) (nothing is
 * written out of bounds). */
int ms_adjacency(const int64_t *faces, int64_t m, int64_t n, int64_t *ptr, int32_t *idx) {
    for (int64_t f = 0; f < 3 * m; f++) {
        if (faces[f] < 0 || faces[f] >= n) return -2;
    }
    /* the last vertex listing each vertex (n < 2^31: idx holds int32 vertices) */
    int32_t *last = (int32_t *)malloc((size_t)(n > 0 ? n : 1) * sizeof(int32_t));
    if (last == NULL) return -1;
    /* ptr[v + 1] counts v's entries, then (summed) is v's end, so ptr[v] is v's start:
     * the fill moves it to v's end, one place below where the CSR wants it (moved up
     * after). No fill array beside ptr: 8 bytes a vertex less, and no copy of ptr. */
    memset(ptr, 0, (size_t)(n + 1) * sizeof(int64_t));
    for (int64_t f = 0; f < 3 * m; f++) ptr[faces[f] + 1] += 2;
    for (int64_t v = 0; v < n; v++) ptr[v + 1] += ptr[v];
    for (int64_t f = 0; f < m; f++) {
        int64_t a = faces[3 * f], b = faces[3 * f + 1], c = faces[3 * f + 2];
        idx[ptr[a]++] = (int32_t)b; idx[ptr[a]++] = (int32_t)c;
        idx[ptr[b]++] = (int32_t)a; idx[ptr[b]++] = (int32_t)c;
        idx[ptr[c]++] = (int32_t)a; idx[ptr[c]++] = (int32_t)b;
    }
    memmove(ptr + 1, ptr, (size_t)n * sizeof(int64_t));
    ptr[0] = 0;
    /* compact in place, first occurrences only */
    for (int64_t v = 0; v < n; v++) last[v] = -1;
    int64_t w = 0, start = 0;
    for (int64_t v = 0; v < n; v++) {
        int64_t stop = ptr[v + 1];
        for (int64_t t = start; t < stop; t++) {
            int32_t x = idx[t];
            idx[w] = x;
            w += last[x] != (int32_t)v;
            last[x] = (int32_t)v;
        }
        start = stop;
        ptr[v + 1] = w;
    }
    free(last);
    return 0;
}

/* ms_scattered's sampling: every step-th vertex, up to about MS_SCATTER_SAMPLES. */
static int64_t scatter_step(int64_t n) {
    return n / MS_SCATTER_SAMPLES > 1 ? n / MS_SCATTER_SAMPLES : 1;
}

/* Whether vertex v's first neighbour w lies more than MS_SCATTERED_GAP positions away. */
static int far_apart(int64_t v, int64_t w) {
    return w - v > MS_SCATTERED_GAP || v - w > MS_SCATTERED_GAP;
}

/* Whether a mesh's vertices should be renumbered (ms_bfs_renumber): more than
 * half of up to MS_SCATTER_SAMPLES vertices v evenly spread, among those with neighbours,
 * lie more than MS_SCATTERED_GAP positions from their first neighbour adj[ptr[v]]. A
 * grid-ordered mesh's gap is about its row length (408 on the 1M bench mesh), a scanned
 * or shuffled one's a fair fraction of n; 16384 vertices' points span 384 KiB, within
 * the 1 MiB L2 cache beside their lists, and below that the renumbering (about 0.1 us a
 * vertex on a local order, 0.4 on a scattered one) would not pay. */
int ms_scattered(const int64_t *ptr, const int32_t *adj, int64_t n) {
    if (n <= MS_SCATTERED_GAP) return 0;
    const int64_t step = scatter_step(n);
    int64_t far = 0, seen = 0;
    for (int64_t v = 0; v < n; v += step) {
        if (ptr[v + 1] == ptr[v]) continue;
        far += far_apart(v, adj[ptr[v]]);
        seen++;
    }
    return 2 * far > seen;
}

/* ms_scattered's answer from the faces (m, 3) alone, mapped through remap (NULL: as they
 * are) into [0, n), before the adjacency is built: a vertex's first neighbour in
 * ms_adjacency's lists is, in the first face listing it, the second corner when it is
 * the first corner, else the first corner. One read of the faces,
 * a bit per vertex marking the samples not yet met; it stops once either side holds more
 * than half of all the samples (the samples never met, without neighbours, only shrink
 * the count the answer compares with). */
int ms_scattered_faces(const int64_t *faces, int64_t m, const int64_t *remap, int64_t n) {
    if (n <= MS_SCATTERED_GAP) return 0;
    const int64_t step = scatter_step(n), samples = (n + step - 1) / step;
    uint64_t *unmet = (uint64_t *)calloc((size_t)(n + 63) / 64, sizeof(uint64_t));
    if (unmet == NULL) return 0; /* not renumbered: the same outputs, only slower */
    for (int64_t v = 0; v < n; v += step) unmet[v >> 6] |= (uint64_t)1 << (v & 63);
    int64_t far = 0, seen = 0;
    for (int64_t f = 0; f < 3 * m; f++) {
        const int64_t v = remap == NULL ? faces[f] : remap[faces[f]];
        if ((uint64_t)v >= (uint64_t)n || !((unmet[v >> 6] >> (v & 63)) & 1)) continue;
        unmet[v >> 6] &= ~((uint64_t)1 << (v & 63));
        const int64_t w = faces[f - f % 3 + (f % 3 == 0)];
        far += far_apart(v, remap == NULL ? w : remap[w]);
        seen++;
        if (2 * far > samples || 2 * (seen - far) >= samples) break; /* decided */
    }
    free(unmet);
    return 2 * far > seen;
}

/* The mesh (p (n, 3), fixed (n, 3) or NULL, adjacency (ptr, adj)) with its vertices
 * renumbered in breadth-first order, so that the ring pass reads nearby memory (a scanned
 * or remeshed input numbers its vertices without locality: each ring's reads then miss
 * the caches, about 5 us a vertex against 0.8 on a grid-ordered mesh). The search starts
 * at the lowest vertex not yet met, component after component. order (n,): order[k] the
 * vertex numbered k; rank (n,): its inverse. Row k of (out_ptr (n + 1), out_adj as adj)
 * is old row order[k] mapped through rank, in the same order, so a search over the new
 * lists meets the same vertices in the same order: every ring, and every sum over it, is
 * the same. out_p (and out_fixed when fixed is not NULL) (n, 3): the rows in the new
 * order. */
void ms_bfs_renumber(const int64_t *ptr, const int32_t *adj, int64_t n, const double *p,
                     const double *fixed, int32_t *order, int32_t *rank, int64_t *out_ptr,
                     int32_t *out_adj, double *out_p, double *out_fixed) {
    for (int64_t v = 0; v < n; v++) rank[v] = -1;
    int64_t tail = 0, start = 0;
    for (int64_t head = 0; head < n; head++) {
        if (head == tail) { /* a new component: its lowest vertex not met */
            while (rank[start] >= 0) start++;
            rank[start] = (int32_t)tail;
            order[tail++] = (int32_t)start;
        }
        const int32_t v = order[head];
        for (int64_t t = ptr[v]; t < ptr[v + 1]; t++) {
            const int32_t w = adj[t];
            if (rank[w] < 0) {
                rank[w] = (int32_t)tail;
                order[tail++] = w;
            }
        }
    }
    out_ptr[0] = 0;
    for (int64_t k = 0; k < n; k++) {
        const int64_t v = order[k];
        int64_t o = out_ptr[k];
        for (int64_t t = ptr[v]; t < ptr[v + 1]; t++) out_adj[o++] = rank[adj[t]];
        out_ptr[k + 1] = o;
        for (int c = 0; c < 3; c++) out_p[3 * k + c] = p[3 * v + c];
        if (fixed != NULL) {
            for (int c = 0; c < 3; c++) out_fixed[3 * k + c] = fixed[3 * v + c];
        }
    }
}

/* Room for `need` entries in each of the `count` arrays (entry sizes `size`, capacity
 * *cap, grown by doubling). Returns 0, or -1 out of memory (the arrays stay valid). */
static int reserve(void **arrays, const size_t *size, int count, int64_t *cap, int64_t need) {
    if (need <= *cap) return 0;
    int64_t nc = *cap;
    while (nc < need) nc *= 2;
    for (int t = 0; t < count; t++) {
        void *grown = realloc(arrays[t], (size_t)nc * size[t]);
        if (grown == NULL) return -1;
        arrays[t] = grown;
    }
    *cap = nc;
    return 0;
}


/* One breadth-first level: the members queue[*head .. *tail) on entry each append their
 * neighbours in (ptr, adj) not yet stamped `mark` (every neighbour written, kept when
 * first met). A stamp is stored only for a vertex met first: most neighbours were met
 * before (about 160 of the 222 of a 4-ring on a regular mesh), and storing the same
 * stamp again for each made the search about 30 % slower than this branch (the stores
 * and the reloads of just-stored stamps, measured on the 1M-vertex bench mesh and on a
 * scanned-like mesh). The queue is arrays[0], grown with reserve over `count` arrays;
 * *head and *tail advance. Returns 0, or -1 out of memory (*tail then counts every member
 * stamped so far). */
static inline int bfs_level(const int64_t *ptr, const int32_t *adj, int32_t *stamp, int32_t mark,
                            void **arrays, const size_t *size, int count, int64_t *cap, int64_t *head,
                            int64_t *tail) {
    const int64_t level_end = *tail;
    int64_t t_end = *tail;
    for (; *head < level_end; (*head)++) {
        const int32_t v = ((const int32_t *)arrays[0])[*head];
        const int64_t t0 = ptr[v], t1 = ptr[v + 1];
        if (reserve(arrays, size, count, cap, t_end + (t1 - t0)) != 0) {
            *tail = t_end;
            return -1;
        }
        int32_t *queue = (int32_t *)arrays[0];
        for (int64_t t = t0; t < t1; t++) {
            const int32_t w = adj[t];
            queue[t_end] = w;
            if (stamp[w] != mark) {
                stamp[w] = mark;
                t_end++;
            }
        }
    }
    *tail = t_end;
    return 0;
}

/* shifted[w] = 1 where vertex w + 1's adjacency list is w's with each neighbour plus
 * one (the same length), else 0, for w in [begin, end) of the n vertices (w = n - 1: 0).
 * A mesh numbered along a regular grid (the bench mesh, a height field, a parametric
 * surface) has it at most vertices; a scan or a remeshed surface almost nowhere. */
void ms_shifted_lists(const int64_t *ptr, const int32_t *adj, int64_t n, int64_t begin,
                      int64_t end, uint8_t *shifted) {
    for (int64_t w = begin; w < end; w++) {
        int same = w + 1 < n && ptr[w + 2] - ptr[w + 1] == ptr[w + 1] - ptr[w];
        for (int64_t t = ptr[w], d = ptr[w + 1] - ptr[w]; same && t < ptr[w + 1]; t++)
            same = adj[t + d] == adj[t] + 1;
        shifted[w] = (uint8_t)same;
    }
}

/* ms_ring_pdis (its arguments), its floating point compiled twice: plain and for AVX2
 * (ring_pdis_avx2), each operation the same correctly rounded one (no fused
 * multiply-add: -ffp-contract=off, and the target has no FMA), so both give the same
 * bits. */
static inline __attribute__((always_inline)) int ring_pdis_body(
    const double *p, int64_t n, const int64_t *ptr, const int32_t *adj, const double *fixed,
    const int64_t *rings, int nscales, int gaussian, int64_t begin, int64_t end, int32_t *stamp,
    const int32_t *dest, const uint8_t *shifted, double *out_pdis, double *out_normals,
    double *out_relative, double *out_score) {
    int64_t cap = 1024;
    /* queue (int32), q (3 doubles), d2, mu, |q| and q side by side (4 doubles) */
    void *buf[5] = {malloc((size_t)cap * 4), malloc((size_t)cap * 24), malloc((size_t)cap * 8),
                    malloc((size_t)cap * 8), malloc((size_t)cap * 32)};
    const size_t size[5] = {4, 24, 8, 8, 32};
    /* per scale: the ring's size, its projected distance, l, then o */
    int64_t *mk = (int64_t *)malloc((size_t)nscales * sizeof(int64_t));
    double *spd = (double *)malloc((size_t)nscales * 3 * sizeof(double));
    int rc = 0, local = out_relative != NULL;
    int64_t rmax = rings[nscales - 1];
    /* the previous vertex's queue length after each level (level 0: the vertex) */
    int64_t *ends = (int64_t *)malloc((size_t)(rmax + 1) * sizeof(int64_t));
    if (!buf[0] || !buf[1] || !buf[2] || !buf[3] || !buf[4] || !mk || !spd || !ends) {
        rc = -1;
        goto done;
    }
    for (int64_t i = begin; i < end; i++) {
        const double *pi = p + 3 * i;
        const int64_t io = dest ? dest[i] : i; /* where its results go */
        const double *fn = fixed ? fixed + 3 * i : NULL;
        if (fn && fn[0] == 0.0 && fn[1] == 0.0 && fn[2] == 0.0) fn = NULL;
        int32_t *queue = (int32_t *)buf[0];
        int64_t head = 0, tail = 0;
        /* Vertex i - 1's search, every member plus one, is vertex i's when each list it
         * walked (levels 0 .. rmax - 1) is shifted: that search over the lists plus one
         * meets the members plus one in the same order (a grid-numbered mesh: most
         * vertices). Its stamps are then not stored: a later search's mark is its own
         * vertex, which no earlier search used. */
        int same = shifted != NULL && i > begin;
        for (int64_t j = 0; same && j < ends[rmax - 1]; j++) same = shifted[queue[j]];
        if (same) {
            for (int64_t j = 0; j < ends[rmax]; j++) queue[j] += 1;
        } else {
            queue[tail++] = (int32_t)i;
            stamp[i] = (int32_t)i;
            ends[0] = 1;
        }
        double sx = 0, sy = 0, sz = 0, h2 = 0;
        int64_t done_j = 0;
        int s = 0;
        for (int64_t ring = 1; ring <= rmax; ring++) {
            if (same) {
                tail = ends[ring];
            } else if (bfs_level(ptr, adj, stamp, (int32_t)i, buf, size, 5, &cap, &head, &tail) != 0) {
                rc = -1;
                goto done;
            } else {
                ends[ring] = tail;
            }
            queue = (int32_t *)buf[0];
            while (s < nscales && rings[s] == ring && fn != NULL) {
                /* a fixed normal: the mean offset is all it needs (and the local scale
                 * each offset and its length) */
                double *v = (double *)buf[4], *d2 = (double *)buf[2];
                for (; done_j < tail; done_j++) {
                    const double *pj = p + 3 * (int64_t)queue[done_j];
                    double x = pj[0] - pi[0], y = pj[1] - pi[1], z = pj[2] - pi[2];
                    sx += x; sy += y; sz += z;
                    if (local) {
                        d2[done_j] = x * x + y * y + z * z;
                        v[4 * done_j + 1] = x; v[4 * done_j + 2] = y; v[4 * done_j + 3] = z;
                    }
                }
                double mean[3] = {sx / (double)tail, sy / (double)tail, sz / (double)tail};
                double *nrm = out_normals ? out_normals + 3 * (s * n + io) : NULL;
                mk[s] = tail;
                spd[s] = neighbourhood_pdis(NULL, NULL, tail, mean, 0.0, gaussian, fn, nrm, NULL);
                s++;
            }
            while (s < nscales && rings[s] == ring) {
                int64_t m = tail;
                double *q = (double *)buf[1], *d2 = (double *)buf[2], *v = (double *)buf[4];
                for (; done_j < m; done_j++) {
                    const double *pj = p + 3 * (int64_t)queue[done_j];
                    double x = pj[0] - pi[0], y = pj[1] - pi[1], z = pj[2] - pi[2];
                    q[3 * done_j] = x; q[3 * done_j + 1] = y; q[3 * done_j + 2] = z;
                    double dd = x * x + y * y + z * z;
                    d2[done_j] = dd;
                    if (dd > h2) h2 = dd;
                    sx += x; sy += y; sz += z;
                    if (local) {
                        v[4 * done_j + 1] = x; v[4 * done_j + 2] = y; v[4 * done_j + 3] = z;
                    }
                }
                double mean[3] = {sx / (double)m, sy / (double)m, sz / (double)m};
                double *nrm = out_normals ? out_normals + 3 * (s * n + io) : NULL;
                mk[s] = m;
                spd[s] = neighbourhood_pdis(q, d2, m, mean, h2, gaussian, fn, nrm, (double *)buf[3]);
                s++;
            }
        }
        if (out_pdis != NULL) {
            for (s = 0; s < nscales; s++) out_pdis[s * n + io] = spd[s];
        }
        if (!local) continue;
        /* the lengths apart, over the contiguous squared lengths (SIMD square roots) */
        double *v = (double *)buf[4], *ell = spd + nscales, score = 0.0;
        const double *d2 = (const double *)buf[2];
        for (int64_t j = 0; j < tail; j++) v[4 * j] = sqrt(d2[j]);
        local_scale_prefixes_body(v, mk, nscales, ell, ell + nscales);
        for (s = 0; s < nscales; s++) { /* min(x / l, 1) keeps a NaN, as np.minimum */
            double l = ell[s], r = l > 0 ? spd[s] / l : 0.0, g = l > 0 ? ell[nscales + s] / l : 0.0;
            out_relative[s * n + io] = r > 1.0 ? 1.0 : r;
            score += (g > 1.0 ? 1.0 : g) / (double)nscales;
        }
        out_score[io] = score;
    }
done:
    for (int t = 0; t < 5; t++) free(buf[t]);
    free(mk);
    free(spd);
    free(ends);
    return rc;
}

/* ring_pdis_body for any x86-64 (or other) CPU. */
static int ring_pdis_plain(const double *p, int64_t n, const int64_t *ptr, const int32_t *adj,
                           const double *fixed, const int64_t *rings, int nscales, int gaussian,
                           int64_t begin, int64_t end, int32_t *stamp, const int32_t *dest,
                           const uint8_t *shifted, double *out_pdis, double *out_normals,
                           double *out_relative, double *out_score) {
    return ring_pdis_body(p, n, ptr, adj, fixed, rings, nscales, gaussian, begin, end, stamp,
                          dest, shifted, out_pdis, out_normals, out_relative, out_score);
}

#ifdef HAVE_AVX2_PATH
/* The same compiled for AVX2: the members' lengths 4 square roots an instruction (half
 * the time of SSE2's 2 here: 61 a vertex in a regular mesh's 4-ring), the local scales'
 * 4 sums in one register, three-operand instructions. */
__attribute__((target("avx2"))) static int ring_pdis_avx2(
    const double *p, int64_t n, const int64_t *ptr, const int32_t *adj, const double *fixed,
    const int64_t *rings, int nscales, int gaussian, int64_t begin, int64_t end, int32_t *stamp,
    const int32_t *dest, const uint8_t *shifted, double *out_pdis, double *out_normals,
    double *out_relative, double *out_score) {
    return ring_pdis_body(p, n, ptr, adj, fixed, rings, nscales, gaussian, begin, end, stamp,
                          dest, shifted, out_pdis, out_normals, out_relative, out_score);
}
#endif

/* k-rings by breadth-first search for vertices [begin, end), and for each ring rings[s]
 * the projected distance into out_pdis[s * n + i] when not NULL (normals into
 * out_normals when not NULL). fixed: (n, 3) face-average normals, a zero row meaning PCA.
 * stamp: (n,) int32 scratch of this thread, all -1 initially (or left by an earlier
 * call). The members are summed in the order the search meets them: the vertex, then
 * each ring after the last, its vertices in the order met walking the last ring's new
 * members' lists (RingNeighbourhoods.at). With out_relative (and out_score) not NULL,
 * robust mode's RelativeRule in the same walk: the local scales of each ring in numpy's
 * summation order (local_scale_prefixes), out_relative[s * n + i] = min(pdis / l, 1) and
 * out_score[i] = the sum over the scales of min(o / l, 1) / nscales (0 where l = 0).
 * dest (n,) or NULL: vertex i's results go to column dest[i] instead of i (a mesh
 * renumbered by ms_bfs_renumber, dest its order: the caller's numbering). shifted (n,)
 * or NULL: ms_shifted_lists' flags (a vertex's search then taken from the previous
 * vertex's where they allow). */
int ms_ring_pdis(const double *p, int64_t n, const int64_t *ptr, const int32_t *adj,
                 const double *fixed, const int64_t *rings, int nscales, int gaussian,
                 int64_t begin, int64_t end, int32_t *stamp, const int32_t *dest,
                 const uint8_t *shifted, double *out_pdis, double *out_normals,
                 double *out_relative, double *out_score) {
#ifdef HAVE_AVX2_PATH
    if (use_avx2())
        return ring_pdis_avx2(p, n, ptr, adj, fixed, rings, nscales, gaussian, begin, end,
                              stamp, dest, shifted, out_pdis, out_normals, out_relative,
                              out_score);
#endif
    return ring_pdis_plain(p, n, ptr, adj, fixed, rings, nscales, gaussian, begin, end, stamp,
                           dest, shifted, out_pdis, out_normals, out_relative, out_score);
}

/* The rings of the vertices rows[r] (r < m) in breadth-first order over (ptr, adj), the
 * order ms_ring_pdis sums them in (RingNeighbourhoods.at): ring k is a prefix of ring
 * k + 1. out_len[s * m + r]: the length of ring rings[s] (nrings increasing); when
 * out_idx is not NULL, the last ring's members from out_idx[out_start[r]] on. stamp: (n,)
 * int32 scratch, all -1 on entry and on return. Returns 0, or -1 out of memory. */
int ms_ring_lists(const int64_t *ptr, const int32_t *adj, const int64_t *rows, int64_t m,
                  const int64_t *rings, int nrings, int32_t *stamp, int64_t *out_len,
                  const int64_t *out_start, int32_t *out_idx) {
    int64_t cap = 1024, rmax = rings[nrings - 1];
    void *buf[1] = {malloc((size_t)cap * 4)};
    const size_t size[1] = {4};
    if (!buf[0]) return -1;
    for (int64_t r = 0; r < m; r++) {
        int32_t *queue = (int32_t *)buf[0];
        int64_t head = 0, tail = 0;
        queue[tail++] = (int32_t)rows[r];
        stamp[rows[r]] = 0;
        int s = 0;
        for (int64_t ring = 1; ring <= rmax; ring++) {
            const int grown = bfs_level(ptr, adj, stamp, 0, buf, size, 1, &cap, &head, &tail);
            queue = (int32_t *)buf[0];
            if (grown != 0) {
                for (int64_t j = 0; j < tail; j++) stamp[queue[j]] = -1;
                free(buf[0]);
                return -1;
            }
            while (s < nrings && rings[s] == ring) out_len[s++ * m + r] = tail;
        }
        if (out_idx != NULL) memcpy(out_idx + out_start[r], queue, (size_t)tail * sizeof(int32_t));
        for (int64_t j = 0; j < tail; j++) stamp[queue[j]] = -1;
    }
    free(buf[0]);
    return 0;
}

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
static void face_normal(const double *p, const int64_t *faces, int64_t f, double *u) {
    double c[3];
    double len = face_cross(p, faces[3 * f], faces[3 * f + 1], faces[3 * f + 2], c);
    double dv = len > 0 ? len : 1.0;
    u[0] = c[0] / dv; u[1] = c[1] / dv; u[2] = c[2] / dv;
}

/* Face-average normals exactly as normals.face_average_normals computes them with
 * numpy (same products, same order of the sums: corner 0 of every face in face order,
 * then corner 1, then corner 2): acc (n, 3) zero on entry. Each face's normal is computed
 * again for each corner, which is faster than storing them (no fresh memory). */
void ms_face_average_normals(const double *p, int64_t n, const int64_t *faces, int64_t m,
                             double zero, double *acc) {
    for (int c = 0; c < 3; c++) {
        for (int64_t f = 0; f < m; f++) {
            double u[3];
            face_normal(p, faces, f, u);
            double *t = acc + 3 * faces[3 * f + c];
            t[0] += u[0]; t[1] += u[1]; t[2] += u[2];
        }
    }
    for (int64_t v = 0; v < n; v++) {
        double *t = acc + 3 * v;
        double nn = sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]);
        if (nn > zero) { t[0] /= nn; t[1] /= nn; t[2] /= nn; }
        else { t[0] = 0.0; t[1] = 0.0; t[2] = 0.0; }
    }
}

/* ------------------------------------------------------------------ cleaning */

#if defined(__GNUC__)
#define PREFETCH(address) __builtin_prefetch(address)
#else
#define PREFETCH(address) ((void)(address))
#endif

static inline uint64_t hash64(uint64_t k) {
    k ^= k >> 33;
    k *= 0xff51afd7ed558ccdULL;
    k ^= k >> 33;
    k *= 0xc4ceb9fe1a85ec53ULL;
    k ^= k >> 33;
    return k;
}

static inline uint64_t point_hash(const double *x) {
    uint64_t h = 0x9e3779b97f4a7c15ULL;
    for (int a = 0; a < 3; a++) {
        double v = x[a] + 0.0; /* -0.0 == 0.0 */
        uint64_t bits;
        memcpy(&bits, &v, sizeof bits);
        h = hash64(h ^ bits) + 0x9e3779b97f4a7c15ULL * (uint64_t)(a + 1);
    }
    return h;
}

/* The slot of point x in a table of tmask + 1 entries, and the entry that holds input
 * point i there: the hash's upper 32 bits (a fingerprint, so that a probe reads the
 * points of a slot only when they may be equal: an unprefetched miss otherwise) above
 * i + 1 (0: an empty slot). tmask + 1 <= 2^32, so the slot takes only the lower bits. */
static inline uint64_t dedup_slot(const double *x, int64_t tmask, uint64_t *entry, int64_t i) {
    uint64_t h = point_hash(x);
    *entry = (h & 0xffffffff00000000ULL) | (uint64_t)(i + 1);
    return h & (uint64_t)tmask;
}

/* The probe of a duplicate merge: the points whose slots lie in part `part` of `parts`
 * equal parts of table (tmask + 1 uint64 entries of scratch, the part's cleared first;
 * parts a power of two dividing tmask + 1; n < 2^31), in input order, each looked up
 * among the earlier ones there (linear probing within the part) and inserted if new.
 * Parts see disjoint points and slots: they may run at once. A point equal (==, so -0.0
 * equals 0.0) to an earlier one t gets from_input[i] = -1 - t (first occurrences are left
 * as they were) and counts in dups[s] for the span s of bounds (spans + 1 increasing
 * indices, 0 to n) holding i. */
void ms_dedup_probe(const double *p, int64_t n, uint64_t *table, int64_t tmask, int64_t parts,
                    int64_t part, const int64_t *bounds, int64_t *from_input, int64_t *dups) {
    const uint64_t span = ((uint64_t)tmask + 1) / (uint64_t)parts, lo = (uint64_t)part * span;
    /* cleared here, in order: a page first touched by a probe would cost its fault there
     * (and a prefetch of it is dropped) */
    memset(table + lo, 0, span * sizeof(uint64_t));
    /* Blocks of DEDUP_BLOCK points: first each one's slot, fetched and kept when in the
     * part (without a branch: one on the hash mispredicts every other point with two
     * parts), then the kept ones probed, their slots in cache by then. */
    enum { DEDUP_BLOCK = 32 };
    int64_t keep_i[DEDUP_BLOCK];
    uint64_t keep_slot[DEDUP_BLOCK], keep_entry[DEDUP_BLOCK];
    int64_t s = 0;
    for (int64_t begin = 0; begin < n; begin += DEDUP_BLOCK) {
        const int64_t end = begin + DEDUP_BLOCK < n ? begin + DEDUP_BLOCK : n;
        int k = 0;
        for (int64_t i = begin; i < end; i++) {
            uint64_t entry, h = dedup_slot(p + 3 * i, tmask, &entry, i);
            const int mine = h - lo < span;
            PREFETCH(table + (mine ? h : lo));
            keep_i[k] = i;
            keep_slot[k] = h;
            keep_entry[k] = entry;
            k += mine;
        }
        for (int j = 0; j < k; j++) {
            const int64_t i = keep_i[j];
            const double *x = p + 3 * i;
            uint64_t h = keep_slot[j];
            while (1) {
                const uint64_t e = table[h];
                if (e == 0) {
                    table[h] = keep_entry[j];
                    break;
                }
                if ((e ^ keep_entry[j]) >> 32 == 0) {
                    const int64_t t = (int64_t)(e & 0xffffffffULL) - 1;
                    const double *y = p + 3 * t;
                    if (x[0] == y[0] && x[1] == y[1] && x[2] == y[2]) {
                        while (i >= bounds[s + 1]) s++;
                        dups[s]++;
                        from_input[i] = -1 - t;
                        break;
                    }
                }
                h = lo + ((h - lo + 1) & (span - 1));
            }
        }
    }
}

/* The numbering of a duplicate merge over the input points [lo, hi), after every
 * part's ms_dedup_probe: first occurrences (from_input >= 0) numbered from `base` (the
 * first occurrences before lo) in order, into from_input and to_input, their rows copied
 * to out (room for the cleaned points) unless out is NULL. Spans may run at once. */
void ms_dedup_number(const double *p, int64_t lo, int64_t hi, int64_t base, int64_t *from_input,
                     int64_t *to_input, double *out) {
    const size_t row = 3 * sizeof(double);
    int64_t run = lo; /* the first occurrences [run, i) are copied in one piece */
    for (int64_t i = lo; i < hi; i++) {
        if (from_input[i] < 0) {
            if (out != NULL && run < i)
                memcpy(out + 3 * (base - (i - run)), p + 3 * run, (size_t)(i - run) * row);
            run = i + 1;
            continue;
        }
        from_input[i] = base;
        to_input[base++] = i;
    }
    if (out != NULL && run < hi)
        memcpy(out + 3 * (base - (hi - run)), p + 3 * run, (size_t)(hi - run) * row);
}

/* The last step of a duplicate merge over [lo, hi), after every span's ms_dedup_number:
 * each merged point (from_input -1 - t) takes its first occurrence's cleaned index. Spans
 * may run at once (a first occurrence's index is not written here). */
void ms_dedup_resolve(int64_t lo, int64_t hi, int64_t *from_input) {
    for (int64_t i = lo; i < hi; i++)
        if (from_input[i] < 0) from_input[i] = from_input[-1 - from_input[i]];
}

/* Merge exactly equal points (==, so -0.0 equals 0.0) into their first occurrence, on one
 * thread: ms_dedup_probe, ms_dedup_number, ms_dedup_resolve in turn. table: (tmask + 1)
 * uint64 scratch, tmask + 1 a power of two >= 2 n, <= 2^32; n < 2^31. from_input
 * (n, all 0 at first): cleaned index of each input point; to_input (n, first m used):
 * input index of each cleaned point; out (room for n rows) or NULL: the cleaned points
 * (m, 3) when some points merge, untouched when none does (the cleaned points are then
 * p). Returns m. */
int64_t ms_dedup(const double *p, int64_t n, uint64_t *table, int64_t tmask,
                 int64_t *from_input, int64_t *to_input, double *out) {
    const int64_t bounds[2] = {0, n};
    int64_t dups = 0;
    ms_dedup_probe(p, n, table, tmask, 1, 0, bounds, from_input, &dups);
    ms_dedup_number(p, 0, n, 0, from_input, to_input, dups > 0 ? out : NULL);
    if (dups > 0) ms_dedup_resolve(0, n, from_input);
    return n - dups;
}

int64_t ms_keep_faces(const double *p, const int64_t *faces, int64_t m, const int64_t *from_input,
                      int64_t *out, uint8_t *used) {
    int64_t kept = 0;
    for (int64_t f = 0; f < m; f++) {
        int64_t a = faces[3 * f], b = faces[3 * f + 1], c = faces[3 * f + 2];
        if (from_input != NULL) {
            a = from_input[a]; b = from_input[b]; c = from_input[c];
        }
        double cross[3]; /* kept when its double area (face_cross's length) is > 0 */
        if (!(face_cross(p, a, b, c, cross) > 0.0)) continue;
        out[3 * kept] = a; out[3 * kept + 1] = b; out[3 * kept + 2] = c;
        used[a] = 1; used[b] = 1; used[c] = 1;
        kept++;
    }
    return kept;
}

/* ------------------------------------------------------------ robust mode on meshes */

static int cmp_i64(const void *a, const void *b) {
    int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
    return (x > y) - (x < y);
}

/* creases.dihedral_angles without the angle: the edges (a, b), a < b, with exactly two
 * faces, sorted lexicographically, into out_edges (room for (3 m + 1) / 2 rows), and the dot
 * product u . v of the two faces' unit normals (face_normal; face order: the lower index
 * first) into out_dot. n * m must be below 2^63. Returns the number of edges, or -1 out
 * of memory. out_edges (3 m int64) first holds the sort keys: edge e is written at 2 e,
 * never past the keys still to read (each edge written took two keys). */
int64_t ms_two_face_edges(const double *p, const int64_t *faces, int64_t m, int64_t n,
                          int64_t *out_edges, double *out_dot) {
    /* ptr[v + 1]: where the keys of lower end v start, then (after the fill) end */
    int64_t *ptr = (int64_t *)calloc((size_t)n + 2, sizeof(int64_t));
    /* per lower end, the other end and the face as one key: hi * m + f */
    int64_t *key = out_edges;
    if (!ptr) return -1;
    for (int64_t f = 0; f < m; f++)
        for (int c = 0; c < 3; c++) {
            int64_t a = faces[3 * f + c], b = faces[3 * f + (c + 1) % 3];
            ptr[(a < b ? a : b) + 2]++;
        }
    for (int64_t v = 0; v < n; v++) ptr[v + 2] += ptr[v + 1];
    for (int64_t f = 0; f < m; f++)
        for (int c = 0; c < 3; c++) {
            int64_t a = faces[3 * f + c], b = faces[3 * f + (c + 1) % 3];
            int64_t lo = a < b ? a : b, hi = a < b ? b : a;
            key[ptr[lo + 1]++] = hi * m + f;
        }
    int64_t e = 0;
    for (int64_t v = 0; v < n; v++) {
        int64_t *it = key + ptr[v];
        int64_t k = ptr[v + 1] - ptr[v];
        /* sort by the other end, then the face: insertion sort for short lists, qsort
         * for long ones (a fan of many faces) */
        if (k > 32) qsort(it, (size_t)k, sizeof(int64_t), cmp_i64);
        else for (int64_t i = 1; i < k; i++) {
            int64_t x = it[i], j = i;
            for (; j > 0 && it[j - 1] > x; j--) it[j] = it[j - 1];
            it[j] = x;
        }
        for (int64_t i = 0; i < k;) {
            int64_t hi = it[i] / m, j = i + 1;
            while (j < k && it[j] / m == hi) j++;
            if (j - i == 2) {
                int64_t f0 = it[i] % m, f1 = it[i + 1] % m; /* read before edge e is written */
                double u[3], w[3];
                face_normal(p, faces, f0, u);
                face_normal(p, faces, f1, w);
                out_edges[2 * e] = v;
                out_edges[2 * e + 1] = hi;
                out_dot[e++] = u[0] * w[0] + u[1] * w[1] + u[2] * w[2];
            }
            i = j;
        }
    }
    free(ptr);
    return e;
}

int ms_vertex_faces(const int64_t *faces, int64_t m, int64_t n, int64_t *ptr, int32_t *inc) {
    int64_t *fill = (int64_t *)malloc((size_t)(n > 0 ? n : 1) * sizeof(int64_t));
    if (fill == NULL) return -1;
    memset(ptr, 0, (size_t)(n + 1) * sizeof(int64_t));
    for (int64_t k = 0; k < 3 * m; k++) ptr[faces[k] + 1]++;
    for (int64_t v = 0; v < n; v++) ptr[v + 1] += ptr[v];
    memcpy(fill, ptr, (size_t)n * sizeof(int64_t));
    for (int64_t k = 0; k < 3 * m; k++) inc[fill[faces[k]]++] = (int32_t)(k / 3);
    free(fill);
    return 0;
}

/* The two-face edges (a, b), a < b, of the vertices a in [a0, a1) of ms_vertex_faces'
 * lists, in the order both crease functions meet them: a increasing, then a's faces in
 * order, then the face's corners after a's; each edge where its first face lists it.
 * The dot product of its two faces' unit normals (face_normal, the lower face first, as
 * ms_two_face_edges) sorts it: turned (not >= 1), numbered from e, or flat (>= 1: an
 * angle of exactly 0, most of a mesh's edges), counted in *flat and not numbered. With
 * mask NULL, the turned edges' dot products into dot and the number of the first turned
 * edge of each vertex into estart (n + 1); else the vertices of the turned edges whose
 * angle[e] > threshold marked in mask. Returns the number after the last turned edge. A vertex's
 * faces and their two other corners are read once into a small table (a fan of more than
 * CREASE_FAN faces: read from faces). The face normals go through `cache` when not NULL
 * (normal_cache). */
enum { CREASE_FAN = 64 };

/* A direct-mapped cache of unit face normals (face_normal), NORMAL_CACHE entries indexed
 * by the face's low bits: each face serves up to three edges, met by at most two
 * vertices, and in a mesh whose faces and vertices are numbered along its surface these
 * come close together (the 1M-vertex benchmark mesh: about 2 M normals instead of 6 M). */
enum { NORMAL_CACHE = 8192 };
typedef struct {
    int64_t face; /* -1: empty */
    double u[3];
} cached_normal_t;

/* face f's unit normal into u, from the cache when it holds f (the same bits). */
static inline void normal_cache(cached_normal_t *cache, const double *p, const int64_t *faces,
                                int64_t f, double *u) {
    cached_normal_t *c = cache + (f & (NORMAL_CACHE - 1));
    if (c->face != f) {
        face_normal(p, faces, f, c->u);
        c->face = f;
    }
    u[0] = c->u[0]; u[1] = c->u[1]; u[2] = c->u[2];
}

static int64_t crease_walk(const double *p, const int64_t *faces, int64_t a0, int64_t a1,
                           const int64_t *ptr, const int32_t *inc, int64_t e, double *dot,
                           int64_t *estart, const double *angle, double threshold, uint8_t *mask,
                           cached_normal_t *cache, int64_t *flat) {
    int64_t other[2 * CREASE_FAN];
    for (int64_t a = a0; a < a1; a++) {
        if (estart != NULL) estart[a] = e;
        const int32_t *fa = inc + ptr[a];
        const int64_t deg = ptr[a + 1] - ptr[a];
        const int64_t local = deg <= CREASE_FAN;
        for (int64_t i = 0; local && i < deg; i++) {
            const int64_t *c = faces + 3 * (int64_t)fa[i];
            const int at = c[0] == a ? 0 : c[1] == a ? 1 : 2;
            other[2 * i] = c[(at + 1) % 3];
            other[2 * i + 1] = c[(at + 2) % 3];
        }
        for (int64_t i = 0; i < deg; i++) {
            int64_t corner[2];
            if (local) {
                corner[0] = other[2 * i];
                corner[1] = other[2 * i + 1];
            } else {
                const int64_t *c = faces + 3 * (int64_t)fa[i];
                const int at = c[0] == a ? 0 : c[1] == a ? 1 : 2;
                corner[0] = c[(at + 1) % 3];
                corner[1] = c[(at + 2) % 3];
            }
            for (int k = 0; k < 2; k++) {
                const int64_t b = corner[k];
                if (b < a) continue;
                int64_t count = 1, second = -1, seen = 0;
                for (int64_t j = 0; j < deg; j++) {
                    if (j == i) continue;
                    int has;
                    if (local) {
                        has = other[2 * j] == b || other[2 * j + 1] == b;
                    } else {
                        const int64_t *c = faces + 3 * (int64_t)fa[j];
                        has = c[0] == b || c[1] == b || c[2] == b;
                    }
                    if (!has) continue;
                    if (j < i) {
                        seen = 1;
                        break;
                    }
                    count++;
                    second = fa[j];
                }
                if (seen || count != 2) continue;
                double u[3], w[3];
                if (cache != NULL) {
                    normal_cache(cache, p, faces, fa[i], u);
                    normal_cache(cache, p, faces, second, w);
                } else {
                    face_normal(p, faces, fa[i], u);
                    face_normal(p, faces, second, w);
                }
                const double d = u[0] * w[0] + u[1] * w[1] + u[2] * w[2];
                if (d >= 1.0) {
                    if (flat != NULL) ++*flat;
                    continue;
                }
                if (mask == NULL) {
                    dot[e] = d;
                } else if (angle[e] > threshold) {
                    mask[a] = 1;
                    mask[b] = 1;
                }
                e++;
            }
        }
    }
    if (estart != NULL) estart[a1] = e;
    return e;
}

int64_t ms_crease_dots(const double *p, const int64_t *faces, int64_t n, const int64_t *ptr,
                       const int32_t *inc, double *dot, int64_t *estart, int64_t *flat) {
    /* without room for the cache (256 KB), each normal is computed where it is used */
    cached_normal_t *cache = (cached_normal_t *)malloc(NORMAL_CACHE * sizeof(cached_normal_t));
    for (int64_t k = 0; cache != NULL && k < NORMAL_CACHE; k++) cache[k].face = -1;
    *flat = 0;
    const int64_t e = crease_walk(p, faces, 0, n, ptr, inc, 0, dot, estart, NULL, 0.0, NULL, cache, flat);
    free(cache);
    return e;
}

void ms_crease_mask(const double *p, const int64_t *faces, int64_t n, const int64_t *ptr,
                    const int32_t *inc, const int64_t *estart, const double *angle, double threshold,
                    uint8_t *mask) {
    /* only the vertices with an edge above the threshold are walked again (their normals
     * computed again, to tell the turned edges from the flat ones) */
    for (int64_t a = 0; a < n; a++) {
        int64_t k = estart[a];
        while (k < estart[a + 1] && !(angle[k] > threshold)) k++;
        if (k < estart[a + 1])
            crease_walk(p, faces, a, a + 1, ptr, inc, estart[a], NULL, NULL, angle, threshold, mask,
                        NULL, NULL);
    }
}

/* ------------------------------------------------ robust mode's finishing steps */

/* Slot r's list in L: its first member's position in L->idx and its length. */
static inline void list_span(const ms_lists_t *L, int64_t r, int64_t *first, int64_t *len) {
    *first = L->start ? L->start[r] : r * L->stride;
    *len = L->len ? L->len[r] : L->k;
}

/* The t-th member of L->idx. */
static inline int64_t list_member(const ms_lists_t *L, int64_t t) {
    return L->wide ? ((const int64_t *)L->idx)[t] : ((const int32_t *)L->idx)[t];
}

/* Whether d = p_j - p_i lies across the line through p_i of direction e:
 * |d . e| < cone |d|, each sum over x, y, z in that order (robust._feature_pairs). */
static inline int across_line(const double *pi, const double *pj, const double *e, double cone) {
    const double dx = pj[0] - pi[0], dy = pj[1] - pi[1], dz = pj[2] - pi[2];
    return fabs(dx * e[0] + dy * e[1] + dz * e[2]) < cone * sqrt(dx * dx + dy * dy + dz * dz);
}

/* (a - b) . (a - c), summed over x, y, z in that order: negative when a lies inside the
 * ball on b c as a diameter. */
static inline double ball_dot(const double *a, const double *b, const double *c) {
    return (a[0] - b[0]) * (a[0] - c[0]) + (a[1] - b[1]) * (a[1] - c[1]) +
           (a[2] - b[2]) * (a[2] - c[2]);
}

/* robust._line_directions_of for one point pi: col (m, 9) holds, per feature j of its
 * list, q = p_j - p_i and the products q0 q0, q0 q1, q0 q2, q1 q1, q1 q2, q2 q2. The
 * covariance C = sum q q^T - m qbar qbar^T as numpy forms it (sums in add.reduceat's
 * order, the lower triangle that eigh reads: entry (b, a) = outer_ba - (m qbar_b) qbar_a),
 * negated, to the 3x3 solver: the eigenvector of C's largest eigenvalue into e. */
static void line_direction(const double *col, int64_t m, double *e) {
    const double count = (double)(m > 1 ? m : 1);
    double qbar[3], neg[6];
    static const int row[6] = {0, 1, 2, 1, 2, 2}, column[6] = {0, 0, 0, 1, 1, 2};
    for (int a = 0; a < 3; a++) qbar[a] = segment_sum(col + a, m, 9) / count;
    for (int t = 0; t < 6; t++)
        neg[t] = -(segment_sum(col + 3 + t, m, 9) - count * qbar[row[t]] * qbar[column[t]]);
    smallest_eigvec(neg[0], neg[1], neg[2], neg[3], neg[4], neg[5], e);
}

int ms_line_directions(const double *p, const uint8_t *f0, const int64_t *rows,
                       const ms_lists_t *direction, int64_t begin, int64_t end, double *e) {
    int64_t cap = 0;
    for (int64_t r = begin; r < end; r++) {
        int64_t first, len;
        list_span(direction, r, &first, &len);
        cap = len > cap ? len : cap;
    }
    double *col = (double *)malloc((size_t)(cap > 0 ? cap : 1) * 9 * sizeof(double));
    if (!col) return -1;
    for (int64_t r = begin; r < end; r++) {
        const double *pi = p + 3 * rows[r];
        int64_t first, len, m = 0;
        list_span(direction, r, &first, &len);
        for (int64_t t = first; t < first + len; t++) {
            const int64_t j = list_member(direction, t);
            if (!f0[j]) continue;
            double *c = col + 9 * m++;
            for (int a = 0; a < 3; a++) c[a] = p[3 * j + a] - pi[a];
            c[3] = c[0] * c[0]; c[4] = c[0] * c[1]; c[5] = c[0] * c[2];
            c[6] = c[1] * c[1]; c[7] = c[1] * c[2]; c[8] = c[2] * c[2];
        }
        line_direction(col, m, e + 3 * r);
    }
    free(col);
    return 0;
}

void ms_supported(const double *p, const uint8_t *f0, const int64_t *rows, const double *e,
                  const ms_lists_t *around, double cone, int64_t minimum, const double *score,
                  double free_below, int64_t begin, int64_t end, uint8_t *f1) {
    for (int64_t r = begin; r < end; r++) {
        const int64_t i = rows[r];
        int64_t first, len, along = 0;
        list_span(around, r, &first, &len);
        for (int64_t t = first; t < first + len; t++) {
            const int64_t j = list_member(around, t);
            along += j != i && f0[j] && !across_line(p + 3 * i, p + 3 * j, e + 3 * r, cone);
        }
        f1[i] = along >= minimum || (score != NULL && score[i] < free_below);
    }
}

void ms_smoothed_ranking(const double *score, const int64_t *rows, const ms_lists_t *compare,
                         int64_t window, int64_t begin, int64_t end, double *rank) {
    for (int64_t r = begin; r < end; r++) {
        int64_t first, len;
        list_span(compare, r, &first, &len);
        const int64_t take = len < window ? len : window;
        if (take == 0) continue;
        double acc = 0.0;
        for (int64_t t = first; t < first + take; t++) acc += score[list_member(compare, t)];
        rank[rows[r]] = acc / (double)take;
    }
}

/* Whether a point m of slot r's compare list with between[m], or ranking below i, lies
 * between p_i and p_j: (p_m - p_i) . (p_m - p_j) < 0 (robust.thin's blocking). */
static int parted(const double *p, const ms_lists_t *compare, int64_t first, int64_t len,
                  const double *rank, const uint8_t *between, int64_t i, int64_t j) {
    for (int64_t t = first; t < first + len; t++) {
        const int64_t m = list_member(compare, t);
        if ((between[m] || rank[m] < rank[i]) && ball_dot(p + 3 * m, p + 3 * i, p + 3 * j) < 0)
            return 1;
    }
    return 0;
}

void ms_thin(const double *p, const uint8_t *f1, const int64_t *rows, const double *e,
             const ms_lists_t *compare, const double *rank, double cone, const uint8_t *between,
             int64_t begin, int64_t end, uint8_t *f2) {
    for (int64_t r = begin; r < end; r++) {
        const int64_t i = rows[r];
        int keep = f1[i];
        int64_t first, len;
        list_span(compare, r, &first, &len);
        for (int64_t t = first; keep && t < first + len; t++) {
            const int64_t j = list_member(compare, t);
            if (j != i && f1[j] && rank[j] > rank[i] &&
                across_line(p + 3 * i, p + 3 * j, e + 3 * r, cone) &&
                !(between != NULL && parted(p, compare, first, len, rank, between, i, j)))
                keep = 0;
        }
        f2[i] = (uint8_t)keep;
    }
}

void ms_acute_tips(const double *p, const uint8_t *f0, const int64_t *rows,
                   const ms_lists_t *lists, int64_t begin, int64_t end, uint8_t *out) {
    for (int64_t r = begin; r < end; r++) {
        const int64_t i = rows[r];
        const double *pi = p + 3 * i;
        int64_t first, len;
        int tip = 0;
        list_span(lists, r, &first, &len);
        for (int64_t t = first; !tip && t < first + len; t++) {
            const int64_t j = list_member(lists, t);
            if (j == i || !f0[j]) continue;
            for (int64_t u = t + 1; !tip && u < first + len; u++) {
                const int64_t l = list_member(lists, u);
                tip = l != i && f0[l] && ball_dot(pi, p + 3 * j, p + 3 * l) < 0;
            }
        }
        out[r] = (uint8_t)tip;
    }
}

/* ------------------------------------------------------- thresholds (global steps) */

void ms_extent(const double *p, int64_t n, double *out) {
    double lo[3] = {0.0, 0.0, 0.0}, hi[3] = {0.0, 0.0, 0.0};
    if (n > 0)
        for (int a = 0; a < 3; a++) lo[a] = hi[a] = p[a];
    for (int64_t i = 1; i < n; i++)
        for (int a = 0; a < 3; a++) {
            const double x = p[3 * i + a];
            lo[a] = x < lo[a] ? x : lo[a];
            hi[a] = x > hi[a] ? x : hi[a];
        }
    for (int a = 0; a < 3; a++) out[a] = hi[a] - lo[a];
}

/* Bin of a value in [0, 1]: min(floor(v * MS_BINS), MS_BINS - 1) (threshold.histogram;
 * below 0, not a value the method makes, bin 0 rather than a write out of bounds). On
 * [0, MS_BINS - 1) the conversion's truncation is floor (no call of floor: a plain build
 * has no SSE4.1 rounding instruction). */
static inline int64_t value_bin(double v) {
    const double b = v * MS_BINS;
    if (!(b >= 0.0)) return 0;
    return b >= MS_BINS - 1 ? MS_BINS - 1 : (int64_t)b;
}

/* Otsu's threshold t / MS_BINS from the MS_BINS counts of a histogram, in the integer
 * form of the notes (the first largest split wins); 1.0 when no split has points on both
 * sides (threshold.otsu_from_histogram). */
static double otsu_split(const int64_t *counts) {
    int64_t total = 0, weighted_total = 0;
    for (int64_t b = 0; b < MS_BINS; b++) {
        total += counts[b];
        weighted_total += counts[b] * (2 * b + 1);
    }
    int64_t n0 = 0, s0 = 0, best_t = -1;
    double best = 0.0;
    for (int64_t t = 1; t < MS_BINS; t++) {
        n0 += counts[t - 1];
        s0 += counts[t - 1] * (2 * (t - 1) + 1);
        if (n0 == 0 || n0 == total) continue;
        const double dn0 = (double)n0, dn1 = (double)total - dn0;
        const double ds0 = (double)s0, ds1 = (double)weighted_total - ds0;
        const double diff = ds0 * dn1 - ds1 * dn0;
        const double crit = diff * diff / (dn0 * dn1);
        if (best_t < 0 || crit > best) {
            best = crit;
            best_t = t;
        }
    }
    return best_t < 0 ? 1.0 : (double)best_t / MS_BINS;
}

/* Adds the bins (value_bin) of v = (x[i] - lo) / span (span > 0), v = x[i] (span == 0),
 * or v = 0 (span < 0: a flat scale) of x (n) to counts (MS_BINS) (threshold.histogram). */
static void histogram(const double *x, int64_t n, double lo, double span, int64_t *counts) {
    if (span > 0.0) {
        for (int64_t i = 0; i < n; i++) counts[value_bin((x[i] - lo) / span)]++;
    } else if (span == 0.0) {
        for (int64_t i = 0; i < n; i++) counts[value_bin(x[i])]++;
    } else {
        counts[0] += n;
    }
}

double ms_scale_vote(const double *x, int64_t n, int normalise, double flat_span, int otsu,
                     double floor_, double *out, int64_t *votes, int64_t *count) {
    double lo = 0.0, span = 0.0; /* values as given */
    if (normalise) {
        double mn = n > 0 ? x[0] : 0.0, mx = mn;
        for (int64_t i = 1; i < n; i++) {
            mn = x[i] < mn ? x[i] : mn;
            mx = x[i] > mx ? x[i] : mx;
        }
        lo = mn;
        span = mx - mn > flat_span ? mx - mn : -1.0; /* -1: flat, every value 0 */
    }
    double t = floor_;
    if (otsu) {
        int64_t counts[MS_BINS] = {0};
        histogram(x, n, lo, span, counts);
        const double split = otsu_split(counts);
        t = split > floor_ ? split : floor_;
    }
    int64_t c = 0;
    for (int64_t i = 0; i < n; i++) {
        const double v = span > 0.0 ? (x[i] - lo) / span : span == 0.0 ? x[i] : 0.0;
        const int64_t hit = v >= t;
        if (out != NULL) out[i] = v;
        votes[i] += hit;
        c += hit;
    }
    *count = c;
    return t;
}
