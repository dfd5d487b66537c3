// MeshLab glue around meshlab-sharp's native library: parameters to ms_detect's options
// (the scales read by ms_parse_scales), the current layer to arrays in double, MeshLab's
// progress callback; back: vertex quality (strength), vertex selection (features) and
// optional colour, or the feature curves (the native library's curves.h) as a new layer of edges.
#include "filter_sharp_features.h"

#include "curves.h"
#include "meshlab_sharp.h"

#include <vcg/complex/algorithms/update/bounding.h>
#include <vcg/complex/algorithms/update/selection.h>

#include <chrono>
#include <memory>

namespace {
const char *NAME = "Select Sharp Features (Projected Distance)";
const char *CURVES_NAME = "Extract Sharp Feature Curves";
const char *CURVES_LAYER = "sharp_curves";

static_assert(sizeof(sharp::Point) == 3 * sizeof(double), "vertices pass to ms_detect as (n, 3) doubles");

// The library's progress report to MeshLab's callback (ctx: the vcg::CallBackPos *).
int progress(int percent, const char *message, void *ctx)
{
	vcg::CallBackPos *cb = *static_cast<vcg::CallBackPos **>(ctx);
	if (cb != nullptr)
		cb(percent, message);
	return 0;
}

// The scales parameter `name` read by the library's grammar into scales (count of them);
// false, the message in `error`, when the text is not scales of at least `minimum`.
bool readScales(const RichParameterList &par, const char *name, int minimum, int *scales, int &count,
                QString &error)
{
	char why[512];
	count = ms_parse_scales(qUtf8Printable(par.getString(name)), minimum, scales, MS_MAX_SCALES, why, sizeof why);
	if (count < 0)
		error = QString::fromUtf8(why);
	return count >= 0;
}

// The scales as the library's grammar writes them, "12 16 20".
QString formatScales(const int *scales, int count)
{
	char text[16 * MS_MAX_SCALES];
	ms_format_scales(scales, count, text, sizeof text);
	return QString(text);
}

// The curves as a new layer (vertices and edges; vertex quality: the curve's number; red,
// the features' colour), the current layer staying current, as
// meshlab_sharp.detect_meshset(ms, curves=True) does.
void addCurvesLayer(MeshDocument &md, const sharp::Curves &c)
{
	MeshModel *current = md.mm();
	MeshModel *layer = md.addNewMesh("", CURVES_LAYER, false);
	layer->updateDataMask(MeshModel::MM_VERTQUALITY | MeshModel::MM_VERTCOLOR);
	CMeshO &m = layer->cm;
	size_t nv = 0, ne = 0;
	for (const sharp::Curve &curve : c.curves) {
		nv += curve.points.size();
		ne += curve.closed ? curve.points.size() : curve.points.size() - 1;
	}
	vcg::tri::Allocator<CMeshO>::AddVertices(m, nv);
	vcg::tri::Allocator<CMeshO>::AddEdges(m, ne);
	size_t v = 0, e = 0;
	for (size_t k = 0; k < c.curves.size(); ++k) {
		const sharp::Curve &curve = c.curves[k];
		const size_t first = v, count = curve.points.size();
		for (const sharp::Vec3 &p : curve.points) {
			m.vert[v].P() = CMeshO::CoordType(p[0], p[1], p[2]);
			m.vert[v].Q() = CMeshO::VertexType::QualityType(k);
			m.vert[v].C() = vcg::Color4b(230, 13, 13, 255);
			++v;
		}
		for (size_t i = 0; i < (curve.closed ? count : count - 1); ++i, ++e) {
			m.edge[e].V(0) = &m.vert[first + i];
			m.edge[e].V(1) = &m.vert[first + (i + 1) % count];
		}
	}
	vcg::tri::UpdateBounding<CMeshO>::Box(m);
	md.setCurrentMesh(current->id());
}
}

FilterSharpFeaturesPlugin::FilterSharpFeaturesPlugin()
{
	typeList << FP_SHARP_FEATURES << FP_SHARP_CURVES;
	for (FilterIDType tt : types())
		actionList << new QAction(filterName(tt), this);
}

QString FilterSharpFeaturesPlugin::pluginName() const
{
	return "FilterSharpFeatures";
}

QString FilterSharpFeaturesPlugin::filterName(FilterIDType filter) const
{
	return filter == FP_SHARP_CURVES ? CURVES_NAME : NAME;
}

