// meshlab-sharp native library: the feature curves behind the C ABI of
// native/include/meshlab_sharp.h (plain C types in and out; no C++ exception
// crosses it). The library is compiled with hidden visibility: only the C ABI, declared
// with default visibility by the header, is exported.
#include "meshlab_sharp.h"

#include "curves.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <memory>
#include <new>
#include <stdexcept>
#include <vector>

struct ms_curves {
	sharp::Curves result;
	int64_t vertices = 0;
};

namespace {

// The faces as the curves take them; false when an index is outside [0, n).
template <typename Index>
bool readFaces(const Index *faces, int64_t m, int64_t n, std::vector<std::array<int, 3>> &out)
{
	out.resize(size_t(m));
	for (int64_t i = 0; i < m; ++i)
		for (int k = 0; k < 3; ++k) {
			const Index v = faces[3 * i + k];
			if (v < 0 || int64_t(v) >= n) return false;
			out[size_t(i)][k] = int(v);
		}
	return true;
}

int extract(const double *vertices, const uint8_t *feature, const uint8_t *valid, int64_t n,
            const void *faces, int faceBytes, int64_t m, const double *bounds, const ms_curves_math *math,
            ms_curves **out)
{
	std::vector<sharp::Point> pts(static_cast<size_t>(n));
	for (int64_t i = 0; i < n; ++i) pts[size_t(i)] = {vertices[3 * i], vertices[3 * i + 1], vertices[3 * i + 2]};
	std::vector<char> feat(feature, feature + n);
	std::vector<char> ok;
	if (valid != nullptr) ok.assign(valid, valid + n);
	// the vertices the curves read are finite: a cloud's valid ones, all of a mesh's
	for (int64_t i = 0; i < n; ++i)
		if ((m > 0 || ok.empty() || ok[size_t(i)]) &&
		    !(std::isfinite(pts[size_t(i)].x) && std::isfinite(pts[size_t(i)].y) && std::isfinite(pts[size_t(i)].z)))
			return MS_CURVES_EINVAL;
	std::vector<std::array<int, 3>> tri;
	if (m > 0) {
		const bool inRange = faceBytes == 4
		                         ? readFaces(static_cast<const int32_t *>(faces), m, n, tri)
		                         : readFaces(static_cast<const int64_t *>(faces), m, n, tri);
		if (!inRange) return MS_CURVES_EINVAL;
	}
	std::array<sharp::Vec3, 2> box{};
	if (bounds != nullptr) {
		box[0] = {bounds[0], bounds[1], bounds[2]};
		box[1] = {bounds[3], bounds[4], bounds[5]};
	}
	std::unique_ptr<ms_curves> c(new ms_curves);  // freed when an allocation below fails
	c->result = sharp::extractCurves(pts, feat, ok, tri, bounds != nullptr ? &box : nullptr, math);
	for (const sharp::Curve &curve : c->result.curves) c->vertices += int64_t(curve.points.size());
	*out = c.release();
	return MS_CURVES_OK;
}

}  // namespace

extern "C" {

int ms_curves_extract(const double *vertices, const uint8_t *feature, const uint8_t *valid,
                      int64_t n, const void *faces, int face_bytes, int64_t m,
                      const double *bounds, const ms_curves_math *math, ms_curves **out)
{
	if (out == nullptr) return MS_CURVES_EINVAL;
	*out = nullptr;
	if (n < 0 || m < 0 || (n > 0 && (vertices == nullptr || feature == nullptr)) ||
	    (m > 0 && (faces == nullptr || n > int64_t(1) << 31)) || (face_bytes != 4 && face_bytes != 8))
		return MS_CURVES_EINVAL;
	try {
		return extract(vertices, feature, valid, n, faces, face_bytes, m, bounds, math, out);
	} catch (const std::bad_alloc &) {
		return MS_CURVES_ENOMEM;
	} catch (const std::length_error &) {  // a vector larger than memory could hold
		return MS_CURVES_ENOMEM;
	}
}

int64_t ms_curves_count(const ms_curves *c) { return int64_t(c->result.curves.size()); }

int64_t ms_curves_vertex_count(const ms_curves *c) { return c->vertices; }

int64_t ms_curves_corner_count(const ms_curves *c) { return int64_t(c->result.corners.size()); }

double ms_curves_spacing(const ms_curves *c) { return c->result.spacing; }

void ms_curves_copy(const ms_curves *c, int64_t *sizes, uint8_t *closed, double *lengths,
                    double *points, int64_t *indices)
{
	int64_t at = 0;
	for (size_t k = 0; k < c->result.curves.size(); ++k) {
		const sharp::Curve &curve = c->result.curves[k];
		sizes[k] = int64_t(curve.points.size());
		closed[k] = curve.closed ? 1 : 0;
		lengths[k] = curve.length;
		for (size_t i = 0; i < curve.points.size(); ++i, ++at) {
			std::memcpy(points + 3 * at, curve.points[i].data(), 3 * sizeof(double));
			indices[at] = int64_t(curve.indices[i]);
		}
	}
}

void ms_curves_copy_corners(const ms_curves *c, double *points, int64_t *indices)
{
	for (size_t k = 0; k < c->result.corners.size(); ++k) {
		std::memcpy(points + 3 * k, c->result.corners[k].data(), 3 * sizeof(double));
		indices[k] = int64_t(c->result.cornerIndices[k]);
	}
}

void ms_curves_free(ms_curves *c) { delete c; }

}  // extern "C"
