// See detect.h. The per-point kernels of native/src are called with the same arguments as
// meshlab_sharp/_kernels.py calls them, in chunks of MS_CHUNK points on every core; what
// remains here mirrors the Python modules' global steps: cleaning.py (the compiled path), threshold.py,
// multiscale.py, reference/detect.py (RobustSetup; its finishing steps are the kernel's) and
// creases.py. docs/contributing.md ("The arithmetic both implementations share",
// "Robust mode's arithmetic") is the contract.
#include "detect.h"

#include "cores.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cfloat>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <exception>
#include <limits>
#include <memory>
#include <new>
#include <sstream>
#include <system_error>
#include <thread>


namespace sharp {
namespace {

// Robust mode's threshold floor (the header's MS_R_MIN).
const double R_MIN = MS_R_MIN;

using Index = int64_t;

// An allocator that leaves elements default-initialised (numbers: not written) on
// resize(n): for the large buffers a kernel fills whole, which zeroing would only slow.
template <class T>
struct NoInit : std::allocator<T> {
	template <class U>
	struct rebind {
		using other = NoInit<U>;
	};
	NoInit() = default;
	template <class U>
	NoInit(const NoInit<U> &) {}
	template <class U>
	void construct(U *p) {
		::new (static_cast<void *>(p)) U;
	}
	template <class U, class... A>
	void construct(U *p, A &&...a) {
		::new (static_cast<void *>(p)) U(std::forward<A>(a)...);
	}
};
template <class T>
using Buffer = std::vector<T, NoInit<T>>;

// Throws std::bad_alloc when a kernel ran out of memory (a non-zero status).
void check(int status) {
	if (status != 0) throw std::bad_alloc();
}

// Progress over the stages of a run, and the time spent in each: reported by the calling
// thread only. A stage's time runs from its first report to the next stage's.
class Bar {
public:
	using Clock = std::chrono::steady_clock;
	Bar(ms_progress_fn cb, void *ctx) : cb_(cb), ctx_(ctx), since_(Clock::now()) {}
	void report(int percent, const char *stage) {
		if (stage_ != stage) {
			close();
			stage_ = stage;
		}
		if (!cb_) return;
		char text[160];
		std::snprintf(text, sizeof text, "Sharp features: %s %d%%", stage, percent);
		cb_(percent, text, ctx_);
	}
	// Seconds per stage in order of first entry (a stage entered twice adds up).
	std::vector<std::pair<std::string, double>> times() {
		close();
		return times_;
	}

private:
	void close() {
		const auto now = Clock::now();
		if (!stage_.empty()) {
			const double seconds = std::chrono::duration<double>(now - since_).count();
			auto it = std::find_if(times_.begin(), times_.end(), [&](const auto &t) { return t.first == stage_; });
			if (it == times_.end()) times_.emplace_back(stage_, seconds);
			else it->second += seconds;
		}
		since_ = now;
	}
	ms_progress_fn cb_;
	void *ctx_;
	std::string stage_;
	Clock::time_point since_;
	std::vector<std::pair<std::string, double>> times_;
};

// Threads of the calling thread's run (Options::threads, or cores()): set by detect().
thread_local unsigned runThreads = 1;

unsigned workers() { return runThreads; }

// run(t) on min(workers(), max(items, 1)) threads, t = 0 on the calling thread. Every
// caller takes its items from a shared counter, so a thread that cannot start (no room
// for its stack under an address-space limit: std::system_error, EAGAIN) leaves its share
// to the threads that did; the calling thread alone finishes the work.
template <class Run>
void onCores(Index items, Run run) {
	std::vector<std::thread> pool;
	const unsigned w = unsigned(std::min<Index>(workers(), std::max<Index>(items, 1)));
	pool.reserve(w - 1);  // no allocation once a thread runs: only the threads' own can fail
	try {
		for (unsigned t = 1; t < w; ++t) pool.emplace_back(run, t);
	} catch (const std::system_error &) {
	}
	run(0u);
	for (auto &t : pool) t.join();
}

// task(worker, begin, end) -> kernel status, over [0, n) in chunks of MS_CHUNK on every
// core (as _kernels._run_chunks); worker < workers() names the thread (its scratch). The
// calling thread works too and moves the bar from `from` to `to` as chunks finish.
// Throws std::bad_alloc when a task ran out of memory.
template <class Task>
void chunks(Index n, Task task, Bar &bar, int from, int to, const char *stage) {
	const Index count = (n + MS_CHUNK - 1) / MS_CHUNK;
	std::atomic<Index> next{0}, done{0};
	std::atomic<int> status{0};
	auto work = [&](unsigned w, bool report) {
		for (Index c; (c = next++) < count;) {
			int rc = -1;
			try {  // an exception must not leave a thread
				rc = task(w, c * MS_CHUNK, std::min(n, (c + 1) * MS_CHUNK));
			} catch (const std::bad_alloc &) {
			}
			if (rc != 0) status = rc;
			const Index finished = ++done;
			if (report) bar.report(from + int((to - from) * finished / count), stage);
		}
	};
	bar.report(from, stage);
	onCores(count, [&](unsigned t) { work(t, t == 0); });
	check(status);
	bar.report(to, stage);
}

// f(u) for every u in [0, count), on every core (items taken in turn from a counter).
template <class F>
void eachIndex(Index count, F f) {
	std::atomic<Index> next{0};
	onCores(count, [&](unsigned) {
		for (Index u; (u = next++) < count;) f(u);
	});
}

// The largest |x| of the count values x.
double maxAbs(const double *x, Index count) {
	double big = 0.0;
	for (Index i = 0; i < count; ++i) big = std::max(big, std::fabs(x[i]));
	return big;
}

// neighbourhoods.unit_scale: multiply by 2^-e, 2^(e-1) <= max |coordinate| < 2^e, when e is
// outside (-MS_UNIT_RANGE, MS_UNIT_RANGE]: exact, and no squared distance can then
// overflow or underflow whatever the unit. big: max |coordinate| of xyz (n, 3) (maxAbs).
// Returns xyz itself, or its scaled copy in `scaled`.
const double *unitScale(const double *xyz, Index n, double big, std::vector<double> &scaled) {
	int e = 0;
	std::frexp(big, &e);
	if (big == 0.0 || (-MS_UNIT_RANGE < e && e <= MS_UNIT_RANGE)) return xyz;
	scaled.resize(3 * n);
	for (Index i = 0; i < 3 * n; ++i) scaled[i] = std::ldexp(xyz[i], -e);
	return scaled.data();
}

// neighbourhoods.far_points' bulk: the median of each axis and the reach beyond which a
// point is far, MS_FAR_SPREADS times the largest interquartile range (the median and
// interquartile ranges of at most MS_FAR_SAMPLE points evenly spread through the cloud
// xyz, n x 3, numpy's linear quantiles); reach left at 0 when a sampled coordinate is not
// finite (the input is refused then).
struct FarTest {
	double median[3] = {0.0, 0.0, 0.0}, reach = 0.0;  // reach 0: no point is far
	// Whether point x (3 coordinates) is far (a NaN coordinate is not).
	bool far(const double *x) const {
		bool out = false;
		for (int a = 0; a < 3; ++a) out |= std::fabs(x[a] - median[a]) > reach;
		return reach != 0.0 && out;
	}
};

void farTest(const double *xyz, const Index n, FarTest &test) {
	const Index step = std::max<Index>(1, (n + MS_FAR_SAMPLE - 1) / MS_FAR_SAMPLE);
	double reach = 0.0;
	std::vector<double> sample[3];  // each axis's, read in one pass
	for (Index i = 0; i < n; i += step)
		for (int a = 0; a < 3; ++a) sample[a].push_back(xyz[3 * i + a]);
	for (std::vector<double> &x : sample) {
		if (!std::all_of(x.begin(), x.end(), [](double v) { return std::isfinite(v); })) return;
	}
	for (int a = 0; a < 3; ++a) {
		std::vector<double> &x = sample[a];
		// the order statistics the quantiles read, by selection (the values a sort leaves
		// there): the middle one's first, then each other one among the values on its side
		const Index size = Index(x.size()), mid = (size - 1) / 2;
		std::nth_element(x.begin(), x.begin() + mid, x.end());
		const auto stat = [&](Index k) {
			if (k < mid) std::nth_element(x.begin(), x.begin() + k, x.begin() + mid);
			if (k > mid) std::nth_element(x.begin() + mid + 1, x.begin() + k, x.end());
			return x[size_t(k)];
		};
		const auto quantile = [&](double q) {
			const double h = double(size - 1) * q;
			const Index lo = Index(std::floor(h));
			const double below = stat(lo), above = stat(std::min(lo + 1, size - 1));
			const double t = h - double(lo), diff = above - below;
			return t >= 0.5 ? above - diff * (1.0 - t) : below + diff * t;
		};
		test.median[a] = quantile(0.5);
		const double q25 = quantile(0.25), q75 = quantile(0.75);
		reach = std::max(reach, q75 - q25);
	}
	test.reach = reach * MS_FAR_SPREADS;
}

// What one pass over the input's coordinates (xyz, n x 3) finds, on every core: whether
// every coordinate is finite, the largest |coordinate| (for unitScale) and, with a far
// test, whether some point is far.
struct Scan {
	bool finite = true, anyFar = false;
	double big = 0.0;
};

Scan scanInput(const double *xyz, const Index n, const FarTest *test) {
	const Index count = (n + MS_CHUNK - 1) / MS_CHUNK;
	std::vector<Scan> parts(static_cast<size_t>(count));
	eachIndex(count, [&](Index u) {
		Scan &p = parts[size_t(u)];
		const Index end = std::min(n, (u + 1) * MS_CHUNK);
		for (Index i = 3 * u * MS_CHUNK; i < 3 * end; ++i) {  // branch-free
			const double a = std::fabs(xyz[i]);
			p.finite &= a <= DBL_MAX;
			p.big = std::max(p.big, a);
		}
		for (Index i = u * MS_CHUNK; test != nullptr && i < end; ++i) p.anyFar |= test->far(xyz + 3 * i);
	});
	Scan all;
	for (const Scan &p : parts) {
		all.finite &= p.finite;
		all.anyFar |= p.anyFar;
		all.big = std::max(all.big, p.big);
	}
	return all;
}

// An array in malloc'd memory whose shrinking resize hands the tail back (realloc), where
// a std::vector keeps its whole capacity: ms_adjacency writes its lists at 6 entries a
// face (48 bytes a vertex), then they are trimmed to about half.
template <class T>
class Trimmable {
public:
	size_t size() const { return n_; }
	T *data() { return p_.get(); }
	const T *data() const { return p_.get(); }
	// Room for n (numbers: not written) when larger; else the first n, the rest handed back.
	void resize(size_t n) {
		if (n > n_) {
			T *q = static_cast<T *>(std::realloc(p_.get(), std::max<size_t>(n, 1) * sizeof(T)));
			if (q == nullptr) throw std::bad_alloc();
			p_.release();
			p_.reset(q);
		} else if (n < n_) {
			if (T *q = static_cast<T *>(std::realloc(p_.get(), std::max<size_t>(n, 1) * sizeof(T)))) {
				p_.release();
				p_.reset(q);
			}
		}
		n_ = n;
	}

private:
	struct Free {
		void operator()(T *p) const { std::free(p); }
	};
	std::unique_ptr<T, Free> p_;
	size_t n_ = 0;
};

// A mesh's 1-ring lists in CSR form: ms_adjacency's (each vertex's neighbours in the order
// of its faces).
struct Rings {
	std::vector<Index> ptr;
	Trimmable<int32_t> idx;
};

// ms_adjacency of the faces (F, 3) over n vertices, as _kernels.adjacency.
Rings adjacency(const Index *faces, Index F, Index n) {
	Rings a;
	a.ptr.resize(n + 1);
	a.idx.resize(6 * F);
	check(ms_adjacency(faces, F, n, a.ptr.data(), a.idx.data()));
	a.idx.resize(a.ptr[n]);
	return a;
}

struct Clean {
	Buffer<double> pts;          // cleaned vertices (m, 3), input order (a scattered mesh: breadth-first)
	Buffer<Index> faces;         // cleaned triangles (f, 3)
	std::vector<Index> fromInput;  // cleaned index of each input vertex or -1; empty: itself
	Rings adj;                   // the mesh's adjacency when the renumbering built it and it holds; else empty
	Index n = 0;                 // cleaned vertices (pts may be handed on to a kd-tree)
	Index size() const { return n; }
};

// Fewest faces that cleaning splits between two threads (_kernels' _PARALLEL_FACES).
const Index PARALLEL_ITEMS = Index(1) << 16;

// f(part) for the parts 0 and 1 of a two-part step, on two threads (one unless
// workers() > 1), each part's exception raised after both ran. A side thread that cannot
// start (std::system_error, as in onCores) leaves part 1 to the calling thread.
template <class F>
void twoParts(Index parts, F f, bool threads = true) {
	std::exception_ptr error;
	std::thread side;
	bool alone = parts > 1 && !threads;
	if (parts > 1 && threads) {
		try {
			side = std::thread([&] {
				try {
					f(Index(1));
				} catch (...) {
					error = std::current_exception();
				}
			});
		} catch (const std::system_error &) {
			alone = true;
		}
	}
	if (alone) f(Index(1));
	f(Index(0));
	if (side.joinable()) side.join();
	if (error) std::rethrow_exception(error);
}

// cleaning._clean_compiled's merge (_kernels.merge_duplicates): exact duplicates merged
// into their first occurrence, on one thread (ms_dedup). fromInput (n, all 0): cleaned
// index of each input point;
// out (room for n rows): the cleaned points when some merge. Returns their number m.
Index mergeDuplicates(const double *v, Index n, std::vector<Index> &fromInput, double *out) {
	Index size = 2;
	while (size < 2 * n) size *= 2;
	Buffer<uint64_t> table(size);  // cleared by the probe
	return ms_dedup(v, n, table.data(), size - 1, fromInput.data(), nullptr, out);
}

// _kernels.keep_faces: the faces (F, 3) mapped through remap (or not, when null) whose
// double area on p is > 0, in order, into out (may be faces when remap is null), the
// vertices they use marked in used (m, zeroed); on two threads for many faces, each
// part marking its own array (the same result). Returns the faces kept.
Index keepFaces(const double *p, Index m, const Index *faces, Index F, const Index *remap, Index *out,
                std::vector<uint8_t> &used) {
	const Index parts = workers() > 1 && F >= PARALLEL_ITEMS ? 2 : 1;
	const Index bounds[3] = {0, F * 1 / parts, F};
	Index kept[2] = {0, 0};
	std::vector<uint8_t> second(parts > 1 ? m : 0, 0);
	twoParts(parts, [&](Index part) {
		const Index lo = bounds[part];
		kept[part] = ms_keep_faces(p, faces + 3 * lo, bounds[part + 1] - lo, remap, out + 3 * lo,
		                           part ? second.data() : used.data());
	});
	if (parts == 1) return kept[0];
	// the second part's faces moved to follow the first's (where they are when the first
	// part dropped none)
	if (kept[0] < bounds[1])
		std::copy(out + 3 * bounds[1], out + 3 * (bounds[1] + kept[1]), out + 3 * kept[0]);
	for (Index i = 0; i < m; ++i) used[size_t(i)] |= second[size_t(i)];
	return kept[0] + kept[1];
}

// cleaning._clean_compiled(local_order=True)'s renumbering, between the merge and the
// faces' test: a mesh whose order is scattered (ms_scattered_faces) renumbered
// breadth-first (ms_bfs_renumber), so that the faces' test and every later step read
// nearby memory. faces (F, 3) over the m merged points pts (remapped through fromInput
// when some merged): into c.faces renumbered, pts and fromInput renumbered, the lists
// (renumbered) into c.adj. False (nothing done) when the order has locality.
bool localOrder(Clean &c, const Index *faces, Index F, Index m, bool merged, std::vector<Index> &fromInput) {
	if (m >= (Index(1) << 31) || !ms_scattered_faces(faces, F, merged ? fromInput.data() : nullptr, m))
		return false;
	c.faces.resize(3 * F);
	for (Index i = 0; i < 3 * F; ++i) c.faces[i] = merged ? fromInput[faces[i]] : faces[i];
	Rings adj = adjacency(c.faces.data(), F, m);
	std::vector<int32_t> order(m), rank(m);
	Rings renumbered;
	renumbered.ptr.resize(m + 1);
	renumbered.idx.resize(adj.idx.size());
	Buffer<double> at(3 * m);
	ms_bfs_renumber(adj.ptr.data(), adj.idx.data(), m, c.pts.data(), nullptr, order.data(), rank.data(),
	                renumbered.ptr.data(), renumbered.idx.data(), at.data(), nullptr);
	adj = Rings();
	c.pts.swap(at);
	for (Index &f : c.faces) f = rank[f];
	for (Index &i : fromInput) i = rank[i];
	c.adj = std::move(renumbered);
	return true;
}

// cleaning._clean_compiled: exact duplicates merged into their first occurrence; for
// meshes, renumbered breadth-first when scattered (localOrder), faces of zero double area
// dropped, then unreferenced vertices. v (n, 3), faces (F, 3).
Clean clean(const double *v, Index n, const Index *faces, Index F, bool mesh) {
	std::vector<Index> fromInput(n);  // all 0, as the merge needs
	Clean c;
	c.pts.resize(3 * n);
	const Index m = mergeDuplicates(v, n, fromInput, c.pts.data());
	if (m == n) std::copy(v, v + 3 * n, c.pts.begin());
	c.pts.resize(3 * m);
	c.n = m;
	if (!mesh) {
		if (m < n) c.fromInput = std::move(fromInput);
		return c;
	}
	const bool renumbered = localOrder(c, faces, F, m, m < n, fromInput);
	if (!renumbered) c.faces.resize(3 * F);
	std::vector<uint8_t> used(m, 0);
	const Index nonzero = renumbered
	                          ? keepFaces(c.pts.data(), m, c.faces.data(), F, nullptr, c.faces.data(), used)
	                          : keepFaces(c.pts.data(), m, faces, F, m < n ? fromInput.data() : nullptr,
	                                      c.faces.data(), used);
	c.faces.resize(3 * nonzero);
	if (c.faces.empty()) throw InputError("every face has zero area: nothing is left of the mesh");
	const Index first = Index(std::find(used.begin(), used.end(), uint8_t(0)) - used.begin());
	Index kept = first;  // every vertex before the first unused one keeps its index
	if (first < m) {     // else nothing moves: no map, no pass over the points
		Buffer<Index> renumber(m);
		for (Index i = 0; i < first; ++i) renumber[i] = i;
		for (Index i = first; i < m; ++i) {
			renumber[i] = used[i] ? kept : -1;
			if (!used[i]) continue;
			for (int a = 0; a < 3; ++a) c.pts[3 * kept + a] = c.pts[3 * i + a];
			++kept;
		}
		c.pts.resize(3 * kept);
		c.n = kept;
		for (Index &f : c.faces) f = renumber[f];
		for (Index &i : fromInput) i = i < 0 ? i : renumber[i];
	}
	if (kept < m || nonzero < F) c.adj = Rings();  // the lists are the faces' own no more
	for (Index i = 0; i < n; ++i)  // kept when a vertex moved or was dropped
		if (fromInput[i] != i) {
			c.fromInput = std::move(fromInput);
			break;
		}
	return c;
}

// The kd-tree of the kernel (_kernels.KdTree).
struct Tree {
	Buffer<double> pts;        // (n, 3) in tree order
	std::vector<Index> orig;   // cleaned index of each
	std::vector<double> box;   // node boxes
	int depth = 0;
	Index n = 0;

