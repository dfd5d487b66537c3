/* Compiled kernels of meshlab-sharp: grid kNN, k-rings, weighted PCA normals and
 * projected distances, face-average normals, duplicate merging.
 *
 * A plain C library loaded with ctypes (meshlab_sharp/_kernels.py): no Python headers
 * are needed to build it, and ctypes releases the GIL during a call, so Python threads
 * run chunks of points on every core. Built by setuptools (setup.py) with
 * -ffp-contract=off: no fused multiply-add, every product and sum rounded as numpy
 * rounds it, in the order docs/implementation-notes.md pins down.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

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

#define MORTON_BITS 21
#define MORTON_MAX ((1u << MORTON_BITS) - 1u)
#define EMPTY_KEY UINT64_MAX

/* ------------------------------------------------------------------ Morton codes */

static inline uint64_t spread3(uint64_t x) {
    x &= 0x1fffff;
    x = (x | x << 32) & 0x1f00000000ffffULL;
    x = (x | x << 16) & 0x1f0000ff0000ffULL;
    x = (x | x << 8) & 0x100f00f00f00f00fULL;
    x = (x | x << 4) & 0x10c30c30c30c30c3ULL;
    x = (x | x << 2) & 0x1249249249249249ULL;
    return x;
}

static inline uint32_t compact3(uint64_t x) {
    x &= 0x1249249249249249ULL;
    x = (x ^ (x >> 2)) & 0x10c30c30c30c30c3ULL;
    x = (x ^ (x >> 4)) & 0x100f00f00f00f00fULL;
    x = (x ^ (x >> 8)) & 0x1f0000ff0000ffULL;
    x = (x ^ (x >> 16)) & 0x1f00000000ffffULL;
    x = (x ^ (x >> 32)) & 0x1fffffULL;
    return (uint32_t)x;
}

static inline uint64_t morton3(uint32_t x, uint32_t y, uint32_t z) {
    return spread3(x) | (spread3(y) << 1) | (spread3(z) << 2);
}

static inline uint32_t grid_coord(double v, double o, double inv) {
    double t = floor((v - o) * inv);
    if (!(t > 0.0)) return 0;
    if (t >= (double)MORTON_MAX) return MORTON_MAX;
    return (uint32_t)t;
}

/* Fine-grid Morton code of every point: 2^21 cells of size 1/inv per axis from o. */
void ms_morton_codes(const double *p, int64_t n, double ox, double oy, double oz, double inv,
                     uint64_t *codes) {
    for (int64_t i = 0; i < n; i++) {
        codes[i] = morton3(grid_coord(p[3 * i], ox, inv), grid_coord(p[3 * i + 1], oy, inv),
                           grid_coord(p[3 * i + 2], oz, inv));
    }
}

/* counts[L] = number of distinct cells at level L (cells of 2^L fine cells), L = 0..21,
 * of sorted codes. */
void ms_level_counts(const uint64_t *codes, int64_t n, int64_t *counts) {
    for (int l = 0; l <= MORTON_BITS; l++) counts[l] = n > 0;
    for (int64_t i = 1; i < n; i++) {
        uint64_t x = codes[i] ^ codes[i - 1];
        if (!x) continue;
        int top = 63 - __builtin_clzll(x);  /* highest differing bit */
        int lmax = top / 3;                 /* distinct at levels 0..lmax */
        for (int l = 0; l <= lmax; l++) counts[l]++;
    }
}

static inline uint64_t hash64(uint64_t k) {
    k ^= k >> 33;
    k *= 0xff51afd7ed558ccdULL;
    k ^= k >> 33;
    k *= 0xc4ceb9fe1a85ec53ULL;
    k ^= k >> 33;
    return k;
}

/* Cells of level L of sorted codes into an open-addressing table (size hmask + 1, a
 * power of two, keys initialised to EMPTY_KEY by the caller). */
