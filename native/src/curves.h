// meshlab-sharp native library: feature curves from a detection (the polylines along
// the sharp features), independent of MeshLab's types (internal C++ header; the C ABI
// is native/include/meshlab_sharp.h). The same steps and the same arithmetic as
// the Python package's numpy reference, meshlab_sharp/reference/curves (extract.py,
// graph.py, trace.py, refine.py):
// on meshes, chains of the mesh's own sharp edges; on clouds, the skeleton of the
// feature points refined onto the intersection of the surfaces on each side. In double.
#ifndef MESHLAB_SHARP_CURVES_INTERNAL_H
#define MESHLAB_SHARP_CURVES_INTERNAL_H

#include "curves_types.h"
#include "meshlab_sharp.h"

#include <algorithm>
#include <array>
#include <map>
#include <numeric>
#include <vector>

namespace sharp {

using Vec3 = std::array<double, 3>;

// Union-find over 0..n-1 with path halving; a join hangs the larger root under the
// smaller (reference/curves/graph.py DisjointSets)
struct DisjointSets {
	std::vector<long> parent;
	explicit DisjointSets(long n) : parent(n) { std::iota(parent.begin(), parent.end(), 0L); }
	long root(long i)
	{
		while (parent[i] != i) i = parent[i] = parent[parent[i]];
		return i;
	}
	// whether a and b were apart (they are joined now)
	bool join(long a, long b)
	{
		const long ra = root(a), rb = root(b);
		if (ra == rb) return false;
		parent[std::max(ra, rb)] = std::min(ra, rb);
		return true;
	}
	// the members of each set of two or more, ascending, the sets in their roots' order
	// (trace._groups)
	std::vector<std::vector<long>> groups()
	{
		std::map<long, std::vector<long>> byRoot;
		for (long i = 0; i < long(parent.size()); ++i) byRoot[root(i)].push_back(i);
		std::vector<std::vector<long>> out;
		for (auto &g : byRoot)
			if (g.second.size() >= 2) out.push_back(std::move(g.second));
		return out;
	}
};

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
// triangles (curves are chains of mesh edges), or empty for a cloud; bounds: a cloud's
// grid box {lo, hi} when the vertices are only the part of a larger cloud near the
// features (out of core), or null (the vertices' bounding box); math: the elementwise
// exp, acos and atan2 to use, or null (the C library's).
Curves extractCurves(const std::vector<Point> &vertices, const std::vector<char> &feature,
                     const std::vector<char> &valid,
                     const std::vector<std::array<int, 3>> &faces,
                     const std::array<Vec3, 2> *bounds = nullptr,
                     const ms_curves_math *math = nullptr);

// The chains of a mesh's sharp edges (curves_mesh.cpp; reference/curves/mesh.py): the
// edges whose two faces turn by more than the detection's crease threshold, on the creases
// the detection saw (a sharp edge between two usable vertices), cut at their corners.
struct CreaseChains {
	std::vector<std::vector<long>> chains;  // mesh vertices, in the order traced
	std::vector<char> closed;               // per chain: a loop (the first vertex not repeated)
	std::vector<long> corners;              // three or more chains meet, or a chain turns; ascending
	std::vector<char> rest;                 // the feature vertices left to the skeleton
};

// mask: the (valid) feature vertices; usable: those that may be curve vertices (one per
// distinct position); math: acos for the dihedral angles.
CreaseChains creaseChains(const std::vector<Vec3> &pts, const std::vector<std::array<int, 3>> &faces,
                          const std::vector<char> &mask, const std::vector<char> &usable,
                          const ms_curves_math &math);

}  // namespace sharp

#endif
