"""The compiled refit of the detector (`wall_fit.c`) against its numpy twin (issue 33)."""

import math

import numpy as np
import pytest

from controller.perception import detection as d
from controller.perception.wall_fit import wall_fit_kernel


def _scene(seed: int):
    """Cells of a bent quay, a straight quay with a gap, a corner (a pier) and clutter, in
    the body frame, with the detector's merged Hough lines over them."""
    rng = np.random.default_rng(seed)
    bend = np.linspace(-0.6, 0.6, 400)
    quay = np.column_stack([40 * np.sin(bend), -7.5 + 40 * (1 - np.cos(bend))])
    straight = np.column_stack([np.r_[np.linspace(-50, -5, 220), np.linspace(3, 50, 230)],
                                np.full(450, 7.0)])
    pier = np.column_stack([np.full(30, 20.0), np.linspace(4.0, 7.0, 30)])
    clutter = rng.uniform(-40, 40, (40, 2))
    pts = np.concatenate([quay, straight, pier, clutter])
    pts += rng.normal(0, 0.03, pts.shape)
    xyz = np.column_stack([pts, np.full(len(pts), -0.5)])
    xy = d._cropped_xy(xyz, d.DEFAULT)
    grid, cells = d._occupancy(xy, d.DEFAULT)
    return d._merge(d._hough_pieces(grid, d.DEFAULT), d.DEFAULT), cells


@pytest.mark.parametrize("seed", range(6))
def test_compiled_refit_matches_its_numpy_twin(seed):
    """The same chords, in the same order, to rounding (the twin's products go through
    BLAS); the scene has what each branch needs: a bend (Douglas-Peucker cuts), a gap (two
    runs), a corner (cells left free for the other face)."""
    if wall_fit_kernel() is None:
        pytest.skip("no C compiler: the numpy twin is what runs")
    lines, cells = _scene(seed)
    want = d._refit_numpy(lines, cells, d.DEFAULT)
    got = d._refit(lines, cells, d.DEFAULT)
    assert len(want) >= 6
    assert len(got) == len(want)
    np.testing.assert_allclose(np.array(got), np.array(want), rtol=0, atol=1e-9)


def test_compiled_refit_grows_its_buffer():
    """Room for one chord at first: the kernel says it needs more, is asked again, and the
    chords are those of the numpy twin."""
    from controller.perception.wall_fit import refit_compiled

    lib = wall_fit_kernel()
    if lib is None:
        pytest.skip("no C compiler")
    lines, cells = _scene(1)
    order = sorted(lines, key=lambda ab: -math.dist(*ab))
    got = refit_compiled(lib, order, cells, d.DEFAULT, capacity=1)
    want = d._refit_numpy(lines, cells, d.DEFAULT)
    assert len(want) > 4 and len(got) == len(want)
    np.testing.assert_allclose(np.array(got), np.array(want), rtol=0, atol=1e-9)


def test_refit_of_no_lines_or_too_few_cells():
    assert d._refit([], np.zeros((0, 2)), d.DEFAULT) == []
    line = [((0.0, 5.0), (10.0, 5.0))]
    assert d._refit(line, np.array([[1.0, 5.0], [2.0, 5.0]]), d.DEFAULT) == []
