/* Robust mode's finishing steps (reference.detect.RobustSetup.finish): isolation, line
 * directions, support, the smoothed ranking, thinning, acute tips.
 * Part of meshlab-sharp's native library (meshlab_sharp.h). */
#include "internal.h"

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
 * negated, to the 3x3 solver: the eigenvector of C's largest eigenvalue into e, the mean
 * qbar into qbar. */
static void line_direction(const double *col, int64_t m, double *e, double *qbar) {
    const double count = (double)(m > 1 ? m : 1);
    double neg[6];
    static const int row[6] = {0, 1, 2, 1, 2, 2}, column[6] = {0, 0, 0, 1, 1, 2};
    for (int a = 0; a < 3; a++) qbar[a] = segment_sum(col + a, m, 9) / count;
    for (int t = 0; t < 6; t++)
        neg[t] = -(segment_sum(col + 3 + t, m, 9) - count * qbar[row[t]] * qbar[column[t]]);
    smallest_eigvec(neg[0], neg[1], neg[2], neg[3], neg[4], neg[5], e);
}

/* line_direction's column of one point pj of pi's list: q = p_j - p_i and its products. */
static inline void line_column(const double *pi, const double *pj, double *c) {
    for (int a = 0; a < 3; a++) c[a] = pj[a] - pi[a];
    c[3] = c[0] * c[0]; c[4] = c[0] * c[1]; c[5] = c[0] * c[2];
    c[6] = c[1] * c[1]; c[7] = c[1] * c[2]; c[8] = c[2] * c[2];
}

/* The longest of the lists of slots [begin, end) of L, at least 1: the rows of a
 * per-list scratch. */
static int64_t longest_list(const ms_lists_t *L, int64_t begin, int64_t end) {
    int64_t cap = 1;
    for (int64_t r = begin; r < end; r++) {
        int64_t first, len;
        list_span(L, r, &first, &len);
        cap = len > cap ? len : cap;
    }
    return cap;
}

