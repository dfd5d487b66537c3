/* The constants of the feature curves, defined here once.
 *
 * Two users: the Python package's curves modules (meshlab_sharp/curves: graph.py,
 * trace.py, extract.py, refine.py, fit.py), which read this file with
 * meshlab_sharp/_header.py (no compiler needed), and the MeshLab plugin's port of them
 * (meshlab_plugin_cpp/src/curves_core.cpp), which includes it. What each constant does
 * and why it has its value is documented beside its Python name (the name without the
 * MS_CURVE_ prefix) in the module named above its group. Lengths are in point spacings,
 * angles in degrees.
 *
 * One `#define MS_CURVE_NAME value` a line: a number, an earlier MS_CURVE_ name, a
 * product or quotient of two floating-point numbers or earlier names in parentheses, or
 * a brace list of integers or of floating-point numbers; _header.py parses exactly these
 * forms. */
#ifndef MESHLAB_SHARP_CURVES_H
#define MESHLAB_SHARP_CURVES_H

/* graph.py: linking the feature points, the skeleton's spurs. */
#define MS_CURVE_LINK_NEIGHBOURS 8
#define MS_CURVE_LINK_RADIUS 2.5
#define MS_CURVE_SPUR_LENGTH 4.0
#define MS_CURVE_MESH_FLAT_WEIGHT 0.05
#define MS_CURVE_PRUNE_ROUNDS 4

/* trace.py: turns, tangents, joining the ends. */
#define MS_CURVE_CORNER_TURN 35.0
#define MS_CURVE_TURN_INNER 0.5
#define MS_CURVE_TURN_OUTER 2.0
#define MS_CURVE_TURN_SCALES {1.0, 2.0, 4.0, 8.0}
#define MS_CURVE_MIN_TURN_SCALES 2
#define MS_CURVE_TANGENT_WINDOW 2.0
#define MS_CURVE_GAP_LENGTH 4.0
#define MS_CURVE_SHORTEST_CUT (2.0 * MS_CURVE_GAP_LENGTH)
/* In multiples of MS_CURVE_GAP_LENGTH. */
#define MS_CURVE_LOOP_LENGTH 3.0
#define MS_CURVE_LONG_GAP 12.0
/* An index into MS_CURVE_TURN_SCALES. */
#define MS_CURVE_CORNER_SCALE 2
#define MS_CURVE_LATERAL_OFFSET 2.0

/* extract.py: which curves are kept, the cloud curves' refinement and corners. */
#define MS_CURVE_MIN_CURVE_LENGTH MS_CURVE_GAP_LENGTH
#define MS_CURVE_SPUR_PIECE (2.0 * MS_CURVE_GAP_LENGTH)
#define MS_CURVE_MAX_FLAT_SHARE 0.5
#define MS_CURVE_CELL_SPACINGS 4.0
#define MS_CURVE_MIN_ADVANCE 0.3
/* Vertices on each side. */
#define MS_CURVE_LINE_FIT_HALF 2
#define MS_CURVE_RAW_TANGENT_WINDOW (2.0 * MS_CURVE_TANGENT_WINDOW)
#define MS_CURVE_SNAP 0.75
#define MS_CURVE_MAX_CORNER_CONDITION 1e6

/* refine.py: the two arms' lines across a cloud curve. */
#define MS_CURVE_REFINE_NEIGHBOURS 40
#define MS_CURVE_SLAB 1.0
#define MS_CURVE_ARM_ITERATIONS 3
/* A total weight. */
#define MS_CURVE_MIN_ARM_POINTS 3.0
#define MS_CURVE_MAX_SHIFT 3.0
#define MS_CURVE_MIN_ARM_ANGLE 20.0
#define MS_CURVE_MAX_ARM_RMS 0.5
#define MS_CURVE_ZERO_OFFSET 1e-12
#define MS_CURVE_FRAME_SWITCH 0.9

/* fit.py: line, arc or free-form (Python only: the plugin does not classify). */
#define MS_CURVE_FIT_TOLERANCE 0.5
#define MS_CURVE_FIT_MAX 4.0
#define MS_CURVE_MAX_RADIUS_RATIO 20.0

#endif
