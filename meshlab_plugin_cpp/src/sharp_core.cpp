// See sharp_core.h. Every step mirrors a module of the Python package:
// cleaning.py, neighbourhoods.py, normals.py, projected_distance.py, threshold.py,
// multiscale.py; robust mode robust.py and creases.py. docs/implementation-notes.md and
// docs/robust-mode.md ("The arithmetic, pinned down for the plugin") are the contract.
#include "sharp_core.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <sstream>

#include <Eigen/Dense>
#include <vcg/space/index/kdtree/kdtree.h>

namespace sharp {
namespace {

// Every constant of the Python package the plugin uses, named once.
const int BINS = 256;                      // threshold.BINS
const double FLAT_TOLERANCE = 1e-6;        // threshold.FLAT_TOLERANCE
const double ZERO_NORMAL = 1e-12;          // normals.ZERO_NORMAL
// robust.R_MIN: r on a straight edge turning by CREASE_ANGLE, (2 / pi) sin(10 deg).
const double R_MIN = 0.11054786333836651;
const double CREASE_ANGLE = 20.0;          // creases.CREASE_ANGLE (degrees)
const double NOISE_FACTOR = 4.0 / 0.3186;  // creases.NOISE_FACTOR (lower quartiles)
const int NOISE_KNN = 7;                   // robust.NOISE_KNN
const double NOISE_TOLERATED = 0.15;       // robust.NOISE_TOLERATED
const double NOISE_MAX_FACTOR = 3.0;       // robust.NOISE_MAX_FACTOR
const double THIN_CONE_COS = 0.5;          // robust.THIN_CONE_COS (60 degrees)
const int THIN_KNN = 12;                   // robust.THIN_KNN
const int THIN_RING = 2;                   // robust.THIN_RING
const int SUPPORT_KNN = 16;                // robust.SUPPORT_KNN
const int SUPPORT_MIN = 2;                 // robust.SUPPORT_MIN
const long PAIRWISE_BLOCK = 128;           // numpy's PW_BLOCKSIZE (pairwise summation)

inline double sq(const Point &a, const Point &c) {
	const double dx = a.x - c.x, dy = a.y - c.y, dz = a.z - c.z;
	return dx * dx + dy * dy + dz * dz;
}

// Multiply every coordinate by one power of two, 2^-e with 2^(e-1) <= max |coordinate| < 2^e,
// so that the largest is in [0.5, 1). Exact in binary floating point: every distance ratio,
// normal, threshold and selection is what it was, but squared distances can no longer
// overflow or underflow, whatever the unit (1e-100 or 1e100), here nor in vcg's kd-tree,
// which compares squared offsets in float.
void scaleToUnit(std::vector<Point> &pts) {
	double big = 0.0;
	for (const Point &p : pts) big = std::max({big, std::fabs(p.x), std::fabs(p.y), std::fabs(p.z)});
	if (big == 0.0) return;
	int e = 0;
	std::frexp(big, &e);
	for (Point &p : pts) {
		p.x = std::ldexp(p.x, -e);
		p.y = std::ldexp(p.y, -e);
		p.z = std::ldexp(p.z, -e);
	}
}

struct Clean {
	std::vector<Point> pts;                   // cleaned vertices, input order
	std::vector<std::array<int, 3>> faces;    // cleaned triangles
	std::vector<long> fromInput;              // cleaned index of each input vertex or -1
};

// Exact duplicates merged into their first occurrence; for meshes, zero-area faces
// and then unreferenced vertices dropped (cleaning.py).
Clean clean(const std::vector<Point> &v, const std::vector<std::array<int, 3>> &faces, bool mesh) {
	const long n = long(v.size());
	std::vector<long> order(n);
	std::iota(order.begin(), order.end(), 0L);
	std::stable_sort(order.begin(), order.end(), [&](long a, long b) {
		if (v[a].x != v[b].x) return v[a].x < v[b].x;
		if (v[a].y != v[b].y) return v[a].y < v[b].y;
		return v[a].z < v[b].z;
	});
	std::vector<long> survivor(n);
	for (long i = 0; i < n;) {
		long j = i;
		while (j < n && v[order[j]].x == v[order[i]].x && v[order[j]].y == v[order[i]].y &&
		       v[order[j]].z == v[order[i]].z)
			++j;
		for (long t = i; t < j; ++t) survivor[order[t]] = order[i];  // stable: first occurrence
		i = j;
	}
	std::vector<char> used(n, mesh ? 0 : 1);
	std::vector<std::array<int, 3>> kept;
	if (mesh) {
		for (const auto &f : faces) {
			std::array<int, 3> g{int(survivor[f[0]]), int(survivor[f[1]]), int(survivor[f[2]])};
			const Point &p0 = v[g[0]], &p1 = v[g[1]], &p2 = v[g[2]];
			const double ax = p1.x - p0.x, ay = p1.y - p0.y, az = p1.z - p0.z;
			const double bx = p2.x - p0.x, by = p2.y - p0.y, bz = p2.z - p0.z;
			const double cx = ay * bz - az * by, cy = az * bx - ax * bz, cz = ax * by - ay * bx;
			if (cx == 0.0 && cy == 0.0 && cz == 0.0) continue;  // zero area
			kept.push_back(g);
			used[g[0]] = used[g[1]] = used[g[2]] = 1;
		}
	}
	Clean c;
	std::vector<long> index(n, -1);
	for (long i = 0; i < n; ++i)
		if (survivor[i] == i && used[i]) {
			index[i] = long(c.pts.size());
			c.pts.push_back(v[i]);
		}
	c.fromInput.resize(n);
	for (long i = 0; i < n; ++i) c.fromInput[i] = index[survivor[i]];
	for (auto &f : kept) c.faces.push_back({int(index[f[0]]), int(index[f[1]]), int(index[f[2]])});
	return c;
}

// Weighted PCA normal of the offsets q (neighbour minus centre point) with mean m.
Eigen::Vector3d pcaNormal(const std::vector<Point> &q, const Point &m, bool gaussian) {
	double h2 = 0.0;
	if (gaussian)
		for (const Point &o : q) h2 = std::max(h2, o.x * o.x + o.y * o.y + o.z * o.z);
	Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
	for (const Point &o : q) {
		const double d2 = o.x * o.x + o.y * o.y + o.z * o.z;
		const double mu = (gaussian && h2 > 0.0) ? std::exp(-d2 / h2) : 1.0;
		const double r[3] = {o.x - m.x, o.y - m.y, o.z - m.z};
		for (int a = 0; a < 3; ++a)
			for (int b = a; b < 3; ++b) cov(a, b) += mu * r[a] * r[b];
	}
	for (int a = 0; a < 3; ++a)
		for (int b = 0; b < a; ++b) cov(a, b) = cov(b, a);
	Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(cov);
	return solver.eigenvectors().col(0);  // eigenvalues ascending
}

// pdis = |mean . n| for the neighbourhood nb of point i (projected_distance.py).
double projectedDistance(const std::vector<Point> &pts, long i, const std::vector<long> &nb,
                         const Eigen::Vector3d *fixedNormal, bool gaussian,
                         std::vector<Point> &scratch) {
	scratch.resize(nb.size());
	Point m{0.0, 0.0, 0.0};
	for (size_t j = 0; j < nb.size(); ++j) {
		const Point &p = pts[nb[j]];
		scratch[j] = {p.x - pts[i].x, p.y - pts[i].y, p.z - pts[i].z};
		m.x += scratch[j].x;
		m.y += scratch[j].y;
		m.z += scratch[j].z;
	}
	const double s = double(nb.size());
	m.x /= s;
	m.y /= s;
	m.z /= s;
	const Eigen::Vector3d n = fixedNormal ? *fixedNormal : pcaNormal(scratch, m, gaussian);
	return std::fabs(m.x * n[0] + m.y * n[1] + m.z * n[2]);
}

// Otsu's split in the integer form of docs/implementation-notes.md: T = t / 256.
double otsu(const std::vector<double> &v) {
	std::vector<long long> count(BINS, 0);
	for (double x : v) count[std::min(int(std::floor(x * BINS)), BINS - 1)]++;
	long long total = 0, weightedTotal = 0;
	for (int b = 0; b < BINS; ++b) {
		total += count[b];
		weightedTotal += count[b] * (2LL * b + 1);
	}
	long long n0 = 0, s0 = 0;
	double best = -1.0;
	int bestT = -1;
	for (int t = 1; t < BINS; ++t) {
		n0 += count[t - 1];
		s0 += count[t - 1] * (2LL * (t - 1) + 1);
		const long long n1 = total - n0;
		if (n0 == 0 || n1 == 0) continue;
		const double dn0 = double(n0), dn1 = double(n1);
		const double ds0 = double(s0), ds1 = double(weightedTotal) - ds0;
		const double diff = ds0 * dn1 - ds1 * dn0;
		const double crit = diff * diff / (dn0 * dn1);
		if (crit > best) {
			best = crit;
			bestT = t;
		}
	}
	return bestT < 0 ? 1.0 : double(bestT) / BINS;
}

// kNN of every point in the exact (squared distance, index) order, k = kMax.
std::vector<std::vector<long>> knn(const std::vector<Point> &pts, int kMax,
                                   bool (*progress)(const int, const char *)) {
	const long n = long(pts.size());
	std::vector<vcg::Point3d> vp(n);
	for (long i = 0; i < n; ++i) vp[i] = vcg::Point3d(pts[i].x, pts[i].y, pts[i].z);
	vcg::ConstDataWrapper<vcg::Point3d> wrapper(&vp[0], n, sizeof(vcg::Point3d));
	vcg::KdTree<double> tree(wrapper);
	vcg::KdTree<double>::PriorityQueue queue;
	std::vector<std::vector<long>> out(n);
	std::vector<std::pair<double, long>> cand;
	for (long i = 0; i < n; ++i) {
		if (progress && i % 20000 == 0) progress(int(40 * i / n), "Sharp features: neighbours");
		long kq = std::min<long>(kMax + 1, n);
		while (true) {
			tree.doQueryK(vp[i], int(kq), queue);
			cand.clear();
			for (int j = 0; j < queue.getNofElements(); ++j) {
				const long idx = queue.getIndex(j);
				cand.emplace_back(sq(pts[idx], pts[i]), idx);
			}
			std::sort(cand.begin(), cand.end());
			// A tie across the k-th place may involve points the query left out: widen.
			if (kq == n || long(cand.size()) <= kMax || cand[kMax].first > cand[kMax - 1].first)
				break;
			kq = std::min(2 * kq + 1, n);
		}
		out[i].resize(kMax);
		for (int j = 0; j < kMax; ++j) out[i][j] = cand[j].second;
	}
	return out;
}

std::vector<std::vector<long>> oneRing(long n, const std::vector<std::array<int, 3>> &faces) {
	std::vector<std::vector<long>> adj(n);
	for (const auto &f : faces)
		for (int a = 0; a < 3; ++a)
			for (int b = 0; b < 3; ++b)
				if (a != b) adj[f[a]].push_back(f[b]);
	for (auto &l : adj) {
		std::sort(l.begin(), l.end());
		l.erase(std::unique(l.begin(), l.end()), l.end());
	}
	return adj;
}

std::vector<Eigen::Vector3d> faceAverageNormals(const std::vector<Point> &pts,
                                                const std::vector<std::array<int, 3>> &faces,
                                                std::vector<char> &valid) {
	std::vector<Eigen::Vector3d> acc(pts.size(), Eigen::Vector3d::Zero());
	for (const auto &f : faces) {
		const Point &p0 = pts[f[0]], &p1 = pts[f[1]], &p2 = pts[f[2]];
		const double ax = p1.x - p0.x, ay = p1.y - p0.y, az = p1.z - p0.z;
		const double bx = p2.x - p0.x, by = p2.y - p0.y, bz = p2.z - p0.z;
		Eigen::Vector3d c(ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx);
		const double len = std::sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
		if (len > 0.0) c /= len;
		for (int a = 0; a < 3; ++a) acc[f[a]] += c;
	}
	valid.assign(pts.size(), 0);
	for (size_t i = 0; i < acc.size(); ++i) {
		const Eigen::Vector3d &s = acc[i];
		const double norm = std::sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]);
		if (norm > ZERO_NORMAL) {
			acc[i] = s / norm;
			valid[i] = 1;
		}
	}
	return acc;
}

}  // namespace

