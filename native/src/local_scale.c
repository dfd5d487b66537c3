/* Robust mode's per-point measures: numpy's pairwise sums, the local scale of a
 * neighbourhood (and of every prefix of a list at once), the noise ratio.
 * Part of meshlab-sharp's native library (meshlab_sharp.h). */
#include "internal.h"

/* numpy's pairwise summation of a[0], a[stride], ... (n terms), as its add.reduce
 * inner loop computes it (numpy/_core/src/umath/loops_utils.h.src): fewer than 8
 * terms summed in order from -0.0; up to 128 in 8 interleaved partial sums, combined
 * as ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7)), then the remainder in order;
 * more split in two at a multiple of 8. */
double pairwise_sum(const double *a, int64_t n, int64_t stride) {
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
void local_scale_prefixes_on(const double *v, const int64_t *ks, int nscales,
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
void local_scale_values(const double *q, const double *d2, int64_t m, double *v,
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
double noise_ratio(const double *q, int64_t k) {
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