int ms_line_directions(const double *p, const uint8_t *f0, const int64_t *rows,
                       const ms_lists_t *direction, int64_t begin, int64_t end, double *e) {
    const int64_t cap = longest_list(direction, begin, end);
    double *col = (double *)malloc((size_t)cap * 9 * sizeof(double));
    if (!col) return -1;
    for (int64_t r = begin; r < end; r++) {
        const double *pi = p + 3 * rows[r];
        int64_t first, len, m = 0;
        list_span(direction, r, &first, &len);
        for (int64_t t = first; t < first + len; t++) {
            const int64_t j = list_member(direction, t);
            if (f0[j]) line_column(pi, p + 3 * j, col + 9 * m++);
        }
        double qbar[3];
        line_direction(col, m, e + 3 * r, qbar);
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
 * between p_i and the point b: (p_m - p_i) . (p_m - b) < 0 (robust.thin's blocking, b =
 * p_j; robust.line_test's, b = p_i's foot on the line). */
static int parted(const double *p, const ms_lists_t *compare, int64_t first, int64_t len,
                  const double *rank, const uint8_t *between, int64_t i, const double *b) {
    for (int64_t t = first; t < first + len; t++) {
        const int64_t m = list_member(compare, t);
        if ((between[m] || rank[m] < rank[i]) && ball_dot(p + 3 * m, p + 3 * i, b) < 0)
            return 1;
    }
    return 0;
}

/* Squared distance from p_i to the farthest member of slot r's list (first, len; len > 0):
 * the list's reach, the unit of thinning's side rule (robust.thin). The farthest, not the
 * last: a mesh's ring lists its vertices in the order the ring search meets them, which
 * depends on the vertex and face order. */
static inline double list_reach2(const double *p, const ms_lists_t *L, int64_t first,
                                 int64_t len, int64_t i) {
    const double *pi = p + 3 * i;
    double reach2 = 0.0;
    for (int64_t t = first; t < first + len; t++) {
        const double *q = p + 3 * list_member(L, t);
        const double dx = q[0] - pi[0], dy = q[1] - pi[1], dz = q[2] - pi[2];
        const double d2 = dx * dx + dy * dy + dz * dz;
        if (d2 > reach2) reach2 = d2;
    }
    return reach2;
}

/* Whether d = p_j - p_i lies across the line through p_i of direction e (across_line),
 * or to its side by more than side_reach2's root: |d|^2 - (d . e)^2 > side_reach2
 * (robust.thin's pairs). */
static inline int beside_line(const double *pi, const double *pj, const double *e, double cone,
                              double side_reach2) {
    const double dx = pj[0] - pi[0], dy = pj[1] - pi[1], dz = pj[2] - pi[2];
    const double along = dx * e[0] + dy * e[1] + dz * e[2];
    const double d2 = dx * dx + dy * dy + dz * dz;
    return fabs(along) < cone * sqrt(d2) || d2 - along * along > side_reach2;
}

void ms_thin(const double *p, const uint8_t *f1, const int64_t *rows, const double *e,
             const ms_lists_t *compare, const double *rank, double cone, double side,
             const uint8_t *between, int64_t begin, int64_t end, uint8_t *f2) {
    for (int64_t r = begin; r < end; r++) {
        const int64_t i = rows[r];
        int keep = f1[i];
        int64_t first, len;
        list_span(compare, r, &first, &len);
        /* the reach walks the whole list: only for a point still to test */
        const double side2 = keep && len > 0 ? side * side * list_reach2(p, compare, first, len, i) : 0.0;
        for (int64_t t = first; keep && t < first + len; t++) {
            const int64_t j = list_member(compare, t);
            if (j != i && f1[j] && rank[j] > rank[i] &&
                beside_line(p + 3 * i, p + 3 * j, e + 3 * r, cone, side2) &&
                !(between != NULL && parted(p, compare, first, len, rank, between, i, p + 3 * j)))
                keep = 0;
        }
        f2[i] = (uint8_t)keep;
    }
}

/* The local unit of slot r's list (i first): the mean distance from p_i to the next
 * min(unit, len - 1) members, added in order to 0.0 (robust.line_test). */
static double list_unit(const double *p, const ms_lists_t *L, int64_t first, int64_t len,
                        int64_t i, int64_t unit) {
    const int64_t m = len - 1 < unit ? len - 1 : unit;
    double acc = 0.0;
    for (int64_t t = first + 1; t < first + 1 + m; t++) {
        const double *q = p + 3 * list_member(L, t), *pi = p + 3 * i;
        const double dx = q[0] - pi[0], dy = q[1] - pi[1], dz = q[2] - pi[2];
        acc += sqrt(dx * dx + dy * dy + dz * dz);
    }
    return m > 0 ? acc / (double)m : 0.0;
}

int ms_line_test(const double *p, const uint8_t *f2, const int64_t *rows,
                 const ms_lists_t *compare, const double *rank, const ms_line_rules_t *rules,
                 const uint8_t *between, int64_t begin, int64_t end, uint8_t *f3) {
    const int64_t cap = longest_list(compare, begin, end);
    double *col = (double *)malloc((size_t)cap * 10 * sizeof(double)); /* then w (cap) */
    if (!col) return -1;
    double *w = col + 9 * cap;
    for (int64_t r = begin; r < end; r++) {
        const int64_t i = rows[r];
        const double *pi = p + 3 * i;
        int64_t first, len, m = 0;
        list_span(compare, r, &first, &len);
        for (int64_t t = first; f2[i] && t < first + len; t++) {
            const int64_t j = list_member(compare, t);
            if (j != i && f2[j] && rank[j] > rank[i]) line_column(pi, p + 3 * j, col + 9 * m++);
        }
        int keep = f2[i];
        if (keep && m >= rules->minimum) {
            double e[3], qbar[3];
            line_direction(col, m, e, qbar);
            const double at = qbar[0] * e[0] + qbar[1] * e[1] + qbar[2] * e[2];
            const double u = list_unit(p, compare, first, len, i, rules->unit);
            const double reach = rules->reach * u;
            int ahead = 0, behind = 0; /* i's foot lies among theirs along the line */
            for (int64_t t = 0; t < m; t++) {
                const double *c = col + 9 * t;
                const double rx = c[0] - qbar[0], ry = c[1] - qbar[1], rz = c[2] - qbar[2];
                const double along = rx * e[0] + ry * e[1] + rz * e[2];
                w[t] = rx * rx + ry * ry + rz * rz - along * along;
                ahead |= along > -at + reach;
                behind |= along < -at - reach;
            }
            const double scatter = segment_sum(w, m, 1) / (double)m;
            const double g[3] = {qbar[0] - at * e[0], qbar[1] - at * e[1], qbar[2] - at * e[2]};
            const double off2 = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
            const double far = rules->offset * u, thin = rules->spread * u;
            if (ahead && behind && off2 > far * far && scatter < thin * thin) {
                const double foot[3] = {pi[0] + g[0], pi[1] + g[1], pi[2] + g[2]};
                keep = between != NULL && parted(p, compare, first, len, rank, between, i, foot);
            }
        }
        f3[i] = (uint8_t)keep;
    }
    free(col);
    return 0;
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

/* Whether the point a (cleaned index i) is not among the kmax nearest of its nearest b,
 * whose kmax-th neighbour has squared distance kth and index kth_idx: (|a - b|^2, i)
 * comes after (kth, kth_idx) in the lists' order (squared distance, then index); or
 * whether a's squared distance nth (to its isolated_nth-th nearest) exceeds spread2 times
 * far (that of its kmax-th neighbour to its isolated_ref-th nearest). */
static inline uint8_t isolated_one(const double *a, const double *b, double kth,
                                   int64_t kth_idx, int64_t i, double nth, double far,
                                   double spread2) {
    double dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
    double d2 = dx * dx + dy * dy + dz * dz;
    return !(d2 < kth || (d2 == kth && i <= kth_idx)) || nth > spread2 * far;
}

/* robust.isolated_points from a pass's statistics (cloud_out_t's near, kth_d2, kth_idx,
 * nth_d2, ref_d2) for the points [begin, end) of p (n, 3), cleaned order: out[i] = isolated_one of
 * i and j = near[i]. */
void ms_isolated(const double *p, const int32_t *near, const double *kth_d2,
                 const int32_t *kth_idx, const double *nth_d2, const double *ref_d2,
                 double spread, int64_t begin, int64_t end, uint8_t *out) {
    for (int64_t i = begin; i < end; i++) {
        int64_t j = near[i];
        out[i] = isolated_one(p + 3 * i, p + 3 * j, kth_d2[j], kth_idx[j], i, nth_d2[i],
                              ref_d2[kth_idx[i]], spread * spread);
    }
}

void ms_stage_isolated(const double *a, const double *b, const double *kth_d2,
                       const int64_t *kth_idx, const int64_t *idx, const double *nth_d2,
                       const double *far_d2, double spread, int64_t begin, int64_t end,
                       uint8_t *out) {
    for (int64_t r = begin; r < end; r++)
        out[r] = isolated_one(a + 3 * r, b + 3 * r, kth_d2[r], kth_idx[r], idx[r], nth_d2[r],
                              far_d2[r], spread * spread);
}

/* ms_isolated from a tree_order = 2 pass's statistics, for the tree positions [begin, end):
 * tp (n, 3) the points in tree order, orig their cleaned indices, near[t] and kth_idx[t]
 * tree positions, out[t] per tree position. The nearest lies close by in the tree: reads
 * near the point's own, where cleaned order reads all over the cloud. */
void ms_isolated_tree(const double *tp, const int64_t *orig, const int32_t *near,
                      const double *kth_d2, const int32_t *kth_idx, const double *nth_d2,
                      const double *ref_d2, double spread, int64_t begin, int64_t end,
                      uint8_t *out) {
    for (int64_t t = begin; t < end; t++) {
        int64_t u = near[t];
        out[t] = isolated_one(tp + 3 * t, tp + 3 * u, kth_d2[u], orig[kth_idx[u]], orig[t],
                              nth_d2[t], ref_d2[kth_idx[t]], spread * spread);
    }
}