std::vector<int> parseScales(const std::string &text, int minimum) {
	std::string t = text;
	for (char &ch : t)
		if (ch == ',' || ch == ';') ch = ' ';
	std::vector<int> out;
	if (t.find(':') != std::string::npos) {
		for (char &ch : t)
			if (ch == ':') ch = ' ';
		std::istringstream in(t);
		int a = 0, b = 0, step = 1;
		if (!(in >> a >> b)) throw InputError("invalid scales '" + text + "': use 12 16 20 or 12:40:4");
		if (!(in >> step)) step = 1;
		if (step <= 0) throw InputError("invalid scales '" + text + "': the step must be positive");
		for (int s = a; s <= b; s += step) out.push_back(s);
	} else {
		std::istringstream in(t);
		std::string token;
		while (in >> token) {
			size_t used = 0;
			int s = 0;
			try {
				s = std::stoi(token, &used);
			} catch (const std::exception &) {
				used = 0;
			}
			if (used != token.size()) throw InputError("invalid scales '" + text + "': use 12 16 20 or 12:40:4");
			out.push_back(s);
		}
	}
	std::sort(out.begin(), out.end());
	out.erase(std::unique(out.begin(), out.end()), out.end());
	if (out.empty()) throw InputError("at least one scale is needed");
	if (out.front() < minimum)
		throw InputError("scales must be >= " + std::to_string(minimum) + ", got " + std::to_string(out.front()));
	return out;
}

