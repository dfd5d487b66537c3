/* Weighted PCA normals and projected distances: the 3x3 eigenvector, one
 * neighbourhood's normal and projected distance, and the cloud pass's four scales at once.
 * Part of meshlab-sharp's native library (meshlab_sharp.h). */
#include "internal.h"

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

/* Unit eigenvector of the eigenvalue lam of the symmetric matrix [[a, b, c], [b, d, e],
 * [c, e, f]] as the longest cross product of two rows of A - lam I (the first of equals),
 * normalised; (1, 0, 0) where every cross product is zero. */
static void eigvec_of(double a, double b, double c, double d, double e, double f, double lam,
                      double *out) {
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

static const double tie_direction[3] = MS_EIG_TIE_DIRECTION;

/* Unit eigenvector of the smallest eigenvalue of the symmetric matrix
 * [[a, b, c], [b, d, e], [c, e, f]]: eigenvalue in closed form (trigonometric), vector
 * as the largest cross product of two rows of A - lambda I. Agrees with LAPACK's
 * dsyevd to about 1e-16 when the smallest eigenvalue is well separated (error ~
 * eps * |A| / gap, as for LAPACK itself); where it is not (MS_EIG_TRIPLE_ROOT,
 * MS_EIG_DOUBLE_ROOT), the eigenspace's vector the header names. */
void smallest_eigvec(double a, double b, double c, double d, double e, double f,
                     double *out) {
    double scale = fabs(a) + fabs(b) + fabs(c) + fabs(d) + fabs(e) + fabs(f);
    if (scale == 0.0) {
        out[0] = 1.0; out[1] = 0.0; out[2] = 0.0;
        return;
    }
    /* scale by a power of two (exact) to O(1), for range safety: s = 2^-e with scale =
     * f 2^e, f in [0.5, 1) (frexp), built from the exponent bits when s is normal */
    double s;
    uint64_t bits;
    memcpy(&bits, &scale, sizeof bits);
    int64_t biased = (int64_t)(bits >> 52); /* scale > 0: no sign bit */
    if (biased == 0) { /* subnormal: made normal first (exact), 2^-ex would overflow */
        a *= 0x1p600; b *= 0x1p600; c *= 0x1p600; d *= 0x1p600; e *= 0x1p600; f *= 0x1p600;
        scale = fabs(a) + fabs(b) + fabs(c) + fabs(d) + fabs(e) + fabs(f);
        memcpy(&bits, &scale, sizeof bits);
        biased = (int64_t)(bits >> 52);
    }
    if (biased >= 1 && biased <= 2044) {
        bits = (uint64_t)(2045 - biased) << 52;
        memcpy(&s, &bits, sizeof s);
    } else {
        int ex;
        frexp(scale, &ex);
        s = ldexp(1.0, -ex);
    }
    a *= s; b *= s; c *= s; d *= s; e *= s; f *= s;
    double p1 = b * b + c * c + e * e;
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
    if (p <= MS_EIG_TRIPLE_ROOT * fabs(q)) { /* (p = 0 too: a multiple of I, r NaN) */
        out[0] = tie_direction[0]; out[1] = tie_direction[1]; out[2] = tie_direction[2];
        return;
    }
    double phi = acos(r) / 3.0;
    if (1.0 - r <= MS_EIG_DOUBLE_ROOT) {
        /* the plane across the largest eigenvalue's eigenvector v */
        double v[3];
        eigvec_of(a, b, c, d, e, f, q + 2.0 * p * cos(phi), v);
        double t = tie_direction[0] * v[0] + tie_direction[1] * v[1] + tie_direction[2] * v[2];
        double w0 = tie_direction[0] - t * v[0], w1 = tie_direction[1] - t * v[1];
        double w2 = tie_direction[2] - t * v[2];
        double inv = 1.0 / sqrt(w0 * w0 + w1 * w1 + w2 * w2);
        out[0] = w0 * inv; out[1] = w1 * inv; out[2] = w2 * inv;
        return;
    }
    if (p1 == 0.0) { /* diagonal: the smallest entry's axis (the first of equals) */
        int k = 0;
        if (d < a) k = 1;
        if (f < (k == 0 ? a : d)) k = 2;
        out[0] = k == 0; out[1] = k == 1; out[2] = k == 2;
        return;
    }
    eigvec_of(a, b, c, d, e, f, q + 2.0 * p * cos(phi + 2.0943951023931954923), out);
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
void scatter(const double *q, int64_t m, const double *mean, const double *w,
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
 * the point and their squared lengths d2 (m); see docs/contributing.md.
 * fixed: a fixed unit normal or NULL (PCA). h2 is max d2 (given). */
double neighbourhood_pdis(const double *q, const double *d2, int64_t m,
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
 * builds give the same bits; docs/contributing.md says how this differs from
 * the numpy reference. */
#if defined(__GNUC__) && !defined(__clang__)
/* the functions below pass vectors only inlined: no ABI to keep */
#pragma GCC diagnostic ignored "-Wpsabi"
#endif
typedef double v4d __attribute__((vector_size(32)));
typedef int64_t v4i __attribute__((vector_size(32)));
typedef uint64_t v4u __attribute__((vector_size(32)));
/* a v4d in memory at any 8-byte alignment (malloc's buffers) */
typedef double v4d_mem __attribute__((vector_size(32), aligned(8)));
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
     * us a point) */
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
        /* (and where the smallest eigenvalue is not single: its vector is chosen there) */
        if (s[l] == 0.0 || p[l] <= MS_EIG_TRIPLE_ROOT * fabs(qq[l]) ||
            1.0 - r[l] <= MS_EIG_DOUBLE_ROOT) {
            smallest_eigvec(c00[l], c01[l], c02[l], c11[l], c12[l], c22[l], o);
        } else {
            o[0] = v0[l]; o[1] = v1[l]; o[2] = v2[l];
        }
    }
}

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
pca_lanes_fn pca_lanes(void) {
#ifdef HAVE_AVX2_PATH
    if (use_avx2()) return pca_lanes_avx2;
#endif
    return pca_lanes_plain;
}

/* The normals snrm (3 a scale) of the scales [s0, s1) of one point (mk, smean, sh2 as
 * scale_means gives them), PCA_LANES at a time; ws: room for PCA_LANES mk[s1 - 1]
 * doubles. */
void pca_scales(pca_lanes_fn pca, const double *q, const double *d2, const int64_t *mk,
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
void scale_means(const double *q, const double *d2, const int64_t *mk, int nscales,
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
