// meshlab-sharp: the projected-distance sharp feature detector (Tran et al. 2014),
// independent of MeshLab's types: the filter glue around meshlab-sharp's native library
// (native/, its ABI and the method's constants in native/include/meshlab_sharp.h). The
// library does the per-point work (kd-tree, neighbours, normals, projected distances,
// local scales, noise and isolation statistics, robust mode's support and thinning of
// the candidates) on every core; this core does the small global steps, as the Python
// package does: cleaning map, normalisation, Otsu, the multiscale vote, the mesh's sharp
// edges.
#ifndef MESHLAB_SHARP_CORE_H
#define MESHLAB_SHARP_CORE_H

#include "meshlab_sharp.h"
#include "curves_types.h"  // Point, shared with the curves

#include <array>
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
};

struct Result {
	bool mesh = false;                 // k-rings (true) or kNN (false)
	std::vector<int> scales;           // the scales used (robust mode grows them on noisy clouds)
	std::vector<double> thresholds;    // T per scale (1.0 on a flat scale)
	std::vector<long> candidates;      // candidates per scale
	std::vector<double> strength;      // per input vertex: fraction of scales
	std::vector<char> feature;         // per input vertex: a sharp feature
	std::vector<char> kept;            // per input vertex: took part (not dropped)
	long nClean = 0;
	long nFeatures = 0;
	bool allFlat = false;              // every scale flat: all points on one plane
	std::vector<std::pair<std::string, double>> timings;  // seconds per stage, in order
};

// Bad input: the message is meant for the user.
struct InputError : std::runtime_error {
	explicit InputError(const std::string &what) : std::runtime_error(what) {}
};

// Progress report, MeshLab's vcg::CallBackPos: percent done and a message such as
// "Sharp features: projected distances 45%". Called by the calling thread only.
using Progress = bool (*)(const int percent, const char *message);

// Detect the sharp features of vertices (and triangles, unless empty or asPoints), on
// every core. Throws InputError on unusable input, std::bad_alloc out of memory.
Result detect(const std::vector<Point> &vertices,
              const std::vector<std::array<int, 3>> &faces,
              const Options &options,
              Progress progress = nullptr);

// Parse "12 16 20" or "12,16,20" or a range "12:40:4"; throws InputError.
std::vector<int> parseScales(const std::string &text, int minimum);

// The scales as parseScales reads them back: "12 16 20".
std::string formatScales(const std::vector<int> &scales);

}  // namespace sharp

#endif
