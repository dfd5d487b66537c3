/* Meshes: the 1-ring adjacency, whether a vertex order lacks locality, and the
 * breadth-first renumbering.
 * Part of meshlab-sharp's native library (meshlab_sharp.h). */
#include "internal.h"

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
