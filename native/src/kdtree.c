/* The balanced kd-tree and its exact k-nearest-neighbour search.
 * Part of meshlab-sharp's native library (meshlab_sharp.h). */
#include "internal.h"
#include "knn.h"

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

/* The block_scan to use: the AVX2 one when use_avx2. */
static block_scan_fn block_scanner(void) {
#ifdef HAVE_AVX2_PATH
    if (use_avx2()) return block_scan_avx2;
#endif
    return block_scan;
}

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

/* Returns 0, or -1 out of memory (then knn_cursor_free it all the same). */
int knn_cursor_init(knn_cursor_t *c, const tree_t *T, int64_t k) {
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

void knn_cursor_free(knn_cursor_t *c) {
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
void knn_cursor_next(knn_cursor_t *c, int64_t i) {
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