void ms_build_cells(const uint64_t *codes, int64_t n, int level, uint64_t *hkeys,
                    int64_t *hstart, int64_t *hend, int64_t hmask) {
    int64_t i = 0;
    while (i < n) {
        uint64_t key = codes[i] >> (3 * level);
        int64_t j = i + 1;
        while (j < n && (codes[j] >> (3 * level)) == key) j++;
        uint64_t h = hash64(key) & (uint64_t)hmask;
        while (hkeys[h] != EMPTY_KEY) h = (h + 1) & (uint64_t)hmask;
        hkeys[h] = key;
        hstart[h] = i;
        hend[h] = j;
        i = j;
    }
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
    /* scale by a power of two (exact) to O(1), for range safety */
    int ex;
    frexp(scale, &ex);
    double s = ldexp(1.0, -ex);
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
        double c00 = 0, c01 = 0, c02 = 0, c11 = 0, c12 = 0, c22 = 0;
        int w = gaussian && h2 > 0.0;
        if (w) gaussian_weights(d2, m, h2, mu);
        for (int64_t j = 0; j < m; j++) {
            double rx = q[3 * j] - mean[0], ry = q[3 * j + 1] - mean[1],
                   rz = q[3 * j + 2] - mean[2];
            double wj = w ? mu[j] : 1.0;
            double mx = wj * rx, my = wj * ry, mz = wj * rz;
            c00 += mx * rx; c01 += mx * ry; c02 += mx * rz;
            c11 += my * ry; c12 += my * rz; c22 += mz * rz;
        }
        smallest_eigvec(c00, c01, c02, c11, c12, c22, nrm);
    }
    if (normal != NULL) {
        normal[0] = nrm[0]; normal[1] = nrm[1]; normal[2] = nrm[2];
    }
    return fabs(mean[0] * nrm[0] + mean[1] * nrm[1] + mean[2] * nrm[2]);
}

/* ------------------------------------------------------------------ kNN on the grid */

