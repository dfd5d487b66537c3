/* The kd-tree's k-nearest-neighbour search as the cloud pass uses it (kdtree.c): private
 * to the native library. */
#ifndef MESHLAB_SHARP_KNN_H
#define MESHLAB_SHARP_KNN_H

#include "internal.h"

typedef struct {
    double d2;
    int64_t idx; /* cleaned index (tie rule) */
    int64_t pos; /* tree position (coordinates) */
} cand_t;

/* The k best candidates seen by one query, a max-heap by (d2, idx); until it holds k,
 * only candidates with d2 <= tau (an upper bound of the k-th squared distance) enter. */
typedef struct {
    cand_t *c;
    int64_t n, k;
    double tau;
} heap_t;

typedef struct {
    const double *p;
    const int64_t *orig;
    const double *box;
    int64_t n;
    int depth;
} tree_t;

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

typedef int64_t (*block_scan_fn)(const block_t *, double, double, double, double, int32_t *,
                                 float *);

/* Buckets of nearest_of_block's counting sort. */
#define NEAR_BUCKETS 64

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
MS_INTERNAL int knn_cursor_init(knn_cursor_t *c, const tree_t *T, int64_t k);
MS_INTERNAL void knn_cursor_free(knn_cursor_t *c);
/* The k nearest of the point at tree position i into c->h.c[0..k). */
MS_INTERNAL void knn_cursor_next(knn_cursor_t *c, int64_t i);

#endif