QString FilterSharpFeaturesPlugin::filterInfo(FilterIDType filter) const
{
	if (filter == FP_SHARP_CURVES)
		return "Detects the sharp features as 'Select Sharp Features (Projected Distance)' does "
		       "and adds the feature curves as a new layer 'sharp_curves' of vertices and edges "
		       "(vertex quality: the curve's number; red vertices): one polyline per edge of the "
		       "object, cut at corners and sharp turns, without fragments or spurs. On a mesh the curves are "
		       "chains of the mesh's own edges through feature vertices; on a point cloud the "
		       "skeleton of the feature points, moved onto the intersection of the surfaces "
		       "fitted on each side (below the point spacing). The log gives the numbers of "
		       "curves, closed curves, vertices and corners. The parameters are those of the "
		       "detection. The same steps and arithmetic as the meshlab-sharp Python package.";
	return QString("Selects the sharp features (creases, corners) of a mesh or point cloud automatically, "
	       "with the projected-distance method of Tran et al. (2014): per vertex, the distance "
	       "between the vertex and the centroid of its neighbourhood along the normal; Otsu's "
	       "threshold on its histogram; at several scales (k-rings on a mesh, k nearest "
	       "neighbours on a point cloud). A vertex is a feature if it is a candidate at every "
	       "scale. The default Robust mode also leaves out isolated points (a far outlier on "
	       "its own, or a stray pair or triple off the surface), grows "
	       "the scales on noisy clouds, divides the distance by the local spacing, never "
	       "thresholds below a %1-degree edge (no features on smooth objects), keeps points "
	       "with neighbours along their feature line, thins lines to one point across, and on "
	       "meshes adds the vertices of edges whose faces turn by more than %1 degrees (CAD "
	       "tessellations). Paper mode is the method as the paper describes it. Vertex quality "
	       "is set to the feature strength (the fraction of scales at which the vertex was a "
	       "candidate), the selection to the features; the log lists each scale's threshold and "
	       "candidate count. Nothing to tune: the defaults suit scans and CAD meshes alike. The "
	       "same algorithm, with the same answers, as the meshlab-sharp Python package.")
	    .arg(MS_CREASE_ANGLE);
}

MeshFilterInterface::FilterClass FilterSharpFeaturesPlugin::getClass(QAction *a)
{
	if (ID(a) == FP_SHARP_CURVES)
		return MeshFilterInterface::Remeshing;
	return FilterClass(MeshFilterInterface::Selection | MeshFilterInterface::Quality);
}

MeshFilterInterface::FILTER_ARITY FilterSharpFeaturesPlugin::filterArity(QAction *) const
{
	return SINGLE_MESH;
}

int FilterSharpFeaturesPlugin::getPreConditions(QAction *) const
{
	return MeshModel::MM_NONE;
}

int FilterSharpFeaturesPlugin::postCondition(QAction *a) const
{
	if (ID(a) == FP_SHARP_CURVES)
		return MeshModel::MM_NONE;  // a new layer; the current one is unchanged
	return MeshModel::MM_VERTQUALITY | MeshModel::MM_VERTFLAGSELECT | MeshModel::MM_VERTCOLOR;
}

