/* The stages of a point cloud's sequence that work point by point, and robust mode's
 * rules on the cloud's noise: the one definition of each, composed by ms_detect in memory
 * (detect.cpp) and called tile by tile by the out-of-core path (meshlab_sharp.tiles), which
 * sums the stages' partials (histograms, counts) over the tiles.
 * Part of meshlab-sharp's native library (meshlab_sharp.h). */
#include "internal.h"

double ms_noise_factor(double noise) {
    const double ratio = noise / MS_NOISE_TOLERATED, grown = ratio * ratio;
    const double factor = grown > 1.0 ? grown : 1.0;
    return factor < MS_NOISE_MAX_FACTOR ? factor : MS_NOISE_MAX_FACTOR;
}

double ms_scale_growth(double noise, int64_t n, int top) {
    const double factor = ms_noise_factor(noise), most = (double)n / (double)top;
    return most < factor ? most : factor;
}

int ms_grown_scale(int k, double factor) { return (int)floor((double)k * factor + 0.5); }

int ms_thin_knn(double growth) { return ms_grown_scale(MS_THIN_KNN, growth); }

int ms_quiet_cloud(int mesh, double noise) { return !(mesh || noise > MS_NOISE_QUIET); }

int ms_otsu_splits(int mesh, double noise) { return !ms_quiet_cloud(mesh, noise); }

/* Whether the largest scale's floor reads its histogram: a cloud that is not quiet. */
static int noise_floored(int mesh, double noise) { return !(mesh || ms_quiet_cloud(mesh, noise)); }

double ms_scale_floor(const int64_t *counts, int last, int mesh, double noise) {
    if (!last || !noise_floored(mesh, noise)) return MS_R_MIN;
    const double floor_ = ms_noise_floor(counts);
    return floor_ > MS_R_MIN ? floor_ : MS_R_MIN;
}

double ms_thin_cone(int mesh, double noise) {
    return mesh || ms_quiet_cloud(mesh, noise) ? MS_THIN_CONE_COS : MS_THIN_CONE_COS_NOISY;
}

double ms_thin_side(int mesh, double noise) {
    return mesh || ms_quiet_cloud(mesh, noise) ? MS_THIN_SIDE : MS_THIN_SIDE_NOISY;
}

int ms_ranking_smoothed(int mesh, double noise) {
    return !mesh && ms_noise_factor(noise) == MS_NOISE_MAX_FACTOR;
}

int ms_support_free_score(int mesh, double noise, double *score) {
    if (!ms_quiet_cloud(mesh, noise)) return 0;
    *score = MS_SUPPORT_FREE_SCORE;
    return 1;
}

int ms_robust_plan(double noise, int64_t n_kept, const int *scales, int s, int mesh,
                   ms_robust_plan_t *plan) {
    if (s < 1 || s > MS_MAX_SCALES) return -1;
    const int given_top = scales[s - 1];
    plan->mesh = mesh;
    plan->noise = noise;
    plan->n_scales = s;
    plan->growth = mesh ? 1.0 : ms_scale_growth(noise, n_kept, given_top);
    plan->grown = plan->growth > 1.0;
    for (int k = 0; k < s; k++)
        plan->scales[k] = plan->grown ? ms_grown_scale(scales[k], plan->growth) : scales[k];
    const int top = plan->scales[s - 1];
    plan->otsu = ms_otsu_splits(mesh, noise);
    plan->noise_floor = noise_floored(mesh, noise);
    plan->acute_tests = ms_quiet_cloud(mesh, noise);
    const int support = mesh ? MS_THIN_RING : MS_SUPPORT_KNN;
    const int compare = mesh ? MS_THIN_RING : ms_thin_knn(plan->growth);
    plan->support_knn = support < top ? support : top;
    plan->compare_knn = compare < top ? compare : top;
    plan->ranking_smoothed = ms_ranking_smoothed(mesh, noise);
    plan->free_below = 0.0;
    plan->support_exempt = ms_support_free_score(mesh, noise, &plan->free_below);
    plan->thin_cone = ms_thin_cone(mesh, noise);
    plan->thin_side = ms_thin_side(mesh, noise);
    plan->thin_between = ms_quiet_cloud(mesh, noise);
    plan->curved_dropped = mesh;
    plan->thin_line = !mesh && !plan->ranking_smoothed;
    return 0;
}

void ms_plan_thresholds(const ms_robust_plan_t *plan, const int64_t *counts, double *thresholds) {
    const int s = plan->n_scales;
    for (int k = 0; k < s; k++) {
        const int64_t *c = plan->otsu ? counts + (int64_t)k * MS_BINS : NULL;
        const double floor_ = ms_scale_floor(c, k == s - 1, plan->mesh, plan->noise);
        thresholds[k] = ms_stage_threshold(c, plan->otsu, floor_);
    }
}

