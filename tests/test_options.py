"""API options: scales given as one int, the bound on the number of scales, and what
``kept`` says in robust mode."""

from __future__ import annotations

import numpy as np
import pytest
import shapes

import meshlab_sharp
from meshlab_sharp.options import MAX_SCALES

CUBE = shapes.cube_grid_points(11)


def test_one_int_is_one_scale():
    one = meshlab_sharp.detect(CUBE, scales=12)
    listed = meshlab_sharp.detect(CUBE, scales=[12])
    assert one.scales == (12,)
    np.testing.assert_array_equal(one.mask, listed.mask)
    assert meshlab_sharp.detect(CUBE, scales=np.int64(12)).scales == (12,)


@pytest.mark.parametrize("bad", ["12", True, 12.5, object()])
def test_scales_that_are_no_integers(bad):
    with pytest.raises(meshlab_sharp.InputError, match="scales must be"):
        meshlab_sharp.detect(CUBE, scales=bad)


def test_too_many_scales_fail_before_any_work():
    with pytest.raises(meshlab_sharp.InputError, match=f"at most {MAX_SCALES}"):
        meshlab_sharp.detect(CUBE, scales=range(2, 100_000_000))
    with pytest.raises(meshlab_sharp.InputError, match=r"kNN sizes must be <= 512, got 1000"):
        meshlab_sharp.detect(CUBE, scales=[12, 1000])
    with pytest.raises(meshlab_sharp.InputError, match=r"k = 512"):
        meshlab_sharp.detect(CUBE[:500], scales=[12, 512])


def test_robust_mode_reports_isolated_points_as_not_kept():
    far = np.array([[50.0, 50.0, 50.0], [-40.0, 60.0, 0.0]])
    cloud = np.vstack([CUBE, far])
    paper = meshlab_sharp.detect(cloud, mode="paper")
    robust = meshlab_sharp.detect(cloud, mode="robust")
    assert paper.kept.all()
    expected = np.ones(len(cloud), bool)
    expected[-2:] = False  # the two far points did not take part (as in the plugin)
    np.testing.assert_array_equal(robust.kept, expected)
    assert not robust.mask[-2:].any()
    assert robust.summary()["n_dropped"] == 2
