// The C face of the detection sequence (detect.h): ms_detect and its accessors, and the
// scales grammar, as native/include/meshlab_sharp.h declares them. No exception leaves
// these functions: each becomes a status and a message.
#include "detect.h"

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <exception>
#include <memory>
#include <new>

struct ms_detection {
	sharp::Result result;
};

namespace {

// The message into err (errlen bytes, NUL-terminated, cut to fit; err may be NULL).
int fail(int status, const char *message, char *err, int errlen) {
	if (err != nullptr && errlen > 0) {
		const size_t length = std::min(std::strlen(message), size_t(errlen - 1));
		std::memcpy(err, message, length);
		err[length] = '\0';
	}
	return status;
}

}  // namespace

extern "C" {

void ms_detect_defaults(ms_detect_options *opt) {
	static const int knn[] = MS_DEFAULT_KNN_SCALES, rings[] = MS_DEFAULT_RING_SCALES;
	*opt = ms_detect_options{};
	opt->mode = MS_DEFAULT_MODE;
	opt->weighting = MS_DEFAULT_WEIGHTING;
	opt->n_knn_scales = int(sizeof knn / sizeof knn[0]);
	std::copy(std::begin(knn), std::end(knn), opt->knn_scales);
	opt->n_ring_scales = int(sizeof rings / sizeof rings[0]);
	std::copy(std::begin(rings), std::end(rings), opt->ring_scales);
}

int ms_detect(const double *xyz, int64_t n, const int64_t *faces, int64_t m, const ms_detect_options *opt,
              ms_progress_fn progress, void *progress_ctx, ms_detection **out, char *err, int errlen) {
	*out = nullptr;
	ms_detect_options given;
	if (opt == nullptr) ms_detect_defaults(&given);
	else given = *opt;
	// the scales as ms_parse_scales leaves them: 1 to MS_MAX_SCALES, ascending, >= the minimum
	auto valid = [](const int *scales, int count, int minimum) {
		if (count < 1 || count > MS_MAX_SCALES || scales[0] < minimum) return false;
		for (int s = 1; s < count; ++s)
			if (scales[s] <= scales[s - 1]) return false;
		return true;
	};
	if (given.mode != 0 && given.mode != 1) return fail(MS_EINPUT, "unknown mode", err, errlen);
	if (given.weighting != 0 && given.weighting != 1) return fail(MS_EINPUT, "unknown weighting", err, errlen);
	if (!valid(given.knn_scales, given.n_knn_scales, MS_MIN_KNN_SCALE) ||
	    !valid(given.ring_scales, given.n_ring_scales, MS_MIN_RING_SCALE))
		return fail(MS_EINPUT, "invalid scales", err, errlen);
	if (n < 0 || m < 0 || (faces == nullptr && m > 0) || (xyz == nullptr && n > 0))
		return fail(MS_EINPUT, "negative counts or missing arrays", err, errlen);
	// the largest of the scales used, as the command line words it
	const bool mesh = faces != nullptr && m > 0 && given.as_points == 0;
	const int largest = mesh ? given.ring_scales[given.n_ring_scales - 1] : given.knn_scales[given.n_knn_scales - 1];
	const int most = mesh ? MS_MAX_RING_SCALE : MS_MAX_KNN_SCALE;
	if (largest > most) {
		char message[96];
		std::snprintf(message, sizeof message, "%s must be <= %d, got %d", mesh ? "rings" : "kNN sizes", most, largest);
		return fail(MS_EINPUT, message, err, errlen);
	}
	sharp::Options options;
	options.robust = given.mode == 1;
	options.gaussian = given.weighting == 0;
	options.asPoints = given.as_points != 0;
	options.threads = unsigned(std::max(0, given.threads));
	options.details = given.details != 0;
	options.knnScales.assign(given.knn_scales, given.knn_scales + given.n_knn_scales);
	options.ringScales.assign(given.ring_scales, given.ring_scales + given.n_ring_scales);
	try {
		std::unique_ptr<ms_detection> d(new ms_detection);
		d->result = sharp::detect(xyz, n, faces, faces == nullptr ? 0 : m, options, progress, progress_ctx);
		*out = d.release();
		return MS_OK;
	} catch (const sharp::InputError &e) {
		return fail(MS_EINPUT, e.what(), err, errlen);
	} catch (const std::bad_alloc &) {
		return fail(MS_ENOMEM, "out of memory", err, errlen);
	} catch (const std::exception &e) {
		return fail(MS_EINTERNAL, e.what(), err, errlen);
	}
}

void ms_detection_counts(const ms_detection *d, int64_t *out) {
	const sharp::Result &r = d->result;
	out[MS_COUNT_INPUT] = int64_t(r.strength.size());
	out[MS_COUNT_CLEAN] = r.nClean;
	out[MS_COUNT_FEATURES] = r.nFeatures;
	out[MS_COUNT_SCALES] = int64_t(r.scales.size());
	out[MS_COUNT_MESH] = r.mesh;
	out[MS_COUNT_ALL_FLAT] = r.allFlat;
	out[MS_COUNT_TIMINGS] = int64_t(r.timings.size());
}

void ms_detection_vertices(const ms_detection *d, double *strength, uint8_t *feature, uint8_t *kept) {
	const sharp::Result &r = d->result;
	if (strength != nullptr) std::copy(r.strength.begin(), r.strength.end(), strength);
	if (feature != nullptr) std::copy(r.feature.begin(), r.feature.end(), feature);
	if (kept != nullptr) std::copy(r.kept.begin(), r.kept.end(), kept);
}

void ms_detection_scales(const ms_detection *d, int *scales, double *thresholds, int64_t *candidates) {
	const sharp::Result &r = d->result;
	if (scales != nullptr) std::copy(r.scales.begin(), r.scales.end(), scales);
	if (thresholds != nullptr) std::copy(r.thresholds.begin(), r.thresholds.end(), thresholds);
	if (candidates != nullptr) std::copy(r.candidates.begin(), r.candidates.end(), candidates);
}

void ms_detection_timing(const ms_detection *d, int i, char *name, int cap, double *seconds) {
	const auto &timings = d->result.timings;
	const bool known = i >= 0 && size_t(i) < timings.size();
	fail(MS_OK, known ? timings[size_t(i)].first.c_str() : "", name, cap);
	*seconds = known ? timings[size_t(i)].second : 0.0;
}

int ms_detection_details(const ms_detection *d, double *distances, double *normals) {
	const sharp::Result &r = d->result;
	if (r.distances.empty() && r.normals.empty()) return 0;
	if (distances != nullptr) std::copy(r.distances.begin(), r.distances.end(), distances);
	if (normals != nullptr) std::copy(r.normals.begin(), r.normals.end(), normals);
	return 1;
}

void ms_detection_free(ms_detection *d) { delete d; }

int ms_parse_scales(const char *text, int minimum, int *out, int cap, char *err, int errlen) {
	try {
		const std::vector<int> scales = sharp::parseScales(text, minimum);
		const int count = int(std::min(scales.size(), size_t(std::max(cap, 0))));
		std::copy(scales.begin(), scales.begin() + count, out);
		return count;
	} catch (const sharp::InputError &e) {
		return fail(MS_EINPUT, e.what(), err, errlen);
	} catch (const std::bad_alloc &) {
		return fail(MS_ENOMEM, "out of memory", err, errlen);
	}
}

int ms_format_scales(const int *scales, int count, char *out, int cap) {
	const std::string text = sharp::formatScales(std::vector<int>(scales, scales + std::max(count, 0)));
	fail(MS_OK, text.c_str(), out, cap);
	return int(text.size());
}

}  // extern "C"