void FilterSharpFeaturesPlugin::initParameterSet(QAction *a, MeshModel &, RichParameterList &par)
{
	ms_detect_options defaults;
	ms_detect_defaults(&defaults);
	par.addParam(RichString("knnScales", formatScales(defaults.knn_scales, defaults.n_knn_scales),
	                        "Point-cloud scales (k)",
	                        "Point clouds only: the neighbourhood sizes k (the k nearest neighbours, "
	                        "the point included), one per scale; a feature must be a candidate at "
	                        "every scale. A list like '12 16 20' or a range 'start:stop:step'. "
	                        "Smaller values find finer details and react more to noise; Robust mode "
	                        "grows them on noisy clouds by itself."));
	par.addParam(RichString("ringScales", formatScales(defaults.ring_scales, defaults.n_ring_scales),
	                        "Mesh scales (rings)",
	                        "Meshes only: the neighbourhood of a vertex at scale k is every vertex "
	                        "within k edges of it (its k-ring), one per scale; a feature must be a "
	                        "candidate at every scale. A list like '1 2 3 4' or a range '1:4'."));
	par.addParam(RichEnum("weighting", MS_DEFAULT_WEIGHTING, QStringList() << "Gaussian" << "None", "Normal weighting",
	                      "How the normals of a point cloud are fitted to each neighbourhood: "
	                      "Gaussian weights exp(-d^2/h^2) (d a neighbour's distance, h the "
	                      "farthest neighbour's), so that near points count more, or None, a "
	                      "plain PCA. Meshes use their face normals."));
	par.addParam(RichBool("asPoints", false, "Treat a mesh as points",
	                      "Ignore the faces and process the vertices as a point cloud, with the "
	                      "point-cloud scales (k nearest neighbours)."));
	par.addParam(RichEnum("mode", MS_DEFAULT_MODE, QStringList() << "Paper" << "Robust", "Mode",
	                      QString("Robust (default): isolated points left out, scales grown with the "
	                      "measured noise, projected distance relative to the local spacing, a "
	                      "threshold floor of a %1-degree edge, support along and thinning across "
	                      "the feature lines (lines one point wide), and on meshes the vertices "
	                      "of edges whose faces turn by more than %1 degrees: copes with outliers, "
	                      "noise, uneven density and thin walls, finds no features on smooth "
	                      "objects, and handles CAD tessellations. Paper: Tran et al.'s method "
	                      "as the paper describes it (min-max normalised distances, Otsu's "
	                      "threshold at every scale).")
	                          .arg(MS_CREASE_ANGLE)));
	if (ID(a) == FP_SHARP_CURVES)
		return;
	par.addParam(RichBool("colorize", true, "Colour the features",
	                      "Colour the features red and the other vertices grey (the vertex "
	                      "colours are replaced). Off: only quality and selection are set."));
}

