// meshlab-sharp: the projected-distance sharp feature detector (Tran et al. 2014),
// independent of MeshLab's types. It follows ../shared/ALGORITHM.md and the arithmetic
// pinned down in docs/implementation-notes.md and docs/robust-mode.md, as the Python
// package does, in double.
#ifndef MESHLAB_SHARP_CORE_H
#define MESHLAB_SHARP_CORE_H

#include <array>
#include <stdexcept>
#include <string>
#include <vector>

namespace sharp {

struct Point { double x, y, z; };

struct Options {
	std::vector<int> knnScales{12, 16, 20, 24, 28, 32, 36, 40};  // point clouds
	std::vector<int> ringScales{1, 2, 3, 4};                       // meshes
	bool gaussian = true;   // Gaussian-weighted PCA normals; false: plain PCA
	bool asPoints = false;  // ignore the faces
	bool robust = false;    // robust mode (docs/robust-mode.md); false: the paper's method
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
};

// Bad input: the message is meant for the user.
struct InputError : std::runtime_error {
	explicit InputError(const std::string &what) : std::runtime_error(what) {}
};

// Detect the sharp features of vertices (and triangles, unless empty or asPoints).
// Throws InputError on unusable input; never aborts.
Result detect(const std::vector<Point> &vertices,
              const std::vector<std::array<int, 3>> &faces,
              const Options &options,
              bool (*progress)(const int percent, const char *stage) = nullptr);

// Parse "12 16 20" or "12,16,20" or a range "12:40:4"; throws InputError.
std::vector<int> parseScales(const std::string &text, int minimum);

}  // namespace sharp

#endif
