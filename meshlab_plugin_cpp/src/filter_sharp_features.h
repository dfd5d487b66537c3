// meshlab-sharp MeshLab 2020.09 filter plugin: "Select Sharp Features (Projected Distance)" and
// "Extract Sharp Feature Curves".
#ifndef FILTER_SHARP_FEATURES_H
#define FILTER_SHARP_FEATURES_H

#include <common/interfaces.h>

class FilterSharpFeaturesPlugin : public QObject, public MeshFilterInterface
{
	Q_OBJECT
	MESHLAB_PLUGIN_IID_EXPORTER(MESH_FILTER_INTERFACE_IID)
	Q_INTERFACES(MeshFilterInterface)

public:
	enum { FP_SHARP_FEATURES, FP_SHARP_CURVES };

	FilterSharpFeaturesPlugin();

	QString pluginName() const override;
	QString filterName(FilterIDType filter) const override;
	QString filterInfo(FilterIDType filter) const override;
	FilterClass getClass(QAction *a) override;
	FILTER_ARITY filterArity(QAction *) const override;
	int getPreConditions(QAction *) const override;
	int postCondition(QAction *) const override;
	void initParameterSet(QAction *, MeshModel &m, RichParameterList &par) override;
	bool applyFilter(QAction *action, MeshDocument &md, const RichParameterList &par,
	                 vcg::CallBackPos *cb) override;
};

#endif
