"""The numpy reference: the method written readably, array by array, each step giving
the same bits as the native library (:mod:`meshlab_sharp._kernels`; the normalisation
and Otsu's threshold stay in :mod:`meshlab_sharp.threshold`, which the tiles use too).

It is the oracle of the tests (``tests/test_equivalence.py`` compares the two) and the
fallback where no compiler built the native library: ``detect(..., backend="numpy")``
(or ``MESHLAB_SHARP_BACKEND=numpy``) runs it. The product modules dispatch each step to
the compiled function or to the reference one here, by the backend of the call; the
reference imports nothing from them (``tests/test_layout.py``). The out-of-core tiles
run robust mode's finishing steps from here on each tile.

Modules, one per step:

* :mod:`.neighbourhoods`: k nearest neighbours, mesh adjacency and k-rings;
* :mod:`.normals`: face-average normals, weighted PCA normals;
* :mod:`.projected_distance`: the projected distance of one scale;
* :mod:`.cleaning`: duplicate merge and zero-area faces, with pymeshlab's filters;
* :mod:`.creases`: a mesh's dihedral angles and sharp vertices;
* :mod:`.robust`: robust mode's isolated points, noise ratio, sheet filter, local scale,
  line directions, support, thinning, acute tips and smoothed ranking;
* :mod:`.curves`: the feature curves (graph, tracing, refinement, corners), which
  :func:`meshlab_sharp.curves.extract_curves` runs with ``backend="numpy"``.
"""