double ms_flat_span(const double *extent) {
    return MS_FLAT_TOLERANCE *
           sqrt(extent[0] * extent[0] + extent[1] * extent[1] + extent[2] * extent[2]);
}

/* Scale s's value of point i: x[i * point_stride + s * scale_stride], min-max normalised
 * with lo[s] and span[s] (span > 0; span < 0, a flat scale: 0) when lo is not NULL. */
static inline double stage_value(const double *x, int64_t point_stride, int64_t scale_stride,
                                 int64_t i, int s, const double *lo, const double *span) {
    const double v = x[i * point_stride + (int64_t)s * scale_stride];
    if (lo == NULL) return v;
    return span[s] > 0.0 ? (v - lo[s]) / span[s] : 0.0;
}

/* The spans of lo, hi (s each) by the flat rule (ms_normal_span), into span (s). */
static void stage_spans(const double *lo, const double *hi, double flat_span, int s, double *span) {
    for (int k = 0; k < s && lo != NULL; k++) span[k] = ms_normal_span(lo[k], hi[k], flat_span);
}

void ms_stage_histograms(const double *x, int64_t point_stride, int64_t scale_stride, int s,
                         int64_t begin, int64_t end, const double *lo, const double *hi,
                         double flat_span, int64_t *counts) {
    double span[MS_MAX_SCALES];
    stage_spans(lo, hi, flat_span, s, span);
    /* consecutive points counted in STAGE_LANES histograms in turn, summed after: a run of
     * points in one bin then waits on no increment but its lane's (the counts are the
     * same) */
    enum { STAGE_LANES = 4 };
    int64_t lane[STAGE_LANES][MS_BINS];
    for (int k = 0; k < s; k++) {
        int64_t *c = counts + (int64_t)k * MS_BINS;
        memset(lane, 0, sizeof lane);
        int64_t i = begin;
        for (; i + STAGE_LANES <= end; i += STAGE_LANES)
            for (int l = 0; l < STAGE_LANES; l++)
                lane[l][ms_value_bin(stage_value(x, point_stride, scale_stride, i + l, k, lo, span))]++;
        for (; i < end; i++) lane[0][ms_value_bin(stage_value(x, point_stride, scale_stride, i, k, lo, span))]++;
        for (int b = 0; b < MS_BINS; b++) c[b] += lane[0][b] + lane[1][b] + lane[2][b] + lane[3][b];
    }
}

double ms_stage_threshold(const int64_t *counts, int otsu, double floor_) {
    if (!otsu) return floor_;
    const double split = ms_otsu_split(counts);
    return split > floor_ ? split : floor_;
}

/* Points decided together: their votes fit on the stack. */
#define STAGE_BLOCK 1024

void ms_stage_decide(const double *x, int64_t point_stride, int64_t scale_stride, int s,
                     int64_t begin, int64_t end, const double *lo, const double *hi,
                     double flat_span, const double *thresholds, uint8_t *feature,
                     double *strength, int64_t *counts, double *out) {
    double span[MS_MAX_SCALES];
    stage_spans(lo, hi, flat_span, s, span);
    for (int64_t b = begin; b < end; b += STAGE_BLOCK) {
        const int64_t e = end - b < STAGE_BLOCK ? end : b + STAGE_BLOCK;
        int64_t votes[STAGE_BLOCK] = {0};
        for (int k = 0; k < s; k++) {
            const double t = thresholds[k];
            int64_t c = 0;
            for (int64_t i = b; i < e; i++) {
                const double v = stage_value(x, point_stride, scale_stride, i, k, lo, span);
                const int64_t hit = v >= t;
                if (out != NULL) out[i * point_stride + (int64_t)k * scale_stride] = v;
                votes[i - b] += hit;
                c += hit;
            }
            counts[k] += c;
        }
        for (int64_t i = b; i < e; i++) {
            feature[i] = (uint8_t)(votes[i - b] == s);
            strength[i] = (double)votes[i - b] / (double)s;
        }
    }
}

int64_t ms_stage_acute_tests(const double *score, const uint8_t *feature, int64_t begin,
                             int64_t end, int mesh, double noise, uint8_t *tested) {
    int64_t count = 0;
    if (!ms_quiet_cloud(mesh, noise)) return 0;
    for (int64_t i = begin; i < end; i++) {
        const uint8_t t = !feature[i] && score[i] >= MS_ACUTE_SCORE && score[i] < MS_ACUTE_SCORE_MAX;
        tested[i] = t;
        count += t;
    }
    return count;
}

int64_t ms_stage_curved(const double *first, const double *last, int64_t begin, int64_t end,
                        int s_first, int s_last, uint8_t *feature) {
    int64_t count = 0;
    const double a = (double)s_last, b = (double)s_first;
    for (int64_t i = begin; i < end; i++) {
        if (feature[i] && first[i] * first[i] * a < last[i] * last[i] * b) {
            feature[i] = 0;
            count++;
        }
    }
    return count;
}
