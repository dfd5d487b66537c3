// See sharp_core.h. Every step mirrors a module of the Python package:
// cleaning.py, neighbourhoods.py, normals.py, projected_distance.py, threshold.py,
// multiscale.py. docs/implementation-notes.md is the contract between the two.
#include "sharp_core.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <sstream>

#include <Eigen/Dense>
#include <vcg/space/index/kdtree/kdtree.h>

namespace sharp {
namespace {

const int BINS = 256;
const double FLAT_TOLERANCE = 1e-6;  // threshold.py
const double ZERO_NORMAL = 1e-12;    // normals.py
// robust.py: r on a straight edge turning by 20 degrees, (2 / pi) sin(10 deg).
const double R_MIN = 0.11061587104123714;
const double THIN_CONE_COS = 0.5;
const int THIN_KNN = 16;
const int THIN_RING = 2;

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
// Also sets meanDistance = (1/m) sum |p_j - p_i| (robust.py's local scale l_i).
double projectedDistance(const std::vector<Point> &pts, long i, const std::vector<long> &nb,
                         const Eigen::Vector3d *fixedNormal, bool gaussian,
                         std::vector<Point> &scratch, double &meanDistance) {
	scratch.resize(nb.size());
	Point m{0.0, 0.0, 0.0};
	double dsum = 0.0;
	for (size_t j = 0; j < nb.size(); ++j) {
		const Point &p = pts[nb[j]];
		scratch[j] = {p.x - pts[i].x, p.y - pts[i].y, p.z - pts[i].z};
		m.x += scratch[j].x;
		m.y += scratch[j].y;
		m.z += scratch[j].z;
		dsum += std::sqrt(sq(p, pts[i]));
	}
	const double s = double(nb.size());
	meanDistance = dsum / s;
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

// robust.py's thinning: a feature i is dropped when a feature j of K(i), lying more
// than 60 degrees from the line direction e_i (largest eigenvector over the features of
// D(i)), has a larger score. Decisions use the features before thinning.
std::vector<char> thin(const std::vector<Point> &pts, const std::vector<char> &feature,
                       const std::vector<double> &score, const std::vector<std::vector<long>> &D,
                       const std::vector<std::vector<long>> &K) {
	std::vector<char> out = feature;
	for (size_t i = 0; i < pts.size(); ++i) {
		if (!feature[i]) continue;
		Eigen::Vector3d qsum = Eigen::Vector3d::Zero();
		Eigen::Matrix3d outer = Eigen::Matrix3d::Zero();
		double count = 0.0;
		for (long j : D[i]) {
			if (!feature[j]) continue;
			const Eigen::Vector3d q(pts[j].x - pts[i].x, pts[j].y - pts[i].y, pts[j].z - pts[i].z);
			qsum += q;
			outer += q * q.transpose();
			count += 1.0;
		}
		const Eigen::Vector3d qbar = qsum / std::max(count, 1.0);
		const Eigen::Matrix3d cov = outer - std::max(count, 1.0) * qbar * qbar.transpose();
		Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(cov);
		const Eigen::Vector3d e = solver.eigenvectors().col(2);
		for (long j : K[i]) {
			if (j == long(i) || !feature[j]) continue;
			const double dx = pts[j].x - pts[i].x, dy = pts[j].y - pts[i].y, dz = pts[j].z - pts[i].z;
			const double along = std::fabs(dx * e[0] + dy * e[1] + dz * e[2]);
			if (along < THIN_CONE_COS * std::sqrt(dx * dx + dy * dy + dz * dz) && score[j] > score[i]) {
				out[i] = 0;
				break;
			}
		}
	}
	return out;
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
	const int sMax = r.scales.back();
	if (!r.mesh) {
		const long n = long(c.pts.size());
		if (n == 1 && nIn > 1) throw InputError("all " + std::to_string(nIn) + " points are identical");
		if (n < sMax)
			throw InputError(std::to_string(n) + " distinct points, fewer than the largest scale k = " +
			                 std::to_string(sMax));
	}
	r.nClean = long(c.pts.size());
	const size_t S = r.scales.size();

	// The points processed: every cleaned point, less the isolated ones in robust mode.
	std::vector<Point> pts = c.pts;
	scaleToUnit(pts);
	std::vector<long> toClean(pts.size());
	std::iota(toClean.begin(), toClean.end(), 0L);
	std::vector<std::vector<long>> hoods;  // kNN at the largest scale (clouds)
	if (!r.mesh) {
		hoods = knn(pts, sMax, progress);
		if (options.robust) {
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
				if (long(kept.size()) < sMax)
					throw InputError("too few points are left once isolated points are removed");
				pts.swap(kept);
				toClean.swap(keptIdx);
				hoods = knn(pts, sMax, progress);
			}
		}
	}
	const long n = long(pts.size());
	std::vector<std::vector<double>> pdis(S, std::vector<double>(n, 0.0));
	std::vector<std::vector<double>> ell(S, std::vector<double>(n, 0.0));
	std::vector<std::vector<long>> D, K;  // thinning: direction and comparison lists
	std::vector<Point> scratch;
	std::vector<long> nb;

	if (!r.mesh) {
		for (long i = 0; i < n; ++i) {
			if (progress && i % 20000 == 0) progress(40 + int(50 * i / n), "Sharp features: projected distances");
			for (size_t s = 0; s < S; ++s) {
				nb.assign(hoods[i].begin(), hoods[i].begin() + r.scales[s]);
				pdis[s][i] = projectedDistance(pts, i, nb, nullptr, options.gaussian, scratch, ell[s][i]);
			}
		}
		if (options.robust) {
			D = hoods;
			K.resize(n);
			const int kc = std::min(THIN_KNN, sMax);
			for (long i = 0; i < n; ++i) K[i].assign(hoods[i].begin(), hoods[i].begin() + kc);
		}
	} else {
		std::vector<char> valid;
		const auto normals = faceAverageNormals(pts, c.faces, valid);
		const auto adj = oneRing(n, c.faces);
		const int compareRing = std::min(THIN_RING, sMax);
		if (options.robust) {
			D.resize(n);
			K.resize(n);
		}
		std::vector<long> stamp(n, -1), frontier, next;
		for (long i = 0; i < n; ++i) {
			if (progress && i % 20000 == 0) progress(int(90 * i / n), "Sharp features: rings");
			nb.assign(1, i);
			frontier.assign(1, i);
			stamp[i] = i;
			int ring = 0;
			if (options.robust && compareRing == 0) K[i] = nb;
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
					if (options.robust && ring == compareRing) K[i] = nb;
				}
				pdis[s][i] = projectedDistance(pts, i, nb, valid[i] ? &normals[i] : nullptr,
				                               options.gaussian, scratch, ell[s][i]);
			}
			if (options.robust) D[i] = nb;
		}
	}

