/* Cleaning: merging equal points, keeping the faces with an area.
 * Part of meshlab-sharp's native library (meshlab_sharp.h). */
#include "internal.h"

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

/* The probe of a duplicate merge: the points in input order, each looked up among the
 * earlier ones in table (tmask + 1 uint64 entries of scratch, cleared here; linear
 * probing; n < 2^31) and inserted if new. A point equal (==, so -0.0 equals 0.0) to an
 * earlier one t gets from_input[i] = -1 - t (first occurrences are left as they were).
 * Returns the number of such points. */
static int64_t dedup_probe(const double *p, int64_t n, uint64_t *table, int64_t tmask,
                           int64_t *from_input) {
    /* cleared here, in order: a page first touched by a probe would cost its fault there
     * (and a prefetch of it is dropped) */
    memset(table, 0, ((size_t)tmask + 1) * sizeof(uint64_t));
    /* Blocks of DEDUP_BLOCK points: first each one's slot, fetched, then the points
     * probed, their slots in cache by then. */
    enum { DEDUP_BLOCK = 32 };
    uint64_t keep_slot[DEDUP_BLOCK], keep_entry[DEDUP_BLOCK];
    int64_t dups = 0;
    for (int64_t begin = 0; begin < n; begin += DEDUP_BLOCK) {
        const int64_t end = begin + DEDUP_BLOCK < n ? begin + DEDUP_BLOCK : n;
        for (int64_t i = begin; i < end; i++) {
            const uint64_t h = dedup_slot(p + 3 * i, tmask, &keep_entry[i - begin], i);
            PREFETCH(table + h);
            keep_slot[i - begin] = h;
        }
        for (int64_t i = begin; i < end; i++) {
            const double *x = p + 3 * i;
            const uint64_t entry = keep_entry[i - begin];
            uint64_t h = keep_slot[i - begin];
            while (1) {
                const uint64_t e = table[h];
                if (e == 0) {
                    table[h] = entry;
                    break;
                }
                if ((e ^ entry) >> 32 == 0) {
                    const int64_t t = (int64_t)(e & 0xffffffffULL) - 1;
                    const double *y = p + 3 * t;
                    if (x[0] == y[0] && x[1] == y[1] && x[2] == y[2]) {
                        dups++;
                        from_input[i] = -1 - t;
                        break;
                    }
                }
                h = (h + 1) & (uint64_t)tmask;
            }
        }
    }
    return dups;
}

/* The numbering of a duplicate merge, after dedup_probe: first occurrences
 * (from_input >= 0) numbered in order, into from_input and (unless NULL) to_input,
 * their rows copied to out (room for the cleaned points) unless out is NULL. */
static void dedup_number(const double *p, int64_t n, int64_t *from_input, int64_t *to_input,
                         double *out) {
    const size_t row = 3 * sizeof(double);
    int64_t base = 0;
    int64_t run = 0; /* the first occurrences [run, i) are copied in one piece */
    for (int64_t i = 0; i < n; i++) {
        if (from_input[i] < 0) {
            if (out != NULL && run < i)
                memcpy(out + 3 * (base - (i - run)), p + 3 * run, (size_t)(i - run) * row);
            run = i + 1;
            continue;
        }
        if (to_input != NULL) to_input[base] = i;
        from_input[i] = base++;
    }
    if (out != NULL && run < n)
        memcpy(out + 3 * (base - (n - run)), p + 3 * run, (size_t)(n - run) * row);
}

/* Merge exactly equal points into their first occurrence (meshlab_sharp.h): the probe,
 * the numbering, then each merged point (from_input -1 - t) given its first
 * occurrence's cleaned index. */
int64_t ms_dedup(const double *p, int64_t n, uint64_t *table, int64_t tmask,
                 int64_t *from_input, int64_t *to_input, double *out) {
    const int64_t dups = dedup_probe(p, n, table, tmask, from_input);
    dedup_number(p, n, from_input, to_input, dups > 0 ? out : NULL);
    if (dups > 0)
        for (int64_t i = 0; i < n; i++)
            if (from_input[i] < 0) from_input[i] = from_input[-1 - from_input[i]];
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
