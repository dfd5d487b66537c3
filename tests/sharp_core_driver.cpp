// A command-line driver of the plugin's core without MeshLab (tests/test_sharp_core.py
// builds it with gcc and g++ from meshlab_plugin_cpp/src/sharp_core.cpp and the native
// library native/src/*.c alone):
//   sharp_core_driver IN OUT MODE KNN_SCALES RING_SCALES WEIGHTING AS_POINTS
// IN: int64 n, int64 m, n x 3 float64 vertices, m x 3 int32 faces (little endian).
// OUT: n float64 strengths, then n uint8 features. MODE "paper" or "robust", WEIGHTING
// "gaussian" or "none", AS_POINTS 0 or 1. stdout: the scales, thresholds (%.17g),
// candidate counts and the progress callback's calls; bad input: "error: ..." on stderr,
// status 2.
#include "sharp_core.h"

#include <cstdio>
#include <cstring>
#include <fstream>
#include <iostream>

namespace {
std::vector<int> percents;

bool record(const int percent, const char *message) {
	if (std::strncmp(message, "Sharp features: ", 16) != 0) std::abort();
	percents.push_back(percent);
	return true;
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
	std::vector<sharp::Point> vertices(n);
	in.read(reinterpret_cast<char *>(vertices.data()), std::streamsize(24 * n));
	std::vector<std::array<int, 3>> faces(m);
	in.read(reinterpret_cast<char *>(faces.data()), std::streamsize(12 * m));
	if (!in) {
		std::cerr << "error: short input file\n";
		return 1;
	}
	sharp::Options options;
	options.robust = std::strcmp(argv[3], "robust") == 0;
	options.gaussian = std::strcmp(argv[6], "gaussian") == 0;
	options.asPoints = std::strcmp(argv[7], "1") == 0;
	sharp::Result r;
	try {
		options.knnScales = sharp::parseScales(argv[4], MS_MIN_KNN_SCALE);
		options.ringScales = sharp::parseScales(argv[5], MS_MIN_RING_SCALE);
		r = sharp::detect(vertices, faces, options, record);
	} catch (const sharp::InputError &e) {
		std::cerr << "error: " << e.what() << "\n";
		return 2;
	}
	std::ofstream out(argv[2], std::ios::binary);
	out.write(reinterpret_cast<const char *>(r.strength.data()), std::streamsize(8 * n));
	out.write(reinterpret_cast<const char *>(r.feature.data()), std::streamsize(n));
	std::printf("mesh %d\nscales", int(r.mesh));
	for (int s : r.scales) std::printf(" %d", s);
	std::printf("\nthresholds");
	for (double t : r.thresholds) std::printf(" %.17g", t);
	std::printf("\ncandidates");
	for (long c : r.candidates) std::printf(" %ld", c);
	std::printf("\nprogress");
	for (int p : percents) std::printf(" %d", p);
	std::printf("\n");
	return 0;
}
