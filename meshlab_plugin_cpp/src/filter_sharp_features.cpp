// MeshLab glue around sharp_core: reads the current layer, runs the detector in double,
// writes vertex quality (strength), vertex selection (features) and optional colour; or
// adds the feature curves (the native library's curves.h) as a new layer of edges.
#include "filter_sharp_features.h"

#include "curves.h"
#include "sharp_core.h"

#include <vcg/complex/algorithms/update/bounding.h>
#include <vcg/complex/algorithms/update/selection.h>

#include <chrono>

namespace {
const char *NAME = "Select Sharp Features (Projected Distance)";
const char *CURVES_NAME = "Extract Sharp Feature Curves";
const char *CURVES_LAYER = "sharp_curves";

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
	const sharp::Options defaults;
	par.addParam(RichString("knnScales", QString::fromStdString(sharp::formatScales(defaults.knnScales)),
	                        "Point-cloud scales (k)",
	                        "Point clouds only: the neighbourhood sizes k (the k nearest neighbours, "
	                        "the point included), one per scale; a feature must be a candidate at "
	                        "every scale. A list like '12 16 20' or a range 'start:stop:step'. "
	                        "Smaller values find finer details and react more to noise; Robust mode "
	                        "grows them on noisy clouds by itself."));
	par.addParam(RichString("ringScales", QString::fromStdString(sharp::formatScales(defaults.ringScales)),
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
	sharp::Options options;
	try {
		options.knnScales = sharp::parseScales(par.getString("knnScales").toStdString(), MS_MIN_KNN_SCALE);
		options.ringScales = sharp::parseScales(par.getString("ringScales").toStdString(), MS_MIN_RING_SCALE);
	} catch (const sharp::InputError &e) {
		return fail(e.what());
	}
	// An .mlx script may give an enum any integer: only the listed choices run.
	const int weighting = par.getEnum("weighting");
	const int mode = par.getEnum("mode");
	if (weighting != 0 && weighting != 1)
		return fail(QString("weighting = %1 is not one of the choices 0 (Gaussian) and 1 (None)").arg(weighting));
	if (mode != 0 && mode != 1)
		return fail(QString("mode = %1 is not one of the choices 0 (Paper) and 1 (Robust)").arg(mode));
	options.gaussian = weighting == 0;
	options.asPoints = par.getBool("asPoints");
	options.robust = mode == 1;

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

	sharp::Result r;
	const auto start = std::chrono::steady_clock::now();
	try {
		r = sharp::detect(pts, faces, options, cb);
	} catch (const sharp::InputError &e) {
		return fail(e.what());
	} catch (const std::exception &e) {
		return fail(QString("internal error: ") + e.what());
	}

	const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

	if (ID(action) == FP_SHARP_CURVES) {
		sharp::Curves c;
		try {
			c = sharp::extractCurves(pts, r.feature, r.kept, options.asPoints ? decltype(faces)() : faces);
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
		    r.mesh ? "mesh (k-rings)" : "points (kNN)", options.robust ? "robust" : "paper",
		    r.nFeatures, int(live.size()));
		return true;
	}

	mm->updateDataMask(MeshModel::MM_VERTQUALITY);
	const bool colorize = par.getBool("colorize");
	if (colorize)
		mm->updateDataMask(MeshModel::MM_VERTCOLOR);
	vcg::tri::UpdateSelection<CMeshO>::VertexClear(m);
	for (size_t i = 0; i < live.size(); ++i) {
		live[i]->Q() = CMeshO::VertexType::QualityType(r.strength[i]);
		if (r.feature[i])
			live[i]->SetS();
		if (colorize)
			live[i]->C() = r.feature[i] ? vcg::Color4b(230, 13, 13, 255) : vcg::Color4b(200, 200, 200, 255);
	}

	QString scales;
	for (size_t s = 0; s < r.scales.size(); ++s)
		scales += QString(" %1=%2:T=%3,candidates=%4")
		              .arg(r.mesh ? "ring" : "k")
		              .arg(r.scales[s])
		              .arg(r.thresholds[s], 0, 'g', 17)
		              .arg(r.candidates[s]);
	Log("Sharp features: %s, %s mode, %ld of %d vertices are features;%s",
	    r.mesh ? "mesh (k-rings)" : "points (kNN)", options.robust ? "robust" : "paper", r.nFeatures,
	    int(live.size()), qUtf8Printable(scales));
	if (r.allFlat)
		Log("Sharp features: no features: all points lie on one plane.");
	QString stages;
	for (const auto &t : r.timings)
		stages += QString("%1%2 %3 s").arg(stages.isEmpty() ? "" : ", ").arg(t.first.c_str()).arg(t.second, 0, 'f', 3);
	Log("Sharp features: detection took %.3f s (%s)", seconds, qUtf8Printable(stages));
	return true;
}

MESHLAB_PLUGIN_NAME_EXPORTER(FilterSharpFeaturesPlugin)