	// Normalise, threshold, vote (threshold.py, multiscale.py; robust.py in robust mode).
	double lo[3] = {pts[0].x, pts[0].y, pts[0].z}, hi[3] = {lo[0], lo[1], lo[2]};
	for (const Point &p : pts) {
		lo[0] = std::min(lo[0], p.x), hi[0] = std::max(hi[0], p.x);
		lo[1] = std::min(lo[1], p.y), hi[1] = std::max(hi[1], p.y);
		lo[2] = std::min(lo[2], p.z), hi[2] = std::max(hi[2], p.z);
	}
	const double dx = hi[0] - lo[0], dy = hi[1] - lo[1], dz = hi[2] - lo[2];
	const double flatSpan = FLAT_TOLERANCE * std::sqrt(dx * dx + dy * dy + dz * dz);
	std::vector<int> votes(n, 0);
	std::vector<double> v(n), score(n, 0.0);
	r.allFlat = !options.robust;  // the flat-scale rule belongs to paper mode
	for (size_t s = 0; s < S; ++s) {
		double T = 1.0;
		bool active = true;
		if (options.robust) {
			for (long i = 0; i < n; ++i) {
				v[i] = ell[s][i] > 0.0 ? std::min(pdis[s][i] / ell[s][i], 1.0) : 0.0;
				score[i] += v[i] / double(S);
			}
			T = std::max(otsu(v), R_MIN);
		} else {
			const auto mm = std::minmax_element(pdis[s].begin(), pdis[s].end());
			const double pmin = *mm.first, pmax = *mm.second;
			active = pmax - pmin > flatSpan;
			if (active) {
				r.allFlat = false;
				for (long i = 0; i < n; ++i) v[i] = (pdis[s][i] - pmin) / (pmax - pmin);
				T = otsu(v);
			}
		}
		long count = 0;
		if (active) {
			for (long i = 0; i < n; ++i)
				if (v[i] >= T) {
					votes[i]++;
					count++;
				}
		}
		r.thresholds.push_back(T);
		r.candidates.push_back(count);
	}
	std::vector<char> feature(n);
	for (long i = 0; i < n; ++i) feature[i] = votes[i] == int(S);
	if (options.robust) feature = thin(pts, feature, score, D, K);

	// Back to the input's order.
	std::vector<long> processed(c.pts.size(), -1);
	for (long i = 0; i < n; ++i) processed[toClean[i]] = i;
	r.strength.assign(nIn, 0.0);
	r.feature.assign(nIn, 0);
	r.kept.assign(nIn, 0);
	for (long i = 0; i < nIn; ++i) {
		const long ci = c.fromInput[i];
		if (ci < 0 || processed[ci] < 0) continue;
		const long pi = processed[ci];
		r.kept[i] = 1;
		r.strength[i] = double(votes[pi]) / double(S);
		r.feature[i] = feature[pi];
		r.nFeatures += r.feature[i];
	}
	if (progress) progress(100, "Sharp features: done");
	return r;
}

}  // namespace sharp