	// As _kernels.build_tree: the top MS_KD_TOP levels one after the other, the nodes of
	// each on every core, then the subtrees below them (the same tree as ms_kdtree_build).
	explicit Tree(Buffer<double> p) : pts(std::move(p)), orig(pts.size() / 3), n(Index(pts.size() / 3)) {
		depth = std::max(0, int(std::ceil(std::log2(double(std::max<Index>(n, 1)) / MS_KD_LEAF))));
		box.resize(6 * ((Index(2) << depth) - 1));
		for (Index i = 0; i < n; ++i) orig[size_t(i)] = i;
		const int top = std::min(depth, MS_KD_TOP);
		for (int level = 0; level < top; ++level) {  // the disjoint nodes of one level
			eachIndex(Index(1) << level, [&](Index u) {
				ms_kdtree_build_level(pts.data(), orig.data(), n, depth, level, u, u + 1, box.data());
			});
		}
		eachIndex(Index(1) << top, [&](Index u) {
			ms_kdtree_build_subtrees(pts.data(), orig.data(), n, depth, u, u + 1, box.data());
		});
	}
};

// f(t) for every tree position t in [0, n), in chunks of MS_CHUNK on every core.
template <class F>
void eachPosition(Index n, F f) {
	eachIndex((n + MS_CHUNK - 1) / MS_CHUNK, [&](Index u) {
		for (Index t = u * MS_CHUNK, end = std::min(n, t + MS_CHUNK); t < end; ++t) f(t);
	});
}

// Per-point values v in tree order moved to the cleaned order: v[t] to orig[t]
// (_kernels.to_cleaned_order), on every core.
template <class T>
std::vector<T> toCleaned(const std::vector<Index> &orig, const std::vector<T> &v) {
	std::vector<T> out(v.size());
	eachPosition(Index(orig.size()), [&](Index t) { out[size_t(orig[size_t(t)])] = v[size_t(t)]; });
	return out;
}

// The tree's points in the cleaned order (row t to row orig[t]), on every core.
Buffer<double> cleanedPoints(const Tree &t) {
	Buffer<double> out(t.pts.size());
	eachPosition(t.n, [&](Index x) {
		for (int a = 0; a < 3; ++a) out[3 * t.orig[x] + a] = t.pts[3 * x + a];
	});
	return out;
}

// What one pass of ms_cloud_pdis computed (_kernels.ScalePass, CloudStats): per scale s
// and tree position t at [s * n + t] (tree order: the kernel writes its rows one after the
// other, as _kernels' pass; near and kthIdx hold tree positions, for ms_isolated_tree;
// near and kthIdx int32, as cloud_out_t's: a MeshLab layer counts its vertices in an int).
struct CloudPass {
	Buffer<double> pdis, relative, normals;  // filled whole by the kernel (normals: when asked)
	std::vector<double> score, noise, kthD2;
	std::vector<int32_t> near, kthIdx;
	std::vector<double> nthD2, refD2;  // isolation's second rule
	// The noise and isolation statistics freed, once read.
	void dropStatistics() {
		std::vector<double>().swap(noise), std::vector<double>().swap(kthD2);
		std::vector<int32_t>().swap(near), std::vector<int32_t>().swap(kthIdx);
		std::vector<double>().swap(nthD2), std::vector<double>().swap(refD2);
	}
};

// One pass over the tree's points at the scales ks: projected distances (paper mode) or
// relative distances and score (robust), and with noiseK > 0 the isolation and noise
// statistics (_kernels.cloud_projected_distances).
CloudPass cloudPass(const Tree &t, const std::vector<int> &scales, bool gaussian, bool relative,
                    int noiseK, Bar &bar, int from, int to, bool normals = false) {
	const std::vector<Index> ks(scales.begin(), scales.end());
	const size_t S = ks.size();
	CloudPass c;
	cloud_out_t out{};
	if (relative) {
		c.relative.resize(S * t.n);
		c.score.resize(t.n);
		out.relative = c.relative.data();
		out.score = c.score.data();
		// robust mode's sheet filter (robust.sheet_mask): every scale's neighbourhood, and
		// the noise's, without the points on another sheet
		out.sheet_gap = MS_SHEET_GAP;
		out.sheet_min = MS_SHEET_MIN;
		out.sheet_own = MS_SHEET_OWN;
		out.sheet_column = MS_SHEET_COLUMN;
		out.sheet_column_gap = MS_SHEET_COLUMN_GAP;
		out.sheet_far_span = MS_SHEET_FAR_SPAN;
		out.sheet_trim = MS_SHEET_TRIM;
		out.sheet_trim_cos = MS_SHEET_TRIM_COS;
	} else {
		c.pdis.resize(S * t.n);
		out.pdis = c.pdis.data();
	}
	if (noiseK > 0) {
		c.noise.resize(t.n);
		c.kthD2.resize(t.n);
		c.near.resize(t.n);
		c.kthIdx.resize(t.n);
		c.nthD2.resize(t.n);
		c.refD2.resize(t.n);
		out.noise = c.noise.data();
		out.noise_k = noiseK;
		out.near = c.near.data();
		out.kth_d2 = c.kthD2.data();
		out.kth_idx = c.kthIdx.data();
		out.nth_d2 = c.nthD2.data();
		out.ref_d2 = c.refD2.data();
		out.isolated_nth = MS_ISOLATED_NTH;
		out.isolated_ref = MS_ISOLATED_REF;
	}
	if (normals) {  // the normals at every scale (S, n, 3)
		c.normals.resize(3 * S * t.n);
		out.normals = c.normals.data();
	}
	out.tree_order = noiseK > 0 ? 2 : 1;
	chunks(t.n, [&](unsigned, Index a, Index b) {
		return ms_cloud_pdis(t.pts.data(), t.orig.data(), t.n, t.box.data(), t.depth, ks.data(), int(S),
		                     int(gaussian), a, b, &out);
	}, bar, from, to, "neighbours and projected distances");
	return c;
}

// The cleaned mesh's adjacency: cleaning's when it built it (handed on), else ms_adjacency's.
Rings adjacency(Clean &c) {
	if (!c.adj.ptr.empty()) return std::move(c.adj);
	return adjacency(c.faces.data(), Index(c.faces.size() / 3), c.size());
}

// The rings `inner` and `outer` (inner <= outer) of the vertices rows, breadth-first as
// ms_ring_pdis sums them (ms_ring_lists, as _kernels.ring_members): the outer ring of row
// r at idx[start[r]...], length[r] of it the inner ring, length[m + r] the outer.
struct RingRows {
	std::vector<Index> start, length;
	std::vector<int32_t> idx;
	// The ring inner (which = 0) or outer (1) of each row, for the finishing steps.
	ms_lists_t lists(int which) const {
		return {idx.data(), 0, start.data(), 0, length.data() + which * (start.size() - 1), 0};
	}
};

RingRows ringRows(const Rings &adj, const std::vector<Index> &rows, int inner, int outer) {
	const Index m = Index(rows.size());
	const Index rings[2] = {inner, outer};
	std::vector<int32_t> stamp(adj.ptr.size() - 1, -1);
	RingRows out{std::vector<Index>(m + 1, 0), std::vector<Index>(2 * m), {}};
	check(ms_ring_lists(adj.ptr.data(), adj.idx.data(), rows.data(), m, rings, 2, stamp.data(), out.length.data(),
	                    nullptr, nullptr));
	for (Index r = 0; r < m; ++r) out.start[r + 1] = out.start[r] + out.length[m + r];
	out.idx.resize(out.start[m]);
	check(ms_ring_lists(adj.ptr.data(), adj.idx.data(), rows.data(), m, rings, 2, stamp.data(), out.length.data(),
	                    out.start.data(), out.idx.data()));
	return out;
}

// The kernel's view of a byte mask.
const uint8_t *bytes(const std::vector<char> &mask) { return reinterpret_cast<const uint8_t *>(mask.data()); }

// Robust mode's support and thinning of the candidates rows = the points of f0, by the
// kernel's finishing steps on every core, as _kernels.support_and_thin: per candidate its
// line direction (lists D), support (lists S; a score below freeBelow exempts, when
// exempt: reference.detect.support_exempt) and, with smooth, the score averaged over the
// first THIN_KNN of K (robust.smoothed_ranking); then, every candidate's support known, thinning
// across the line (cone) or beside it (side; both ms_robust_plan's) over K, the points not
// in f0 blocking with block (reference.detect.thin_blockers); then, with line, every
// candidate's thinning known, the line test over K (ms_line_test, the same blockers).
std::vector<char> supportAndThin(const Buffer<double> &p, const std::vector<char> &f0,
                                 const std::vector<double> &score, const std::vector<Index> &rows,
                                 const ms_lists_t &D, const ms_lists_t &S, const ms_lists_t &K, bool exempt,
                                 double freeBelow, bool smooth, bool block, double cone, double side, bool line,
                                 Bar &bar, int from, int to) {
	const Index c = Index(rows.size());
	std::vector<double> e(3 * c), smoothed(smooth ? score : std::vector<double>());
	const double *rank = smooth ? smoothed.data() : score.data();
	std::vector<uint8_t> f1(f0.size(), 0), between(block ? f0.size() : 0);
	for (size_t i = 0; i < between.size(); ++i) between[i] = !f0[i];
	chunks(c, [&](unsigned, Index a, Index b) {
		if (ms_line_directions(p.data(), bytes(f0), rows.data(), &D, a, b, e.data()) != 0) return -1;
		ms_supported(p.data(), bytes(f0), rows.data(), e.data(), &S, MS_THIN_CONE_COS, MS_SUPPORT_MIN,
		             exempt ? score.data() : nullptr, freeBelow, a, b, f1.data());
		if (smooth) ms_smoothed_ranking(score.data(), rows.data(), &K, MS_THIN_KNN, a, b, smoothed.data());
		return 0;
	}, bar, from, (from + to) / 2, "support and thinning");
	std::vector<char> f2(f0.size(), 0);
	chunks(c, [&](unsigned, Index a, Index b) {
		ms_thin(p.data(), f1.data(), rows.data(), e.data(), &K, rank, cone, side,
		        block ? between.data() : nullptr, a, b, reinterpret_cast<uint8_t *>(f2.data()));
		return 0;
	}, bar, (from + to) / 2, to, "support and thinning");
	if (!line) return f2;
	std::vector<char> f3(f0.size(), 0);
	const ms_line_rules_t rules{MS_LINE_OFFSET, MS_LINE_SPREAD, MS_LINE_REACH, MS_LINE_MIN, MS_LINE_UNIT};
	chunks(c, [&](unsigned, Index a, Index b) {
		return ms_line_test(p.data(), bytes(f2), rows.data(), &K, rank, &rules, block ? between.data() : nullptr, a,
		                    b, reinterpret_cast<uint8_t *>(f3.data()));
	}, bar, to, to, "support and thinning");
	return f3;
}

// creases.sharp_vertices: both vertices of every edge with exactly two faces whose unit
// normals turn by more than max(CREASE_ANGLE, NOISE_FACTOR * lower quartile of the angles);
// the edges and their normals' dot products from the kernel (_kernels.crease_vertices).
// Each vertex's faces, in face order (ms_vertex_faces): what the sharp edges and the
// faces' windings read.
struct Incidence {
	std::vector<Index> ptr;
	Buffer<int32_t> inc;
};

Incidence vertexFaces(const Buffer<Index> &faces, Index n) {
	const Index F = Index(faces.size() / 3);
	Incidence out{std::vector<Index>(n + 1), Buffer<int32_t>(3 * F)};
	check(ms_vertex_faces(faces.data(), F, n, out.ptr.data(), out.inc.data()));
	return out;
}

std::vector<char> sharpVertices(const Buffer<double> &p, const Buffer<Index> &faces, const Incidence &at) {
	const Index n = Index(p.size() / 3);
	const Index *ptr = at.ptr.data();
	const int32_t *inc = at.inc.data();
	std::vector<Index> estart(n + 1);
	Buffer<double> angles((3 * (faces.size() / 3) + 1) / 2);  // the turned edges' only written
	int64_t flat = 0; // edges whose angle is exactly 0, left out of angles
	angles.resize(ms_crease_dots(p.data(), faces.data(), n, ptr, inc, angles.data(), estart.data(), &flat));
	for (double &a : angles) a = std::acos(std::min(1.0, std::max(-1.0, a)));
	double theta = MS_CREASE_ANGLE * (M_PI / 180.0);
	const size_t all = angles.size() + size_t(flat);
	// the quartile is element (all - 1) / 4 of all the angles; the flat ones are the
	// smallest (0: NOISE_FACTOR * 0 leaves theta at the floor)
	if (all > 0 && (all - 1) / 4 >= size_t(flat)) {
		std::vector<double> sorted(angles.begin(), angles.end());
		const size_t at = (all - 1) / 4 - size_t(flat);
		std::nth_element(sorted.begin(), sorted.begin() + at, sorted.end());
		theta = std::max(theta, MS_NOISE_FACTOR * sorted[at]);
	}
	std::vector<uint8_t> mask(n, 0);
	ms_crease_mask(p.data(), faces.data(), n, ptr, inc, estart.data(), angles.data(), theta, mask.data());
	return std::vector<char>(mask.begin(), mask.end());
}

// What one mode leaves per processed point.
struct Decision {
	std::vector<Index> toClean;    // cleaned index of each processed point; empty: every one, in order
	std::vector<double> strength;  // fraction of scales (1 on robust mode's sharp mesh edges)
	std::vector<char> feature;
	// Options::details: per scale and processed point the distances Otsu split (S, p) and
	// the normals (S, p, 3); else empty.
	Buffer<double> distances, normals;
};

// Per-scale rows (S, n, width) in tree order moved to the cleaned order (toCleaned).
void toCleanedRows(const std::vector<Index> &orig, Buffer<double> &rows, int width) {
	if (rows.empty()) return;
	const size_t n = orig.size(), block = n * size_t(width);
	std::vector<double> tmp(block);
	for (size_t at = 0; at < rows.size(); at += block) {
		for (size_t t = 0; t < n; ++t)
			for (int a = 0; a < width; ++a) tmp[size_t(orig[t]) * width + a] = rows[at + t * width + a];
		std::copy(tmp.begin(), tmp.end(), rows.begin() + at);
	}
}

// Decision's details kept for S scales of n points: the distances written by
// stageDecision(), the normals moved from the pass's.
void keepDetails(Decision &d, bool details, size_t S, Index n, Buffer<double> &normals) {
	if (!details) return;
	d.distances.resize(S * n);
	d.normals.swap(normals);
}

// The distances' row of scale s (null without details).
double *detailRow(Decision &d, size_t s, Index n) { return d.distances.empty() ? nullptr : &d.distances[s * n]; }

// The pointwise stages (stages.c) over the n points' values x, scale s at x[s * n ...], in
// the order `order` maps to the cleaned points (empty: that order): each scale's threshold
// from the histograms summed over chunks of points on every core (ms_stage_threshold:
// with otsu, Otsu's split, never below floor, or with a plan its floors, ms_plan_thresholds;
// lo, hi and flatSpan: ms_stage_histograms' normalisation), then the decision
// (ms_stage_decide); thresholds and candidates to r, strength and feature (in the
// cleaned order) to d; with values not null, the values the thresholds split (S, n; x's
// order: normalised with lo, else x's) into values.
void stageDecision(const double *x, Index n, size_t S, const double *lo, const double *hi, double flatSpan, bool otsu,
                   double floor, const std::vector<Index> &order, Decision &d, Result &r,
                   const ms_robust_plan_t *plan = nullptr, double *values = nullptr) {
	const Index count = (n + MS_CHUNK - 1) / MS_CHUNK;
	const int s = int(S);
	std::vector<int64_t> counts(otsu ? size_t(count) * S * MS_BINS : 0, 0);
	if (otsu)
		eachIndex(count, [&](Index u) {
			ms_stage_histograms(x, 1, n, s, u * MS_CHUNK, std::min(n, (u + 1) * MS_CHUNK), lo, hi, flatSpan,
			                    &counts[size_t(u) * S * MS_BINS]);
		});
	std::vector<double> thresholds(S);
	for (Index u = 1; u < count && otsu; ++u)  // the chunks' histograms summed into the first's
		for (size_t b = 0; b < S * MS_BINS; ++b) counts[b] += counts[size_t(u) * S * MS_BINS + b];
	if (plan != nullptr)  // robust mode's floors
		ms_plan_thresholds(plan, otsu ? counts.data() : nullptr, thresholds.data());
	else
		for (size_t k = 0; k < S; ++k)
			thresholds[k] = ms_stage_threshold(otsu ? &counts[k * MS_BINS] : nullptr, otsu, floor);
	d.feature.assign(n, 0);
	d.strength.assign(n, 0.0);
	uint8_t *feature = reinterpret_cast<uint8_t *>(d.feature.data());
	std::vector<int64_t> candidates(size_t(count) * S, 0);
	eachIndex(count, [&](Index u) {
		const Index a = u * MS_CHUNK, b = std::min(n, a + MS_CHUNK);
		if (order.empty()) {
			ms_stage_decide(x, 1, n, s, a, b, lo, hi, flatSpan, thresholds.data(), feature, d.strength.data(),
			                &candidates[size_t(u) * S], values);
			return;
		}
		// a chunk's decision, then moved to the cleaned order
		uint8_t chunkFeature[MS_CHUNK];
		double chunkStrength[MS_CHUNK];
		ms_stage_decide(x + a, 1, n, s, 0, b - a, lo, hi, flatSpan, thresholds.data(), chunkFeature, chunkStrength,
		                &candidates[size_t(u) * S], values == nullptr ? nullptr : values + a);
		for (Index i = a; i < b; ++i) {
			feature[order[i]] = chunkFeature[i - a];
			d.strength[order[i]] = chunkStrength[i - a];
		}
	});
	for (size_t k = 0; k < S; ++k) {
		int64_t c = 0;
		for (Index u = 0; u < count; ++u) c += candidates[size_t(u) * S + k];
		r.thresholds.push_back(thresholds[k]);
		r.candidates.push_back(long(c));
	}
}

// What the ring pass reads of a mesh, besides its points: the adjacency, the
// face-average normals (n, 3) and, in robust mode, the vertices of its sharp edges
// (creases.py). Unless the run has one thread, on two threads: in paper mode the faces'
// turns (ms_face_windings: on a mesh wound either way round its incidence and
// union-find) and then the normals beside the adjacency; in robust mode the sharp edges
// (the longest) beside the turns (from the incidence the sharp edges read too), the
// adjacency and the normals.
// The faces are freed once read (no later step reads them, as pipeline.py).
struct MeshLists {
	Rings adj;
	std::vector<double> normals;
	std::vector<char> edges;
};

MeshLists meshLists(Clean &c, bool robust) {
	MeshLists out;
	const Index n = c.size(), F = Index(c.faces.size() / 3);
	std::vector<uint8_t> turned(size_t(std::max<Index>(F, 1)));
	auto normals = [&] {
		out.normals.assign(3 * n, 0.0);
		check(ms_face_average_normals_at(c.pts.data(), n, c.faces.data(), F, turned.data(), MS_ZERO_NORMAL,
		                                 out.normals.data()) < 0);
	};
	if (!robust) {  // the faces' turns and then the normals beside the adjacency
		twoParts(2, [&](Index part) {
			if (part == 0) return void(out.adj = adjacency(c));
			check(ms_face_windings(c.faces.data(), F, n, turned.data()) < 0);
			normals();
		}, workers() > 1);
	} else {  // the sharp edges (the longest) beside the turns, the adjacency and the normals
		const Incidence at = vertexFaces(c.faces, n);  // read by the turns and the sharp edges
		twoParts(2, [&](Index part) {
			if (part == 1) return void(out.edges = sharpVertices(c.pts, c.faces, at));
			check(ms_face_windings_at(c.faces.data(), F, n, at.ptr.data(), at.inc.data(), turned.data()) < 0);
			out.adj = adjacency(c);
			normals();
		}, workers() > 1);
	}
	Buffer<Index>().swap(c.faces);
	return out;
}

// The mesh's projected distances (S, n) at every ring by the kernel's breadth-first search,
// the face-average normals fixed (n, 3; zero rows: PCA), as _kernels.ring_projected_distances;
// with score not null, robust mode's relative distances (S, n) instead, and the score (n)
// into *score, from the same walk (relative=True); with normalsOut not null, the normals
// (S, n, 3) into it (keep_normals=True).
Buffer<double> ringPdis(const Clean &c, const Rings &adj, const std::vector<double> &normals,
                        const std::vector<int> &scales, bool gaussian, std::vector<double> *score, Bar &bar,
                        int from, int to, Buffer<double> *normalsOut = nullptr) {
	const Index n = c.size();
	const std::vector<Index> rings(scales.begin(), scales.end());
	Buffer<double> out(rings.size() * n);  // filled whole by the kernel
	if (score) score->assign(n, 0.0);
	double *pdis = score ? nullptr : out.data(), *relative = score ? out.data() : nullptr;
	double *scores = score ? score->data() : nullptr;
	if (normalsOut) normalsOut->resize(3 * rings.size() * n);  // the normals at every ring (S, n, 3)
	double *usedNormals = normalsOut ? normalsOut->data() : nullptr;
	// a scattered vertex order renumbered breadth-first (same rings, same sums), for locality
	const double *pts = c.pts.data(), *fixed = normals.data();
	const Index *ptr = adj.ptr.data();
	const int32_t *idx = adj.idx.data(), *dest = nullptr;
	std::vector<int32_t> order, rank, idxAt;
	std::vector<Index> ptrAt;
	std::vector<double> ptsAt, fixedAt;
	if (ms_scattered(ptr, idx, n)) {
		order.resize(n), rank.resize(n), ptrAt.resize(n + 1), idxAt.resize(adj.idx.size());
		ptsAt.resize(3 * n), fixedAt.resize(3 * n);
		ms_bfs_renumber(ptr, idx, n, pts, fixed, order.data(), rank.data(), ptrAt.data(), idxAt.data(),
		                ptsAt.data(), fixedAt.data());
		pts = ptsAt.data(), fixed = fixedAt.data(), ptr = ptrAt.data(), idx = idxAt.data(), dest = order.data();
	}
	// where a vertex's search is the previous vertex's plus one (a grid-numbered mesh)
	std::vector<uint8_t> shifted(n);
	ms_shifted_lists(ptr, idx, n, 0, n, shifted.data());
	std::vector<std::vector<int32_t>> stamps(workers());
	chunks(n, [&](unsigned w, Index a, Index b) {
		if (stamps[w].empty()) stamps[w].assign(n, -1);
		return ms_ring_pdis(pts, n, ptr, idx, fixed, rings.data(), int(rings.size()), int(gaussian), a, b,
		                    stamps[w].data(), dest, shifted.data(), pdis, usedNormals, relative, scores);
	}, bar, from, to, score ? "rings, projected distances and local scales" : "rings and projected distances");
	return out;
}

// The paper's method (ALGORITHM.md): min-max normalisation with the flat-scale rule,
// Otsu, candidates at every scale.
Decision paperMode(Clean &c, const Options &options, Result &r, Bar &bar) {
	const Index n = c.size();
	const size_t S = r.scales.size();
	double box[3];
	ms_extent(c.pts.data(), n, box);
	Buffer<double> pdis, normals;
	std::vector<Index> orig;  // a cloud's tree order: the cleaned index of each row of pdis
	if (r.mesh) {
		bar.report(0, "neighbourhoods");
		const MeshLists lists = meshLists(c, false);
		pdis = ringPdis(c, lists.adj, lists.normals, r.scales, options.gaussian, nullptr, bar, 0, 90,
		                options.details ? &normals : nullptr);
	} else {
		bar.report(0, "kd-tree");
		Tree tree(std::move(c.pts));  // no later step reads the points
		CloudPass pass = cloudPass(tree, r.scales, options.gaussian, false, 0, bar, 5, 90, options.details);
		pdis.swap(pass.pdis);
		normals.swap(pass.normals);
		orig.swap(tree.orig);
	}
	const double flatSpan = ms_flat_span(box);
	bar.report(90, "thresholds");
	std::vector<double> lo(S, 0.0), hi(S, 0.0);  // each scale's range
	eachIndex(Index(S), [&](Index s) {
		const double *x = &pdis[s * n];
		double mn = n > 0 ? x[0] : 0.0, mx = mn;
		for (Index i = 1; i < n; ++i) {
			mn = x[i] < mn ? x[i] : mn;
			mx = x[i] > mx ? x[i] : mx;
		}
		lo[s] = mn, hi[s] = mx;
	});
	Decision d;
	keepDetails(d, options.details, S, n, normals);
	stageDecision(pdis.data(), n, S, lo.data(), hi.data(), flatSpan, true, 0.0, orig, d, r, nullptr, detailRow(d, 0, n));
	Buffer<double>().swap(pdis);
	if (!orig.empty()) {
		toCleanedRows(orig, d.distances, 1);
		toCleanedRows(orig, d.normals, 3);
	}
	// a flat scale's threshold is 1.0, and only a flat scale's: any other's normalised
	// values hold 0 and 1, which Otsu's split parts
	r.allFlat = std::all_of(r.thresholds.begin(), r.thresholds.end(), [](double t) { return !(t < 1.0); });
	return d;
}

// The points of mask in tree order (cleaned indices) and the k nearest of each, at
// table[c * k ...] (_kernels.cloud_knn_of_mask: searched in tree order, the rows of a leaf
// together).
struct KnnOfMask {
	std::vector<Index> rows, table;
	int k;
	// The first `first` of each row, the rows beginning at `starts` in the table.
	ms_lists_t lists(int first, const std::vector<Index> &starts) const {
		return {table.data(), 1, starts.data(), k, nullptr, first};
	}
};

KnnOfMask knnOfMask(const Tree &t, const std::vector<char> &mask, int k, Bar &bar, int from, int to) {
	KnnOfMask out{{}, {}, k};
	std::vector<Index> pos;
	for (Index x = 0; x < t.n; ++x)
		if (mask[t.orig[x]]) {
			pos.push_back(x);
			out.rows.push_back(t.orig[x]);
		}
	out.table.resize(pos.size() * k);
	chunks(Index(pos.size()), [&](unsigned, Index a, Index b) {
		return ms_knn_rows(t.pts.data(), t.orig.data(), t.n, t.box.data(), t.depth, pos.data(), k, a, b,
		                   out.table.data());
	}, bar, from, to, "support and thinning");
	return out;
}

// reference.detect.RobustSetup on a cloud: isolated points left out (isolated_from_stats),
// then what ms_robust_plan decides: the scales grown with the noise and the pass at them,
// the thresholds, the acute tests, the lists and the ranking; relative distances and
// score from the kernel (RelativeRule.from_pass); acute tips, support and thinning by the
// kernel on the candidates' kNN rows (RobustSetup._finish_compiled).
Decision robustCloud(Clean &c, const Options &options, Result &r, Bar &bar) {
	Decision d;  // its toClean: empty (all cleaned points) unless isolated ones are left out
	const int top0 = r.scales.back();
	const int k0 = std::min(MS_NOISE_KNN, top0);
	bar.report(0, "kd-tree");
	auto tree = std::make_unique<Tree>(std::move(c.pts));  // the points in cleaned order: pts below
	Buffer<double> pts;  // the points processed, in cleaned order once the pass is done
	CloudPass pass = cloudPass(*tree, r.scales, options.gaussian, true, k0, bar, 5, 45, options.details);
	std::vector<uint8_t> isolated(tree->n);  // per tree position (_kernels.isolated_from_stats)
	eachIndex((tree->n + MS_CHUNK - 1) / MS_CHUNK, [&](Index u) {
		ms_isolated_tree(tree->pts.data(), tree->orig.data(), pass.near.data(), pass.kthD2.data(),
		                 pass.kthIdx.data(), pass.nthD2.data(), pass.refD2.data(),
		                 MS_ISOLATED_SPREAD, u * MS_CHUNK, std::min(tree->n, (u + 1) * MS_CHUNK), isolated.data());
	});
	isolated = toCleaned(tree->orig, isolated);
	const Index nKeep = tree->n - Index(std::count(isolated.begin(), isolated.end(), uint8_t(1)));
	if (nKeep < tree->n) {
		std::vector<Index> keep;
		keep.reserve(nKeep);
		for (Index i = 0; i < tree->n; ++i)
			if (!isolated[i]) keep.push_back(i);
		if (Index(keep.size()) < top0) throw InputError("too few points are left once isolated points are removed");
		pass = CloudPass();
		{
			const Buffer<double> all = cleanedPoints(*tree);
			tree.reset();
			pts.resize(3 * keep.size());
			for (size_t i = 0; i < keep.size(); ++i)
				for (int a = 0; a < 3; ++a) pts[3 * i + a] = all[3 * keep[i] + a];
		}
		d.toClean.swap(keep);
		tree = std::make_unique<Tree>(pts);
		pass = cloudPass(*tree, r.scales, options.gaussian, true, k0, bar, 45, 65, options.details);
	}
	const Index n = tree->n;
	const Index at = (n - 1) / 2;
	std::nth_element(pass.noise.begin(), pass.noise.begin() + at, pass.noise.end());
	ms_robust_plan_t plan;  // every decision below (the median noise ratio's)
	ms_robust_plan(pass.noise[at], n, r.scales.data(), int(r.scales.size()), 0, &plan);  // scales checked
	pass.dropStatistics();
	if (plan.grown) {
		r.scales.assign(plan.scales, plan.scales + plan.n_scales);
		if (r.scales.back() > n)
			throw InputError("k = " + std::to_string(r.scales.back()) + " nearest neighbours needs at least " +
			                 std::to_string(r.scales.back()) + " points, got " + std::to_string(n));
		pass = CloudPass();
		pass = cloudPass(*tree, r.scales, options.gaussian, true, 0, bar, 65, 85, options.details);
	}
	bar.report(85, "thresholds");
	keepDetails(d, options.details, r.scales.size(), n, pass.normals);
	stageDecision(pass.relative.data(), n, r.scales.size(), nullptr, nullptr, 0.0, plan.otsu != 0, R_MIN, tree->orig,
	              d, r, &plan, detailRow(d, 0, n));
	Buffer<double>().swap(pass.relative);
	toCleanedRows(tree->orig, d.distances, 1);
	toCleanedRows(tree->orig, d.normals, 3);
	pass.score = toCleaned(tree->orig, pass.score);
	if (pts.empty()) pts = cleanedPoints(*tree);
	bar.report(85, "support and thinning");
	const int top = r.scales.back();
	// robust.acute_tests: one search for them and the candidates (RobustSetup._finish_compiled)
	std::vector<uint8_t> tests(n, 0);
	const bool tested = plan.acute_tests &&
	                    ms_stage_acute_tests(pass.score.data(), bytes(d.feature), 0, n, 0, plan.noise, tests.data()) > 0;
	std::vector<char> todo = d.feature;
	for (Index i = 0; tested && i < n; ++i) todo[i] |= char(tests[i]);
	std::vector<uint8_t>().swap(tests);
	const KnnOfMask knn = knnOfMask(*tree, todo, top, bar, 85, 90);
	const int thinK = plan.compare_knn;
	std::vector<Index> starts, rows;  // the candidates and where their rows begin in the table
	if (tested) {  // robust.acute_tips
		std::vector<Index> tests, at;
		for (size_t c = 0; c < knn.rows.size(); ++c)
			if (!d.feature[knn.rows[c]]) {
				tests.push_back(knn.rows[c]);
				at.push_back(Index(c) * top);
			}
		const ms_lists_t near{knn.table.data(), 1, at.data(), 0, nullptr, thinK};
		std::vector<uint8_t> tip(tests.size());
		chunks(Index(tests.size()), [&](unsigned, Index a, Index b) {
			ms_acute_tips(pts.data(), bytes(d.feature), tests.data(), &near, a, b, tip.data());
			return 0;
		}, bar, 90, 90, "support and thinning");
		for (size_t c = 0; c < tests.size(); ++c)
			if (tip[c]) d.feature[tests[c]] = 1;
	}
	for (size_t c = 0; c < knn.rows.size(); ++c)
		if (d.feature[knn.rows[c]]) {
			starts.push_back(Index(c) * top);
			rows.push_back(knn.rows[c]);
		}
	if (rows.empty()) return d;
	d.feature = supportAndThin(pts, d.feature, pass.score, rows, knn.lists(top, starts),
	                           knn.lists(plan.support_knn, starts), knn.lists(thinK, starts), plan.support_exempt != 0,
	                           plan.free_below, plan.ranking_smoothed != 0, plan.thin_between != 0, plan.thin_cone,
	                           plan.thin_side, plan.thin_line != 0, bar, 90, 95);
	return d;
}

// Robust mode on a mesh: the relative distances and the score from the kernel's ring pass
// (the local scales summed in breadth-first order, as RobustSetup), support and thinning
// over the 2-ring, and the vertices of the mesh's sharp edges (creases.py).
Decision robustMesh(Clean &c, const Options &options, Result &r, Bar &bar) {
	const Index n = c.size();
	const size_t S = r.scales.size();
	const int top = r.scales.back();
	bar.report(0, "neighbourhoods");
	const MeshLists lists = meshLists(c, true);
	const Rings &adj = lists.adj;
	const std::vector<char> &edges = lists.edges;
	std::vector<double> score;
	Buffer<double> normals;
	Buffer<double> relative = ringPdis(c, adj, lists.normals, r.scales, options.gaussian, &score, bar, 0, 85,
	                                   options.details ? &normals : nullptr);
	bar.report(85, "thresholds");
	Decision d;
	keepDetails(d, options.details, S, n, normals);
	ms_robust_plan_t plan;  // a mesh's: Otsu over the floor at every scale, its ring, cone and side rule
	ms_robust_plan(0.0, n, r.scales.data(), int(S), 1, &plan);  // scales checked
	stageDecision(relative.data(), n, S, nullptr, nullptr, 0.0, plan.otsu != 0, R_MIN, {}, d, r, &plan,
	              detailRow(d, 0, n));
	if (plan.curved_dropped)  // the candidates on a curved surface (its relative distance grows with the ring)
		ms_stage_curved(relative.data(), relative.data() + (S - 1) * size_t(n), 0, n, r.scales.front(),
		                r.scales.back(), reinterpret_cast<uint8_t *>(d.feature.data()));
	Buffer<double>().swap(relative);
	bar.report(85, "support and thinning");
	std::vector<Index> rows;
	for (Index i = 0; i < n; ++i)
		if (d.feature[i]) rows.push_back(i);
	if (!rows.empty()) {
		const RingRows rings = ringRows(adj, rows, plan.support_knn, top);
		d.feature = supportAndThin(c.pts, d.feature, score, rows, rings.lists(1), rings.lists(0), rings.lists(0), false,
		                           0.0, false, false, plan.thin_cone, plan.thin_side, plan.thin_line != 0, bar, 85,
		                           95);
	}
	for (Index i = 0; i < n; ++i)
		if (edges[i]) {
			d.feature[i] = 1;
			d.strength[i] = 1.0;
		}
	return d;
}

// Per-scale rows (S, p, width) of the p processed points moved to the nIn input
// vertices (S, nIn, width), NaN where a vertex took no part: input vertex i is cleaned
// vertex fromInput[i] (itself when fromInput is empty; -1: dropped), that processed
// point processed[.] (-1: left out; processed empty: itself).
void toInputRows(const Buffer<double> &rows, int width, size_t p, const std::vector<Index> &fromInput,
                 const std::vector<Index> &processed, Index nIn, std::vector<double> &out) {
	if (rows.empty()) return;
	const size_t S = rows.size() / (p * size_t(width));
	out.assign(S * size_t(nIn) * width, std::numeric_limits<double>::quiet_NaN());
	for (Index i = 0; i < nIn; ++i) {
		const Index ci = fromInput.empty() ? i : fromInput[i];
		const Index at = ci < 0 || processed.empty() ? ci : processed[ci];
		if (at < 0) continue;
		const size_t pi = size_t(at);
		for (size_t s = 0; s < S; ++s)
			for (int a = 0; a < width; ++a)
				out[(s * nIn + i) * width + a] = rows[(s * p + pi) * width + a];
	}
}

// The command line's grammar (meshlab_sharp.cli.parse_scales), read the same way:
// a list "12,16,20" (commas) or "12 16 20" (ASCII white space), never both, or an
// inclusive range "12:40:4" ("1:4" steps by 1); each number an optional sign and digits,
// white space around it allowed, at most 2^31 - 1 in magnitude. Errors name the text.
bool isSpace(const char ch) {
	return ch == ' ' || ch == '\t' || ch == '\n' || ch == '\r' || ch == '\f' || ch == '\v';
}

// One number of the grammar; false when `token` is not one.
bool scaleNumber(const std::string &token, long &value) {
	size_t i = 0, end = token.size();
	while (i < end && isSpace(token[i])) ++i;
	while (end > i && isSpace(token[end - 1])) --end;
	const bool negative = i < end && token[i] == '-';
	if (i < end && (token[i] == '+' || token[i] == '-')) ++i;
	if (i == end) return false;
	long v = 0;
	for (; i < end; ++i) {
		if (token[i] < '0' || token[i] > '9') return false;
		v = 10 * v + (token[i] - '0');
		if (v > 2147483647L) return false;
	}
	value = negative ? -v : v;
	return true;
}

std::vector<std::string> splitAt(const std::string &text, const char sep) {
	std::vector<std::string> parts(1);
	for (char ch : text)
		if (ch == sep)
			parts.emplace_back();
		else
			parts.back() += ch;
	return parts;
}

InputError badScales(const std::string &text, const std::string &why) {
	return InputError("invalid scales '" + text + "': " + why);
}

}  // namespace

std::vector<int> parseScales(const std::string &text, int minimum) {
	const std::string hint = "use a list like 12,16,20 or 12 16 20, or a range like 12:40:4";
	std::vector<long> values;
	if (text.find(':') != std::string::npos) {
		const std::vector<std::string> parts = splitAt(text, ':');
		long v[3] = {0, 0, 1};
		if (parts.size() != 2 && parts.size() != 3) throw badScales(text, hint);
		for (size_t j = 0; j < parts.size(); ++j)
			if (!scaleNumber(parts[j], v[j])) throw badScales(text, hint);
		if (v[2] <= 0) throw badScales(text, hint);
		if (v[1] < v[0]) throw badScales(text, "the range is empty");
		const long count = (v[1] - v[0]) / v[2] + 1;  // checked before it is built
		if (count > MS_MAX_SCALES)
			throw badScales(text, std::to_string(count) + " scales, more than " + std::to_string(MS_MAX_SCALES));
		for (long s = v[0]; s <= v[1]; s += v[2]) values.push_back(s);
	} else {
		std::vector<std::string> items;
		if (text.find(',') != std::string::npos) {
			items = splitAt(text, ',');
		} else {
			std::string token;
			for (char ch : text + " ")
				if (!isSpace(ch))
					token += ch;
				else if (!token.empty())
					items.push_back(token), token.clear();
		}
		if (items.empty()) throw badScales(text, hint);
		for (const std::string &item : items) {
			long v = 0;
			if (!scaleNumber(item, v)) throw badScales(text, hint);
			values.push_back(v);
		}
		if (long(values.size()) > MS_MAX_SCALES)
			throw badScales(text, std::to_string(values.size()) + " scales, more than " + std::to_string(MS_MAX_SCALES));
	}
	std::vector<int> out(values.begin(), values.end());
	std::sort(out.begin(), out.end());
	out.erase(std::unique(out.begin(), out.end()), out.end());
	if (out.front() < minimum)
		throw InputError("scales must be >= " + std::to_string(minimum) + ", got " + std::to_string(out.front()));
	return out;
}

std::string formatScales(const std::vector<int> &scales) {
	std::string out;
	for (int s : scales) out += (out.empty() ? "" : " ") + std::to_string(s);
	return out;
}

Result detect(const double *xyz, const Index nIn, const Index *faces, const Index m, const Options &options,
              ms_progress_fn progress, void *ctx) {
	runThreads = options.threads > 0 ? options.threads : cores();
	Bar bar(progress, ctx);
	bar.report(0, "cleaning");
	if (nIn == 0) throw InputError("the layer has no vertices");
	Result r;
	r.mesh = m > 0 && !options.asPoints;
	// a cloud's far points dropped first (as pipeline.py): kept, they would set the unit;
	// found in the pass that checks the coordinates (the culprit of a refusal after it)
	FarTest test;
	if (!r.mesh) farTest(xyz, nIn, test);
	const Scan scan = scanInput(xyz, nIn, r.mesh ? nullptr : &test);
	for (Index i = 0; !scan.finite; ++i)
		if (!std::isfinite(xyz[i]))
			throw InputError("vertex " + std::to_string(i / 3) + " has a non-finite coordinate (NaN or inf)");
	bool inRange = true;
	for (Index i = 0; i < 3 * m; ++i) inRange &= uint64_t(faces[i]) < uint64_t(nIn);
	if (!inRange) throw InputError("a face index is out of range");
	std::vector<Index> near;
	std::vector<double> rest;
	if (scan.anyFar) {
		for (Index i = 0; i < nIn; ++i)
			if (!test.far(xyz + 3 * i)) {
				near.push_back(i);
				rest.insert(rest.end(), xyz + 3 * i, xyz + 3 * i + 3);
			}
	}
	const Index nNear = scan.anyFar ? Index(near.size()) : nIn;
	std::vector<double> scaled;
	const double *nearXyz = scan.anyFar ? rest.data() : xyz;
	Clean c = clean(unitScale(nearXyz, nNear, scan.anyFar ? maxAbs(nearXyz, 3 * nNear) : scan.big, scaled), nNear, faces,
	                r.mesh ? m : 0, r.mesh);
	scaled = std::vector<double>();
	rest = std::vector<double>();
	if (scan.anyFar) {  // the map from the input, the far points dropped
		std::vector<Index> fromInput(nIn, -1);
		for (size_t j = 0; j < near.size(); ++j)
			fromInput[near[j]] = c.fromInput.empty() ? Index(j) : c.fromInput[j];
		c.fromInput.swap(fromInput);
	}
	r.scales = r.mesh ? options.ringScales : options.knnScales;
	if (!r.mesh) {
		const Index n = c.size();
		if (n == 1 && nIn > 1) throw InputError("all " + std::to_string(nIn) + " points are identical");
		if (n < r.scales.back())
			throw InputError(std::to_string(n) + " distinct points, fewer than the largest scale k = " +
			                 std::to_string(r.scales.back()));
	}
	r.nClean = long(c.size());

	Decision d = !options.robust ? paperMode(c, options, r, bar)
	             : r.mesh        ? robustMesh(c, options, r, bar)
	                             : robustCloud(c, options, r, bar);

	r.timings = bar.times();
	Buffer<double>().swap(c.pts);

	// Back to the input's order.
	if (c.fromInput.empty() && d.toClean.empty()) {  // every input point, in order
		r.strength.swap(d.strength);
		r.feature.swap(d.feature);
		r.kept.assign(nIn, 1);
		r.nFeatures = long(std::count(r.feature.begin(), r.feature.end(), 1));
		r.distances.assign(d.distances.begin(), d.distances.end());
		Buffer<double>().swap(d.distances);
		r.normals.assign(d.normals.begin(), d.normals.end());
		bar.report(100, "done");
		return r;
	}
	std::vector<Index> processed;  // the processed point of each cleaned one (empty: itself)
	if (!d.toClean.empty()) processed.assign(c.size(), -1);
	for (size_t i = 0; i < d.toClean.size(); ++i) processed[d.toClean[i]] = Index(i);
	const size_t p = d.toClean.empty() ? size_t(c.size()) : d.toClean.size();
	toInputRows(d.distances, 1, p, c.fromInput, processed, nIn, r.distances);
	Buffer<double>().swap(d.distances);
	toInputRows(d.normals, 3, p, c.fromInput, processed, nIn, r.normals);
	Buffer<double>().swap(d.normals);
	r.strength.assign(nIn, 0.0);
	r.feature.assign(nIn, 0);
	r.kept.assign(nIn, 0);
	for (Index i = 0; i < nIn; ++i) {
		const Index ci = c.fromInput.empty() ? i : c.fromInput[i];
		const Index pi = ci < 0 || processed.empty() ? ci : processed[ci];
		if (pi < 0) continue;
		r.kept[i] = 1;
		r.strength[i] = d.strength[pi];
		r.feature[i] = d.feature[pi];
		r.nFeatures += r.feature[i];
	}
	bar.report(100, "done");
	return r;
}

}  // namespace sharp
