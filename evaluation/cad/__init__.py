"""A CAD evaluation with exact truth: real parts from public packages, their sharp
edges read from the B-rep through gmsh/OpenCASCADE (a source-tree tool, not installed).

- :mod:`evaluation.cad.sources`: the parts (``freecad-common``'s STEP and FreeCAD
  B-reps, the gmsh wheel's demos) and loading them into gmsh;
- :mod:`evaluation.cad.truth`: the sharp curves and corners of a B-rep;
- :mod:`evaluation.cad.inputs`: a fine mesh, an STL-like tessellation, clouds, a scan;
- :mod:`evaluation.cad.run`: detection and curves in the default mode, scored;
- :mod:`evaluation.cad.figure`: truth, features and curves side by side.

``scripts/evaluate_cad.py`` runs it and writes ``docs/evaluation-cad.json``.
"""