bool FilterSharpFeaturesPlugin::applyFilter(QAction *action, MeshDocument &md, const RichParameterList &par,
                                            vcg::CallBackPos *cb)
{
	// Errors go to MeshLab's log (meshlabserver prints it) and to errorMessage (the GUI).
	auto fail = [this](const QString &why) {
		errorMessage = "Sharp features: " + why;
		Log("Sharp features: error: %s", qUtf8Printable(why));
		return false;
	};
	MeshModel *mm = md.mm();
	if (mm == nullptr)
		return fail("there is no current layer");
	CMeshO &m = mm->cm;
	ms_detect_options options;
	ms_detect_defaults(&options);
	QString error;
	if (!readScales(par, "knnScales", MS_MIN_KNN_SCALE, options.knn_scales, options.n_knn_scales, error) ||
	    !readScales(par, "ringScales", MS_MIN_RING_SCALE, options.ring_scales, options.n_ring_scales, error))
		return fail(error);
	options.weighting = par.getEnum("weighting");
	options.mode = par.getEnum("mode");
	options.as_points = par.getBool("asPoints");
	// An .mlx script may give an enum any integer: only the listed choices run.
	if (options.weighting != 0 && options.weighting != 1)
		return fail(QString("weighting = %1 is not one of the choices 0 (Gaussian) and 1 (None)").arg(options.weighting));
	if (options.mode != 0 && options.mode != 1)
		return fail(QString("mode = %1 is not one of the choices 0 (Paper) and 1 (Robust)").arg(options.mode));
	const bool robust = options.mode == 1;

	// Live vertices in layer order; faces re-indexed to that order.
	std::vector<CMeshO::VertexPointer> live;
	std::vector<int> index(m.vert.size(), -1);
	for (size_t i = 0; i < m.vert.size(); ++i)
		if (!m.vert[i].IsD()) {
			index[i] = int(live.size());
			live.push_back(&m.vert[i]);
		}
	std::vector<sharp::Point> pts(live.size());
	for (size_t i = 0; i < live.size(); ++i)
		pts[i] = {double(live[i]->P()[0]), double(live[i]->P()[1]), double(live[i]->P()[2])};
	std::vector<std::array<int, 3>> faces;
	for (auto &f : m.face) {
		if (f.IsD()) continue;
		std::array<int, 3> t{};
		bool ok = true;
		for (int a = 0; a < 3; ++a) {
			const CMeshO::VertexPointer vp = f.V(a);
			const long vi = (vp == nullptr) ? -1 : long(vp - &m.vert[0]);
			if (vi < 0 || vi >= long(m.vert.size()) || index[vi] < 0) ok = false;
			else t[a] = index[vi];
		}
		if (!ok)
			return fail("a face references a missing vertex");
		faces.push_back(t);
	}
	std::vector<int64_t> triangles;
	for (const auto &t : faces)
		triangles.insert(triangles.end(), t.begin(), t.end());

	const auto start = std::chrono::steady_clock::now();
	ms_detection *run = nullptr;
	char why[512];
	const int status = ms_detect(reinterpret_cast<const double *>(pts.data()), int64_t(pts.size()), triangles.data(), int64_t(faces.size()), &options,
	                             progress, &cb, &run, why, sizeof why);
	if (status == MS_EINPUT)
		return fail(why);
	if (status != MS_OK)
		return fail(QString("internal error: ") + why);
	const std::unique_ptr<ms_detection, void (*)(ms_detection *)> owned(run, ms_detection_free);
	int64_t counts[MS_DETECTION_COUNTS];
	ms_detection_counts(run, counts);
	const bool mesh = counts[MS_COUNT_MESH] != 0;
	const long nFeatures = long(counts[MS_COUNT_FEATURES]);
	std::vector<double> strength(live.size());
	std::vector<char> feature(live.size()), kept(live.size());
	ms_detection_vertices(run, strength.data(), reinterpret_cast<uint8_t *>(feature.data()),
	                      reinterpret_cast<uint8_t *>(kept.data()));
	const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

	if (ID(action) == FP_SHARP_CURVES) {
		sharp::Curves c;
		try {
			c = sharp::extractCurves(pts, feature, kept, options.as_points ? decltype(faces)() : faces);
		} catch (const std::exception &e) {
			return fail(QString("internal error: ") + e.what());
		}
		addCurvesLayer(md, c);
		size_t vertices = 0, closed = 0;
		for (const sharp::Curve &curve : c.curves)
			vertices += curve.points.size(), closed += curve.closed;
		Log("Sharp feature curves: %d curves (%d closed), %d vertices, %d corners, spacing %.17g; "
		    "%s, %s mode, %ld of %d vertices are features",
		    int(c.curves.size()), int(closed), int(vertices), int(c.corners.size()), c.spacing,
		    mesh ? "mesh (k-rings)" : "points (kNN)", robust ? "robust" : "paper", nFeatures, int(live.size()));
		return true;
	}

	mm->updateDataMask(MeshModel::MM_VERTQUALITY);
	const bool colorize = par.getBool("colorize");
	if (colorize)
		mm->updateDataMask(MeshModel::MM_VERTCOLOR);
	vcg::tri::UpdateSelection<CMeshO>::VertexClear(m);
	for (size_t i = 0; i < live.size(); ++i) {
		live[i]->Q() = CMeshO::VertexType::QualityType(strength[i]);
		if (feature[i])
			live[i]->SetS();
		if (colorize)
			live[i]->C() = feature[i] ? vcg::Color4b(230, 13, 13, 255) : vcg::Color4b(200, 200, 200, 255);
	}

	const int nScales = int(counts[MS_COUNT_SCALES]);
	std::vector<int> scales(nScales);
	std::vector<double> thresholds(nScales);
	std::vector<int64_t> candidates(nScales);
	ms_detection_scales(run, scales.data(), thresholds.data(), candidates.data());
	QString perScale;
	for (int s = 0; s < nScales; ++s)
		perScale += QString(" %1=%2:T=%3,candidates=%4")
		                .arg(mesh ? "ring" : "k")
		                .arg(scales[s])
		                .arg(thresholds[s], 0, 'g', 17)
		                .arg(qlonglong(candidates[s]));
	Log("Sharp features: %s, %s mode, %ld of %d vertices are features;%s", mesh ? "mesh (k-rings)" : "points (kNN)",
	    robust ? "robust" : "paper", nFeatures, int(live.size()), qUtf8Printable(perScale));
	if (counts[MS_COUNT_ALL_FLAT])
		Log("Sharp features: no features: all points lie on one plane.");
	QString stages;
	for (int i = 0; i < int(counts[MS_COUNT_TIMINGS]); ++i) {
		char stage[64];
		double spent = 0.0;
		ms_detection_timing(run, i, stage, sizeof stage, &spent);
		stages += QString("%1%2 %3 s").arg(stages.isEmpty() ? "" : ", ").arg(stage).arg(spent, 0, 'f', 3);
	}
	Log("Sharp features: detection took %.3f s (%s)", seconds, qUtf8Printable(stages));
	return true;
}

MESHLAB_PLUGIN_NAME_EXPORTER(FilterSharpFeaturesPlugin)
