// meshlab-sharp native library: the plain types that the feature curves and the
// MeshLab plugin's detection core share (internal C++ header).
#ifndef MESHLAB_SHARP_CURVES_TYPES_H
#define MESHLAB_SHARP_CURVES_TYPES_H

namespace sharp {

// One input point (mesh vertex).
struct Point { double x, y, z; };

}  // namespace sharp

#endif
