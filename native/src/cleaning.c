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

/* The probe of a duplicate merge: the points whose slots lie in part `part` of `parts`
 * equal parts of table (tmask + 1 uint64 entries of scratch, the part's cleared first;
 * parts a power of two dividing tmask + 1; n < 2^31), in input order, each looked up
 * among the earlier ones there (linear probing within the part) and inserted if new.
 * Parts see disjoint points and slots: they may run at once. A point equal (==, so -0.0
 * equals 0.0) to an earlier one t gets from_input[i] = -1 - t (first occurrences are left
 * as they were) and counts in dups[s] for the span s of bounds (spans + 1 increasing
 * indices, 0 to n) holding i. */
void ms_dedup_probe(const double *p, int64_t n, uint64_t *table, int64_t tmask, int64_t parts,
                    int64_t part, const int64_t *bounds, int64_t *from_input, int64_t *dups) {
    const uint64_t span = ((uint64_t)tmask + 1) / (uint64_t)parts, lo = (uint64_t)part * span;
    /* cleared here, in order: a page first touched by a probe would cost its fault there
     * (and a prefetch of it is dropped) */
    memset(table + lo, 0, span * sizeof(uint64_t));
    /* Blocks of DEDUP_BLOCK points: first each one's slot, fetched and kept when in the
     * part (without a branch: one on the hash mispredicts every other point with two
     * parts), then the kept ones probed, their slots in cache by then. */
    enum { DEDUP_BLOCK = 32 };
    int64_t keep_i[DEDUP_BLOCK];
    uint64_t keep_slot[DEDUP_BLOCK], keep_entry[DEDUP_BLOCK];
    int64_t s = 0;
    for (int64_t begin = 0; begin < n; begin += DEDUP_BLOCK) {
        const int64_t end = begin + DEDUP_BLOCK < n ? begin + DEDUP_BLOCK : n;
        int k = 0;
        for (int64_t i = begin; i < end; i++) {
            uint64_t entry, h = dedup_slot(p + 3 * i, tmask, &entry, i);
            const int mine = h - lo < span;
            PREFETCH(table + (mine ? h : lo));
            keep_i[k] = i;
            keep_slot[k] = h;
            keep_entry[k] = entry;
            k += mine;
        }
        for (int j = 0; j < k; j++) {
            const int64_t i = keep_i[j];
            const double *x = p + 3 * i;
            uint64_t h = keep_slot[j];
            while (1) {
                const uint64_t e = table[h];
                if (e == 0) {
                    table[h] = keep_entry[j];
                    break;
                }
                if ((e ^ keep_entry[j]) >> 32 == 0) {
                    const int64_t t = (int64_t)(e & 0xffffffffULL) - 1;
                    const double *y = p + 3 * t;
                    if (x[0] == y[0] && x[1] == y[1] && x[2] == y[2]) {
                        while (i >= bounds[s + 1]) s++;
                        dups[s]++;
                        from_input[i] = -1 - t;
                        break;
                    }
                }
                h = lo + ((h - lo + 1) & (span - 1));
            }
        }
    }
}

/* The numbering of a duplicate merge over the input points [lo, hi), after every
 * part's ms_dedup_probe: first occurrences (from_input >= 0) numbered from `base` (the
 * first occurrences before lo) in order, into from_input and (unless NULL) to_input,
 * their rows copied to out (room for the cleaned points) unless out is NULL. Spans may
 * run at once. */
void ms_dedup_number(const double *p, int64_t lo, int64_t hi, int64_t base, int64_t *from_input,
                     int64_t *to_input, double *out) {
    const size_t row = 3 * sizeof(double);
    int64_t run = lo; /* the first occurrences [run, i) are copied in one piece */
    for (int64_t i = lo; i < hi; i++) {
        if (from_input[i] < 0) {
            if (out != NULL && run < i)
                memcpy(out + 3 * (base - (i - run)), p + 3 * run, (size_t)(i - run) * row);
            run = i + 1;
            continue;
        }
        if (to_input != NULL) to_input[base] = i;
        from_input[i] = base++;
    }
    if (out != NULL && run < hi)
        memcpy(out + 3 * (base - (hi - run)), p + 3 * run, (size_t)(hi - run) * row);
}

/* The last step of a duplicate merge over [lo, hi), after every span's ms_dedup_number:
 * each merged point (from_input -1 - t) takes its first occurrence's cleaned index. Spans
 * may run at once (a first occurrence's index is not written here). */
void ms_dedup_resolve(int64_t lo, int64_t hi, int64_t *from_input) {
    for (int64_t i = lo; i < hi; i++)
        if (from_input[i] < 0) from_input[i] = from_input[-1 - from_input[i]];
}

/* Merge exactly equal points (==, so -0.0 equals 0.0) into their first occurrence, on one
 * thread: ms_dedup_probe, ms_dedup_number, ms_dedup_resolve in turn. table: (tmask + 1)
 * uint64 scratch, tmask + 1 a power of two >= 2 n, <= 2^32; n < 2^31. from_input
 * (n, all 0 at first): cleaned index of each input point; to_input (n, first m used):
 * input index of each cleaned point; out (room for n rows) or NULL: the cleaned points
 * (m, 3) when some points merge, untouched when none does (the cleaned points are then
 * p). Returns m. */
int64_t ms_dedup(const double *p, int64_t n, uint64_t *table, int64_t tmask,
                 int64_t *from_input, int64_t *to_input, double *out) {
    const int64_t bounds[2] = {0, n};
    int64_t dups = 0;
    ms_dedup_probe(p, n, table, tmask, 1, 0, bounds, from_input, &dups);
    ms_dedup_number(p, 0, n, 0, from_input, to_input, dups > 0 ? out : NULL);
    if (dups > 0) ms_dedup_resolve(0, n, from_input);
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