namespace {

// ---- Robust mode (robust.py, creases.py) ----

// numpy's pairwise summation of a[0..n) (8 accumulators, blocks of PAIRWISE_BLOCK).
double pairwiseSum(const double *a, long n) {
	if (n < 8) {
		double res = -0.0;
		for (long i = 0; i < n; ++i) res += a[i];
		return res;
	}
	if (n <= PAIRWISE_BLOCK) {
		double acc[8];
		for (int j = 0; j < 8; ++j) acc[j] = a[j];
		long i = 8;
		for (; i < n - (n % 8); i += 8)
			for (int j = 0; j < 8; ++j) acc[j] += a[i + j];
		double res = ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
		for (; i < n; ++i) res += a[i];
		return res;
	}
	long n2 = n / 2;
	n2 -= n2 % 8;
	return pairwiseSum(a, n2) + pairwiseSum(a + n2, n - n2);
}

// One segment of np.add.reduceat (robust._segment_sums): the first element plus the
// pairwise sum of the others. Bit for bit what the Python package computes.
double segmentSum(const std::vector<double> &a) {
	if (a.empty()) return 0.0;
	return a[0] + pairwiseSum(a.data() + 1, long(a.size()) - 1);
}

// Scratch columns for segment sums.
struct Columns {
	std::vector<double> c[9];
	void clear() {
		for (auto &v : c) v.clear();
	}
};

// robust.local_scale for the list nb of point i: l = mean |p_j - p_i|, o = |mean of
// p_j - p_i|.
void localScale(const std::vector<Point> &pts, long i, const std::vector<long> &nb, Columns &col,
                double &l, double &o) {
	col.clear();
	for (long j : nb) {
		const double qx = pts[j].x - pts[i].x, qy = pts[j].y - pts[i].y, qz = pts[j].z - pts[i].z;
		col.c[0].push_back(std::sqrt(qx * qx + qy * qy + qz * qz));
		col.c[1].push_back(qx);
		col.c[2].push_back(qy);
		col.c[3].push_back(qz);
	}
	const double count = double(std::max<size_t>(nb.size(), 1));
	l = nb.empty() ? 0.0 : segmentSum(col.c[0]) / count;
	const double cx = segmentSum(col.c[1]) / count, cy = segmentSum(col.c[2]) / count,
	             cz = segmentSum(col.c[3]) / count;
	o = std::sqrt(cx * cx + cy * cy + cz * cz);
}

// robust.relative_distances: min(x / l, 1), 0 where l is 0.
inline double relative(double x, double l) { return l > 0.0 ? std::min(x / l, 1.0) : 0.0; }

// robust.line_directions for a feature point i: the unit eigenvector of the largest
// eigenvalue of the covariance of p_j - p_i over the features j of D (i included).
Eigen::Vector3d lineDirection(const std::vector<Point> &pts, long i, const std::vector<long> &D,
                              const std::vector<char> &feature, Columns &col) {
	col.clear();
	for (long j : D) {
		if (!feature[j]) continue;
		const double q[3] = {pts[j].x - pts[i].x, pts[j].y - pts[i].y, pts[j].z - pts[i].z};
		for (int a = 0; a < 3; ++a) {
			col.c[a].push_back(q[a]);
			for (int b = 0; b <= a; ++b) col.c[3 + a * (a + 1) / 2 + b].push_back(q[a] * q[b]);
		}
	}
	const double count = double(std::max<size_t>(col.c[0].size(), 1));
	double qbar[3];
	for (int a = 0; a < 3; ++a) qbar[a] = segmentSum(col.c[a]) / count;
	Eigen::Matrix3d cov;
	for (int a = 0; a < 3; ++a)
		for (int b = 0; b <= a; ++b) {  // the lower triangle, as numpy's eigh reads it
			cov(a, b) = segmentSum(col.c[3 + a * (a + 1) / 2 + b]) - count * qbar[a] * qbar[b];
			cov(b, a) = cov(a, b);
		}
	Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(cov);
	return solver.eigenvectors().col(2);  // eigenvalues ascending
}

// Whether d = p_j - p_i lies across the line through i: |d . e| < THIN_CONE_COS |d|.
inline bool across(const Point &pi, const Point &pj, const Eigen::Vector3d &e) {
	const double dx = pj.x - pi.x, dy = pj.y - pi.y, dz = pj.z - pi.z;
	return std::fabs(dx * e[0] + dy * e[1] + dz * e[2]) < THIN_CONE_COS * std::sqrt(dx * dx + dy * dy + dz * dz);
}

// robust.supported then robust.thin, with the line directions of F0 computed once:
// F1 = features with at least SUPPORT_MIN other features along their line in S(i);
// F2 = F1 less the points beaten, across the line, by a higher score in K(i).
std::vector<char> supportAndThin(const std::vector<Point> &pts, const std::vector<char> &f0,
                                 const std::vector<double> &score,
                                 const std::vector<std::vector<long>> &D,
                                 const std::vector<std::vector<long>> &S,
                                 const std::vector<std::vector<long>> &K) {
	const long n = long(pts.size());
	std::vector<Eigen::Vector3d> e(n, Eigen::Vector3d::Zero());
	std::vector<char> f1(n, 0);
	Columns col;
	for (long i = 0; i < n; ++i) {
		if (!f0[i]) continue;
		e[i] = lineDirection(pts, i, D[i], f0, col);
		int along = 0;
		for (long j : S[i])
			if (j != i && f0[j] && !across(pts[i], pts[j], e[i])) ++along;
		f1[i] = along >= SUPPORT_MIN;
	}
	std::vector<char> f2 = f1;
	for (long i = 0; i < n; ++i) {
		if (!f1[i]) continue;
		for (long j : K[i])
			if (j != i && f1[j] && across(pts[i], pts[j], e[i]) && score[j] > score[i]) {
				f2[i] = 0;
				break;
			}
	}
	return f2;
}

// robust.noise_scale_factor: min(max(1, (nu / NOISE_TOLERATED)^2), NOISE_MAX_FACTOR), nu
// the lower median of |d . n| / |d|, n the plain PCA normal of the k nearest, d the
// offset of the nearest.
double noiseScaleFactor(const std::vector<Point> &pts, const std::vector<std::vector<long>> &hoods, int k) {
	const long n = long(pts.size());
	std::vector<double> ratio(n, 0.0);
	std::vector<Point> q(k);
	for (long i = 0; i < n; ++i) {
		Point c{0.0, 0.0, 0.0};
		for (int j = 0; j < k; ++j) {
			const Point &p = pts[hoods[i][j]];
			q[j] = {p.x - pts[i].x, p.y - pts[i].y, p.z - pts[i].z};
			c.x += q[j].x;
			c.y += q[j].y;
			c.z += q[j].z;
		}
		c.x /= k;
		c.y /= k;
		c.z /= k;
		Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
		for (const Point &o : q) {
			const double r[3] = {o.x - c.x, o.y - c.y, o.z - c.z};
			for (int a = 0; a < 3; ++a)
				for (int b = 0; b <= a; ++b) cov(a, b) += r[a] * r[b];
		}
		for (int a = 0; a < 3; ++a)
			for (int b = a + 1; b < 3; ++b) cov(a, b) = cov(b, a);
		Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(cov);
		const Eigen::Vector3d nrm = solver.eigenvectors().col(0);
		const Point &d = q[1];
		const double length = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
		const double off = std::fabs(d.x * nrm[0] + d.y * nrm[1] + d.z * nrm[2]);
		ratio[i] = length > 0.0 ? off / length : 0.0;
	}
	const long at = (n - 1) / 2;
	std::nth_element(ratio.begin(), ratio.begin() + at, ratio.end());
	return std::min(std::max(1.0, std::pow(ratio[at] / NOISE_TOLERATED, 2.0)), NOISE_MAX_FACTOR);
}

// creases.sharp_vertices: both vertices of every edge with exactly two faces whose unit
// normals turn by more than max(CREASE_ANGLE, NOISE_FACTOR * lower quartile of the angles).
std::vector<char> sharpVertices(const std::vector<Point> &pts, const std::vector<std::array<int, 3>> &faces) {
	std::vector<std::array<double, 3>> u(faces.size());
	std::vector<std::array<long, 3>> edges;  // (a, b, face), a < b
	for (size_t f = 0; f < faces.size(); ++f) {
		const Point &p0 = pts[faces[f][0]], &p1 = pts[faces[f][1]], &p2 = pts[faces[f][2]];
		const double x1 = p1.x - p0.x, y1 = p1.y - p0.y, z1 = p1.z - p0.z;
		const double x2 = p2.x - p0.x, y2 = p2.y - p0.y, z2 = p2.z - p0.z;
		const double c[3] = {y1 * z2 - z1 * y2, z1 * x2 - x1 * z2, x1 * y2 - y1 * x2};
		const double len = std::sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
		const double div = len > 0.0 ? len : 1.0;
		u[f] = {c[0] / div, c[1] / div, c[2] / div};
		for (int a = 0; a < 3; ++a) {
			const long v0 = faces[f][a], v1 = faces[f][(a + 1) % 3];
			edges.push_back({std::min(v0, v1), std::max(v0, v1), long(f)});
		}
	}
	std::sort(edges.begin(), edges.end());
	std::vector<std::array<long, 2>> pairs;
	std::vector<double> angles;
	for (size_t s = 0; s < edges.size();) {
		size_t t = s;
		while (t < edges.size() && edges[t][0] == edges[s][0] && edges[t][1] == edges[s][1]) ++t;
		if (t - s == 2) {
			const auto &a = u[edges[s][2]], &b = u[edges[s + 1][2]];
			const double dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
			pairs.push_back({edges[s][0], edges[s][1]});
			angles.push_back(std::acos(std::min(1.0, std::max(-1.0, dot))));
		}
		s = t;
	}
	double theta = CREASE_ANGLE * (M_PI / 180.0);
	if (!angles.empty()) {
		std::vector<double> sorted = angles;
		const size_t at = (sorted.size() - 1) / 4;
		std::nth_element(sorted.begin(), sorted.begin() + at, sorted.end());
		theta = std::max(theta, NOISE_FACTOR * sorted[at]);
	}
	std::vector<char> out(pts.size(), 0);
	for (size_t e = 0; e < pairs.size(); ++e)
		if (angles[e] > theta) out[pairs[e][0]] = out[pairs[e][1]] = 1;
	return out;
}

// What one mode leaves per processed point.
struct Decision {
	std::vector<long> toClean;     // cleaned index of each processed point
	std::vector<double> strength;  // fraction of scales (1 on robust mode's sharp mesh edges)
	std::vector<char> feature;
};

// Otsu per scale on the values v, the votes, thresholds and candidate counts.
void vote(const std::vector<double> &v, double T, bool active, std::vector<int> &votes, Result &r) {
	long count = 0;
	if (active)
		for (size_t i = 0; i < v.size(); ++i)
			if (v[i] >= T) {
				votes[i]++;
				count++;
			}
	r.thresholds.push_back(T);
	r.candidates.push_back(count);
}

// The paper's method (ALGORITHM.md): kNN or BFS k-rings, min-max normalisation with the
// flat-scale rule, Otsu, candidates at every scale.
Decision paperMode(const std::vector<Point> &pts, const Clean &c, const Options &options, Result &r,
                   bool (*progress)(const int, const char *)) {
	const long n = long(pts.size());
	const size_t S = r.scales.size();
	const int sMax = r.scales.back();
	std::vector<std::vector<double>> pdis(S, std::vector<double>(n, 0.0));
	std::vector<Point> scratch;
	std::vector<long> nb;
	if (!r.mesh) {
		const auto hoods = knn(pts, sMax, progress);
		for (long i = 0; i < n; ++i) {
			if (progress && i % 20000 == 0) progress(40 + int(50 * i / n), "Sharp features: projected distances");
			for (size_t s = 0; s < S; ++s) {
				nb.assign(hoods[i].begin(), hoods[i].begin() + r.scales[s]);
				pdis[s][i] = projectedDistance(pts, i, nb, nullptr, options.gaussian, scratch);
			}
		}
	} else {
		std::vector<char> valid;
		const auto normals = faceAverageNormals(pts, c.faces, valid);
		const auto adj = oneRing(n, c.faces);
		std::vector<long> stamp(n, -1), frontier, next;
		for (long i = 0; i < n; ++i) {
			if (progress && i % 20000 == 0) progress(int(90 * i / n), "Sharp features: rings");
			nb.assign(1, i);
			frontier.assign(1, i);
			stamp[i] = i;
			int ring = 0;
			for (size_t s = 0; s < S; ++s) {
				while (ring < r.scales[s]) {  // grow one ring
					next.clear();
					for (long u : frontier)
						for (long w : adj[u])
							if (stamp[w] != i) {
								stamp[w] = i;
								next.push_back(w);
								nb.push_back(w);
							}
					frontier.swap(next);
					++ring;
				}
				pdis[s][i] = projectedDistance(pts, i, nb, valid[i] ? &normals[i] : nullptr,
				                               options.gaussian, scratch);
			}
		}
	}

	// Normalise, threshold, vote (threshold.py, multiscale.py).
	double lo[3] = {pts[0].x, pts[0].y, pts[0].z}, hi[3] = {lo[0], lo[1], lo[2]};
	for (const Point &p : pts) {
		lo[0] = std::min(lo[0], p.x), hi[0] = std::max(hi[0], p.x);
		lo[1] = std::min(lo[1], p.y), hi[1] = std::max(hi[1], p.y);
		lo[2] = std::min(lo[2], p.z), hi[2] = std::max(hi[2], p.z);
	}
	const double dx = hi[0] - lo[0], dy = hi[1] - lo[1], dz = hi[2] - lo[2];
	const double flatSpan = FLAT_TOLERANCE * std::sqrt(dx * dx + dy * dy + dz * dz);
	std::vector<int> votes(n, 0);
	std::vector<double> v(n);
	r.allFlat = true;
	for (size_t s = 0; s < S; ++s) {
		double T = 1.0;
		const auto mm = std::minmax_element(pdis[s].begin(), pdis[s].end());
		const double pmin = *mm.first, pmax = *mm.second;
		const bool active = pmax - pmin > flatSpan;
		if (active) {
			r.allFlat = false;
			for (long i = 0; i < n; ++i) v[i] = (pdis[s][i] - pmin) / (pmax - pmin);
			T = otsu(v);
		}
		vote(v, T, active, votes, r);
	}
	Decision d;
	d.toClean.resize(n);
	std::iota(d.toClean.begin(), d.toClean.end(), 0L);
	d.strength.resize(n);
	d.feature.resize(n);
	for (long i = 0; i < n; ++i) {
		d.strength[i] = double(votes[i]) / double(S);
		d.feature[i] = votes[i] == int(S);
	}
	return d;
}

// The k-rings of a mesh in the order of the Python package's RingNeighbourhoods
// (backend "numpy", scipy's sparse product): ring k + 1 lists the vertices met first
// when walking ring k's list and, for each member, its sorted 1-ring (itself included),
// in reverse order. The order fixes the rounding of the sums in robust mode.
class SparseRings {
public:
	SparseRings(long n, const std::vector<std::array<int, 3>> &faces) : adj_(oneRing(n, faces)), mark_(n, -1) {
		for (long i = 0; i < n; ++i) {
			adj_[i].insert(std::lower_bound(adj_[i].begin(), adj_[i].end(), i), i);
		}
	}
	// Start at vertex i: the 0-ring {i}.
	const std::vector<long> &start(long i) {
		current_.assign(1, i);
		return current_;
	}
	// The next ring, from the current one.
	const std::vector<long> &grow() {
		++generation_;
		next_.clear();
		for (long j : current_)
			for (long k : adj_[j])
				if (mark_[k] != generation_) {
					mark_[k] = generation_;
					next_.push_back(k);
				}
		std::reverse(next_.begin(), next_.end());
		current_.swap(next_);
		return current_;
	}

private:
	std::vector<std::vector<long>> adj_;
	std::vector<long> mark_;
	long generation_ = 0;
	std::vector<long> current_, next_;
};

// Robust mode (docs/robust-mode.md, robust.RobustSetup): isolated points left out and
// scales grown with the noise (clouds), r = pdis / l with Otsu's threshold floored at
// R_MIN, candidates at every scale, support along the line, thinning across it by the
// mean of o / l; on meshes also the vertices of sharp mesh edges (creases.py).
Decision robustMode(std::vector<Point> pts, const Clean &c, const Options &options, Result &r,
                    bool (*progress)(const int, const char *)) {
	Decision d;
	d.toClean.resize(pts.size());
	std::iota(d.toClean.begin(), d.toClean.end(), 0L);
	const size_t S = r.scales.size();
	std::vector<std::vector<long>> D, Sup, K;  // direction, support and comparison lists
	std::vector<Point> scratch;
	Columns col;
	std::vector<std::vector<double>> pdis(S), ell(S), off(S);

	if (!r.mesh) {
		auto hoods = knn(pts, r.scales.back(), progress);
		std::vector<Point> kept;
		std::vector<long> keptIdx;
		for (size_t i = 0; i < pts.size(); ++i) {
			const auto &nj = hoods[hoods[i][1]];
			if (std::find(nj.begin(), nj.end(), long(i)) != nj.end()) {
				kept.push_back(pts[i]);
				keptIdx.push_back(long(i));
			}
		}
		if (kept.size() < pts.size()) {
			if (long(kept.size()) < r.scales.back())
				throw InputError("too few points are left once isolated points are removed");
			pts.swap(kept);
			d.toClean.swap(keptIdx);
			hoods = knn(pts, r.scales.back(), progress);
		}
		const long n = long(pts.size());
		const double factor =
		    std::min(noiseScaleFactor(pts, hoods, std::min(NOISE_KNN, r.scales.back())),
		             double(n) / double(r.scales.back()));
		if (factor > 1.0) {
			for (int &k : r.scales) k = int(std::floor(k * factor + 0.5));
			hoods = knn(pts, r.scales.back(), progress);
		}
		const int top = r.scales.back();
		std::vector<long> nb;
		for (size_t s = 0; s < S; ++s) {
			pdis[s].resize(n);
			ell[s].resize(n);
			off[s].resize(n);
		}
		Sup.resize(n);
		K.resize(n);
		for (long i = 0; i < n; ++i) {
			if (progress && i % 20000 == 0) progress(40 + int(50 * i / n), "Sharp features: projected distances");
			for (size_t s = 0; s < S; ++s) {
				nb.assign(hoods[i].begin(), hoods[i].begin() + r.scales[s]);
				pdis[s][i] = projectedDistance(pts, i, nb, nullptr, options.gaussian, scratch);
				localScale(pts, i, nb, col, ell[s][i], off[s][i]);
			}
			Sup[i].assign(hoods[i].begin(), hoods[i].begin() + std::min(SUPPORT_KNN, top));
			K[i].assign(hoods[i].begin(), hoods[i].begin() + std::min(THIN_KNN, top));
		}
		D.swap(hoods);
	} else {
		const long n = long(pts.size());
		std::vector<char> valid;
		const auto normals = faceAverageNormals(pts, c.faces, valid);
		SparseRings rings(n, c.faces);
		const int top = r.scales.back();
		const int compareRing = std::min(THIN_RING, top);
		for (size_t s = 0; s < S; ++s) {
			pdis[s].resize(n);
			ell[s].resize(n);
			off[s].resize(n);
		}
		D.resize(n);
		Sup.resize(n);
		for (long i = 0; i < n; ++i) {
			if (progress && i % 20000 == 0) progress(int(90 * i / n), "Sharp features: rings");
			rings.start(i);
			size_t s = 0;
			for (int ring = 1; ring <= top; ++ring) {
				const std::vector<long> &nb = rings.grow();
				if (ring == compareRing) Sup[i] = nb;
				if (ring == top) D[i] = nb;
				if (ring == r.scales[s]) {
					pdis[s][i] = projectedDistance(pts, i, nb, valid[i] ? &normals[i] : nullptr,
					                               options.gaussian, scratch);
					localScale(pts, i, nb, col, ell[s][i], off[s][i]);
					++s;
				}
			}
		}
		K = Sup;
	}

	const long n = long(pts.size());
	std::vector<int> votes(n, 0);
	std::vector<double> v(n), score(n, 0.0);
	for (size_t s = 0; s < S; ++s) {
		for (long i = 0; i < n; ++i) {
			v[i] = relative(pdis[s][i], ell[s][i]);
			score[i] += relative(off[s][i], ell[s][i]) / double(S);
		}
		vote(v, std::max(otsu(v), R_MIN), true, votes, r);
	}
	std::vector<char> f0(n);
	d.strength.resize(n);
	for (long i = 0; i < n; ++i) {
		f0[i] = votes[i] == int(S);
		d.strength[i] = double(votes[i]) / double(S);
	}
	d.feature = supportAndThin(pts, f0, score, D, Sup, K);
	if (r.mesh) {
		const auto edges = sharpVertices(pts, c.faces);
		for (long i = 0; i < n; ++i)
			if (edges[i]) {
				d.feature[i] = 1;
				d.strength[i] = 1.0;
			}
	}
	return d;
}

}  // namespace

