"""Golden outputs (tests/data/golden, written by scripts/make_golden.py), and that each
named constant of robust mode decides part of them.

A change of either mode's answers must be deliberate: regenerate the files with
``python3 scripts/make_golden.py`` and commit them with the change.
"""

from __future__ import annotations

from collections.abc import Callable
from types import ModuleType

import golden
import numpy as np
import pytest

from meshlab_sharp import creases, robust
from meshlab_sharp.reference import detect as reference_sequence
from meshlab_sharp.reference import robust as reference


@pytest.fixture(scope="module")
def inputs() -> dict[str, tuple[np.ndarray, np.ndarray | None]]:
    return {name: make() for name, make in golden.SHAPES.items()}


@pytest.mark.parametrize("name", sorted(golden.SHAPES))
@pytest.mark.parametrize("mode", golden.MODES)
def test_golden_outputs(inputs, name, mode):
    points, faces = inputs[name]
    stored = golden.load(name)
    assert stored["n_points"] == len(points)
    assert stored["coordinate_sum"] == pytest.approx(float(points.sum()), rel=1e-12, abs=1e-9)
    assert golden.outputs(points, faces, mode) == stored[mode]


#: Every named constant of robust mode, moved a little each way (relative to its
#: current value, so that retuning a constant does not silence its test).
#: ``robust.CREASE_ANGLE`` is ``creases.CREASE_ANGLE`` imported: robust mode reads the
#: crease angle through ``creases.CREASE_ANGLE`` (the sharp mesh edges) and through
#: ``robust.R_MIN`` (the threshold floor, computed from it at import), patched here
#: separately. The lower quartile's position ``(E - 1) // 4`` and the 256 bins are not
#: named constants of robust mode; test_robust_spec.py pins them.
NUDGES: dict[str, tuple[ModuleType, str, Callable[[float], float]]] = {
    "crease angle -3 deg": (creases, "CREASE_ANGLE", lambda v: v - 3.0),
    "crease angle +3 deg": (creases, "CREASE_ANGLE", lambda v: v + 3.0),
    "R_MIN x0.85 (17 deg)": (robust, "R_MIN", lambda v: v * 0.85),
    "R_MIN x1.15 (23 deg)": (robust, "R_MIN", lambda v: v * 1.15),
    "cone cos -0.1": (robust, "THIN_CONE_COS", lambda v: v - 0.1),
    "cone cos +0.1": (robust, "THIN_CONE_COS", lambda v: v + 0.1),
    "noisy cone cos -0.05": (robust, "THIN_CONE_COS_NOISY", lambda v: v - 0.05),
    "noisy cone cos +0.05": (robust, "THIN_CONE_COS_NOISY", lambda v: v + 0.05),
    "thin side x0.85": (robust, "THIN_SIDE", lambda v: v * 0.85),
    "thin side x1.15": (robust, "THIN_SIDE", lambda v: v * 1.15),
    "noisy thin side x0.85": (robust, "THIN_SIDE_NOISY", lambda v: v * 0.85),
    "noisy thin side x1.15": (robust, "THIN_SIDE_NOISY", lambda v: v * 1.15),
    "line offset x0.85": (robust, "LINE_OFFSET", lambda v: v * 0.85),
    "line offset x1.15": (robust, "LINE_OFFSET", lambda v: v * 1.15),
    "line spread x0.85": (robust, "LINE_SPREAD", lambda v: v * 0.85),
    "line spread x1.15": (robust, "LINE_SPREAD", lambda v: v * 1.15),
    "line min -1": (robust, "LINE_MIN", lambda v: v - 1),
    "line min +1": (robust, "LINE_MIN", lambda v: v + 1),
    "line unit -2": (robust, "LINE_UNIT", lambda v: v - 2),
    "line unit +2": (robust, "LINE_UNIT", lambda v: v + 2),
    "line reach x0.85": (robust, "LINE_REACH", lambda v: v * 0.85),
    "line reach x1.15": (robust, "LINE_REACH", lambda v: v * 1.15),
    "thinning kNN -2": (robust, "THIN_KNN", lambda v: v - 2),
    "thinning kNN +2": (robust, "THIN_KNN", lambda v: v + 2),
    "mesh ring -1": (robust, "THIN_RING", lambda v: v - 1),
    "mesh ring +1": (robust, "THIN_RING", lambda v: v + 1),
    "support kNN -2": (robust, "SUPPORT_KNN", lambda v: v - 2),
    "support kNN +2": (robust, "SUPPORT_KNN", lambda v: v + 2),
    "support min -1": (robust, "SUPPORT_MIN", lambda v: v - 1),
    "support min +1": (robust, "SUPPORT_MIN", lambda v: v + 1),
    "support free score x0.85": (robust, "SUPPORT_FREE_SCORE", lambda v: v * 0.85),
    "support free score x1.15": (robust, "SUPPORT_FREE_SCORE", lambda v: v * 1.15),
    "acute score x0.85": (robust, "ACUTE_SCORE", lambda v: v * 0.85),
    "acute score x1.15": (robust, "ACUTE_SCORE", lambda v: v * 1.15),
    "acute score cap x0.85": (robust, "ACUTE_SCORE_MAX", lambda v: v * 0.85),
    "acute score cap x1.15": (robust, "ACUTE_SCORE_MAX", lambda v: v * 1.15),
    "isolated nth -1": (robust, "ISOLATED_NTH", lambda v: v - 1),
    "isolated nth +1": (robust, "ISOLATED_NTH", lambda v: v + 1),
    "isolated ref -2": (robust, "ISOLATED_REF", lambda v: v - 2),
    "isolated ref +2": (robust, "ISOLATED_REF", lambda v: v + 2),
    "isolated spread x0.85": (robust, "ISOLATED_SPREAD", lambda v: v * 0.85),
    "isolated spread x1.15": (robust, "ISOLATED_SPREAD", lambda v: v * 1.15),
    "noise kNN -1": (robust, "NOISE_KNN", lambda v: v - 1),
    "noise kNN +1": (robust, "NOISE_KNN", lambda v: v + 1),
    "noise tolerated x0.93": (robust, "NOISE_TOLERATED", lambda v: v * 0.93),
    "noise tolerated x1.07": (robust, "NOISE_TOLERATED", lambda v: v * 1.07),
    "noise quiet x0.85": (robust, "NOISE_QUIET", lambda v: v * 0.85),
    "noise quiet x1.15": (robust, "NOISE_QUIET", lambda v: v * 1.15),
    "noise cap x0.85": (robust, "NOISE_MAX_FACTOR", lambda v: v * 0.85),
    "noise cap x1.15": (robust, "NOISE_MAX_FACTOR", lambda v: v * 1.15),
    "quartile factor x0.9": (creases, "NOISE_FACTOR", lambda v: v * 0.9),
    "quartile factor x1.1": (creases, "NOISE_FACTOR", lambda v: v * 1.1),
    "sheet gap x0.85": (robust, "SHEET_GAP", lambda v: v * 0.85),
    "sheet gap x1.15": (robust, "SHEET_GAP", lambda v: v * 1.15),
    "sheet min -1": (robust, "SHEET_MIN", lambda v: v - 1),
    "sheet min +1": (robust, "SHEET_MIN", lambda v: v + 1),
    "sheet own x0.8": (robust, "SHEET_OWN", lambda v: v * 0.8),
    "sheet own x1.25": (robust, "SHEET_OWN", lambda v: v * 1.25),
    "sheet column x0.85": (robust, "SHEET_COLUMN", lambda v: v * 0.85),
    "sheet column x1.15": (robust, "SHEET_COLUMN", lambda v: v * 1.15),
    "sheet column gap x0.85": (robust, "SHEET_COLUMN_GAP", lambda v: v * 0.85),
    "sheet column gap x1.15": (robust, "SHEET_COLUMN_GAP", lambda v: v * 1.15),
    "sheet far span x0.8": (robust, "SHEET_FAR_SPAN", lambda v: v * 0.8),
    "sheet far span x1.25": (robust, "SHEET_FAR_SPAN", lambda v: v * 1.25),
    "sheet trim x0.85": (robust, "SHEET_TRIM", lambda v: v * 0.85),
    "sheet trim x1.15": (robust, "SHEET_TRIM", lambda v: v * 1.15),
    "sheet trim cos 0.97": (robust, "SHEET_TRIM_COS", lambda v: 0.97),
    "sheet trim cos 0.995": (robust, "SHEET_TRIM_COS", lambda v: 0.995),
}


