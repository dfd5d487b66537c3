// MeshLab glue around sharp_core: reads the current layer, runs the detector in double,
// writes vertex quality (strength), vertex selection (features) and optional colour.
#include "filter_sharp_features.h"

#include "sharp_core.h"

#include <vcg/complex/algorithms/update/selection.h>

#include <chrono>

namespace {
const char *NAME = "Select Sharp Features (Projected Distance)";
}

FilterSharpFeaturesPlugin::FilterSharpFeaturesPlugin()
{
	typeList << FP_SHARP_FEATURES;
	for (FilterIDType tt : types())
		actionList << new QAction(filterName(tt), this);
}

QString FilterSharpFeaturesPlugin::pluginName() const
{
	return "FilterSharpFeatures";
}

QString FilterSharpFeaturesPlugin::filterName(FilterIDType) const
{
	return NAME;
}

QString FilterSharpFeaturesPlugin::filterInfo(FilterIDType) const
{
	return "Selects the sharp features (creases, corners) of a mesh or point cloud automatically, "
	       "with the projected-distance method of Tran et al. (2014): per vertex, the distance "
	       "between the vertex and the centroid of its neighbourhood along the normal; Otsu's "
	       "threshold on its histogram; at several scales (k-rings on a mesh, k nearest "
	       "neighbours on a point cloud). A vertex is a feature if it is a candidate at every "
	       "scale. The default Robust mode also leaves out isolated points (outliers), grows "
	       "the scales on noisy clouds, divides the distance by the local spacing, never "
	       "thresholds below a 20-degree edge (no features on smooth objects), keeps points "
	       "with neighbours along their feature line, thins lines to one point across, and on "
	       "meshes adds the vertices of edges whose faces turn by more than 20 degrees (CAD "
	       "tessellations). Paper mode is the method as the paper describes it. Vertex quality "
	       "is set to the feature strength (fraction of scales), the selection to the features. "
	       "The same algorithm as the meshlab-sharp Python package.";
}

MeshFilterInterface::FilterClass FilterSharpFeaturesPlugin::getClass(QAction *)
{
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

int FilterSharpFeaturesPlugin::postCondition(QAction *) const
{
	return MeshModel::MM_VERTQUALITY | MeshModel::MM_VERTFLAGSELECT | MeshModel::MM_VERTCOLOR;
}

void FilterSharpFeaturesPlugin::initParameterSet(QAction *, MeshModel &, RichParameterList &par)
{
	const sharp::Options defaults;
	par.addParam(RichString("knnScales", QString::fromStdString(sharp::formatScales(defaults.knnScales)),
	                        "Point-cloud scales (k)",
	                        "Neighbourhood sizes k (k nearest neighbours, the point included) used "
	                        "on point clouds: a list like '12 16 20' or a range 'start:stop:step'."));
	par.addParam(RichString("ringScales", QString::fromStdString(sharp::formatScales(defaults.ringScales)),
	                        "Mesh scales (rings)",
	                        "k-ring sizes used on meshes: a list like '1 2 3 4' or a range '1:4'."));
	par.addParam(RichEnum("weighting", 0, QStringList() << "Gaussian" << "None", "Normal weighting",
	                      "Weights of the PCA normals: Gaussian exp(-d^2/h^2), h the farthest "
	                      "neighbour, or none (plain PCA)."));
	par.addParam(RichBool("asPoints", false, "Treat a mesh as points",
	                      "Ignore the faces and use k nearest neighbours."));
	par.addParam(RichEnum("mode", 1, QStringList() << "Paper" << "Robust", "Mode",
	                      "Robust (default): isolated points left out, scales grown with the "
	                      "measured noise, projected distance relative to the local spacing, a "
	                      "threshold floor of a 20-degree edge, support along and thinning across "
	                      "the feature lines, and on meshes the edges whose faces turn by more "
	                      "than 20 degrees (docs/robust-mode.md): survives outliers and noise, "
	                      "says 'no features' on smooth objects, handles CAD tessellations. "
	                      "Paper: the method as the paper describes it (ALGORITHM.md)."));
	par.addParam(RichBool("colorize", true, "Colour the features",
	                      "Features red, the other vertices grey."));
}

bool FilterSharpFeaturesPlugin::applyFilter(QAction *, MeshDocument &md, const RichParameterList &par,
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
		options.knnScales = sharp::parseScales(par.getString("knnScales").toStdString(), 2);
		options.ringScales = sharp::parseScales(par.getString("ringScales").toStdString(), 1);
	} catch (const sharp::InputError &e) {
		return fail(e.what());
	}
	options.gaussian = par.getEnum("weighting") == 0;
	options.asPoints = par.getBool("asPoints");
	options.robust = par.getEnum("mode") == 1;

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