Result detect(const std::vector<Point> &vertices, const std::vector<std::array<int, 3>> &faces,
              const Options &options, bool (*progress)(const int, const char *)) {
	const long nIn = long(vertices.size());
	if (nIn == 0) throw InputError("the layer has no vertices");
	for (long i = 0; i < nIn; ++i) {
		const Point &p = vertices[i];
		if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
			throw InputError("vertex " + std::to_string(i) + " has a non-finite coordinate (NaN or inf)");
	}
	Result r;
	r.mesh = !faces.empty() && !options.asPoints;
	for (const auto &f : faces)
		for (int a = 0; a < 3; ++a)
			if (f[a] < 0 || f[a] >= nIn) throw InputError("a face index is out of range");
	const Clean c = clean(vertices, r.mesh ? faces : std::vector<std::array<int, 3>>{}, r.mesh);
	if (r.mesh && c.faces.empty()) throw InputError("every face has zero area: nothing is left of the mesh");
	r.scales = r.mesh ? options.ringScales : options.knnScales;
	if (!r.mesh) {
		const long n = long(c.pts.size());
		if (n == 1 && nIn > 1) throw InputError("all " + std::to_string(nIn) + " points are identical");
		if (n < r.scales.back())
			throw InputError(std::to_string(n) + " distinct points, fewer than the largest scale k = " +
			                 std::to_string(r.scales.back()));
	}
	r.nClean = long(c.pts.size());

	std::vector<Point> pts = c.pts;
	scaleToUnit(pts);
	const Decision d = options.robust ? robustMode(pts, c, options, r, progress)
	                                  : paperMode(pts, c, options, r, progress);

	// Back to the input's order.
	std::vector<long> processed(c.pts.size(), -1);
	for (size_t i = 0; i < d.toClean.size(); ++i) processed[d.toClean[i]] = long(i);
	r.strength.assign(nIn, 0.0);
	r.feature.assign(nIn, 0);
	r.kept.assign(nIn, 0);
	for (long i = 0; i < nIn; ++i) {
		const long ci = c.fromInput[i];
		if (ci < 0 || processed[ci] < 0) continue;
		const long pi = processed[ci];
		r.kept[i] = 1;
		r.strength[i] = d.strength[pi];
		r.feature[i] = d.feature[pi];
		r.nFeatures += r.feature[i];
	}
	if (progress) progress(100, "Sharp features: done");
	return r;
}

}  // namespace sharp
