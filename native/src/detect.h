// The detection sequence of both modes (internal to the native library; its C face is
// ms_detect in native/include/meshlab_sharp.h, detect_api.cpp): the per-point kernels of
// native/src (kd-tree, neighbours, normals, projected distances, local scales, noise and
// isolation statistics, robust mode's support and thinning of the candidates) on every
// core, and the small global steps around them: cleaning map, unit scaling,
// normalisation, Otsu, the multiscale vote, the mesh's sharp edges.
#ifndef MESHLAB_SHARP_DETECT_H
#define MESHLAB_SHARP_DETECT_H

#include "meshlab_sharp.h"

#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace sharp {

struct Options {
	std::vector<int> knnScales MS_DEFAULT_KNN_SCALES;    // point clouds
	std::vector<int> ringScales MS_DEFAULT_RING_SCALES;  // meshes
	bool gaussian = MS_DEFAULT_WEIGHTING == 0;  // Gaussian-weighted PCA normals; false: plain PCA
	bool asPoints = false;                      // ignore the faces
	bool robust = MS_DEFAULT_MODE == 1;  // robust mode (docs/method.md); false: the paper's method
	unsigned threads = 0;                // threads of the run; 0: one per core this process may use
	bool details = false;                // keep the per-scale distances and normals (Result)
};

struct Result {
	bool mesh = false;                 // k-rings (true) or kNN (false)
	std::vector<int> scales;           // the scales used (robust mode grows them on noisy clouds)
	std::vector<double> thresholds;    // T per scale (1.0 on a flat scale)
	std::vector<long> candidates;      // candidates per scale
	std::vector<double> strength;      // per input vertex: fraction of scales
	std::vector<char> feature;         // per input vertex: a sharp feature
	std::vector<char> kept;            // per input vertex: took part (not dropped)
	// With Options::details, per scale and input vertex (NaN where it took no part): the
	// distances Otsu split (normalised, or robust mode's relative ones), (S, n), and the
	// unit normals they were measured along, (S, n, 3); else empty.
	std::vector<double> distances, normals;
	long nClean = 0;
	long nFeatures = 0;
	bool allFlat = false;              // every scale flat: all points on one plane
	std::vector<std::pair<std::string, double>> timings;  // seconds per stage, in order
};

// Bad input: the message is meant for the user.
struct InputError : std::runtime_error {
	explicit InputError(const std::string &what) : std::runtime_error(what) {}
};

// Nothing of the C++ sequence is exported: the library's face is its C ABI.
#pragma GCC visibility push(hidden)

// Detect the sharp features of the n vertices xyz (n, 3) (and the m triangles faces
// (m, 3), unless m is 0 or asPoints), on options.threads threads. progress (may be null)
// is called by the calling thread only, with ctx, percent done and a message such as
// "Sharp features: neighbours and projected distances 45%". Throws InputError on unusable
// input, std::bad_alloc out of memory.
Result detect(const double *xyz, int64_t n, const int64_t *faces, int64_t m, const Options &options,
              ms_progress_fn progress, void *ctx);

// Parse "12 16 20" or "12,16,20" or a range "12:40:4"; throws InputError.
std::vector<int> parseScales(const std::string &text, int minimum);

// The scales as parseScales reads them back: "12 16 20".
std::string formatScales(const std::vector<int> &scales);

#pragma GCC visibility pop

}  // namespace sharp

#endif
