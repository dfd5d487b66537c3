// A command-line driver of the native library's detection through its C ABI (ms_detect,
// ms_parse_scales), as the MeshLab plugin calls it, without MeshLab
// (tests/test_sharp_core.py builds it with gcc and g++ from native/src alone):
//   sharp_core_driver IN OUT MODE KNN_SCALES RING_SCALES WEIGHTING AS_POINTS
// IN: int64 n, int64 m, n x 3 float64 vertices, m x 3 int32 faces (little endian).
// OUT: n float64 strengths, then n uint8 features. MODE "paper" or "robust", WEIGHTING
// "gaussian" or "none", AS_POINTS 0 or 1. stdout: the scales, thresholds (%.17g),
// candidate counts and the progress callback's calls; bad input: "error: ..." on stderr,
// status 2.
#include "meshlab_sharp.h"

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <vector>

namespace {
int record(const int percent, const char *message, void *ctx) {
	if (std::strncmp(message, "Sharp features: ", 16) != 0) std::abort();
	static_cast<std::vector<int> *>(ctx)->push_back(percent);
	return 0;
}
}  // namespace

int main(int argc, char **argv) {
	if (argc != 8) {
		std::cerr << "usage: sharp_core_driver IN OUT MODE KNN_SCALES RING_SCALES WEIGHTING AS_POINTS\n";
		return 1;
	}
	std::ifstream in(argv[1], std::ios::binary);
	int64_t n = 0, m = 0;
	in.read(reinterpret_cast<char *>(&n), 8);
	in.read(reinterpret_cast<char *>(&m), 8);
	std::vector<double> vertices(3 * n);
	in.read(reinterpret_cast<char *>(vertices.data()), std::streamsize(24 * n));
	std::vector<int32_t> faces32(3 * m);
	in.read(reinterpret_cast<char *>(faces32.data()), std::streamsize(12 * m));
	if (!in) {
		std::cerr << "error: short input file\n";
		return 1;
	}
	const std::vector<int64_t> faces(faces32.begin(), faces32.end());
	ms_detect_options options;
	ms_detect_defaults(&options);
	options.mode = std::strcmp(argv[3], "robust") == 0 ? 1 : 0;
	options.weighting = std::strcmp(argv[6], "gaussian") == 0 ? 0 : 1;
	options.as_points = std::strcmp(argv[7], "1") == 0;
	char error[512];
	options.n_knn_scales = ms_parse_scales(argv[4], MS_MIN_KNN_SCALE, options.knn_scales, MS_MAX_SCALES, error, 512);
	if (options.n_knn_scales >= 0)
		options.n_ring_scales =
		    ms_parse_scales(argv[5], MS_MIN_RING_SCALE, options.ring_scales, MS_MAX_SCALES, error, 512);
	std::vector<int> percents;
	ms_detection *d = nullptr;
	if (options.n_knn_scales < 0 || options.n_ring_scales < 0 ||
	    ms_detect(vertices.data(), n, faces.data(), m, &options, record, &percents, &d, error, 512) != MS_OK) {
		std::cerr << "error: " << error << "\n";
		return 2;
	}
	int64_t counts[MS_DETECTION_COUNTS];
	ms_detection_counts(d, counts);
	std::vector<double> strength(n), thresholds(counts[MS_COUNT_SCALES]);
	std::vector<uint8_t> feature(n);
	std::vector<int> scales(counts[MS_COUNT_SCALES]);
	std::vector<int64_t> candidates(counts[MS_COUNT_SCALES]);
	ms_detection_vertices(d, strength.data(), feature.data(), nullptr);
	ms_detection_scales(d, scales.data(), thresholds.data(), candidates.data());
	ms_detection_free(d);
	std::ofstream out(argv[2], std::ios::binary);
	out.write(reinterpret_cast<const char *>(strength.data()), std::streamsize(8 * n));
	out.write(reinterpret_cast<const char *>(feature.data()), std::streamsize(n));
	std::printf("mesh %d\nscales", int(counts[MS_COUNT_MESH]));
	for (int s : scales) std::printf(" %d", s);
	std::printf("\nthresholds");
	for (double t : thresholds) std::printf(" %.17g", t);
	std::printf("\ncandidates");
	for (int64_t c : candidates) std::printf(" %lld", static_cast<long long>(c));
	std::printf("\nprogress");
	for (int p : percents) std::printf(" %d", p);
	std::printf("\n");
	return 0;
}
