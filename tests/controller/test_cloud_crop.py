"""The compiled crop of a LiDAR cloud against its numpy twin (issue 33)."""

import numpy as np
import pytest

from controller.perception.detection import DEFAULT, _crop, _crop_numpy, crop_rows, crop_xy
from controller.perception.tracking import (TrackerConfig, _tracker_crop, split_crop,
                                            split_crop_numpy)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("order", ["C", "F"])
@pytest.mark.parametrize("which", ["detection", "tracker"])
def test_compiled_crop_matches_its_numpy_twin_at_the_thresholds(dtype, order, which):
    """Random clouds, many points exactly on a threshold (band, range, hull and wake
    boxes): the same indices, x and y, in the cloud's own precision, for row- and
    column-major clouds."""
    cfg = DEFAULT if which == "detection" else _tracker_crop(TrackerConfig(viewpoints=((0, 0, 1),)))
    x0, x1 = cfg.hull_x_m
    thresholds = [-cfg.min_height_m, -cfg.max_height_m, cfg.range_m, -cfg.range_m, x0, x1,
                  cfg.hull_half_width_m, -cfg.hull_half_width_m, x0 - cfg.wake_length_m,
                  cfg.wake_half_width_m]
    rng = np.random.default_rng(7)
    pts = rng.uniform(-60, 60, (40_000, 3))
    pts[:, 2] = rng.uniform(-4, 1, len(pts))
    for j in range(3):
        pts[rng.integers(0, len(pts), 4000), j] = rng.choice(thresholds, 4000)
    pts = np.asarray(pts, dtype, order=order)
    got, want = _crop(pts, cfg), _crop_numpy(pts, cfg)
    assert len(want[0]) > 1000
    for a, b in zip(got, want):
        assert a.dtype == b.dtype and np.array_equal(a, b)


def test_crop_of_an_empty_or_strided_cloud():
    assert all(len(a) == 0 for a in crop_xy(np.zeros((0, 3), np.float32)))
    buf = np.zeros((3, 10), np.float32)
    buf[0] = np.arange(10) + 10.0  # ahead of the hull
    buf[2] = -0.5  # in the band
    idx, x, _ = crop_xy(buf.T)  # the simulator's column-major view
    assert np.array_equal(idx, np.arange(10)) and np.array_equal(x, buf[0])


def _cloud(dtype, order, cfg, n=30_000, seed=3):
    x0, x1 = cfg.hull_x_m
    special = [-cfg.min_height_m, -cfg.max_height_m, x0, x1, cfg.hull_half_width_m,
               -cfg.hull_half_width_m]
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-30, 30, (n, 3))
    pts[:, 2] = rng.uniform(-4, 1, n)
    for j in range(3):
        pts[rng.integers(0, n, n // 10), j] = rng.choice(special, n // 10)
    return np.asarray(pts, dtype, order=order)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("order", ["C", "F"])
def test_crop_rows_are_the_cloud_indexed_by_the_crop(dtype, order):
    cfg = _tracker_crop(TrackerConfig())
    pts = _cloud(dtype, order, cfg)
    rows = crop_rows(pts, cfg)
    want = pts[_crop_numpy(pts, cfg)[0]]
    assert rows.dtype == want.dtype and rows.flags.c_contiguous and np.array_equal(rows, want)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("viewpoints", [(), ((3.5, 0.0, 1.3),)])
def test_split_of_the_trackers_crop_matches_its_numpy_twin(dtype, viewpoints):
    cfg = TrackerConfig(viewpoints=viewpoints)
    cloud = crop_rows(_cloud(dtype, "F", cfg.detection), _tracker_crop(cfg))
    got, want = split_crop(cloud, cfg), split_crop_numpy(cloud, cfg)
    for a, b in zip(got, want):
        if b is None:
            assert a is None
        else:
            assert a.dtype == b.dtype and np.array_equal(a, b)
    assert (want[2] is not None) == bool(viewpoints)


@pytest.mark.parametrize("seed", range(3))
def test_compiled_occupancy_matches_its_numpy_twin(seed):
    """Points on cell borders, outside the grid and many per cell: the same grid and the
    same centroids bit for bit."""
    from controller.perception.detection import _occupancy, _occupancy_numpy

    rng = np.random.default_rng(seed)
    r, cell = DEFAULT.range_m, DEFAULT.cell_m
    xy = rng.uniform(-r - 5, r + 5, (20_000, 2))
    xy[:5000] = np.round(xy[:5000] / cell) * cell  # on the borders
    xy[5000:9000] = xy[5000:5001] + rng.normal(0, 0.01, (4000, 2))  # crowded cells
    (g1, c1), (g2, c2) = _occupancy(xy, DEFAULT), _occupancy_numpy(xy, DEFAULT)
    assert g1.dtype == g2.dtype and np.array_equal(g1, g2)
    assert np.array_equal(c1, c2) and len(c1) > 1000


def test_compiled_grid_lookup_matches_its_numpy_twin():
    """The tracker's lookup of its wall grid at points: points on cell edges, outside the
    grid on every side (clipped to its border cells), the same values as numpy's."""
    from controller.perception.clusters import grid_at, grid_at_numpy

    rng = np.random.default_rng(5)
    r, cell = 60.0, 0.1
    n = int(np.ceil(2 * r / cell))
    grid = (rng.random((n, n)) < 0.3).astype(np.uint8)
    xy = rng.uniform(-70, 70, (20_000, 2))
    xy[::7] = np.round(xy[::7] / cell) * cell  # exactly on cell edges
    got, want = grid_at(grid, xy, r, cell), grid_at_numpy(grid, xy, r, cell)
    assert got.dtype == want.dtype == bool and want.any() and not want.all()
    assert np.array_equal(got, want)