typedef struct {
    double d2;
    int64_t idx; /* cleaned index (tie rule) */
    int64_t pos; /* sorted position (coordinates) */
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

typedef struct {
    const double *p;
    const int64_t *orig;
    const uint64_t *codes;
    int64_t n;
    double o[3];
    double fine;
    int level;
    const uint64_t *hkeys;
    const int64_t *hstart;
    const int64_t *hend;
    int64_t hmask;
} grid_t;

static inline void cell_range(const grid_t *g, int lev, uint64_t key, int64_t *s, int64_t *e) {
    if (lev == g->level) {
        uint64_t h = hash64(key) & (uint64_t)g->hmask;
        while (1) {
            uint64_t k = g->hkeys[h];
            if (k == key) { *s = g->hstart[h]; *e = g->hend[h]; return; }
            if (k == EMPTY_KEY) { *s = *e = 0; return; }
            h = (h + 1) & (uint64_t)g->hmask;
        }
    }
    uint64_t lo = key << (3 * lev), hi = (key + 1) << (3 * lev);
    if (lev == MORTON_BITS) { lo = 0; hi = UINT64_MAX; }
    int64_t a = 0, b = g->n;
    while (a < b) { int64_t m = (a + b) >> 1; if (g->codes[m] < lo) a = m + 1; else b = m; }
    *s = a;
    b = g->n;
    while (a < b) { int64_t m = (a + b) >> 1; if (g->codes[m] < hi) a = m + 1; else b = m; }
    *e = a;
}

typedef struct {
    cand_t *c;
    int64_t n, cap;
} cbuf_t;

static int cbuf_reserve(cbuf_t *b, int64_t need) {
    if (need <= b->cap) return 0;
    int64_t cap = b->cap ? b->cap : 256;
    while (cap < need) cap *= 2;
    cand_t *c = (cand_t *)realloc(b->c, (size_t)cap * sizeof(cand_t));
    if (!c) return -1;
    b->c = c;
    b->cap = cap;
    return 0;
}

/* k nearest of the point at sorted position i into buf->c[0..k), sorted by (d2, idx).
 * Returns 0, or -1 when out of memory. */
static int knn_one(const grid_t *g, int64_t i, int64_t k, cbuf_t *buf) {
    const double *pi = g->p + 3 * i;
    uint64_t code = g->codes[i];
    uint32_t gc[3] = {compact3(code), compact3(code >> 1), compact3(code >> 2)};
    for (int lev = g->level;; lev++) {
        if (lev > MORTON_BITS) lev = MORTON_BITS;
        int64_t cmax = (int64_t)(MORTON_MAX >> lev);
        int64_t c[3] = {gc[0] >> lev, gc[1] >> lev, gc[2] >> lev};
        double cs = g->fine * (double)(1ULL << lev);
        double margin = g->fine;
        int rmax = lev == MORTON_BITS ? 0 : 3;
        buf->n = 0;
        for (int r = 0; r <= rmax; r++) {
            /* add the shell of Chebyshev radius r */
            for (int64_t dz = -r; dz <= r; dz++) {
                int64_t z = c[2] + dz;
                if (z < 0 || z > cmax) continue;
                for (int64_t dy = -r; dy <= r; dy++) {
                    int64_t y = c[1] + dy;
                    if (y < 0 || y > cmax) continue;
                    int edge = (dz == -r || dz == r || dy == -r || dy == r);
                    int64_t step = edge ? 1 : 2 * r;
                    for (int64_t dx = -r; dx <= r; dx += (step ? step : 1)) {
                        int64_t x = c[0] + dx;
                        if (x >= 0 && x <= cmax) {
                            int64_t s, e;
                            cell_range(g, lev, morton3((uint32_t)x, (uint32_t)y, (uint32_t)z),
                                       &s, &e);
                            if (e > s) {
                                if (cbuf_reserve(buf, buf->n + (e - s))) return -1;
                                cand_t *out = buf->c + buf->n;
                                for (int64_t j = s; j < e; j++) {
                                    const double *pj = g->p + 3 * j;
                                    double dx_ = pj[0] - pi[0], dy_ = pj[1] - pi[1],
                                           dz_ = pj[2] - pi[2];
                                    out->d2 = dx_ * dx_ + dy_ * dy_ + dz_ * dz_;
                                    out->idx = g->orig[j];
                                    out->pos = j;
                                    out++;
                                }
                                buf->n += e - s;
                            }
                        }
                        if (r == 0) break;
                    }
                }
            }
            if (r == 0 && rmax > 0) continue;
            /* distance from p to the outside of the searched block */
            double bound = INFINITY;
            for (int a = 0; a < 3; a++) {
                if (c[a] - r > 0) {
                    double face = g->o[a] + (double)(c[a] - r) * cs;
                    double dd = pi[a] - face;
                    if (dd < bound) bound = dd;
                }
                if (c[a] + r + 1 <= cmax) {
                    double face = g->o[a] + (double)(c[a] + r + 1) * cs;
                    double dd = face - pi[a];
                    if (dd < bound) bound = dd;
                }
            }
            if (bound == INFINITY) {
                if (buf->n >= k) { select_sorted(buf->c, buf->n, k); return 0; }
                break; /* cannot happen with n >= k */
            }
            bound -= margin;
            if (bound > 0.0) {
                double b2 = bound * bound;
                int64_t inside = 0;
                for (int64_t j = 0; j < buf->n; j++) inside += buf->c[j].d2 < b2;
                if (inside >= k) { select_sorted(buf->c, buf->n, k); return 0; }
            }
        }
        if (lev == MORTON_BITS) {
            select_sorted(buf->c, buf->n, buf->n < k ? buf->n : k);
            return 0;
        }
    }
}

typedef struct {
    double *x, *y, *z, *d2;
    int64_t *idx, *pos;
    int64_t n, cap;
} block_t;

static int block_reserve(block_t *b, int64_t need) {
    if (need <= b->cap) return 0;
    int64_t cap = b->cap ? b->cap : 512;
    while (cap < need) cap *= 2;
    double **dp[4] = {&b->x, &b->y, &b->z, &b->d2};
    for (int t = 0; t < 4; t++) {
        double *r = (double *)realloc(*dp[t], (size_t)cap * sizeof(double));
        if (!r) return -1;
        *dp[t] = r;
    }
    int64_t *r1 = (int64_t *)realloc(b->idx, (size_t)cap * sizeof(int64_t));
    if (!r1) return -1;
    b->idx = r1;
    int64_t *r2 = (int64_t *)realloc(b->pos, (size_t)cap * sizeof(int64_t));
    if (!r2) return -1;
    b->pos = r2;
    b->cap = cap;
    return 0;
}

/* The points of the 3x3x3 cells around cell c (level g->level), as arrays. */
static int gather_block(const grid_t *g, const int64_t *c, block_t *b) {
    int64_t cmax = (int64_t)(MORTON_MAX >> g->level);
    b->n = 0;
    for (int64_t dz = -1; dz <= 1; dz++) {
        int64_t z = c[2] + dz;
        if (z < 0 || z > cmax) continue;
        for (int64_t dy = -1; dy <= 1; dy++) {
            int64_t y = c[1] + dy;
            if (y < 0 || y > cmax) continue;
            for (int64_t dx = -1; dx <= 1; dx++) {
                int64_t x = c[0] + dx;
                if (x < 0 || x > cmax) continue;
                int64_t s, e;
                cell_range(g, g->level, morton3((uint32_t)x, (uint32_t)y, (uint32_t)z), &s, &e);
                if (e <= s) continue;
                if (block_reserve(b, b->n + (e - s))) return -1;
                for (int64_t j = s; j < e; j++) {
                    int64_t t = b->n++;
                    b->x[t] = g->p[3 * j];
                    b->y[t] = g->p[3 * j + 1];
                    b->z[t] = g->p[3 * j + 2];
                    b->idx[t] = g->orig[j];
                    b->pos[t] = j;
                }
            }
        }
    }
    return 0;
}

/* kNN of sorted positions [begin, end) at k = max(ks), then for each scale ks[s] the
 * projected distance into out_pdis[s * n + orig[i]] (and the normal into
 * out_normals[(s * n + orig[i]) * 3], when not NULL). With out_idx (n, kmax) not NULL,
 * store the neighbour indices (and the pdis too when out_pdis is not NULL). Returns 0, -1 out of memory.
 *
 * Points are taken cell by cell: the 27 cells around a cell are gathered once for all
 * its points. A point's k nearest are among them when at least k lie closer than the
 * block's faces; the k-th distance of the previous point plus the distance between the
 * two bounds this point's k-th distance (triangle inequality), which prunes the
 * candidates before the selection. Otherwise the search widens (knn_one). */
int ms_cloud_pdis(const double *p, const int64_t *orig, const uint64_t *codes, int64_t n,
                  double ox, double oy, double oz, double fine, int level,
                  const uint64_t *hkeys, const int64_t *hstart, const int64_t *hend,
                  int64_t hmask, const int64_t *ks, int nscales, int gaussian, int64_t begin,
                  int64_t end, double *out_pdis, double *out_normals, int64_t *out_idx) {
    grid_t g = {p, orig, codes, n, {ox, oy, oz}, fine, level, hkeys, hstart, hend, hmask};
    int64_t kmax = ks[nscales - 1];
    cbuf_t buf = {NULL, 0, 0};
    block_t blk = {NULL, NULL, NULL, NULL, NULL, NULL, 0, 0};
    double *q = (double *)malloc((size_t)kmax * 3 * sizeof(double));
    double *d2 = (double *)malloc((size_t)kmax * sizeof(double));
    double *mu = (double *)malloc((size_t)kmax * sizeof(double));
    int rc = 0;
    uint64_t cell = EMPTY_KEY;
    int64_t c[3] = {0, 0, 0};
    int64_t cmax = (int64_t)(MORTON_MAX >> level);
    double cs = fine * (double)(1ULL << level);
    double prev_r = -1.0, prev_p[3] = {0, 0, 0};
    if (!q || !d2 || !mu) { rc = -1; goto done; }
    for (int64_t i = begin; i < end; i++) {
        const double *pi = p + 3 * i;
        uint64_t key = codes[i] >> (3 * level);
        if (key != cell) {
            cell = key;
            c[0] = compact3(key); c[1] = compact3(key >> 1); c[2] = compact3(key >> 2);
            if (gather_block(&g, c, &blk)) { rc = -1; goto done; }
        }
        double bound = INFINITY;
        for (int a = 0; a < 3; a++) {
            if (c[a] - 1 > 0) {
                double dd = pi[a] - (g.o[a] + (double)(c[a] - 1) * cs);
                if (dd < bound) bound = dd;
            }
            if (c[a] + 2 <= cmax) {
                double dd = (g.o[a] + (double)(c[a] + 2) * cs) - pi[a];
                if (dd < bound) bound = dd;
            }
        }
        bound -= fine;
        int found = 0;
        if (bound > 0.0 && blk.n >= kmax) {
            double b2 = bound == INFINITY ? INFINITY : bound * bound;
            double px = pi[0], py = pi[1], pz = pi[2];
            int64_t nb = blk.n;
            double *bd = blk.d2;
            for (int64_t j = 0; j < nb; j++) {
                double dx = blk.x[j] - px, dy = blk.y[j] - py, dz = blk.z[j] - pz;
                bd[j] = dx * dx + dy * dy + dz * dz;
            }
            double limit = b2;
            if (prev_r >= 0.0) {
                double ex = px - prev_p[0], ey = py - prev_p[1], ez = pz - prev_p[2];
                double t = prev_r + sqrt(ex * ex + ey * ey + ez * ez);
                double tau = t * t * (1.0 + 1e-9) + 1e-300;
                if (tau < limit) limit = tau;
            }
            /* strictly inside the block (< b2), or within the triangle bound */
            if (cbuf_reserve(&buf, nb)) { rc = -1; goto done; }
            int64_t m = 0;
            for (int64_t j = 0; j < nb; j++) {
                if (bd[j] < limit || (limit < b2 && bd[j] == limit)) {
                    buf.c[m].d2 = bd[j]; buf.c[m].idx = blk.idx[j]; buf.c[m].pos = blk.pos[j];
                    m++;
                }
            }
            if (m < kmax && limit < b2) {
                /* rounding paranoia: retry with the block bound */
                m = 0;
                for (int64_t j = 0; j < nb; j++) {
                    if (bd[j] < b2) {
                        buf.c[m].d2 = bd[j]; buf.c[m].idx = blk.idx[j]; buf.c[m].pos = blk.pos[j];
                        m++;
                    }
                }
            }
            if (m >= kmax) {
                buf.n = m;
                select_sorted(buf.c, m, kmax);
                found = 1;
            }
        }
        if (!found && knn_one(&g, i, kmax, &buf)) { rc = -1; goto done; }
        prev_r = sqrt(buf.c[kmax - 1].d2);
        prev_p[0] = pi[0]; prev_p[1] = pi[1]; prev_p[2] = pi[2];
        int64_t oi = orig[i];
        if (out_idx != NULL) {
            for (int64_t j = 0; j < kmax; j++) out_idx[oi * kmax + j] = buf.c[j].idx;
            if (out_pdis == NULL) continue;
        }
        for (int64_t j = 0; j < kmax; j++) {
            const double *pj = p + 3 * buf.c[j].pos;
            q[3 * j] = pj[0] - pi[0];
            q[3 * j + 1] = pj[1] - pi[1];
            q[3 * j + 2] = pj[2] - pi[2];
            d2[j] = buf.c[j].d2;
        }
        double sx = 0, sy = 0, sz = 0, h2 = 0;
        int64_t j = 0;
        for (int s = 0; s < nscales; s++) {
            int64_t m = ks[s];
            for (; j < m; j++) {
                sx += q[3 * j]; sy += q[3 * j + 1]; sz += q[3 * j + 2];
                if (d2[j] > h2) h2 = d2[j];
            }
            double mean[3] = {sx / (double)m, sy / (double)m, sz / (double)m};
            double *nrm = out_normals ? out_normals + 3 * (s * n + oi) : NULL;
            out_pdis[s * n + oi] = neighbourhood_pdis(q, d2, m, mean, h2, gaussian, NULL, nrm, mu);
        }
    }
done:
    free(buf.c);
    free(blk.x); free(blk.y); free(blk.z); free(blk.d2); free(blk.idx); free(blk.pos);
    free(q);
    free(d2);
    free(mu);
    return rc;
}

/* ------------------------------------------------------------------ meshes */

/* 1-ring adjacency of a triangle mesh, CSR with repeats (each face adds both other
 * corners to each corner): ptr (n + 1), idx (6 m). */
void ms_adjacency(const int64_t *faces, int64_t m, int64_t n, int64_t *ptr, int32_t *idx) {
    memset(ptr, 0, (size_t)(n + 1) * sizeof(int64_t));
    for (int64_t f = 0; f < 3 * m; f++) ptr[faces[f] + 1] += 2;
    for (int64_t v = 0; v < n; v++) ptr[v + 1] += ptr[v];
    int64_t *fill = (int64_t *)malloc((size_t)n * sizeof(int64_t));
    if (fill == NULL) return;
    memcpy(fill, ptr, (size_t)n * sizeof(int64_t));
    for (int64_t f = 0; f < m; f++) {
        int64_t a = faces[3 * f], b = faces[3 * f + 1], c = faces[3 * f + 2];
        idx[fill[a]++] = (int32_t)b; idx[fill[a]++] = (int32_t)c;
        idx[fill[b]++] = (int32_t)a; idx[fill[b]++] = (int32_t)c;
        idx[fill[c]++] = (int32_t)a; idx[fill[c]++] = (int32_t)b;
    }
    free(fill);
}

/* k-rings by breadth-first search for vertices [begin, end), and for each ring rings[s]
 * the projected distance into out_pdis[s * n + i] (normals into out_normals when not
 * NULL). fixed: (n, 3) face-average normals, a zero row meaning PCA. stamp: (n,) int32
 * scratch of this thread, all -1 initially (or left by an earlier call). With out_sizes
 * and out_members (not NULL), store ring sizes (nscales, n) instead... (unused). */
int ms_ring_pdis(const double *p, int64_t n, const int64_t *ptr, const int32_t *adj,
                 const double *fixed, const int64_t *rings, int nscales, int gaussian,
                 int64_t begin, int64_t end, int32_t *stamp, double *out_pdis,
                 double *out_normals) {
    int64_t cap = 1024;
    int32_t *queue = (int32_t *)malloc((size_t)cap * sizeof(int32_t));
    double *q = (double *)malloc((size_t)cap * 3 * sizeof(double));
    double *d2 = (double *)malloc((size_t)cap * sizeof(double));
    double *mu = (double *)malloc((size_t)cap * sizeof(double));
    int rc = 0;
    int64_t rmax = rings[nscales - 1];
    if (!queue || !q || !d2 || !mu) { rc = -1; goto done; }
    for (int64_t i = begin; i < end; i++) {
        const double *pi = p + 3 * i;
        const double *fn = fixed ? fixed + 3 * i : NULL;
        if (fn && fn[0] == 0.0 && fn[1] == 0.0 && fn[2] == 0.0) fn = NULL;
        int64_t head = 0, tail = 0;
        queue[tail++] = (int32_t)i;
        stamp[i] = (int32_t)i;
        double sx = 0, sy = 0, sz = 0, h2 = 0;
        int64_t done_j = 0;
        int s = 0;
        for (int64_t ring = 1; ring <= rmax; ring++) {
            int64_t level_end = tail;
            for (; head < level_end; head++) {
                int32_t v = queue[head];
                for (int64_t t = ptr[v]; t < ptr[v + 1]; t++) {
                    int32_t w = adj[t];
                    if (stamp[w] == (int32_t)i) continue;
                    stamp[w] = (int32_t)i;
                    if (tail == cap) {
                        int64_t nc = cap * 2;
                        int32_t *nq = (int32_t *)realloc(queue, (size_t)nc * sizeof(int32_t));
                        if (!nq) { rc = -1; goto done; }
                        queue = nq;
                        double *nq2 = (double *)realloc(q, (size_t)nc * 3 * sizeof(double));
                        if (!nq2) { rc = -1; goto done; }
                        q = nq2;
                        double *nd = (double *)realloc(d2, (size_t)nc * sizeof(double));
                        if (!nd) { rc = -1; goto done; }
                        d2 = nd;
                        double *nm = (double *)realloc(mu, (size_t)nc * sizeof(double));
                        if (!nm) { rc = -1; goto done; }
                        mu = nm;
                        cap = nc;
                    }
                    queue[tail++] = w;
                }
            }
            while (s < nscales && rings[s] == ring) {
                int64_t m = tail;
                for (; done_j < m; done_j++) {
                    const double *pj = p + 3 * (int64_t)queue[done_j];
                    double x = pj[0] - pi[0], y = pj[1] - pi[1], z = pj[2] - pi[2];
                    q[3 * done_j] = x; q[3 * done_j + 1] = y; q[3 * done_j + 2] = z;
                    double dd = x * x + y * y + z * z;
                    d2[done_j] = dd;
                    if (dd > h2) h2 = dd;
                    sx += x; sy += y; sz += z;
                }
                double mean[3] = {sx / (double)m, sy / (double)m, sz / (double)m};
                double *nrm = out_normals ? out_normals + 3 * (s * n + i) : NULL;
                out_pdis[s * n + i] = neighbourhood_pdis(q, d2, m, mean, h2, gaussian, fn, nrm, mu);
                s++;
            }
        }
    }
done:
    free(queue);
    free(q);
    free(d2);
    free(mu);
    return rc;
}

/* Face-average normals exactly as normals.face_average_normals computes them with
 * numpy (same products, same order of the sums): acc (n, 3) zero on entry. */
void ms_face_average_normals(const double *p, int64_t n, const int64_t *faces, int64_t m,
                             double zero, double *acc) {
    for (int c = 0; c < 3; c++) {
        for (int64_t f = 0; f < m; f++) {
            const double *p0 = p + 3 * faces[3 * f], *p1 = p + 3 * faces[3 * f + 1],
                         *p2 = p + 3 * faces[3 * f + 2];
            double a0 = p1[0] - p0[0], a1 = p1[1] - p0[1], a2 = p1[2] - p0[2];
            double b0 = p2[0] - p0[0], b1 = p2[1] - p0[1], b2 = p2[2] - p0[2];
            double x = a1 * b2 - a2 * b1, y = a2 * b0 - a0 * b2, z = a0 * b1 - a1 * b0;
            double len = sqrt(x * x + y * y + z * z);
            double dv = len > 0 ? len : 1.0;
            double *t = acc + 3 * faces[3 * f + c];
            t[0] += x / dv; t[1] += y / dv; t[2] += z / dv;
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

/* Merge exactly equal points (==, so -0.0 equals 0.0) into their first occurrence.
 * table: (tmask + 1) int64 scratch, all -1. from_input (n): cleaned index of each
 * input point; to_input (n, first m used): input index of each cleaned point.
 * Returns m. */
int64_t ms_dedup(const double *p, int64_t n, int64_t *table, int64_t tmask,
                 int64_t *from_input, int64_t *to_input) {
    int64_t m = 0;
    for (int64_t i = 0; i < n; i++) {
        const double *x = p + 3 * i;
        uint64_t h = point_hash(x) & (uint64_t)tmask;
        while (1) {
            int64_t t = table[h];
            if (t < 0) {
                table[h] = i;
                from_input[i] = m;
                to_input[m++] = i;
                break;
            }
            const double *y = p + 3 * t;
            if (x[0] == y[0] && x[1] == y[1] && x[2] == y[2]) {
                from_input[i] = from_input[t];
                break;
            }
            h = (h + 1) & (uint64_t)tmask;
        }
    }
    return m;
}

/* Double area of each face as vcg computes it: |(p1 - p0) ^ (p2 - p0)|. */
void ms_face_double_areas(const double *p, const int64_t *faces, int64_t m, double *out) {
    for (int64_t f = 0; f < m; f++) {
        const double *p0 = p + 3 * faces[3 * f], *p1 = p + 3 * faces[3 * f + 1],
                     *p2 = p + 3 * faces[3 * f + 2];
        double a0 = p1[0] - p0[0], a1 = p1[1] - p0[1], a2 = p1[2] - p0[2];
        double b0 = p2[0] - p0[0], b1 = p2[1] - p0[1], b2 = p2[2] - p0[2];
        double x = a1 * b2 - a2 * b1, y = a2 * b0 - a0 * b2, z = a0 * b1 - a1 * b0;
        out[f] = sqrt(x * x + y * y + z * z);
    }
}
