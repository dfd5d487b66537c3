// meshlab-sharp feature curves: a mesh's sharp edges as curves, the chains of the mesh
// edges between feature vertices whose two faces turn by more than the detection's crease
// threshold, cut where three or more chains meet or a chain turns (the numpy reference
// meshlab_sharp/reference/curves/mesh.py, with the same arithmetic; see curves.h).
#include "curves.h"

#include "meshlab_sharp.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <set>
#include <utility>

namespace sharp {
namespace {

using Edge = std::array<long, 2>;

const double PI = 3.14159265358979323846;

double radians(double deg) { return deg * (PI / 180.0); }

// np.linalg.norm along an axis of length 3
double length3(const Vec3 &a) { return std::sqrt((a[0] * a[0] + a[1] * a[1]) + a[2] * a[2]); }

// the unit normal of each face as np.cross and np.linalg.norm give it (zero for a face of
// zero area), and whether the face has an area
void faceNormals(const std::vector<Vec3> &pts, const std::vector<std::array<int, 3>> &faces,
                 std::vector<Vec3> &normal, std::vector<char> &solid)
{
	normal.resize(faces.size());
	solid.resize(faces.size());
	for (size_t i = 0; i < faces.size(); ++i) {
		const Vec3 &p0 = pts[faces[i][0]], &p1 = pts[faces[i][1]], &p2 = pts[faces[i][2]];
		const Vec3 a{p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]};
		const Vec3 b{p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]};
		const Vec3 c{a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
		const double nrm = length3(c);
		solid[i] = nrm > 0;
		const double d = nrm > 0 ? nrm : 1.0;
		normal[i] = {c[0] / d, c[1] / d, c[2] / d};
	}
}

// mesh.py _sharp_edges: the edges (a < b, sorted) between usable vertices whose two faces
// turn by more than the crease threshold of all the mesh's two-face edges
std::vector<Edge> sharpEdges(const std::vector<Vec3> &pts, const std::vector<std::array<int, 3>> &faces,
                             const std::vector<char> &usable, const ms_curves_math &math)
{
	std::vector<Vec3> normal;
	std::vector<char> solid;
	faceNormals(pts, faces, normal, solid);
	struct Side { Edge e; long face; bool up; };
	std::vector<Side> sides;
	sides.reserve(3 * faces.size());
	for (size_t i = 0; i < faces.size(); ++i)
		for (int k = 0; k < 3; ++k) {
			const long a = faces[i][k], b = faces[i][(k + 1) % 3];
			sides.push_back({{std::min(a, b), std::max(a, b)}, long(i), a < b});
		}
	std::sort(sides.begin(), sides.end(), [](const Side &x, const Side &y) {
		return x.e != y.e ? x.e < y.e : x.face < y.face;
	});
	std::vector<Edge> edges;
	std::vector<double> dots;
	for (size_t s = 0; s < sides.size();) {
		size_t t = s + 1;
		while (t < sides.size() && sides[t].e == sides[s].e) ++t;
		const long f0 = sides[s].face, f1 = t - s == 2 ? sides[s + 1].face : -1;
		if (f1 >= 0 && solid[f0] && solid[f1]) {
			const Vec3 &u = normal[f0], &v = normal[f1];
			double dot = (u[0] * v[0] + u[2] * v[2]) + u[1] * v[1];  // np.einsum's order
			if (sides[s].up == sides[s + 1].up) dot = -dot;  // one face wound the other way round
			edges.push_back(sides[s].e);
			dots.push_back(std::max(-1.0, std::min(1.0, dot)));
		}
		s = t;
	}
	if (edges.empty()) return {};
	std::vector<double> angle(dots.size());
	math.acos(dots.data(), angle.data(), int64_t(dots.size()));
	std::vector<double> sorted = angle;
	const size_t at = (sorted.size() - 1) / 4;
	std::nth_element(sorted.begin(), sorted.begin() + long(at), sorted.end());
	const double threshold = std::max(radians(MS_CREASE_ANGLE), MS_NOISE_FACTOR * sorted[at]);
	std::vector<Edge> out;
	for (size_t i = 0; i < edges.size(); ++i)
		if (angle[i] > threshold && usable[edges[i][0]] && usable[edges[i][1]]) out.push_back(edges[i]);
	return out;
}

long findRoot(std::vector<long> &parent, long v)
{
	while (parent[v] != v) v = parent[v] = parent[parent[v]];
	return v;
}

// mesh.py _turns: whether a-b-c turns at b by more than the angle of cosTurn
bool turns(const Vec3 &a, const Vec3 &b, const Vec3 &c, double cosTurn)
{
	const Vec3 u{b[0] - a[0], b[1] - a[1], b[2] - a[2]};
	const Vec3 w{c[0] - b[0], c[1] - b[1], c[2] - b[2]};
	const double dot = (u[0] * w[0] + u[1] * w[1]) + u[2] * w[2];
	return dot < cosTurn * (length3(u) * length3(w));
}

}  // namespace

