// meshlab-sharp feature curves: the steps of the numpy reference
// meshlab_sharp/reference/curves, line for line (see curves.h). Sums, dot products and
// reductions are evaluated in the order numpy evaluates them (pairwise sums along an
// array's last axis, sequential sums along the others, einsum's (0, 2, 1) order over
// three components, BLAS's fused order for `@` and the norm of one vector), and exp,
// acos and atan2 are the caller's (ms_curves_math: numpy's from Python), so that the
// curves are the reference's to the bit. With the C library's math (the MeshLab plugin)
// cloud vertices differ from them in the last bits.
#include "curves.h"

#include "cores.h"

#include "meshlab_sharp.h"

#include <algorithm>
#include <cmath>
#include <deque>
#include <exception>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <numeric>
#include <queue>
#include <set>
#include <system_error>
#include <thread>
#include <tuple>
#include <unordered_set>
#include <utility>

namespace sharp {
namespace {

// The constants: MS_CURVE_ in meshlab_sharp.h, shared with the Python modules.
const double TURN_SCALES[] = MS_CURVE_TURN_SCALES;
constexpr int N_SCALES = int(sizeof TURN_SCALES / sizeof TURN_SCALES[0]);

const double PI = 3.141592653589793238462643383279502884;
const double INF = std::numeric_limits<double>::infinity();

using Edge = std::array<long, 2>;

// ---------------------------------------------------------------- arithmetic

Vec3 sub(const Vec3 &a, const Vec3 &b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
Vec3 add(const Vec3 &a, const Vec3 &b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
Vec3 mul(double s, const Vec3 &a) { return {s * a[0], s * a[1], s * a[2]}; }
Vec3 neg(const Vec3 &a) { return {-a[0], -a[1], -a[2]}; }
// np.linalg.norm along an axis of length 3 (and scipy's squared distances)
double sq(const Vec3 &a) { return (a[0] * a[0] + a[1] * a[1]) + a[2] * a[2]; }
double norm(const Vec3 &a) { return std::sqrt(sq(a)); }
// np.einsum("ij,ij->i") over 3 components
double edot(const Vec3 &a, const Vec3 &b) { return (a[0] * b[0] + a[2] * b[2]) + a[1] * b[1]; }
// a @ b of two (3,) arrays and np.linalg.norm of one (sqrt(a @ a)): numpy hands them to
// BLAS (ddot), whose x86-64 kernels (OpenBLAS, Haswell and later) fuse the products
// into the sum in this order
double bdot(const Vec3 &a, const Vec3 &b) { return std::fma(a[2], b[2], std::fma(a[1], b[1], a[0] * b[0])); }
double bnorm(const Vec3 &a) { return std::sqrt(bdot(a, a)); }
// one row of a (3, 3) @ (3,) product (BLAS dgemv), in that kernel's order
double gemvRow(const std::array<double, 3> &row, const Vec3 &x)
{
	return std::fma(row[2], x[2], std::fma(row[0], x[0], row[1] * x[1]));
}
Vec3 cross(const Vec3 &a, const Vec3 &b)
{
	return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
Vec3 unit(const Vec3 &v)
{
	const double n = norm(v);
	const double d = n > 0 ? n : 1.0;
	return {v[0] / d, v[1] / d, v[2] / d};
}
double radians(double deg) { return deg * (PI / 180.0); }
double degrees(double rad) { return rad * (180.0 / PI); }

// numpy's pairwise summation (a reduction along the last axis)
double pairwiseSum(const double *a, size_t n)
{
	if (n < 8) {
		double res = -0.0;
		for (size_t i = 0; i < n; ++i) res += a[i];
		return res;
	}
	if (n <= 128) {
		double r[8];
		for (int j = 0; j < 8; ++j) r[j] = a[j];
		size_t i = 8;
		for (; i < n - (n % 8); i += 8)
			for (int j = 0; j < 8; ++j) r[j] += a[i + j];
		double res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
		for (; i < n; ++i) res += a[i];
		return res;
	}
	size_t n2 = n / 2;
	n2 -= n2 % 8;
	return pairwiseSum(a, n2) + pairwiseSum(a + n2, n - n2);
}
double pairwiseSum(const std::vector<double> &a) { return pairwiseSum(a.data(), a.size()); }

double median(std::vector<double> v)
{
	std::sort(v.begin(), v.end());
	const size_t n = v.size();
	if (n % 2) return v[n / 2];
	return (v[n / 2 - 1] + v[n / 2]) / 2.0;
}

bool lexLess(const Vec3 &a, const Vec3 &b)
{
	return std::lexicographical_compare(a.begin(), a.end(), b.begin(), b.end());
}

long searchLeft(const std::vector<double> &a, double x)
{
	return long(std::lower_bound(a.begin(), a.end(), x) - a.begin());
}
long searchRight(const std::vector<double> &a, double x)
{
	return long(std::upper_bound(a.begin(), a.end(), x) - a.begin());
}
long clip(long v, long lo, long hi) { return std::max(lo, std::min(v, hi)); }

// 3x3 symmetric eigenvalues (Jacobi), for np.linalg.cond of a symmetric matrix
double condition(std::array<std::array<double, 3>, 3> a)
{
	for (int sweep = 0; sweep < 50; ++sweep) {
		double off = std::fabs(a[0][1]) + std::fabs(a[0][2]) + std::fabs(a[1][2]);
		if (off == 0) break;
		for (int p = 0; p < 2; ++p)
			for (int q = p + 1; q < 3; ++q) {
				if (a[p][q] == 0) continue;
				const double theta = (a[q][q] - a[p][p]) / (2 * a[p][q]);
				const double t = (theta >= 0 ? 1.0 : -1.0) / (std::fabs(theta) + std::sqrt(theta * theta + 1));
				const double c = 1 / std::sqrt(t * t + 1), s = t * c;
				for (int k = 0; k < 3; ++k) {
					const double akp = a[k][p], akq = a[k][q];
					a[k][p] = c * akp - s * akq;
					a[k][q] = s * akp + c * akq;
				}
				for (int k = 0; k < 3; ++k) {
					const double apk = a[p][k], aqk = a[q][k];
					a[p][k] = c * apk - s * aqk;
					a[q][k] = s * apk + c * aqk;
				}
			}
	}
	double lo = INF, hi = 0;
	for (int k = 0; k < 3; ++k) {
		lo = std::min(lo, std::fabs(a[k][k]));
		hi = std::max(hi, std::fabs(a[k][k]));
	}
	return lo > 0 ? hi / lo : INF;
}

// np.linalg.solve of a 3x3 system (LU with partial pivoting)
Vec3 solve3(std::array<std::array<double, 3>, 3> a, Vec3 b)
{
	for (int c = 0; c < 3; ++c) {
		int piv = c;
		for (int r = c + 1; r < 3; ++r)
			if (std::fabs(a[r][c]) > std::fabs(a[piv][c])) piv = r;
		std::swap(a[c], a[piv]);
		std::swap(b[c], b[piv]);
		for (int r = c + 1; r < 3; ++r) {
			const double f = a[r][c] / a[c][c];
			for (int k = c; k < 3; ++k) a[r][k] -= f * a[c][k];
			b[r] -= f * b[c];
		}
	}
	Vec3 x{};
	for (int r = 2; r >= 0; --r) {
		double s = b[r];
		for (int k = r + 1; k < 3; ++k) s -= a[r][k] * x[k];
		x[r] = s / a[r][r];
	}
	return x;
}

// The C library's exp, acos and atan2, element by element (the default ms_curves_math)
void cExp(const double *x, double *out, int64_t n)
{
	for (int64_t i = 0; i < n; ++i) out[i] = std::exp(x[i]);
}
void cAcos(const double *x, double *out, int64_t n)
{
	for (int64_t i = 0; i < n; ++i) out[i] = std::acos(x[i]);
}
void cAtan2(const double *y, const double *x, double *out, int64_t n)
{
	for (int64_t i = 0; i < n; ++i) out[i] = std::atan2(y[i], x[i]);
}
const ms_curves_math C_MATH = {cExp, cAcos, cAtan2};

// ---------------------------------------------------------------- threads

// Fewest items a block of inBlocks takes: smaller inputs stay on the calling thread.
constexpr size_t MIN_BLOCK = 4096;

// body(begin, end) over [0, n) in contiguous blocks, one per core this process may use (each at least `least`
// items), the first on the calling thread; a block whose thread cannot start runs on the
// calling thread. body writes only its own items' results, so the bits do not depend on
// the threads. An exception of a block is rethrown once every block is done.
template <class Body>
void inBlocks(size_t n, const Body &body, size_t least = MIN_BLOCK)
{
	const size_t blocks = std::min<size_t>(cores(),
	                                       std::max<size_t>(1, n / least));
	std::vector<std::exception_ptr> errors(blocks);
	auto run = [&](size_t b) {
		try {
			body(n * b / blocks, n * (b + 1) / blocks);
		} catch (...) {
			errors[b] = std::current_exception();
		}
	};
	std::vector<std::thread> pool;
	pool.reserve(blocks);
	size_t started = 1;
	try {
		for (; started < blocks; ++started) pool.emplace_back(run, started);
	} catch (const std::system_error &) {
	}
	run(0);
	for (size_t b = started; b < blocks; ++b) run(b);
	for (std::thread &t : pool) t.join();
	for (const std::exception_ptr &e : errors)
		if (e) std::rethrow_exception(e);
}

// ---------------------------------------------------------------- k nearest neighbours

// A kd-tree: k nearest neighbours ordered by (squared distance, index), as cKDTree
// orders them (ties by index).
class KdTree {
public:
	explicit KdTree(const std::vector<Vec3> &points) : pts_(points), idx_(points.size())
	{
		std::iota(idx_.begin(), idx_.end(), 0L);
		if (!pts_.empty()) build(0, long(idx_.size()));
	}
	size_t size() const { return pts_.size(); }

	// (squared distance, index) of the k nearest, nearer than `bound` (strictly).
	std::vector<std::pair<double, long>> query(const Vec3 &q, size_t k, double bound = INF) const
	{
		std::vector<std::pair<double, long>> heap;  // max-heap on (d2, index)
		const double b2 = bound == INF ? INF : bound * bound;
		if (!nodes_.empty()) search(0, q, k, b2, heap);
		std::sort_heap(heap.begin(), heap.end());
		return heap;
	}

	// indices of the points within r (squared distance <= r^2), ascending
	std::vector<long> ball(const Vec3 &q, double r) const
	{
		std::vector<long> out;
		if (!nodes_.empty()) collect(0, q, r * r, out);
		std::sort(out.begin(), out.end());
		return out;
	}

private:
	struct Node { long lo, hi; int dim; double split; long left, right; };
	const std::vector<Vec3> &pts_;
	std::vector<long> idx_;
	std::vector<Node> nodes_;

	long build(long lo, long hi)
	{
		const long id = long(nodes_.size());
		nodes_.push_back({lo, hi, -1, 0.0, -1, -1});
		if (hi - lo <= 16) return id;
		Vec3 mn{INF, INF, INF}, mx{-INF, -INF, -INF};
		for (long i = lo; i < hi; ++i)
			for (int d = 0; d < 3; ++d) {
				mn[d] = std::min(mn[d], pts_[idx_[i]][d]);
				mx[d] = std::max(mx[d], pts_[idx_[i]][d]);
			}
		int dim = 0;
		for (int d = 1; d < 3; ++d)
			if (mx[d] - mn[d] > mx[dim] - mn[dim]) dim = d;
		if (mx[dim] - mn[dim] <= 0) return id;
		const long mid = (lo + hi) / 2;
		std::nth_element(idx_.begin() + lo, idx_.begin() + mid, idx_.begin() + hi,
		                 [&](long a, long b) { return pts_[a][dim] < pts_[b][dim]; });
		const double split = pts_[idx_[mid]][dim];
		nodes_[id].dim = dim;
		nodes_[id].split = split;
		const long left = build(lo, mid);
		const long right = build(mid, hi);
		nodes_[id].left = left;
		nodes_[id].right = right;
		return id;
	}

	void collect(long id, const Vec3 &q, double r2, std::vector<long> &out) const
	{
		const Node &nd = nodes_[id];
		if (nd.dim < 0) {
			for (long i = nd.lo; i < nd.hi; ++i)
				if (sq(sub(q, pts_[idx_[i]])) <= r2) out.push_back(idx_[i]);
			return;
		}
		const double diff = q[nd.dim] - nd.split;
		if (diff <= 0 || diff * diff <= r2) collect(nd.left, q, r2, out);
		if (diff >= 0 || diff * diff <= r2) collect(nd.right, q, r2, out);
	}

	void search(long id, const Vec3 &q, size_t k, double b2,
	            std::vector<std::pair<double, long>> &heap) const
	{
		const Node &nd = nodes_[id];
		if (nd.dim < 0) {
			for (long i = nd.lo; i < nd.hi; ++i) {
				const long j = idx_[i];
				const double d2 = sq(sub(pts_[j], q));
				if (!(d2 < b2)) continue;
				const std::pair<double, long> item{d2, j};
				if (heap.size() < k) {
					heap.push_back(item);
					std::push_heap(heap.begin(), heap.end());
				} else if (item < heap.front()) {
					std::pop_heap(heap.begin(), heap.end());
					heap.back() = item;
					std::push_heap(heap.begin(), heap.end());
				}
			}
			return;
		}
		const double diff = q[nd.dim] - nd.split;
		const long first = diff < 0 ? nd.left : nd.right;
		const long second = diff < 0 ? nd.right : nd.left;
		search(first, q, k, b2, heap);
		const double worst = heap.size() < k ? b2 : std::min(b2, heap.front().first);
		if (diff * diff <= worst) search(second, q, k, b2, heap);
	}
};

// ---------------------------------------------------------------- graph.py

struct Adjacency { std::vector<long> indptr, nbr, eid; };

Adjacency adjacency(long n, const std::vector<Edge> &edges)
{
	const long e = long(edges.size());
	std::vector<long> a(2 * e), b(2 * e), ids(2 * e), order(2 * e);
	for (long i = 0; i < e; ++i) {
		a[i] = edges[i][0], b[i] = edges[i][1], ids[i] = i;
		a[e + i] = edges[i][1], b[e + i] = edges[i][0], ids[e + i] = i;
	}
	std::iota(order.begin(), order.end(), 0L);
	std::stable_sort(order.begin(), order.end(),
	                 [&](long x, long y) { return a[x] != a[y] ? a[x] < a[y] : b[x] < b[y]; });
	Adjacency adj;
	adj.indptr.assign(n + 1, 0);
	for (long x : a) adj.indptr[x + 1] += 1;
	for (long i = 0; i < n; ++i) adj.indptr[i + 1] += adj.indptr[i];
	for (long x : order) {
		adj.nbr.push_back(b[x]);
		adj.eid.push_back(ids[x]);
	}
	return adj;
}

std::vector<Edge> sortedPairs(std::vector<Edge> out)
{
	for (Edge &p : out)
		if (p[0] > p[1]) std::swap(p[0], p[1]);
	std::sort(out.begin(), out.end());
	return out;
}

// scipy.sparse.csgraph.minimum_spanning_tree (Kruskal, edges in stable weight order of
// the canonical CSR matrix)
std::vector<Edge> spanningForest(long n, const std::vector<Edge> &edges, const std::vector<double> &w)
{
	std::vector<long> order(edges.size());
	std::iota(order.begin(), order.end(), 0L);
	std::sort(order.begin(), order.end(), [&](long x, long y) { return edges[x] < edges[y]; });
	std::stable_sort(order.begin(), order.end(), [&](long x, long y) { return w[x] < w[y]; });
	DisjointSets sets(n);
	std::vector<Edge> tree;
	for (long j : order) {
		if (w[j] == 0) continue;  // an explicit zero is no edge
		if (sets.join(edges[j][0], edges[j][1])) tree.push_back(edges[j]);
	}
	return sortedPairs(tree);
}

using AdjList = std::map<long, std::vector<std::pair<long, double>>>;

bool pathShorter(const AdjList &adj, long a, long b, double limit)
{
	std::map<long, double> best{{a, 0.0}};
	std::priority_queue<std::pair<double, long>, std::vector<std::pair<double, long>>,
	                    std::greater<std::pair<double, long>>> heap;
	heap.push({0.0, a});
	while (!heap.empty()) {
		const double d = heap.top().first;
		const long node = heap.top().second;
		heap.pop();
		if (node == b) return true;
		auto it = best.find(node);
		if (it != best.end() && d > it->second) continue;
		auto found = adj.find(node);
		if (found == adj.end()) continue;
		for (const auto &entry : found->second) {
			const long nxt = entry.first;
			const double nd = d + entry.second;
			auto bt = best.find(nxt);
			if (nd < limit && (bt == best.end() || nd < bt->second)) {
				best[nxt] = nd;
				heap.push({nd, nxt});
			}
		}
	}
	return false;
}

std::vector<Edge> closeLoops(long n, const std::vector<Edge> &forest, const std::vector<Edge> &edges,
                             const std::vector<Vec3> &pos, double minLength)
{
	std::vector<long> degree(n, 0);
	for (const Edge &e : forest) degree[e[0]]++, degree[e[1]]++;
	std::set<Edge> tree(forest.begin(), forest.end());
	std::vector<Edge> cand;
	for (const Edge &e : edges)
		if ((degree[e[0]] == 1 || degree[e[1]] == 1) && !tree.count(e)) cand.push_back(e);
	if (cand.empty()) return forest;
	std::vector<double> candLength(cand.size());
	for (size_t i = 0; i < cand.size(); ++i) candLength[i] = norm(sub(pos[cand[i][0]], pos[cand[i][1]]));
	AdjList adj;
	for (const Edge &e : forest) {
		const double d = norm(sub(pos[e[0]], pos[e[1]]));
		adj[e[0]].push_back({e[1], d});
		adj[e[1]].push_back({e[0], d});
	}
	std::vector<long> order(cand.size());
	std::iota(order.begin(), order.end(), 0L);
	std::stable_sort(order.begin(), order.end(), [&](long x, long y) {
		if (candLength[x] != candLength[y]) return candLength[x] < candLength[y];
		return cand[x] < cand[y];
	});
	auto degreeOf = [&](long v) { auto it = adj.find(v); return it == adj.end() ? 0 : long(it->second.size()); };
	std::vector<Edge> out = forest;
	for (long k : order) {
		const long a = cand[k][0], b = cand[k][1];
		if (degreeOf(a) != 1 && degreeOf(b) != 1) continue;
		if (pathShorter(adj, a, b, minLength)) continue;
		out.push_back({a, b});
		adj[a].push_back({b, candLength[k]});
		adj[b].push_back({a, candLength[k]});
	}
	return out;
}

// graph.bridge_leaves: each free end of the forest linked to the nearest node of another
// tree within reach that lies within angle (degrees) of its direction (from the
// node MS_CURVE_BRIDGE_BACK links back; another free end, each within that of the
// other's); shortest first, each joining two trees still apart
std::vector<Edge> bridgeLeaves(long n, const std::vector<Edge> &forest, const std::vector<Vec3> &pos,
                               double reach, double angle)
{
	DisjointSets sets(n);
	std::vector<std::vector<long>> nb(n);
	for (const Edge &e : forest) {
		nb[e[0]].push_back(e[1]);
		nb[e[1]].push_back(e[0]);
		sets.join(e[0], e[1]);
	}
	std::vector<long> leaves;
	for (long a = 0; a < n; ++a)
		if (nb[a].size() == 1) leaves.push_back(a);
	if (leaves.empty()) return forest;
	std::map<long, std::pair<Vec3, double>> direction;
	for (long a : leaves) {
		long prev = a, cur = nb[a][0];
		for (int step = 0; step < MS_CURVE_BRIDGE_BACK - 1; ++step) {
			if (nb[cur].size() != 2) break;
			const long next = nb[cur][0] == prev ? nb[cur][1] : nb[cur][0];
			prev = cur;
			cur = next;
		}
		const Vec3 d = sub(pos[a], pos[cur]);
		direction[a] = {d, norm(d)};
	}
	const KdTree tree(pos);
	const double minCos = std::cos(radians(angle));
	std::vector<std::tuple<double, long, long>> cand;
	for (long a : leaves) {
		const Vec3 &d = direction[a].first;
		const double dLength = direction[a].second;
		const long own = sets.root(a);
		for (long b : tree.ball(pos[a], reach)) {
			if (sets.root(b) == own) continue;
			const Vec3 v = sub(pos[b], pos[a]);
			const double length = norm(v);
			if (edot(v, d) < minCos * length * dLength) continue;
			auto other = direction.find(b);
			// two free ends: each ahead of the other
			if (other != direction.end() && edot(neg(v), other->second.first) < minCos * length * other->second.second)
				continue;
			cand.emplace_back(length, a, b);
		}
	}
	std::sort(cand.begin(), cand.end());
	std::vector<Edge> out = forest;
	for (const auto &c : cand) {
		const long a = std::get<1>(c), b = std::get<2>(c);
		if (sets.join(a, b)) out.push_back({std::min(a, b), std::max(a, b)});
	}
	return out;
}

std::vector<Edge> pruneSpurs(long n, const std::vector<Edge> &edges, const std::vector<Vec3> &pos,
                             double minLength)
{
	std::vector<char> keep(edges.size(), 1);
	std::vector<double> edgeLength(edges.size());
	for (size_t i = 0; i < edges.size(); ++i) edgeLength[i] = norm(sub(pos[edges[i][0]], pos[edges[i][1]]));
	for (int round = 0; round < MS_CURVE_PRUNE_ROUNDS; ++round) {
		std::vector<long> current;
		std::vector<Edge> sub_;
		for (size_t i = 0; i < edges.size(); ++i)
			if (keep[i]) current.push_back(long(i)), sub_.push_back(edges[i]);
		const Adjacency adj = adjacency(n, sub_);
		std::vector<long> degree(n);
		for (long i = 0; i < n; ++i) degree[i] = adj.indptr[i + 1] - adj.indptr[i];
		std::map<long, std::vector<std::tuple<double, long, std::vector<long>>>> spurs;
		std::vector<long> junctionOrder;
		for (long leaf = 0; leaf < n; ++leaf) {
			if (degree[leaf] != 1) continue;
			long prev = -1, node = leaf;
			double length = 0.0;
			std::vector<long> path;
			while (true) {
				long step = adj.indptr[node];
				while (adj.nbr[step] == prev) ++step;
				const long edge = current[adj.eid[step]];
				path.push_back(edge);
				const long nxt = adj.nbr[step];
				length += edgeLength[edge];
				prev = node, node = nxt;
				if (degree[node] != 2 || length >= minLength) break;
			}
			if (degree[node] >= 3 && length < minLength) {
				if (!spurs.count(node)) junctionOrder.push_back(node);
				spurs[node].push_back({length, leaf, path});
			}
		}
		bool removed = false;
		for (long junction : junctionOrder) {
			auto &found = spurs[junction];
			std::sort(found.begin(), found.end());
			const long drop = std::max(0L, degree[junction] - 2);
			for (long i = 0; i < std::min(drop, long(found.size())); ++i) {
				for (long e : std::get<2>(found[i])) keep[e] = 0;
				removed = true;
			}
		}
		if (!removed) break;
	}
	std::vector<Edge> out;
	for (size_t i = 0; i < edges.size(); ++i)
		if (keep[i]) out.push_back(edges[i]);
	return out;
}

std::vector<std::vector<long>> tracePaths(long n, const std::vector<Edge> &edges)
{
	const Adjacency adj = adjacency(n, edges);
	std::vector<long> degree(n);
	for (long i = 0; i < n; ++i) degree[i] = adj.indptr[i + 1] - adj.indptr[i];
	std::vector<char> used(edges.size(), 0);
	std::vector<std::vector<long>> paths;
	auto walk = [&](long start, long j) {
		std::vector<long> path{start};
		while (true) {
			used[adj.eid[j]] = 1;
			const long node = adj.nbr[j];
			path.push_back(node);
			if (degree[node] != 2) return path;
			j = -1;
			for (long k = adj.indptr[node]; k < adj.indptr[node + 1]; ++k)
				if (!used[adj.eid[k]]) { j = k; break; }
			if (j < 0) return path;
		}
	};
	for (long node = 0; node < n; ++node) {
		if (degree[node] == 2 || degree[node] == 0) continue;
		for (long j = adj.indptr[node]; j < adj.indptr[node + 1]; ++j)
			if (!used[adj.eid[j]]) paths.push_back(walk(node, j));
	}
	for (long node = 0; node < n; ++node) {
		if (degree[node] != 2) continue;
		const long j = adj.indptr[node];
		if (!used[adj.eid[j]]) paths.push_back(walk(node, j));
	}
	return paths;
}

// ---------------------------------------------------------------- pieces (trace.py)

struct Piece {
	std::vector<long> nodes;
	std::vector<Vec3> points;
	bool closed = false;

	double length() const
	{
		std::vector<double> seg;
		for (size_t i = 1; i < points.size(); ++i) seg.push_back(norm(sub(points[i], points[i - 1])));
		if (closed && !points.empty()) seg.push_back(norm(sub(points[0], points.back())));
		return pairwiseSum(seg);
	}
	Piece reversed() const
	{
		Piece r{nodes, points, false};
		std::reverse(r.nodes.begin(), r.nodes.end());
		std::reverse(r.points.begin(), r.points.end());
		return r;
	}
	Piece select(const std::vector<long> &sel) const
	{
		Piece r;
		for (long i : sel) r.nodes.push_back(nodes[i]), r.points.push_back(points[i]);
		return r;
	}
};

std::vector<double> arc(const std::vector<Vec3> &p)
{
	std::vector<double> cum{0.0};
	for (size_t i = 1; i < p.size(); ++i) cum.push_back(cum.back() + norm(sub(p[i], p[i - 1])));
	return cum;
}

std::vector<Vec3> padded(const Piece &pc, long pad)
{
	if (!pc.closed) return pc.points;
	const long m = long(pc.points.size());
	const long reps = (pad + m - 1) / m;
	std::vector<Vec3> all;
	for (long r = 0; r < 2 * reps + 1; ++r) all.insert(all.end(), pc.points.begin(), pc.points.end());
	return std::vector<Vec3>(all.begin() + (m * reps - pad), all.begin() + (m * reps - pad) + m + 2 * pad);
}

std::vector<Vec3> tangents(const Piece &pc, double window)
{
	const long m = long(pc.points.size());
	const long pad = pc.closed ? m : 0;
	const std::vector<Vec3> p = padded(pc, pad);
	const std::vector<double> cum = arc(p);
	const long last = long(cum.size()) - 1;
	std::vector<Vec3> t(m);
	for (long i = 0; i < m; ++i) {
		const long at = i + pad;
		const long back = clip(searchRight(cum, cum[at] - window) - 1, 0, last);
		const long ahead = clip(searchLeft(cum, cum[at] + window), 0, last);
		t[i] = unit(sub(p[ahead], p[back]));
	}
	return t;
}

// Concatenated pieces, arc length within each piece and the key that keeps pieces apart
// (batch_tangents, _ends).
struct Batch {
	std::vector<Vec3> points;
	std::vector<long> starts, stops, piece;
	std::vector<double> cum;
};

Batch batch(const std::vector<const Piece *> &pieces)
{
	Batch b;
	for (size_t i = 0; i < pieces.size(); ++i) {
		b.starts.push_back(long(b.points.size()));
		b.points.insert(b.points.end(), pieces[i]->points.begin(), pieces[i]->points.end());
		b.stops.push_back(long(b.points.size()) - 1);
		b.piece.insert(b.piece.end(), pieces[i]->points.size(), long(i));
	}
	const size_t total = b.points.size();
	std::vector<double> step(total > 0 ? total - 1 : 0);
	for (size_t i = 0; i + 1 < total; ++i) step[i] = norm(sub(b.points[i + 1], b.points[i]));
	for (size_t i = 1; i < b.starts.size(); ++i) step[b.starts[i] - 1] = 0.0;
	b.cum.assign(1, 0.0);
	for (double s : step) b.cum.push_back(b.cum.back() + s);
	std::vector<double> base(total);
	for (size_t i = 0; i < total; ++i) base[i] = b.cum[b.starts[b.piece[i]]];
	for (size_t i = 0; i < total; ++i) b.cum[i] -= base[i];
	return b;
}

std::vector<double> keys(const Batch &b, double gap)
{
	std::vector<double> key(b.cum.size());
	for (size_t i = 0; i < key.size(); ++i) key[i] = b.cum[i] + double(b.piece[i]) * gap;
	return key;
}

double maxOf(const std::vector<double> &v)
{
	double m = -INF;
	for (double x : v) m = std::max(m, x);
	return m;
}

std::vector<Vec3> batchTangents(const std::vector<Piece> &pieces, double window)
{
	std::vector<const Piece *> ptrs;
	for (const Piece &pc : pieces) ptrs.push_back(&pc);
	const Batch b = batch(ptrs);
	std::vector<Vec3> out(b.points.size());
	if (out.empty()) return out;
	const double gap = maxOf(b.cum) + 2 * window + 1.0;
	const std::vector<double> key = keys(b, gap);
	for (size_t i = 0; i < key.size(); ++i) {
		const long lo = b.starts[b.piece[i]], hi = b.stops[b.piece[i]];
		const long back = clip(searchRight(key, key[i] - window) - 1, lo, hi);
		const long ahead = clip(searchLeft(key, key[i] + window), lo, hi);
		out[i] = unit(sub(b.points[ahead], b.points[back]));
	}
	for (size_t i = 0; i < pieces.size(); ++i)
		if (pieces[i].closed) {
			const std::vector<Vec3> t = tangents(pieces[i], window);
			std::copy(t.begin(), t.end(), out.begin() + b.starts[i]);
		}
	return out;
}

// One scale of trace._least_turn: the turn between the chords before and after each
// vertex where neither is empty (numpy's arccos of all the vertices at once: math.acos)
void addTurns(const std::vector<Vec3> &before, const std::vector<Vec3> &after, const ms_curves_math &math,
              std::vector<double> &least, std::vector<int> &valid)
{
	const size_t m = before.size();
	std::vector<double> cs(m), angle(m);
	for (size_t i = 0; i < m; ++i) cs[i] = std::max(-1.0, std::min(1.0, edot(before[i], after[i])));
	math.acos(cs.data(), angle.data(), int64_t(m));
	for (size_t i = 0; i < m; ++i) {
		if (!(norm(before[i]) > 0 && norm(after[i]) > 0)) continue;
		valid[i]++;
		least[i] = std::min(least[i], degrees(angle[i]));
	}
}

std::vector<double> turnAngles(const Piece &pc, double spacing, const ms_curves_math &math)
{
	const long m = long(pc.points.size());
	const long pad = pc.closed ? m : 0;
	const std::vector<Vec3> p = padded(pc, pad);
	const std::vector<double> cum = arc(p);
	const long last = long(p.size()) - 1;
	std::vector<double> least(m, INF);
	std::vector<int> valid(m, 0);
	std::vector<Vec3> before(m), after(m);
	for (int s = 0; s < N_SCALES; ++s) {
		const double scale = TURN_SCALES[s] * spacing;
		for (long i = 0; i < m; ++i) {
			const double c = cum[i + pad];
			const long farB = clip(searchRight(cum, c + -MS_CURVE_TURN_OUTER * scale) - 1, 0, last);
			const long nearB = clip(searchRight(cum, c + -MS_CURVE_TURN_INNER * scale) - 1, 0, last);
			const long farA = clip(searchLeft(cum, c + MS_CURVE_TURN_OUTER * scale), 0, last);
			const long nearA = clip(searchLeft(cum, c + MS_CURVE_TURN_INNER * scale), 0, last);
			before[i] = unit(sub(p[nearB], p[farB]));
			after[i] = unit(sub(p[farA], p[nearA]));
		}
		addTurns(before, after, math, least, valid);
	}
	std::vector<double> angle(m);
	for (long i = 0; i < m; ++i) angle[i] = valid[i] >= MS_CURVE_MIN_TURN_SCALES ? least[i] : 0.0;
	return angle;
}

// trace._open_turn_angles: turnAngles of many open pieces in one pass over their batch
// (arc lengths and chords as in ends()), one vector per piece
std::vector<std::vector<double>> openTurnAngles(const std::vector<const Piece *> &pieces, double spacing,
                                                const ms_curves_math &math)
{
	std::vector<std::vector<double>> out;
	if (pieces.empty()) return out;
	const Batch b = batch(pieces);
	const double smax = TURN_SCALES[N_SCALES - 1] * spacing;
	const double gap = maxOf(b.cum) + 2 * MS_CURVE_TURN_OUTER * smax + 1.0;
	const std::vector<double> key = keys(b, gap);
	const size_t total = key.size();
	std::vector<double> least(total, INF);
	std::vector<int> valid(total, 0);
	std::vector<Vec3> before(total), after(total);
	for (int s = 0; s < N_SCALES; ++s) {
		const double scale = TURN_SCALES[s] * spacing;
		for (size_t i = 0; i < total; ++i) {
			const long lo = b.starts[b.piece[i]], hi = b.stops[b.piece[i]];
			const double c = key[i];
			const long farB = clip(searchRight(key, c + -MS_CURVE_TURN_OUTER * scale) - 1, lo, hi);
			const long nearB = clip(searchRight(key, c + -MS_CURVE_TURN_INNER * scale) - 1, lo, hi);
			const long farA = clip(searchLeft(key, c + MS_CURVE_TURN_OUTER * scale), lo, hi);
			const long nearA = clip(searchLeft(key, c + MS_CURVE_TURN_INNER * scale), lo, hi);
			before[i] = unit(sub(b.points[nearB], b.points[farB]));
			after[i] = unit(sub(b.points[farA], b.points[nearA]));
		}
		addTurns(before, after, math, least, valid);
	}
	for (size_t k = 0; k < pieces.size(); ++k) {
		std::vector<double> angle;
		for (long i = b.starts[k]; i <= b.stops[k]; ++i) angle.push_back(valid[i] >= MS_CURVE_MIN_TURN_SCALES ? least[i] : 0.0);
		out.push_back(angle);
	}
	return out;
}

// Split a piece at the vertices `at` (sorted): closed pieces start at the first.
std::vector<Piece> splitAt(const Piece &pc, const std::vector<long> &at)
{
	const long m = long(pc.points.size());
	std::vector<long> idx, bounds;
	if (pc.closed) {
		for (long i = at[0]; i < m; ++i) idx.push_back(i);
		for (long i = 0; i <= at[0]; ++i) idx.push_back(i);
		for (long c : at) bounds.push_back(c - at[0]);
		bounds.push_back(m);
	} else {
		for (long i = 0; i < m; ++i) idx.push_back(i);
		bounds.push_back(0);
		bounds.insert(bounds.end(), at.begin(), at.end());
		bounds.push_back(m - 1);
	}
	std::vector<Piece> out;
	for (size_t k = 0; k + 1 < bounds.size(); ++k) {
		const long a = bounds[k], b = bounds[k + 1];
		if (b > a) out.push_back(pc.select(std::vector<long>(idx.begin() + a, idx.begin() + b + 1)));
	}
	return out;
}

std::vector<Piece> cutAtTurns(const Piece &pc, const std::vector<double> &angle, double spacing)
{
	const double window = MS_CURVE_TURN_OUTER * spacing;
	const std::vector<double> cum = arc(pc.points);
	std::vector<long> order(angle.size());
	std::iota(order.begin(), order.end(), 0L);
	std::stable_sort(order.begin(), order.end(), [&](long x, long y) { return -angle[x] < -angle[y]; });
	const double total = pc.closed ? pc.length() : 0.0;
	std::vector<long> cuts;
	for (long i : order) {
		if (angle[i] <= MS_CURVE_CORNER_TURN) break;
		bool near = false;
		for (long c : cuts) {
			const double d = std::fabs(cum[c] - cum[i]);
			if (pc.closed ? std::min(d, total - d) < window : d < window) near = true;
		}
		if (!near) cuts.push_back(i);
	}
	if (cuts.empty() || (pc.closed && cuts.size() == 1)) return {pc};
	std::sort(cuts.begin(), cuts.end());
	return splitAt(pc, cuts);
}

struct Ends {
	std::vector<long> piece, side;
	std::vector<Vec3> point;
	std::vector<Vec3> out[N_SCALES];
	std::vector<Vec3> anchor[N_SCALES];  // the end chord's vertex nearer the end
};

Ends ends(const std::vector<Piece> &pieces, double spacing)
{
	Ends e;
	std::vector<long> which;
	std::vector<const Piece *> ptrs;
	for (size_t i = 0; i < pieces.size(); ++i)
		if (!pieces[i].closed && pieces[i].points.size() >= 2) which.push_back(long(i)), ptrs.push_back(&pieces[i]);
	if (which.empty()) return e;
	const Batch b = batch(ptrs);
	const double smax = TURN_SCALES[N_SCALES - 1] * spacing;
	const double gap = maxOf(b.cum) + 2 * MS_CURVE_TURN_OUTER * smax + 1.0;
	const std::vector<double> key = keys(b, gap);
	const size_t q = which.size();
	for (size_t i = 0; i < q; ++i) {
		const long start = b.starts[i], stop = b.stops[i];
		e.piece.push_back(which[i]), e.piece.push_back(which[i]);
		e.side.push_back(0), e.side.push_back(1);
		e.point.push_back(b.points[start]), e.point.push_back(b.points[stop]);
		const Vec3 chord = sub(b.points[stop], b.points[start]);
		for (int s = 0; s < N_SCALES; ++s) {
			const double scale = TURN_SCALES[s] * spacing;
			const long nearF = clip(searchLeft(key, key[start] + MS_CURVE_TURN_INNER * scale), start, stop);
			const long farF = clip(searchLeft(key, key[start] + MS_CURVE_TURN_OUTER * scale), start, stop);
			const long nearL = clip(searchRight(key, key[stop] - MS_CURVE_TURN_INNER * scale) - 1, start, stop);
			const long farL = clip(searchRight(key, key[stop] - MS_CURVE_TURN_OUTER * scale) - 1, start, stop);
			const Vec3 first = nearF == farF ? chord : sub(b.points[farF], b.points[nearF]);
			const Vec3 lastv = nearL == farL ? chord : sub(b.points[nearL], b.points[farL]);
			e.out[s].push_back(neg(unit(first)));
			e.out[s].push_back(unit(lastv));
			e.anchor[s].push_back(nearF == farF ? b.points[start] : b.points[nearF]);
			e.anchor[s].push_back(nearL == farL ? b.points[stop] : b.points[nearL]);
		}
	}
	return e;
}

// scipy's query_pairs(r): pairs i < j with squared distance <= r^2, sorted
std::vector<Edge> pairsWithin(const std::vector<Vec3> &pts, double r)
{
	const KdTree tree(pts);
	std::vector<Edge> out;
	for (size_t i = 0; i < pts.size(); ++i)
		for (long j : tree.ball(pts[i], r))
			if (j > long(i)) out.push_back({long(i), j});
	return out;
}

std::vector<std::vector<long>> endClusters(const Ends &e, const std::vector<Piece> &pieces, double spacing)
{
	const long q = long(e.piece.size());
	DisjointSets sets(q);
	for (const Edge &p : pairsWithin(e.point, MS_CURVE_GAP_LENGTH * spacing)) {
		if (e.piece[p[0]] == e.piece[p[1]] && pieces[e.piece[p[0]]].length() < MS_CURVE_LOOP_LENGTH * MS_CURVE_GAP_LENGTH * spacing)
			continue;
		sets.join(p[0], p[1]);
	}
	return sets.groups();
}

bool continues(const Ends &e, long a, long b, double spacing)
{
	for (int s = 0; s < N_SCALES; ++s) {
		const Vec3 &oa = e.out[s][a], &ob = e.out[s][b];
		if (-bdot(oa, ob) < std::cos(radians(MS_CURVE_CORNER_TURN))) continue;
		for (const Vec3 &gap : {sub(e.point[b], e.point[a]), sub(e.anchor[s][b], e.anchor[s][a])}) {
			const double offA = bnorm(sub(gap, mul(bdot(gap, oa), oa)));
			const double offB = bnorm(sub(gap, mul(bdot(gap, ob), ob)));
			if (std::max(offA, offB) <= MS_CURVE_LATERAL_OFFSET * spacing) return true;
		}
	}
	return false;
}

// trace.meeting_clusters: the free ends added to the ends whose lines they meet at a
// corner across up to MS_CURVE_LONG_GAP spacings
std::vector<std::vector<long>> meetingClusters(const Ends &e, const std::vector<std::vector<long>> &clusters,
                                               double spacing)
{
	const long q = long(e.piece.size());
	DisjointSets sets(q);  // each cluster already one set
	std::vector<char> freeEnd(q, 1);
	for (const auto &c : clusters)
		for (long i : c) sets.parent[i] = c[0], freeEnd[i] = 0;
	if (q < 2 || std::find(freeEnd.begin(), freeEnd.end(), 1) == freeEnd.end()) return clusters;
	struct Pair { double gap; long a, b; };
	std::vector<Pair> pairs;
	for (const Edge &p : pairsWithin(e.point, MS_CURVE_LONG_GAP * spacing))
		if ((freeEnd[p[0]] || freeEnd[p[1]]) && e.piece[p[0]] != e.piece[p[1]])
			pairs.push_back({norm(sub(e.point[p[0]], e.point[p[1]])), p[0], p[1]});
	std::stable_sort(pairs.begin(), pairs.end(), [](const Pair &x, const Pair &y) {
		return std::tie(x.gap, x.a, x.b) < std::tie(y.gap, y.a, y.b);
	});
	const std::vector<Vec3> &out = e.out[MS_CURVE_CORNER_SCALE], &anchor = e.anchor[MS_CURVE_CORNER_SCALE];
	const double turn = std::cos(radians(MS_CURVE_CORNER_TURN));
	for (const Pair &p : pairs) {
		const long a = p.a, b = p.b;
		const double c = bdot(out[a], out[b]);
		if (std::abs(c) > turn) continue;
		const Vec3 w = sub(anchor[a], anchor[b]);
		const double da = bdot(out[a], w), db = bdot(out[b], w);
		const double det = 1.0 - c * c;
		const double sa = (c * db - da) / det, sb = (db - c * da) / det;
		const Vec3 xa = add(anchor[a], mul(sa, out[a])), xb = add(anchor[b], mul(sb, out[b]));
		if (bnorm(sub(xa, xb)) > MS_CURVE_LATERAL_OFFSET * spacing) continue;
		const Vec3 meet = mul(0.5, add(xa, xb));
		const double aheadA = bdot(sub(meet, e.point[a]), out[a]), aheadB = bdot(sub(meet, e.point[b]), out[b]);
		if (std::min(aheadA, aheadB) < -MS_CURVE_LATERAL_OFFSET * spacing || std::max(aheadA, aheadB) > MS_CURVE_LONG_GAP * spacing)
			continue;
		sets.join(a, b);
	}
	return sets.groups();
}

bool facesGap(const Ends &e, long a, long b)
{
	const Vec3 gap = sub(e.point[b], e.point[a]);
	const double limit = std::cos(radians(MS_CURVE_CORNER_TURN)) * bnorm(gap);
	return bdot(gap, e.out[N_SCALES - 1][a]) >= limit && bdot(neg(gap), e.out[N_SCALES - 1][b]) >= limit;
}

using Bridge = std::function<Piece(long, long)>;

std::vector<Piece> bridged(const std::vector<Piece> &parts, bool closed, const Bridge &bridge)
{
	std::vector<Piece> out;
	const size_t n = parts.size();
	const size_t pairs = closed ? n : n - 1;
	for (size_t k = 0; k < pairs; ++k) {
		const Piece &a = parts[k], &b = parts[(k + 1) % n];
		out.push_back(a);
		if (a.nodes.back() != b.nodes.front()) {
			Piece mid = bridge(a.nodes.back(), b.nodes.front());
			if (!mid.nodes.empty()) out.push_back(mid);
		}
	}
	if (!closed) out.push_back(parts.back());
	return out;
}

std::vector<Piece> joinPieces(const std::vector<Piece> &pieces, double spacing, const Bridge *bridge)
{
	const Ends e = ends(pieces, spacing);
	const auto clusters = endClusters(e, pieces, spacing);
	std::map<std::pair<long, long>, std::pair<long, long>> link;
	auto connect = [&](long i, long j) {
		const long a = e.piece[i], b = e.piece[j], sa = e.side[i], sb = e.side[j];
		if (link.count({a, sa}) || link.count({b, sb})) return;
		if (a == b && pieces[a].length() < MS_CURVE_LOOP_LENGTH * MS_CURVE_GAP_LENGTH * spacing) return;
		link[{a, sa}] = {b, sb};
		link[{b, sb}] = {a, sa};
	};
	for (const auto &c : clusters)
		if (c.size() == 2 && continues(e, c[0], c[1], spacing)) connect(c[0], c[1]);
	std::vector<char> isFree(e.piece.size(), 1);
	for (const auto &c : clusters)
		for (long i : c) isFree[i] = 0;
	std::vector<long> alone;
	for (size_t i = 0; i < isFree.size(); ++i)
		if (isFree[i]) alone.push_back(long(i));
	if (alone.size() >= 2) {
		std::vector<Vec3> pts;
		for (long i : alone) pts.push_back(e.point[i]);
		std::vector<Edge> pairs;
		for (const Edge &p : pairsWithin(pts, MS_CURVE_LONG_GAP * spacing)) pairs.push_back({alone[p[0]], alone[p[1]]});
		std::vector<double> gaps(pairs.size());
		for (size_t k = 0; k < pairs.size(); ++k) gaps[k] = norm(sub(e.point[pairs[k][0]], e.point[pairs[k][1]]));
		std::vector<long> order(pairs.size());
		std::iota(order.begin(), order.end(), 0L);
		std::stable_sort(order.begin(), order.end(), [&](long x, long y) {
			if (gaps[x] != gaps[y]) return gaps[x] < gaps[y];
			return pairs[x] < pairs[y];
		});
		for (long k : order) {
			const long i = pairs[k][0], j = pairs[k][1];
			if (continues(e, i, j, spacing) && facesGap(e, i, j)) connect(i, j);
		}
	}
	if (link.empty()) return pieces;
	std::vector<char> done(pieces.size(), 0);
	std::vector<Piece> out;
	auto chain = [&](long start, long entry) {
		std::vector<Piece> parts;
		long p = start, side = entry;
		bool closed = false;
		while (true) {
			done[p] = 1;
			parts.push_back(side == 0 ? Piece{pieces[p].nodes, pieces[p].points, false} : pieces[p].reversed());
			auto nxt = link.find({p, 1 - side});
			if (nxt == link.end()) break;
			if (done[nxt->second.first]) {
				closed = nxt->second == std::make_pair(start, entry);
				break;
			}
			p = nxt->second.first, side = nxt->second.second;
		}
		if (bridge != nullptr) parts = bridged(parts, closed, *bridge);
		Piece r;
		for (const Piece &q : parts)
			for (size_t k = 0; k < q.nodes.size(); ++k)
				if (r.nodes.empty() || q.nodes[k] != r.nodes.back())
					r.nodes.push_back(q.nodes[k]), r.points.push_back(q.points[k]);
		if (closed && r.nodes.size() > 1 && r.nodes.front() == r.nodes.back())
			r.nodes.pop_back(), r.points.pop_back();
		r.closed = closed;
		return r;
	};
	for (size_t i = 0; i < pieces.size(); ++i) {
		if (done[i]) continue;
		if (pieces[i].closed) {
			done[i] = 1;
			out.push_back(pieces[i]);
		} else if (!link.count({long(i), 0})) {
			out.push_back(chain(long(i), 0));
		} else if (!link.count({long(i), 1})) {
			out.push_back(chain(long(i), 1));
		}
	}
	for (size_t i = 0; i < pieces.size(); ++i)
		if (!done[i]) out.push_back(chain(long(i), 0));
	return out;
}

// trace._vertex_ahead: the vertex of another curve that end q's line (the end chord at
// MS_CURVE_CORNER_SCALE) reaches first, ahead of the end, within MS_CURVE_LONG_GAP spacings
// of it and MS_CURVE_LATERAL_OFFSET spacings of the line (the lowest index of equally near
// ones); -1 when none
long vertexAhead(const Ends &e, long q, const KdTree &tree, const std::vector<Vec3> &data,
                 const std::vector<long> &owner, double spacing)
{
	const Vec3 &out = e.out[MS_CURVE_CORNER_SCALE][q], &anchor = e.anchor[MS_CURVE_CORNER_SCALE][q];
	const Vec3 &point = e.point[q];
	long best = -1;
	double bestAhead = INF;
	for (long j : tree.ball(point, MS_CURVE_LONG_GAP * spacing)) {
		if (owner[j] == e.piece[q]) continue;
		const double ahead = bdot(sub(data[j], point), out);
		const Vec3 w = sub(data[j], anchor);
		if (ahead <= 0.0 || bnorm(sub(w, mul(bdot(w, out), out))) > MS_CURVE_LATERAL_OFFSET * spacing) continue;
		if (ahead < bestAhead || (ahead == bestAhead && j < best)) best = j, bestAhead = ahead;
	}
	return best;
}

// trace.split_at_touches; lines (clouds): where no other curve is within
// MS_CURVE_GAP_LENGTH spacings of a free end, the end's line reaches on (vertexAhead)
std::vector<Piece> splitAtTouches(const std::vector<Piece> &pieces, double spacing, bool lines)
{
	const Ends e = ends(pieces, spacing);
	const auto clusters = endClusters(e, pieces, spacing);
	std::vector<char> isFree(e.piece.size(), 1);
	for (const auto &c : clusters)
		for (long i : c) isFree[i] = 0;
	if (std::find(isFree.begin(), isFree.end(), 1) == isFree.end()) return pieces;
	std::vector<long> owner, local;
	std::vector<Vec3> data;
	for (size_t i = 0; i < pieces.size(); ++i)
		for (size_t k = 0; k < pieces[i].points.size(); ++k)
			owner.push_back(long(i)), local.push_back(long(k)), data.push_back(pieces[i].points[k]);
	const double reach = MS_CURVE_GAP_LENGTH * spacing;
	const KdTree tree(data);
	std::map<long, std::set<long>> cuts;
	for (size_t q = 0; q < isFree.size(); ++q) {
		if (!isFree[q]) continue;
		long best = -1;
		double bestD = INF;
		for (long j : tree.ball(e.point[q], reach)) {
			if (owner[j] == e.piece[q]) continue;
			const double d = bnorm(sub(data[j], e.point[q]));
			if (d < bestD) bestD = d, best = j;
		}
		if (best < 0 && lines) best = vertexAhead(e, long(q), tree, data, owner, spacing);
		if (best < 0) continue;
		const Piece &pc = pieces[owner[best]];
		const long v = local[best];
		const std::vector<double> cum = arc(pc.points);
		if (pc.closed || (cum[v] > reach && cum.back() - cum[v] > reach)) cuts[owner[best]].insert(v);
	}
	if (cuts.empty()) return pieces;
	std::vector<Piece> out;
	for (size_t i = 0; i < pieces.size(); ++i) {
		auto it = cuts.find(long(i));
		if (it == cuts.end()) {
			out.push_back(pieces[i]);
			continue;
		}
		for (Piece &pc : splitAt(pieces[i], std::vector<long>(it->second.begin(), it->second.end())))
			out.push_back(pc);
	}
	return out;
}

// ---------------------------------------------------------------- meshes

// Shortest paths along the mesh edges of the faces touching a feature vertex (MeshPaths).
class MeshPaths {
public:
	MeshPaths(const std::vector<Vec3> &pts, const std::vector<std::array<int, 3>> &faces,
	          const std::vector<char> &mask)
	    : pts_(pts)
	{
		std::vector<std::array<int, 3>> f;
		for (const auto &t : faces)
			if (mask[t[0]] || mask[t[1]] || mask[t[2]]) f.push_back(t);
		for (const auto &t : f) ids_.insert(ids_.end(), t.begin(), t.end());
		std::sort(ids_.begin(), ids_.end());
		ids_.erase(std::unique(ids_.begin(), ids_.end()), ids_.end());
		std::set<Edge> e;
		for (const auto &t : f)
			for (int k = 0; k < 3; ++k) {
				const long a = local(t[k]), b = local(t[(k + 1) % 3]);
				e.insert({std::min(a, b), std::max(a, b)});
			}
		const long n = long(ids_.size());
		std::vector<std::vector<std::pair<long, double>>> rows(n);
		for (const Edge &x : e) {
			const double d = norm(sub(pts_[ids_[x[0]]], pts_[ids_[x[1]]]));
			rows[x[0]].push_back({x[1], d});
			rows[x[1]].push_back({x[0], d});
		}
		for (auto &r : rows) std::sort(r.begin(), r.end());
		rows_ = rows;
		for (long v : ids_) positions_.push_back(pts_[v]);
		tree_.reset(new KdTree(positions_));
	}

	// the nearest vertex, the lowest of equally near ones
	long nearest(const Vec3 &p) const { return ids_[tree_->query(p, 1)[0].second]; }

	// vertices strictly between a and b on the shortest path; found = false when none is
	// within limit (MeshPaths.path: a heap of (distance, vertex), a vertex's predecessor
	// the first settled vertex reaching it at its final distance)
	std::vector<long> path(long a, long b, double limit, bool &found) const
	{
		found = false;
		const long ia = local(a), ib = local(b);
		if (ia < 0 || ib < 0) return {};
		if (ia == ib) {
			found = true;
			return {};
		}
		const long n = long(ids_.size());
		std::vector<double> val(n, INF);
		std::vector<long> pred(n, -1);
		std::vector<char> state(n, 0);  // 0 not in heap, 1 in heap, 2 scanned
		std::priority_queue<std::pair<double, long>, std::vector<std::pair<double, long>>,
		                    std::greater<std::pair<double, long>>> heap;
		val[ia] = 0.0, state[ia] = 1;
		heap.push({0.0, ia});
		while (!heap.empty()) {
			const double d = heap.top().first;
			const long v = heap.top().second;
			heap.pop();
			if (state[v] == 2 || d != val[v]) continue;
			state[v] = 2;
			if (v == ib) break;
			for (const auto &entry : rows_[v]) {
				const long j = entry.first;
				if (state[j] == 2) continue;
				const double next = d + entry.second;
				if (!(next <= limit)) continue;
				if (state[j] == 0 || val[j] > next) {
					state[j] = 1, val[j] = next, pred[j] = v;
					heap.push({next, j});
				}
			}
		}
		if (state[ib] != 2) return {};
		found = true;
		std::vector<long> inner;
		for (long v = pred[ib]; v != ia; v = pred[v]) inner.push_back(ids_[v]);
		std::reverse(inner.begin(), inner.end());
		return inner;
	}

private:
	const std::vector<Vec3> &pts_;
	std::vector<long> ids_;
	std::vector<std::vector<std::pair<long, double>>> rows_;
	std::vector<Vec3> positions_;
	std::unique_ptr<KdTree> tree_;

	long local(long v) const
	{
		auto it = std::lower_bound(ids_.begin(), ids_.end(), v);
		return (it == ids_.end() || *it != v) ? -1 : long(it - ids_.begin());
	}
};

std::vector<Piece> skeletonPieces(long n, const std::vector<Edge> &edges, const std::vector<double> &w,
                                  const std::vector<Vec3> &pos, double spacing,
                                  const std::vector<long> &feat, double bridgeReach = 0.0,
                                  double bridgeAngle = 0.0)
{
	std::vector<Edge> forest = spanningForest(n, edges, w);
	forest = closeLoops(n, forest, edges, pos, MS_CURVE_LOOP_LENGTH * MS_CURVE_GAP_LENGTH * spacing);
	// clouds: the free ends bridged (bridgeReach in spacings, bridgeAngle in degrees)
	if (bridgeReach > 0.0) forest = bridgeLeaves(n, forest, pos, bridgeReach * spacing, bridgeAngle);
	forest = pruneSpurs(n, forest, pos, MS_CURVE_SPUR_LENGTH * spacing);
	std::vector<Piece> pieces;
	for (std::vector<long> path : tracePaths(n, forest)) {
		const bool closed = path.size() > 2 && path.front() == path.back();
		if (closed) path.pop_back();
		Piece pc;
		pc.closed = closed;
		for (long v : path) pc.nodes.push_back(feat.empty() ? v : feat[v]), pc.points.push_back(pos[v]);
		pieces.push_back(pc);
	}
	return pieces;
}

// the skeleton of the feature vertices rest (those away from the sharp edges); the
// spacing around all the features mask
std::vector<Piece> meshPieces(const std::vector<Vec3> &pts, const std::vector<std::array<int, 3>> &faces,
                              const std::vector<char> &mask, const std::vector<long> &feat,
                              const std::vector<Vec3> &fp, const std::vector<char> &rest, double &spacing)
{
	spacing = 0.0;
	std::vector<std::array<int, 3>> near;
	for (const auto &t : faces)
		if (int(mask[t[0]] != 0) + int(mask[t[1]] != 0) + int(mask[t[2]] != 0) >= 2) near.push_back(t);
	if (near.empty()) return {};
	std::vector<Vec3> normal(near.size());
	for (size_t i = 0; i < near.size(); ++i) {
		const Vec3 &p0 = pts[near[i][0]], &p1 = pts[near[i][1]], &p2 = pts[near[i][2]];
		const Vec3 c = cross(sub(p1, p0), sub(p2, p0));
		const double nrm = norm(c);
		const double d = nrm > 0 ? nrm : 1.0;
		normal[i] = {c[0] / d, c[1] / d, c[2] / d};
	}
	const long m = long(near.size());
	std::vector<Edge> e(3 * m);
	std::vector<long> face(3 * m);
	for (long i = 0; i < m; ++i)
		for (int k = 0; k < 3; ++k) {
			const long a = near[i][k], b = near[i][(k + 1) % 3];
			e[k * m + i] = {std::min(a, b), std::max(a, b)};
			face[k * m + i] = i;
		}
	std::vector<long> order(3 * m);
	std::iota(order.begin(), order.end(), 0L);
	std::stable_sort(order.begin(), order.end(), [&](long x, long y) { return e[x] < e[y]; });
	std::vector<double> allLengths;
	std::vector<Edge> edges;
	std::vector<double> weights;
	for (size_t s = 0; s < order.size();) {
		size_t t = s + 1;
		while (t < order.size() && e[order[t]] == e[order[s]]) ++t;
		const Edge ed = e[order[s]];
		const double length = norm(sub(pts[ed[0]], pts[ed[1]]));
		allLengths.push_back(length);
		if (mask[ed[0]] && mask[ed[1]]) {
			double cosTurn = 0.0;  // boundary / non-manifold: 90 degrees
			if (t - s == 2) cosTurn = edot(normal[face[order[s]]], normal[face[order[s + 1]]]);
			const double sinHalf = std::sqrt(std::max(0.0, std::min(1.0, (1.0 - cosTurn) / 2.0)));
			edges.push_back(ed);
			weights.push_back(length / (sinHalf + MS_CURVE_MESH_FLAT_WEIGHT));
		}
		s = t;
	}
	if (edges.empty()) return {};
	spacing = median(allLengths);
	std::vector<long> node(pts.size(), -1);
	for (size_t i = 0; i < feat.size(); ++i) node[feat[i]] = long(i);
	std::vector<Edge> local;
	std::vector<double> w;
	for (size_t i = 0; i < edges.size(); ++i) {
		const long a = node[edges[i][0]], b = node[edges[i][1]];
		if (a >= 0 && b >= 0 && rest[edges[i][0]] && rest[edges[i][1]]) local.push_back({a, b}), w.push_back(weights[i]);
	}
	return skeletonPieces(long(feat.size()), local, w, fp, spacing, feat);
}

// ---------------------------------------------------------------- clouds (refine.py)

// Most cells cellNeighbourhood flags in a dense grid (one byte each).
constexpr long MAX_DENSE_CELLS = 1L << 24;

// A grid cell by its three coordinates (cellNeighbourhood's cells beyond a dense grid).
struct Cell {
	long a, b, c;
	bool operator==(const Cell &o) const { return a == o.a && b == o.b && c == o.c; }
};
struct CellHash {
	size_t operator()(const Cell &k) const
	{
		uint64_t h = uint64_t(k.a) * 0x9e3779b97f4a7c15ULL;
		h = (h ^ (h >> 29) ^ uint64_t(k.b)) * 0xbf58476d1ce4e5b9ULL;
		h = (h ^ (h >> 31) ^ uint64_t(k.c)) * 0x94d049bb133111ebULL;
		return size_t(h ^ (h >> 32));
	}
};

// The valid points (indices, increasing) whose cell is among the 3x3x3 cells around a
// centre: mark(a, b, c) records a wanted cell, wanted(a, b, c) reads one (from several
// threads).
template <class Cellof, class Mark, class Wanted>
std::vector<long> pointsInCells(const std::vector<Vec3> &pts, const std::vector<char> &valid,
                                const std::vector<Vec3> &centres, const Cellof &cell, const Mark &mark,
                                const Wanted &wanted)
{
	for (const Vec3 &c : centres) {
		const long a = cell(c, 0), b = cell(c, 1), z = cell(c, 2);
		for (long i = -1; i <= 1; ++i)
			for (long j = -1; j <= 1; ++j)
				for (long k = -1; k <= 1; ++k) mark(a + i, b + j, z + k);
	}
	std::vector<char> in(pts.size());
	inBlocks(pts.size(), [&](size_t begin, size_t end) {
		for (size_t i = begin; i < end; ++i)
			in[i] = valid[i] && wanted(cell(pts[i], 0), cell(pts[i], 1), cell(pts[i], 2));
	});
	std::vector<long> out;
	for (size_t i = 0; i < pts.size(); ++i)
		if (in[i]) out.push_back(long(i));
	return out;
}

std::vector<long> cellNeighbourhood(const std::vector<Vec3> &pts, const std::vector<char> &valid,
                                    const std::vector<Vec3> &centres, double radius,
                                    const std::array<Vec3, 2> *bounds)
{
	Vec3 lo{INF, INF, INF}, hi{-INF, -INF, -INF};
	if (bounds != nullptr) {
		lo = (*bounds)[0], hi = (*bounds)[1];
	} else {  // the valid points' box: the others are never read (a far one would blow it up)
		for (size_t i = 0; i < pts.size(); ++i)
			if (valid[i])
				for (int d = 0; d < 3; ++d) lo[d] = std::min(lo[d], pts[i][d]), hi[d] = std::max(hi[d], pts[i][d]);
	}
	auto along = [&](double x, int d) { return std::min(std::max(std::floor((x - lo[d]) / radius), -MS_CURVE_MAX_CELL), MS_CURVE_MAX_CELL); };
	auto cell = [&](const Vec3 &p, int d) { return long(along(p[d], d)) + 1; };
	double span[3];
	for (int d = 0; d < 3; ++d) span[d] = along(hi[d], d) + 3;
	const double cells = span[0] * span[1] * span[2];
	// The wanted cells: a flag per cell where the grid is small enough, else a hash set of
	// the cells' three coordinates (no flat key, which a grid huge against the features'
	// spacing would overflow). A coordinate beyond MS_CURVE_MAX_CELL (the far-points rule
	// keeps inputs well inside it) is clamped to it.
	if (cells <= double(MAX_DENSE_CELLS)) {
		const long dims[3] = {long(span[0]), long(span[1]), long(span[2])};
		auto key = [&](long a, long b, long c) { return (a * dims[1] + b) * dims[2] + c; };
		const long dense = long(cells);
		std::vector<char> flag(size_t(dense), 0);
		return pointsInCells(
		    pts, valid, centres, cell,
		    [&](long a, long b, long c) {
			    const long at = key(a, b, c);
			    if (at >= 0 && at < dense) flag[size_t(at)] = 1;
		    },
		    [&](long a, long b, long c) {
			    const long at = key(a, b, c);
			    return at >= 0 && at < dense && flag[size_t(at)];
		    });
	}
	std::unordered_set<Cell, CellHash> wanted;
	return pointsInCells(
	    pts, valid, centres, cell, [&](long a, long b, long c) { wanted.insert({a, b, c}); },
	    [&](long a, long b, long c) { return wanted.count({a, b, c}) > 0; });
}

// _arm_lines up to numpy's arctan2: the weight total, the centroid and the second moments
struct ArmSums { double total, c[2], sxx, syy, sxy; };

ArmSums armSums(const std::vector<std::array<double, 2>> &xy, const std::vector<double> &w)
{
	const size_t k = xy.size();
	ArmSums r{};
	r.total = pairwiseSum(w);
	const double safe = r.total > 0 ? r.total : 1.0;
	for (int j = 0; j < 2; ++j) {
		double s = w[0] * xy[0][j];
		for (size_t i = 1; i < k; ++i) s += w[i] * xy[i][j];
		r.c[j] = s / safe;
	}
	std::vector<double> xx(k), yy(k), xyv(k);
	for (size_t i = 0; i < k; ++i) {
		const double d0 = xy[i][0] - r.c[0], d1 = xy[i][1] - r.c[1];
		xx[i] = w[i] * (d0 * d0);
		yy[i] = w[i] * (d1 * d1);
		xyv[i] = (w[i] * d0) * d1;
	}
	r.sxx = pairwiseSum(xx), r.syy = pairwiseSum(yy), r.sxy = pairwiseSum(xyv);
	return r;
}

struct ArmLine { double c[2], a[2], rms, total; };

// _arm_lines from the sums and atan2(2 sxy, sxx - syy)
ArmLine armLine(const std::vector<std::array<double, 2>> &xy, const std::vector<double> &w,
                const ArmSums &sums, double angle)
{
	const size_t k = xy.size();
	ArmLine r{};
	r.total = sums.total;
	r.c[0] = sums.c[0], r.c[1] = sums.c[1];
	const double safe = r.total > 0 ? r.total : 1.0;
	const double theta = 0.5 * angle;
	r.a[0] = std::cos(theta), r.a[1] = std::sin(theta);
	std::vector<double> off2(k);
	for (size_t i = 0; i < k; ++i) {
		const double d0 = xy[i][0] - r.c[0], d1 = xy[i][1] - r.c[1];
		const double off = d0 * -r.a[1] + d1 * r.a[0];
		off2[i] = w[i] * (off * off);
	}
	r.rms = std::sqrt(pairwiseSum(off2) / safe);
	return r;
}

double lineOffset(const std::array<double, 2> &p, const ArmLine &l)
{
	const double d0 = p[0] - l.c[0], d1 = p[1] - l.c[1];
	return std::fabs(d0 * l.a[1] - d1 * l.a[0]);
}

// One curve vertex's neighbours in the plane across the curve (plane_intersection_positions).
struct Across {
	Vec3 u, w;
	std::vector<std::array<double, 2>> xy, unitv;
	std::vector<double> weight, w1, w2;
	std::vector<char> use, side;
	ArmLine l1, l2;
};

// Vertices refined together: numpy's exp and arctan2 (math.exp, math.atan2) take each
// batch's values at once.
constexpr size_t REFINE_BATCH = 4096;

// refine.plane_intersection_positions of the vertices [first, last): moved, fitted, flat.
void planeIntersections(size_t first, size_t last, const std::vector<Vec3> &vertices,
                        const std::vector<Vec3> &dirs, const std::vector<std::vector<long>> &nbrs,
                        const std::vector<Vec3> &treePts, const std::vector<char> &treeFeature,
                        const KdTree &tree, double spacing, const ms_curves_math &math, std::vector<Vec3> &moved,
                        std::vector<char> &fitted, std::vector<char> &flat)
{
	const size_t nv = last - first;
	std::vector<Across> across(nv);
	std::vector<double> arg;  // exp's argument, vertex after vertex
	for (size_t v = 0; v < nv; ++v) {
		Across &x = across[v];
		const Vec3 &vertex = vertices[first + v], &t = dirs[first + v];
		const Vec3 helper = std::fabs(t[0]) < MS_CURVE_FRAME_SWITCH ? Vec3{1.0, 0.0, 0.0} : Vec3{0.0, 1.0, 0.0};
		x.u = cross(t, helper);
		const double un = norm(x.u);
		x.u = {x.u[0] / un, x.u[1] / un, x.u[2] / un};
		x.w = cross(t, x.u);
		const std::vector<long> &nb = nbrs[first + v];
		const size_t k = nb.size();
		x.xy.resize(k), x.unitv.resize(k), x.use.resize(k);
		std::vector<double> radius(k);
		// the nearest features of another edge across the curve, ahead and behind along it
		double ahead = std::numeric_limits<double>::infinity(), behind = ahead;
		for (size_t i = 0; i < k; ++i) {
			const Vec3 d = sub(treePts[nb[i]], vertex);
			x.xy[i] = {edot(d, x.u), edot(d, x.w)};
			const double along = edot(d, t) / (MS_CURVE_SLAB * spacing);
			arg.push_back(-0.5 * (along * along));
			const double r = std::sqrt(x.xy[i][0] * x.xy[i][0] + x.xy[i][1] * x.xy[i][1]);
			radius[i] = r;
			if (treeFeature[nb[i]] && r > MS_CURVE_OTHER_EDGE * spacing) {
				if (along > 0) ahead = std::min(ahead, r);
				if (along < 0) behind = std::min(behind, r);
			}
			const double rr = r > 0 ? r : 1.0;
			x.unitv[i] = {x.xy[i][0] / rr, x.xy[i][1] / rr};
		}
		// the arms end short of another edge running beside this one (a thin wall's other
		// rim): seen on both sides along the curve, unlike an edge crossing near a corner
		const double reach = std::max(ahead, behind) - MS_CURVE_OTHER_EDGE_MARGIN * spacing;
		for (size_t i = 0; i < k; ++i)
			x.use[i] = !treeFeature[nb[i]] && radius[i] > MS_CURVE_ZERO_OFFSET * spacing && radius[i] < reach;
	}
	std::vector<double> weight(arg.size());
	math.exp(arg.data(), weight.data(), int64_t(arg.size()));
	size_t at = 0;
	std::vector<double> bisector(2 * nv);
	for (size_t v = 0; v < nv; ++v) {
		Across &x = across[v];
		const size_t k = x.xy.size();
		x.weight.assign(weight.begin() + at, weight.begin() + at + k);
		at += k;
		double *bis = &bisector[2 * v];
		for (int j = 0; j < 2; ++j) {
			double s = x.unitv[0][j] * double(x.use[0]);
			for (size_t i = 1; i < k; ++i) s += x.unitv[i][j] * double(x.use[i]);
			bis[j] = s;
		}
		x.side.resize(k);
		for (size_t i = 0; i < k; ++i) x.side[i] = (bis[0] * x.unitv[i][1] - bis[1] * x.unitv[i][0]) > 0;
	}
	std::vector<ArmSums> sums(2 * nv);
	std::vector<double> ys(2 * nv), xs(2 * nv), angles(2 * nv);
	for (int it = 0; it < MS_CURVE_ARM_ITERATIONS; ++it) {
		for (size_t v = 0; v < nv; ++v) {
			Across &x = across[v];
			const size_t k = x.xy.size();
			x.w1.resize(k), x.w2.resize(k);
			for (size_t i = 0; i < k; ++i) {
				x.w1[i] = (x.use[i] && x.side[i]) ? x.weight[i] : 0.0;
				x.w2[i] = (x.use[i] && !x.side[i]) ? x.weight[i] : 0.0;
			}
			sums[2 * v] = armSums(x.xy, x.w1);
			sums[2 * v + 1] = armSums(x.xy, x.w2);
		}
		for (size_t j = 0; j < 2 * nv; ++j) ys[j] = 2 * sums[j].sxy, xs[j] = sums[j].sxx - sums[j].syy;
		math.atan2(ys.data(), xs.data(), angles.data(), int64_t(2 * nv));
		for (size_t v = 0; v < nv; ++v) {
			Across &x = across[v];
			x.l1 = armLine(x.xy, x.w1, sums[2 * v], angles[2 * v]);
			x.l2 = armLine(x.xy, x.w2, sums[2 * v + 1], angles[2 * v + 1]);
			for (size_t i = 0; i < x.xy.size(); ++i) x.side[i] = lineOffset(x.xy[i], x.l1) <= lineOffset(x.xy[i], x.l2);
		}
	}
	for (size_t v = 0; v < nv; ++v) {
		const Across &x = across[v];
		const ArmLine &l1 = x.l1, &l2 = x.l2;
		const double *bis = &bisector[2 * v];
		const double crossA = l1.a[0] * l2.a[1] - l1.a[1] * l2.a[0];
		const double safe = std::fabs(crossA) > 0 ? crossA : 1.0;
		const double diff0 = l2.c[0] - l1.c[0], diff1 = l2.c[1] - l1.c[1];
		const double s = (diff0 * l2.a[1] - diff1 * l2.a[0]) / safe;
		const double hit0 = l1.c[0] + s * l1.a[0], hit1 = l1.c[1] + s * l1.a[1];
		const bool isFitted = l1.total >= MS_CURVE_MIN_ARM_POINTS && l2.total >= MS_CURVE_MIN_ARM_POINTS &&
		                      std::max(l1.rms, l2.rms) <= MS_CURVE_MAX_ARM_RMS * spacing;
		const bool crease = std::fabs(crossA) >= std::sin(radians(MS_CURVE_MIN_ARM_ANGLE));
		// a thin wall's two faces (parallel arms) leave its rim on one side, a wall apart
		const bool oneSide = (l1.c[0] * l1.a[0] + l1.c[1] * l1.a[1]) * (l2.c[0] * l1.a[0] + l2.c[1] * l1.a[1]) > 0;
		const double apart = std::fabs(diff0 * l1.a[1] - diff1 * l1.a[0]);
		const bool wall = oneSide && apart > MS_CURVE_THIN_WALL * spacing;
		bool ok = isFitted && crease && std::sqrt(bis[0] * bis[0] + bis[1] * bis[1]) > 0 &&
		          std::sqrt(hit0 * hit0 + hit1 * hit1) <= MS_CURVE_MAX_SHIFT * spacing;
		const Vec3 &vertex = vertices[first + v];
		const Vec3 there = add(add(vertex, mul(hit0, x.u)), mul(hit1, x.w));
		// arms on one side and far apart whose lines meet far from every point: across a
		// thin wall, not on its rim
		if (ok && oneSide && apart > MS_CURVE_WALL_APART * spacing) {
			const double gap = MS_CURVE_WALL_GAP * spacing;
			ok = tree.query(there, 1)[0].first <= gap * gap;
		}
		moved[first + v] = ok ? there : vertex;
		fitted[first + v] = ok;
		flat[first + v] = isFitted && !crease && !wall;
	}
}

std::vector<Vec3> lineFitPositions(const std::vector<Vec3> &points, const std::vector<Vec3> &dirs,
                                   int half, bool closed)
{
	const long m = long(points.size());
	if (closed && m <= half) return points;
	std::vector<Vec3> out(m);
	const double count = 2 * half + 1;
	for (long i = 0; i < m; ++i) {
		Vec3 total{0.0, 0.0, 0.0};
		for (long j = i - half; j <= i + half; ++j)  // in order, like refine.py
			total = add(total, points[closed ? ((j % m) + m) % m : clip(j, 0, m - 1)]);
		const Vec3 mean{total[0] / count, total[1] / count, total[2] / count};
		const double along = edot(sub(points[i], mean), dirs[i]);
		out[i] = add(mean, mul(along, dirs[i]));
	}
	return out;
}

std::vector<long> advancing(const std::vector<Vec3> &p, const std::vector<Vec3> &t, double spacing)
{
	std::vector<long> keep{0};
	Vec3 last = p[0];
	const double step = MS_CURVE_MIN_ADVANCE * spacing;
	for (size_t i = 1; i + 1 < p.size(); ++i)
		if (bdot(sub(p[i], last), t[i]) >= step) keep.push_back(long(i)), last = p[i];
	if (p.size() > 1) keep.push_back(long(p.size()) - 1);
	return keep;
}

// each feature's distance to the nearest other point (d1) and to the
// MS_CURVE_DENSITY_NEIGHBOURS-th nearest (dk), on every core
void densityDistances(const KdTree &tree, const std::vector<Vec3> &fp, std::vector<double> &d1,
                      std::vector<double> &dk)
{
	const size_t k = std::min<size_t>(MS_CURVE_DENSITY_NEIGHBOURS + 1, tree.size());
	d1.resize(fp.size());
	dk.resize(fp.size());
	inBlocks(fp.size(), [&](size_t begin, size_t end) {
		for (size_t i = begin; i < end; ++i) {
			const auto hits = tree.query(fp[i], k);
			d1[i] = std::sqrt(hits[1].first);
			dk[i] = std::sqrt(hits[k - 1].first);
		}
	});
}

// cloud_spacing: the median d of the features' d1; where DENSITY_SCALE times the median
// of their dk is q d with q > 1, the cloud is irregular and the spacing d q^1.5
double cloudSpacing(const std::vector<double> &d1, const std::vector<double> &dk, bool &irregular)
{
	const double nearest = median(d1);
	const double density = MS_CURVE_DENSITY_SCALE * median(dk);
	irregular = nearest > 0.0 && density > nearest;
	if (!irregular) return nearest;
	const double q = density / nearest;
	return nearest * (q * std::sqrt(q));
}

// local_spacings: each feature's own spacing, MS_CURVE_DENSITY_SCALE times its dk,
// clipped to 1 to MS_CURVE_MAX_LOCAL_SPACING times the cloud's
std::vector<double> localSpacings(const std::vector<double> &dk, double spacing)
{
	std::vector<double> out(dk.size());
	for (size_t i = 0; i < dk.size(); ++i)
		out[i] = std::min(std::max(MS_CURVE_DENSITY_SCALE * dk[i], spacing), MS_CURVE_MAX_LOCAL_SPACING * spacing);
	return out;
}

std::vector<Piece> cloudPieces(const std::vector<Vec3> &pts, const std::vector<char> &mask,
                               const std::vector<char> &ok, const std::vector<long> &feat,
                               const std::vector<Vec3> &fp, const std::array<Vec3, 2> *bounds,
                               const ms_curves_math &math, double &spacing, bool &irregular)
{
	const KdTree fpTree(fp);
	std::vector<double> d1(fp.size());
	inBlocks(fp.size(), [&](size_t begin, size_t end) {
		for (size_t i = begin; i < end; ++i) d1[i] = std::sqrt(fpTree.query(fp[i], 2)[1].first);
	});
	const double featureSpacing = median(d1);
	std::vector<long> near = cellNeighbourhood(pts, ok, fp, MS_CURVE_CELL_SPACINGS * featureSpacing, bounds);
	// in lexicographic order, ties by index (the points beside their indices: fewer cache misses)
	std::vector<std::pair<Vec3, long>> byPoint(near.size());
	for (size_t i = 0; i < near.size(); ++i) byPoint[i] = {pts[near[i]], near[i]};
	std::sort(byPoint.begin(), byPoint.end(), [](const std::pair<Vec3, long> &a, const std::pair<Vec3, long> &b) {
		return lexLess(a.first, b.first) || (!lexLess(b.first, a.first) && a.second < b.second);
	});
	std::vector<Vec3> nearPts(near.size());
	std::vector<char> nearFeature(near.size());
	for (size_t i = 0; i < near.size(); ++i) nearPts[i] = byPoint[i].first, nearFeature[i] = mask[byPoint[i].second];
	const KdTree tree(nearPts);
	std::vector<double> dk;
	densityDistances(tree, fp, d1, dk);
	spacing = cloudSpacing(d1, dk, irregular);
	// cloud_graph, each feature's own spacing (local_spacings) reaching its links
	const std::vector<double> local = localSpacings(dk, spacing);
	const long n = long(fp.size());
	const size_t k = std::min<size_t>(MS_CURVE_LINK_NEIGHBOURS + 1, fp.size());
	const double reach = *std::max_element(local.begin(), local.end());
	std::vector<std::vector<std::pair<double, long>>> linked(fp.size());
	inBlocks(fp.size(), [&](size_t begin, size_t end) {
		for (size_t i = begin; i < end; ++i) linked[i] = fpTree.query(fp[i], k, MS_CURVE_LINK_RADIUS * reach);
	});
	std::set<Edge> pairSet;
	for (long i = 0; i < n; ++i)
		for (const auto &hit : linked[i])
			if (hit.second != i) pairSet.insert({std::min(i, hit.second), std::max(i, hit.second)});
	std::vector<Edge> edges;
	std::vector<double> lengths;
	for (const Edge &e : pairSet) {
		const double length = norm(sub(fp[e[0]], fp[e[1]]));
		if (length < MS_CURVE_LINK_RADIUS * std::min(local[e[0]], local[e[1]])) edges.push_back(e), lengths.push_back(length);
	}
	std::vector<Piece> pieces = skeletonPieces(
		n, edges, lengths, fp, spacing, {}, irregular ? MS_CURVE_IRREGULAR_BRIDGE_REACH : MS_CURVE_BRIDGE_REACH,
		irregular ? MS_CURVE_IRREGULAR_BRIDGE_ANGLE : MS_CURVE_BRIDGE_ANGLE);
	if (pieces.empty()) return {};
	// refine every vertex at once, across the skeleton's directions over a wide window
	std::vector<Vec3> raw;
	for (const Piece &pc : pieces) raw.insert(raw.end(), pc.points.begin(), pc.points.end());
	const size_t kk = std::min<size_t>(MS_CURVE_REFINE_NEIGHBOURS, tree.size());
	std::vector<std::vector<long>> nbrs(raw.size());
	inBlocks(raw.size(), [&](size_t begin, size_t end) {
		for (size_t i = begin; i < end; ++i)
			for (const auto &hit : tree.query(raw[i], kk)) nbrs[i].push_back(hit.second);
	});
	const std::vector<Vec3> dirs = batchTangents(pieces, MS_CURVE_RAW_TANGENT_WINDOW * spacing);
	std::vector<Vec3> moved(raw.size());
	std::vector<char> fitted(raw.size()), flat(raw.size());
	// the batches on every core (math's functions may be called from any thread)
	inBlocks((raw.size() + REFINE_BATCH - 1) / REFINE_BATCH, [&](size_t begin, size_t end) {
		for (size_t first = begin * REFINE_BATCH; first < std::min(raw.size(), end * REFINE_BATCH); first += REFINE_BATCH)
			planeIntersections(first, std::min(raw.size(), first + REFINE_BATCH), raw, dirs, nbrs, nearPts,
			                   nearFeature, tree, spacing, math, moved, fitted, flat);
	}, 1);
	std::vector<Piece> out;
	size_t at = 0;
	for (const Piece &pc : pieces) {
		const size_t m = pc.points.size();
		std::vector<Vec3> p(moved.begin() + at, moved.begin() + at + m);
		const std::vector<Vec3> d(dirs.begin() + at, dirs.begin() + at + m);
		long nFlat = 0;
		bool all = true;
		for (size_t i = 0; i < m; ++i) nFlat += flat[at + i], all = all && fitted[at + i];
		const size_t first = at;
		at += m;
		if (double(nFlat) / double(m) > MS_CURVE_MAX_FLAT_SHARE) continue;  // false detections
		if (!all) {
			const std::vector<Vec3> line = lineFitPositions(pc.points, d, MS_CURVE_LINE_FIT_HALF, pc.closed);
			for (size_t i = 0; i < m; ++i)
				if (!fitted[first + i]) p[i] = line[i];
		}
		p = lineFitPositions(p, d, MS_CURVE_LINE_FIT_HALF, pc.closed);
		Piece q;
		q.closed = pc.closed;
		for (long i : advancing(p, d, spacing)) q.nodes.push_back(feat[pc.nodes[i]]), q.points.push_back(p[i]);
		out.push_back(q);
	}
	return out;
}

// ---------------------------------------------------------------- extract.py

std::vector<Piece> dropShort(const std::vector<Piece> &pieces, double spacing, double share = 1.0)
{
	const Ends e = ends(pieces, spacing);
	const auto clusters = endClusters(e, pieces, spacing);
	std::vector<long> size(e.piece.size(), 1);
	for (const auto &c : clusters)
		for (long i : c) size[i] = long(c.size());
	std::set<long> spur;
	for (size_t i = 0; i < e.piece.size(); i += 2)
		if (std::min(size[i], size[i + 1]) == 1 && std::max(size[i], size[i + 1]) >= 3) spur.insert(e.piece[i]);
	std::vector<Piece> out;
	for (size_t i = 0; i < pieces.size(); ++i) {
		if (pieces[i].closed) {
			out.push_back(pieces[i]);
			continue;
		}
		const double length = pieces[i].length();
		if (length >= share * MS_CURVE_MIN_CURVE_LENGTH * spacing &&
		    (!spur.count(long(i)) || length >= share * MS_CURVE_SPUR_PIECE * spacing))
			out.push_back(pieces[i]);
	}
	return out;
}

// clouds: open pieces shorter than MS_CURVE_SPUR_PIECE spacings whose two ends are free (not
// even meeting another's line at a corner) dropped
std::vector<Piece> dropIsolated(const std::vector<Piece> &pieces, double spacing)
{
	const Ends e = ends(pieces, spacing);
	std::vector<char> joined(pieces.size(), 0);
	for (const auto &c : meetingClusters(e, endClusters(e, pieces, spacing), spacing))
		for (long i : c) joined[e.piece[i]] = 1;
	std::vector<Piece> out;
	for (size_t i = 0; i < pieces.size(); ++i)
		if (pieces[i].closed || joined[i] || pieces[i].length() >= MS_CURVE_SPUR_PIECE * spacing) out.push_back(pieces[i]);
	return out;
}

// trace.cut_at_turns: open pieces shorter than MS_CURVE_SHORTEST_CUT spacings are not cut
std::vector<Piece> cutAll(const std::vector<Piece> &pieces, double spacing, const ms_curves_math &math)
{
	std::vector<const Piece *> longOpen;
	std::vector<long> slot(pieces.size(), -1);
	for (size_t i = 0; i < pieces.size(); ++i)
		if (!pieces[i].closed && pieces[i].length() >= MS_CURVE_SHORTEST_CUT * spacing)
			slot[i] = long(longOpen.size()), longOpen.push_back(&pieces[i]);
	const std::vector<std::vector<double>> angles = openTurnAngles(longOpen, spacing, math);
	std::vector<Piece> out;
	for (size_t i = 0; i < pieces.size(); ++i) {
		if (!pieces[i].closed && slot[i] < 0) {
			out.push_back(pieces[i]);  // too short to hold two curves
			continue;
		}
		const std::vector<double> angle = pieces[i].closed ? turnAngles(pieces[i], spacing, math) : angles[slot[i]];
		for (Piece &q : cutAtTurns(pieces[i], angle, spacing)) out.push_back(q);
	}
	return out;
}

using Mat3 = std::array<std::array<double, 3>, 3>;

// extract._line_system: the normal equations a x = b of the point nearest the lines
// through through[i] along the unit outs[i], i in c
void lineSystem(const std::vector<long> &c, const std::vector<Vec3> &outs, const std::vector<Vec3> &through,
                Mat3 &a, Vec3 &b)
{
	a = Mat3{};
	b = Vec3{0.0, 0.0, 0.0};
	for (long i : c) {
		const Vec3 &o = outs[i];
		Mat3 proj{};
		for (int r = 0; r < 3; ++r)
			for (int k = 0; k < 3; ++k) proj[r][k] = (r == k ? 1.0 : 0.0) - o[r] * o[k];
		for (int r = 0; r < 3; ++r)
			for (int k = 0; k < 3; ++k) a[r][k] += proj[r][k];
		for (int r = 0; r < 3; ++r) b[r] += gemvRow(proj[r], through[i]);
	}
}

// extract._outlying: the ends of cluster c (a well-conditioned system) whose lines pass
// farther than MS_CURVE_CORNER_OFFSET spacings from the others' meeting point, the
// farthest (the first of equally far ones) left out first while more than two remain
// and their system stays well-conditioned; ascending
std::vector<long> outlying(const std::vector<long> &c, const std::vector<Vec3> &outs,
                           const std::vector<Vec3> &through, double spacing)
{
	std::vector<long> kept = c;
	Mat3 a;
	Vec3 b;
	lineSystem(c, outs, through, a, b);
	while (kept.size() > 2) {
		const Vec3 x = solve3(a, b);
		double far = MS_CURVE_CORNER_OFFSET * spacing;
		long worst = -1;
		for (long i : kept) {
			const Vec3 v = sub(x, through[i]);
			const double d = bnorm(sub(v, mul(bdot(v, outs[i]), outs[i])));
			if (d > far) far = d, worst = i;
		}
		if (worst < 0) break;
		std::vector<long> trial;
		for (long i : kept)
			if (i != worst) trial.push_back(i);
		lineSystem(trial, outs, through, a, b);
		if (!(condition(a) < MS_CURVE_MAX_CORNER_CONDITION)) break;
		kept = trial;
	}
	std::vector<long> rest;
	for (long i : c)
		if (std::find(kept.begin(), kept.end(), i) == kept.end()) rest.push_back(i);
	std::sort(rest.begin(), rest.end());
	return rest;
}

std::vector<Piece> corners(std::vector<Piece> pieces, double spacing, const std::vector<Vec3> &pts,
                           const MeshPaths *paths, Curves &result)
{
	const Ends e = ends(pieces, spacing);
	auto clusters = endClusters(e, pieces, spacing);
	// clouds: the end lines 2-8 spacings back, which may meet far from the ends;
	// meshes: the lines of the last mesh edges
	const bool cloud = paths == nullptr;
	if (cloud) clusters = meetingClusters(e, clusters, spacing);
	const std::vector<Vec3> &outs = cloud ? e.out[MS_CURVE_CORNER_SCALE] : e.out[0];
	const std::vector<Vec3> &through = cloud ? e.anchor[MS_CURVE_CORNER_SCALE] : e.point;
	std::vector<Vec3> points;
	std::vector<long> indices;
	std::deque<std::vector<long>> work(clusters.begin(), clusters.end());
	while (!work.empty()) {
		std::vector<long> c = work.front();
		work.pop_front();
		Mat3 a;
		Vec3 b;
		lineSystem(c, outs, through, a, b);
		if (cloud && condition(a) < MS_CURVE_MAX_CORNER_CONDITION) {
			// ends whose lines pass far from the others' meeting point: a short piece's
			// noisy direction, or the ends of a nearby corner; two or more meet apart
			const std::vector<long> rest = outlying(c, outs, through, spacing);
			if (!rest.empty()) {
				std::vector<long> kept;
				for (long i : c)
					if (!std::binary_search(rest.begin(), rest.end(), i)) kept.push_back(i);
				lineSystem(kept, outs, through, a, b);
				if (rest.size() >= 2) work.push_back(rest), c = kept;
			}
		}
		Vec3 sum = e.point[c[0]];
		for (size_t j = 1; j < c.size(); ++j) sum = add(sum, e.point[c[j]]);
		const double cnt = double(c.size());
		const Vec3 mean{sum[0] / cnt, sum[1] / cnt, sum[2] / cnt};
		Vec3 corner = mean;
		if (condition(a) < MS_CURVE_MAX_CORNER_CONDITION) {
			const Vec3 x = solve3(a, b);
			bool near = true;
			if (cloud) {  // within MS_CURVE_LONG_GAP spacings of every end
				for (long i : c) near = near && norm(sub(e.point[i], x)) <= MS_CURVE_LONG_GAP * spacing;
			} else {
				near = bnorm(sub(x, mean)) <= MS_CURVE_GAP_LENGTH * spacing;
			}
			if (near) corner = x;
		}
		long index;
		if (paths == nullptr) {
			long nearest = c[0];
			double best = INF;
			for (long i : c) {
				const double d = norm(sub(e.point[i], corner));
				if (d < best) best = d, nearest = i;
			}
			const Piece &pc0 = pieces[e.piece[nearest]];
			index = e.side[nearest] == 0 ? pc0.nodes.front() : pc0.nodes.back();
		} else {
			index = paths->nearest(corner);
			corner = pts[index];
		}
		points.push_back(corner);
		indices.push_back(index);
		for (long i : c) {
			Piece &pc = pieces[e.piece[i]];
			const size_t at = e.side[i] == 0 ? 0 : pc.nodes.size() - 1;
			const long here = pc.nodes[at];
			if (here == index || (paths == nullptr && bnorm(sub(pc.points[at], corner)) <= MS_CURVE_SNAP * spacing)) {
				pc.points[at] = corner;
				continue;
			}
			bool found = false;
			std::vector<long> add_;
			if (paths != nullptr) add_ = paths->path(here, index, 2 * MS_CURVE_GAP_LENGTH * spacing, found);
			std::vector<Vec3> addPoints;
			for (long v : add_) addPoints.push_back(pts[v]);
			add_.push_back(index);
			addPoints.push_back(corner);
			if (e.side[i] == 0) {
				pc.nodes.insert(pc.nodes.begin(), add_.rbegin(), add_.rend());
				pc.points.insert(pc.points.begin(), addPoints.rbegin(), addPoints.rend());
			} else {
				pc.nodes.insert(pc.nodes.end(), add_.begin(), add_.end());
				pc.points.insert(pc.points.end(), addPoints.begin(), addPoints.end());
			}
		}
	}
	const double shortest = MS_CURVE_LOOP_LENGTH * MS_CURVE_GAP_LENGTH * spacing;
	std::vector<Piece> out;
	for (const Piece &pc : pieces)
		if (pc.closed || pc.points.front() != pc.points.back() || pc.length() >= shortest) out.push_back(pc);
	std::vector<long> order(points.size());
	std::iota(order.begin(), order.end(), 0L);
	std::stable_sort(order.begin(), order.end(), [&](long x, long y) { return lexLess(points[x], points[y]); });
	for (long i : order) result.corners.push_back(points[i]), result.cornerIndices.push_back(indices[i]);
	return out;
}

Curve finalCurve(const Piece &pc)
{
	std::vector<Vec3> p = pc.points;
	std::vector<long> n = pc.nodes;
	const size_t m = p.size();
	if (pc.closed) {
		size_t start = 0;
		for (size_t i = 1; i < m; ++i)
			if (lexLess(p[i], p[start])) start = i;
		std::rotate(p.begin(), p.begin() + start, p.end());
		std::rotate(n.begin(), n.begin() + start, n.end());
		if (m > 2 && lexLess(p[m - 1], p[1])) {
			std::reverse(p.begin() + 1, p.end());
			std::reverse(n.begin() + 1, n.end());
		}
	} else if (lexLess(p.back(), p.front())) {
		std::reverse(p.begin(), p.end());
		std::reverse(n.begin(), n.end());
	}
	Curve c;
	c.points = p;
	c.indices = n;
	c.closed = pc.closed;
	c.length = Piece{n, p, pc.closed}.length();
	return c;
}

}  // namespace

Curves extractCurves(const std::vector<Point> &vertices, const std::vector<char> &feature,
                     const std::vector<char> &valid, const std::vector<std::array<int, 3>> &faces,
                     const std::array<Vec3, 2> *bounds, const ms_curves_math *vectorMath)
{
	const ms_curves_math math = vectorMath != nullptr ? *vectorMath : C_MATH;
	Curves result;
	const size_t n = vertices.size();
	std::vector<Vec3> pts(n);
	for (size_t i = 0; i < n; ++i) pts[i] = {vertices[i].x, vertices[i].y, vertices[i].z};
	std::vector<char> ok(n), both(n);
	for (size_t i = 0; i < n; ++i) ok[i] = valid.empty() ? 1 : valid[i] != 0, both[i] = feature[i] && ok[i];
	std::vector<long> feat;
	for (size_t i = 0; i < n; ++i)
		if (both[i]) feat.push_back(long(i));
	std::stable_sort(feat.begin(), feat.end(), [&](long a, long b) { return lexLess(pts[a], pts[b]); });
	std::vector<long> distinct;
	for (long i : feat)
		if (distinct.empty() || pts[i] != pts[distinct.back()]) distinct.push_back(i);
	feat = distinct;
	if (feat.size() < 2) return result;
	std::vector<Vec3> fp;
	for (long i : feat) fp.push_back(pts[i]);
	std::vector<Piece> pieces;
	double spacing = 0.0;
	std::unique_ptr<MeshPaths> paths;
	CreaseChains creases;
	bool irregular = false;
	if (faces.empty()) {
		std::vector<char> mask(n);
		for (size_t i = 0; i < n; ++i) mask[i] = feature[i] != 0;
		pieces = cloudPieces(pts, mask, ok, feat, fp, bounds, math, spacing, irregular);
	} else {
		std::vector<char> usable(n, 0);
		for (long v : feat) usable[v] = 1;
		creases = creaseChains(pts, faces, both, usable, math);
		pieces = meshPieces(pts, faces, both, feat, fp, creases.rest, spacing);
		paths.reset(new MeshPaths(pts, faces, creases.rest));
	}
	if (spacing <= 0) return result;
	result.spacing = spacing;
	Bridge bridgeFn = [&](long a, long b) {
		bool found = false;
		Piece mid;
		mid.nodes = paths->path(a, b, 2 * MS_CURVE_GAP_LENGTH * spacing, found);
		for (long v : mid.nodes) mid.points.push_back(pts[v]);
		return mid;
	};
	const Bridge *bridge = paths ? &bridgeFn : nullptr;
	pieces = cutAll(pieces, spacing, math);
	// a mesh's short pieces are dropped before joining; a cloud's sampling gaps cut an
	// edge's features into short pieces, which join first: on a regular cloud only the
	// shortest are dropped before, on an irregular one (iid points, a scan) none
	if (paths)
		pieces = dropShort(pieces, spacing);
	else if (!irregular)
		pieces = dropShort(pieces, spacing, MS_CURVE_EARLY_DROP);
	pieces = dropShort(joinPieces(pieces, spacing, bridge), spacing);
	pieces = joinPieces(pieces, spacing, bridge);
	pieces = cutAll(pieces, spacing, math);
	pieces = splitAtTouches(pieces, spacing, !paths);
	if (!paths) pieces = dropIsolated(pieces, spacing);
	pieces = corners(pieces, spacing, pts, paths.get(), result);
	if (!creases.chains.empty()) {  // the mesh's sharp edges, and their corners
		for (size_t i = 0; i < creases.chains.size(); ++i) {
			Piece pc;
			pc.closed = creases.closed[i] != 0;
			for (long v : creases.chains[i]) pc.nodes.push_back(v), pc.points.push_back(pts[v]);
			pieces.push_back(pc);
		}
		std::vector<std::pair<Vec3, long>> all;
		for (size_t i = 0; i < result.corners.size(); ++i) all.push_back({result.corners[i], result.cornerIndices[i]});
		for (long v : creases.corners) all.push_back({pts[v], v});
		std::stable_sort(all.begin(), all.end(), [](const std::pair<Vec3, long> &a, const std::pair<Vec3, long> &b) {
			return lexLess(a.first, b.first);
		});
		result.corners.clear(), result.cornerIndices.clear();
		for (const auto &c : all) result.corners.push_back(c.first), result.cornerIndices.push_back(c.second);
	}
	for (const Piece &pc : pieces)
		if (pc.points.size() >= 2) result.curves.push_back(finalCurve(pc));
	std::stable_sort(result.curves.begin(), result.curves.end(), [](const Curve &a, const Curve &b) {
		const std::array<double, 7> ka{a.points.front()[0], a.points.front()[1], a.points.front()[2],
		                               a.points.back()[0], a.points.back()[1], a.points.back()[2], a.length};
		const std::array<double, 7> kb{b.points.front()[0], b.points.front()[1], b.points.front()[2],
		                               b.points.back()[0], b.points.back()[1], b.points.back()[2], b.length};
		return ka < kb;
	});
	return result;
}

}  // namespace sharp
