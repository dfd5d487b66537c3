/* Meshes: k-rings by breadth-first search, with the normals, projected
 * distances and robust mode's relative distances over them.
 * Part of meshlab-sharp's native library (meshlab_sharp.h). */
#include "internal.h"

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
