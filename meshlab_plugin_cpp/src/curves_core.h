// meshlab-sharp: feature curves from a detection (the polylines along the sharp
// features), independent of MeshLab's types. The same steps and the same arithmetic as
// the Python package's meshlab_sharp/curves (extract.py, graph.py, trace.py, refine.py):
// on meshes, chains of the mesh's own sharp edges; on clouds, the skeleton of the
// feature points refined onto the intersection of the surfaces on each side. In double.
#ifndef MESHLAB_SHARP_CURVES_CORE_H
#define MESHLAB_SHARP_CURVES_CORE_H

#include <array>
#include <vector>

namespace sharp {

struct Point { double x, y, z; };

using Vec3 = std::array<double, 3>;

// One feature curve: vertices in order; a loop's last vertex connects to its first
// (which is not repeated).
struct Curve {
	std::vector<Vec3> points;   // clouds: refined positions; meshes: mesh vertices
	std::vector<long> indices;  // the input vertex each vertex came from
	bool closed = false;
	double length = 0.0;        // the closing segment included for loops
};

struct Curves {
	std::vector<Curve> curves;         // ordered by first vertex, last vertex, length
	std::vector<Vec3> corners;         // where curves meet at an angle, in coordinate order
	std::vector<long> cornerIndices;   // the input vertex of each corner
	double spacing = 0.0;              // the spacing the steps are measured in
};

// The feature curves of a detection. vertices: the input, in input order; feature and
// valid: the features and the kept vertices of ms_detect (per vertex); faces: the
// triangles (curves are chains of mesh edges), or empty for a cloud.
Curves extractCurves(const std::vector<Point> &vertices, const std::vector<char> &feature,
                     const std::vector<char> &valid,
                     const std::vector<std::array<int, 3>> &faces);

}  // namespace sharp

#endif
