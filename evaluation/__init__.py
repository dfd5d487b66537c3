"""meshlab-sharp's evaluation: ground truth and scores (a source-tree tool, not installed).

- :mod:`evaluation.groundtruth`: the evaluation's parts and conditions (thin walls, CAD
  tessellations, OpenSCAD exports, a simulated scan, noise, outliers, density);
- :mod:`evaluation.scoring`: precision, coverage, F1 and thickness against exact edges;
- :mod:`evaluation.scan`: the simulated range scanner.

``scripts/evaluate.py`` and ``scripts/evaluate_curves.py`` write ``docs/evaluation.md``
from them; the tests import them from the repository root.
"""
