// meshlab-sharp feature curves: a mesh's sharp edges as curves, the chains of the mesh
// edges whose two faces turn by more than the detection's crease threshold, on the
// creases the detection saw, cut where one or three or more chains meet or a chain turns
// (the numpy reference meshlab_sharp/reference/curves/mesh.py, with the same arithmetic;
// see curves.h).
#include "curves.h"

#include "internal.h"
#include "meshlab_sharp.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <utility>

namespace sharp {
namespace {

using Edge = std::array<long, 2>;

const double PI = 3.14159265358979323846;

double radians(double deg) { return deg * (PI / 180.0); }

// np.linalg.norm along an axis of length 3
double length3(const Vec3 &a) { return std::sqrt((a[0] * a[0] + a[1] * a[1]) + a[2] * a[2]); }

// a face's normal as creases.dihedral_angles gives it: the cross product over its length
// (face_cross; false for a face of zero area)
bool faceNormal(const std::vector<Vec3> &pts, const std::array<int, 3> &t, Vec3 &normal)
{
	static_assert(sizeof(Vec3) == 3 * sizeof(double), "the points are rows of 3 doubles");
	double c[3];
	const double length = face_cross(pts.front().data(), t[0], t[1], t[2], c);
	normal = {c[0] / length, c[1] / length, c[2] / length};
	return length > 0;
}

// mesh.py _sharp_edges: the edges (a < b, sorted) whose two faces turn by more than the
// crease angle (faces of zero area left out; the angles creases.dihedral_angles' and
// ms_two_face_edges'), between usable or non-feature vertices, in the parts of their
// graph that hold one between two usable vertices; none where the noise raises the
// crease threshold of all the mesh's two-face edges above the crease angle
std::vector<Edge> sharpEdges(const std::vector<Vec3> &pts, const std::vector<std::array<int, 3>> &faces,
                             const std::vector<char> &mask, const std::vector<char> &usable,
                             const ms_curves_math &math)
{
	const long n = long(pts.size());
	std::vector<long> solid;  // the faces of non-zero area
	std::vector<Vec3> normal;
	for (size_t i = 0; i < faces.size(); ++i) {
		Vec3 u;
		if (faceNormal(pts, faces[i], u)) solid.push_back(long(i)), normal.push_back(u);
	}
	const long m = long(solid.size());
	// per lower end, the other end and the face (in solid) as one key: hi * m + f
	std::vector<long> ptr(n + 2, 0), key(3 * m);
	for (long f = 0; f < m; ++f)
		for (int k = 0; k < 3; ++k) {
			const long a = faces[solid[f]][k], b = faces[solid[f]][(k + 1) % 3];
			++ptr[std::min(a, b) + 2];
		}
	for (long v = 0; v < n; ++v) ptr[v + 2] += ptr[v + 1];
	for (long f = 0; f < m; ++f)
		for (int k = 0; k < 3; ++k) {
			const long a = faces[solid[f]][k], b = faces[solid[f]][(k + 1) % 3];
			key[ptr[std::min(a, b) + 1]++] = std::max(a, b) * m + f;
		}
	auto walksUp = [&](long f, long lo, long hi) {  // the face goes from lo straight to hi
		const std::array<int, 3> &c = faces[solid[f]];
		return corners_walk_up(c[0], c[1], c[2], lo, hi);
	};
	std::vector<Edge> edges;
	std::vector<double> dots;
	for (long v = 0; v < n; ++v) {
		const auto first = key.begin() + ptr[v], last = key.begin() + ptr[v + 1];
		std::sort(first, last);
		for (auto it = first; it != last;) {
			const long hi = *it / m;
			auto next = it + 1;
			while (next != last && *next / m == hi) ++next;
			if (next - it == 2) {
				const long f0 = *it % m, f1 = *(it + 1) % m;
				const double d = edge_dot(normal[f0].data(), normal[f1].data(), walksUp(f0, v, hi) == walksUp(f1, v, hi));
				edges.push_back({v, hi});
				dots.push_back(std::max(-1.0, std::min(1.0, d)));
			}
			it = next;
		}
	}
	if (edges.empty()) return {};
	// the lower quartile of the angles (element (e - 1) / 4 in increasing order): the
	// acos of the dot product as far from the top
	std::vector<double> sorted = dots;
	const size_t top = sorted.size() - 1 - (sorted.size() - 1) / 4;
	std::nth_element(sorted.begin(), sorted.begin() + long(top), sorted.end());
	double quartile = 0.0;
	math.acos(&sorted[top], &quartile, 1);
	// a threshold raised by the noise: the mesh's creases are not to be trusted edge by
	// edge (the skeleton of the features follows them)
	const double threshold = radians(MS_CREASE_ANGLE);
	if (MS_NOISE_FACTOR * quartile > threshold) return {};
	// the angles only of the edges that may turn by more: a dot product above the
	// threshold's cosine by more than acos' rounding turns by less (the bound tunes nothing)
	const double below = std::cos(threshold) + 1e-9;
	auto allowed = [&](long v) { return usable[v] || !mask[v]; };
	std::vector<size_t> which;
	std::vector<double> steep;
	for (size_t i = 0; i < edges.size(); ++i)
		if (dots[i] < below && allowed(edges[i][0]) && allowed(edges[i][1])) which.push_back(i), steep.push_back(dots[i]);
	std::vector<double> angle(steep.size());
	if (!steep.empty()) math.acos(steep.data(), angle.data(), int64_t(steep.size()));
	std::vector<Edge> turned;
	DisjointSets sets(n);
	for (size_t j = 0; j < which.size(); ++j)
		if (angle[j] > threshold) {
			const Edge &e = edges[which[j]];
			turned.push_back(e);
			sets.join(e[0], e[1]);
		}
	std::vector<char> seen(n, 0);
	for (const Edge &e : turned)
		if (usable[e[0]] && usable[e[1]]) seen[sets.root(e[0])] = 1;
	std::vector<Edge> out;
	for (const Edge &e : turned)
		if (seen[sets.root(e[0])]) out.push_back(e);
	return out;
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
	const std::vector<Edge> sharp = sharpEdges(pts, faces, mask, usable, math);
	if (sharp.empty()) return out;
	// the usable vertices joined to a vertex of a sharp edge by edges between usable vertices
	DisjointSets sets(n);
	for (const auto &t : faces)
		for (int k = 0; k < 3; ++k) {
			const long a = t[k], b = t[(k + 1) % 3];
			if (usable[a] && usable[b]) sets.join(a, b);
		}
	std::vector<char> crease(n, 0);
	for (const Edge &e : sharp) crease[sets.root(e[0])] = 1, crease[sets.root(e[1])] = 1;
	for (long v = 0; v < n; ++v)
		if (usable[v] && crease[sets.root(v)]) out.rest[v] = 0;
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