CreaseChains creaseChains(const std::vector<Vec3> &pts, const std::vector<std::array<int, 3>> &faces,
                          const std::vector<char> &mask, const std::vector<char> &usable,
                          const ms_curves_math &math)
{
	CreaseChains out;
	const long n = long(pts.size());
	out.rest = mask;
	const std::vector<Edge> sharp = sharpEdges(pts, faces, usable, math);
	if (sharp.empty()) return out;
	// the feature vertices joined to a sharp edge by edges between usable vertices
	std::vector<long> parent(n);
	std::iota(parent.begin(), parent.end(), 0L);
	for (const auto &t : faces)
		for (int k = 0; k < 3; ++k) {
			const long a = t[k], b = t[(k + 1) % 3];
			if (usable[a] && usable[b]) parent[findRoot(parent, a)] = findRoot(parent, b);
		}
	std::vector<char> crease(n, 0);
	for (const Edge &e : sharp) crease[findRoot(parent, e[0])] = 1;
	for (long v = 0; v < n; ++v)
		if (usable[v] && crease[findRoot(parent, v)]) out.rest[v] = 0;
	std::map<long, std::vector<long>> nbrs;
	for (const Edge &e : sharp) nbrs[e[0]].push_back(e[1]), nbrs[e[1]].push_back(e[0]);
	for (auto &kv : nbrs) std::sort(kv.second.begin(), kv.second.end());
	const double cosTurn = std::cos(radians(MS_CURVE_CORNER_TURN));
	std::set<long> cuts;
	for (const auto &kv : nbrs) {
		const long v = kv.first;
		const std::vector<long> &around = kv.second;
		if (around.size() != 2) {
			cuts.insert(v);
			if (around.size() >= 3) out.corners.push_back(v);
		} else if (turns(pts[around[0]], pts[v], pts[around[1]], cosTurn)) {
			cuts.insert(v);
			out.corners.push_back(v);
		}
	}
	std::set<Edge> used;
	auto key = [](long a, long b) { return Edge{std::min(a, b), std::max(a, b)}; };
	auto walk = [&](long start, long next) {
		std::vector<long> path{start};
		long prev = start, here = next;
		used.insert(key(start, next));
		while (!cuts.count(here) && here != start) {
			path.push_back(here);
			const std::vector<long> &around = nbrs[here];
			const long step = around[0] != prev ? around[0] : around[1];
			used.insert(key(here, step));
			prev = here, here = step;
		}
		path.push_back(here);
		return path;
	};
	for (long v : cuts)
		for (long w : nbrs[v])
			if (!used.count(key(v, w))) out.chains.push_back(walk(v, w)), out.closed.push_back(0);
	for (const auto &kv : nbrs) {  // loops without a cut
		const long v = kv.first, w = kv.second[0];
		if (used.count(key(v, w))) continue;
		std::vector<long> path = walk(v, w);
		path.pop_back();
		out.chains.push_back(path);
		out.closed.push_back(1);
	}
	return out;
}

}  // namespace sharp
