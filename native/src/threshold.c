/* Thresholds, the global steps of every path: extent, histograms, Otsu's
 * split, robust mode's noise floor and one scale's vote.
 * Part of meshlab-sharp's native library (meshlab_sharp.h). */
#include "internal.h"

void ms_extent(const double *p, int64_t n, double *out) {
    double lo[3] = {0.0, 0.0, 0.0}, hi[3] = {0.0, 0.0, 0.0};
    if (n > 0)
        for (int a = 0; a < 3; a++) lo[a] = hi[a] = p[a];
    for (int64_t i = 1; i < n; i++)
        for (int a = 0; a < 3; a++) {
            const double x = p[3 * i + a];
            lo[a] = x < lo[a] ? x : lo[a];
            hi[a] = x > hi[a] ? x : hi[a];
        }
    for (int a = 0; a < 3; a++) out[a] = hi[a] - lo[a];
}

/* Bin of a value in [0, 1]: min(floor(v * MS_BINS), MS_BINS - 1) (threshold.histogram;
 * below 0, not a value the method makes, bin 0 rather than a write out of bounds). On
 * [0, MS_BINS - 1) the conversion's truncation is floor (no call of floor: a plain build
 * has no SSE4.1 rounding instruction). */
MS_INTERNAL int64_t ms_value_bin(double v) {
    const double b = v * MS_BINS;
    if (!(b >= 0.0)) return 0;
    return b >= MS_BINS - 1 ? MS_BINS - 1 : (int64_t)b;
}

/* Otsu's threshold t / MS_BINS from the MS_BINS counts of a histogram, in the integer
 * form of the notes (the first largest split wins); 1.0 when no split has points on both
 * sides (threshold.otsu_from_histogram). */
MS_INTERNAL double ms_otsu_split(const int64_t *counts) {
    int64_t total = 0, weighted_total = 0;
    for (int64_t b = 0; b < MS_BINS; b++) {
        total += counts[b];
        weighted_total += counts[b] * (2 * b + 1);
    }
    int64_t n0 = 0, s0 = 0, best_t = -1;
    double best = 0.0;
    for (int64_t t = 1; t < MS_BINS; t++) {
        n0 += counts[t - 1];
        s0 += counts[t - 1] * (2 * (t - 1) + 1);
        if (n0 == 0 || n0 == total) continue;
        const double dn0 = (double)n0, dn1 = (double)total - dn0;
        const double ds0 = (double)s0, ds1 = (double)weighted_total - ds0;
        const double diff = ds0 * dn1 - ds1 * dn0;
        const double crit = diff * diff / (dn0 * dn1);
        if (best_t < 0 || crit > best) {
            best = crit;
            best_t = t;
        }
    }
    return best_t < 0 ? 1.0 : (double)best_t / MS_BINS;
}

MS_INTERNAL double ms_normal_span(double lo, double hi, double flat_span) {
    return hi - lo > flat_span ? hi - lo : -1.0;
}

/* Adds the bins (ms_value_bin) of v = (x[i] - lo) / span (span > 0), v = x[i] (span == 0),
 * or v = 0 (span < 0: a flat scale) of x (n) to counts (MS_BINS) (threshold.histogram). */
static void histogram(const double *x, int64_t n, double lo, double span, int64_t *counts) {
    if (span > 0.0) {
        for (int64_t i = 0; i < n; i++) counts[ms_value_bin((x[i] - lo) / span)]++;
    } else if (span == 0.0) {
        for (int64_t i = 0; i < n; i++) counts[ms_value_bin(x[i])]++;
    } else {
        counts[0] += n;
    }
}

double ms_noise_floor(const int64_t *counts) {
    int64_t total = 0;
    for (int b = 0; b < MS_BINS; b++) total += counts[b];
    if (total == 0) return 0.0;
    const int64_t rank = (total - 1) / 2; /* the lower median's, from 0 */
    int64_t below = 0;
    int b = 0;
    for (; b < MS_BINS - 1; b++) {
        below += counts[b];
        if (below > rank) break;
    }
    const double floor_ = MS_NOISE_FLOOR * (double)(b + 1) / (double)MS_BINS;
    return floor_ < MS_NOISE_FLOOR_MAX ? floor_ : MS_NOISE_FLOOR_MAX;
}

double ms_scale_vote(const double *x, int64_t n, int normalise, double flat_span, int otsu,
                     double floor_, double *out, int64_t *votes, int64_t *count) {
    double lo = 0.0, span = 0.0; /* values as given */
    if (normalise) {
        double mn = n > 0 ? x[0] : 0.0, mx = mn;
        for (int64_t i = 1; i < n; i++) {
            mn = x[i] < mn ? x[i] : mn;
            mx = x[i] > mx ? x[i] : mx;
        }
        lo = mn;
        span = ms_normal_span(mn, mx, flat_span);
    }
    double t = floor_;
    if (otsu) {
        int64_t counts[MS_BINS] = {0};
        histogram(x, n, lo, span, counts);
        const double split = ms_otsu_split(counts);
        t = split > floor_ ? split : floor_;
    }
    int64_t c = 0;
    for (int64_t i = 0; i < n; i++) {
        const double v = span > 0.0 ? (x[i] - lo) / span : span == 0.0 ? x[i] : 0.0;
        const int64_t hit = v >= t;
        if (out != NULL) out[i] = v;
        votes[i] += hit;
        c += hit;
    }
    *count = c;
    return t;
}
/* Counts of the values v[begin, end) added to counts (32769): +0.0 in counts[0], any
 * other value by the top 16 bits b of its IEEE 754 bit pattern in counts[b + 1]: from
 * +0.0 up to +inf and then NaN, the bins follow the values' order (np.partition's, NaN
 * last). Returns how many values have the sign bit set (negative, -0.0; left out). */
int64_t ms_bit_histogram(const double *v, int64_t begin, int64_t end, int64_t *counts) {
    int64_t negative = 0;
    for (int64_t i = begin; i < end; i++) {
        uint64_t bits;
        memcpy(&bits, v + i, sizeof bits);
        uint64_t sign = bits >> 63;
        negative += (int64_t)sign;
        counts[bits ? (bits >> 48) + 1 : 0] += !sign;
    }
    return negative;
}
