/* Robust mode's sheet filter (robust.sheet_mask): the neighbours a point keeps
 * before its scales' normals and distances.
 * Part of meshlab-sharp's native library (meshlab_sharp.h). */
#include "internal.h"

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
int64_t sheet_keep(const double *q, const double *d2, int64_t k, const double *nrm,
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
sheet_params_t sheet_params(const cloud_out_t *out) {
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