@pytest.mark.parametrize("nudge", list(NUDGES))
def test_every_constant_is_pinned_by_the_golden_outputs(inputs, monkeypatch, nudge):
    """The rules on the noise (noise factor, quiet cloud, cones, ...) are the native
    library's, its constants fixed when it is built: they are nudged in the numpy
    reference's statement of the same rules, which robust mode then runs."""
    module, name, change = NUDGES[nudge]
    monkeypatch.setattr(module, name, change(getattr(module, name)))
    if module is robust and hasattr(reference, name):
        monkeypatch.setattr(reference, name, change(getattr(reference, name)))
    monkeypatch.setattr(reference_sequence, "RULES", reference)
    changed = [
        shape
        for shape in sorted(golden.SHAPES)
        if golden.outputs(*inputs[shape], "robust", python_driven=True)
        != golden.load(shape)["robust"]
    ]
    assert changed, f"{nudge}: robust mode's golden outputs do not see {name}"


def test_every_named_constant_is_nudged():
    # a new constant of robust mode needs its nudges above; robust.CREASE_ANGLE is
    # creases.CREASE_ANGLE, re-exported
    named = {
        (module.__name__, name)
        for module in (robust, creases)
        for name in module.__all__
        if name.isupper() and not (module is robust and name == "CREASE_ANGLE")
    }
    assert robust.CREASE_ANGLE is creases.CREASE_ANGLE
    assert named == {(module.__name__, name) for module, name, _ in NUDGES.values()}
