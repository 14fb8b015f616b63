"""The compiled clustering grid of the tracker (`cluster_cells.c`) against its numpy twins
(issue 33): the same points, cells, grid, counts and members, exactly."""

import dataclasses

import numpy as np
import pytest

from controller.perception import clusters as cl
from controller.perception import opencv
from controller.perception.cluster_cells import (cluster_kernel, cluster_members_compiled,
                                                 sociable_points_compiled)
from controller.perception.tracking import TrackerConfig


@pytest.fixture(scope="module")
def lib():
    lib = cluster_kernel()
    if lib is None:
        pytest.skip("no C compiler: the numpy twin is what runs")
    return lib


def _points(seed: int, r: float) -> np.ndarray:
    """Hull-like blobs, lone returns, points on cell boundaries, out of the grid, repeated."""
    rng = np.random.default_rng(seed)
    blobs = [rng.normal(rng.uniform(-r, r, 2), rng.uniform(0.2, 3.0), (int(rng.integers(1, 80)), 2))
             for _ in range(int(rng.integers(0, 12)))]
    lone = rng.uniform(-1.2 * r, 1.2 * r, (int(rng.integers(0, 60)), 2))
    edges = np.round(rng.uniform(-r, r, (20, 2)) * 2) / 2  # on cell boundaries (0.5 m)
    pts = np.concatenate(blobs + [lone, edges, edges[:5], np.array([[-r, -r], [r, r]])])
    return pts[rng.permutation(len(pts))]


@pytest.mark.parametrize("seed", range(8))
def test_sociable_points_match_the_numpy_twin(lib, seed):
    """Without and with a wall grid (random lines drawn as find_clusters draws them)."""
    r, cell = 30.0, 0.5
    n = int(np.ceil(2 * r / cell))
    xy = _points(seed, r)
    rng = np.random.default_rng(20 + seed)
    cfg = TrackerConfig(detection=dataclasses.replace(TrackerConfig().detection, range_m=r))
    walls = np.column_stack([xy[rng.integers(0, len(xy), 3)], rng.uniform(-3, 3, 3),
                             rng.uniform(5, 40, 3)])  # through some of the points
    mask = cl._wall_mask(walls, (0.0, 0.0, 1.0, 0.0), cfg)
    for grid, wall_cell in ((None, 1.0), (mask, cfg.wall_cell_m)):
        got = sociable_points_compiled(lib, xy, r, cell, n, grid, wall_cell)
        want = cl.sociable_points_numpy(xy, r, cell, n, grid, wall_cell)
        for a, b in zip(got, want):
            assert a.shape == b.shape and np.array_equal(a, b)
    assert len(got[0]) < len(sociable_points_compiled(lib, xy, r, cell, n)[0])


@pytest.mark.parametrize("seed", range(8))
def test_cluster_members_match_the_numpy_twin(lib, seed):
    """Components of the dilated grid, as find_clusters makes them, with and without a
    merge of components (root), and min_points from 1 to 12."""
    cv2 = opencv.cv2()
    rng = np.random.default_rng(50 + seed)
    r, cell = 30.0, 0.5
    n = int(np.ceil(2 * r / cell))
    xy, i, j, grid = cl.sociable_points_numpy(_points(seed, r), r, cell, n)
    n_labels, labels = cv2.connectedComponents(cv2.dilate(grid, np.ones((3, 3), np.uint8)),
                                               connectivity=8)
    root = np.minimum(np.arange(n_labels), rng.integers(0, n_labels, n_labels))
    root[0] = 0
    root = np.minimum(root, root[root])
    for min_points in (1, 5, 12):
        for r_ in (None, root):
            got = cluster_members_compiled(lib, i, j, labels, r_, n_labels, min_points)
            want = cl.cluster_members_numpy(i, j, labels if r_ is None else r_[labels],
                                            n_labels, min_points)
            for a, b in zip(got, want):
                assert np.array_equal(a, b)


def test_find_clusters_compiled_and_numpy_agree(monkeypatch):
    """Two moored boats beside a quay and a buoy, seen from the boat: the same clusters."""
    rng = np.random.default_rng(3)
    quay = np.column_stack([np.linspace(-40, 40, 800), np.full(800, 8.0)])
    boat = np.column_stack([rng.uniform(5, 14, 150), rng.uniform(5.0, 7.5, 150)])
    other = np.column_stack([rng.uniform(-20, -12, 120), rng.uniform(-6.0, -4.0, 120)])
    buoy = rng.normal((25.0, -3.0), 0.3, (30, 2))
    xy = np.concatenate([quay, boat, other, buoy]) + rng.normal(0, 0.03, (1100, 2))
    segments = np.array([[0.0, 8.0, 0.0, 80.0], [9.5, 5.0, 0.0, 9.0]])
    cfg = TrackerConfig()
    pose = (100.0, 50.0, 0.3)
    c, s = np.cos(pose[2]), np.sin(pose[2])
    inertial = segments.copy()
    inertial[:, 0] = pose[0] + c * segments[:, 0] - s * segments[:, 1]
    inertial[:, 1] = pose[1] + s * segments[:, 0] + c * segments[:, 1]
    inertial[:, 2] += pose[2]
    got = cl.find_clusters(xy, pose, inertial, cfg)
    monkeypatch.setattr(cl, "cluster_kernel", lambda: None)
    want = cl.find_clusters(xy, pose, inertial, cfg)
    assert len(want) >= 2
    for f in ("centre", "angle", "from_side", "size", "count", "walls"):
        assert np.array_equal(getattr(got, f), getattr(want, f))
    assert all(np.array_equal(a, b) for a, b in zip(got.hulls, want.hulls))


@pytest.mark.parametrize("seed", range(10))
def test_chained_walls_match_the_numpy_twin(seed):
    """Chains of pieces along bends (ends at and about the gap, angles at and about the
    limit), moored boats' faces, lone long segments: the same walls."""
    from controller.perception.wall_chains import chain_kernel, chained_walls_compiled

    lib = chain_kernel()
    if lib is None:
        pytest.skip("no C compiler: the numpy twin is what runs")
    rng = np.random.default_rng(80 + seed)
    cfg = TrackerConfig()
    rows = []
    for _ in range(int(rng.integers(1, 5))):  # chains: each piece starts near the last's end
        p, th = rng.uniform(-50, 50, 2), rng.uniform(-np.pi, np.pi)
        for _ in range(int(rng.integers(1, 6))):
            length = rng.uniform(2, 25)
            gap = rng.choice([0.0, 0.5, cfg.chain_gap_m, rng.uniform(0.8, 1.2)])
            p = p + gap * np.array([np.cos(th + 1.0), np.sin(th + 1.0)])
            mid = p + 0.5 * length * np.array([np.cos(th), np.sin(th)])
            rows.append([*mid, th, length])
            p = p + length * np.array([np.cos(th), np.sin(th)])
            th += rng.choice([0.0, np.radians(cfg.chain_angle_deg), rng.uniform(-0.5, 0.5)])
    rows += [[*rng.uniform(-50, 50, 2), rng.uniform(-4, 4), rng.uniform(1, 60)]
             for _ in range(int(rng.integers(0, 8)))]
    s = np.array(rows)[rng.permutation(len(rows))]
    want = cl.chained_walls_numpy(s, cfg)
    got = chained_walls_compiled(lib, s, cfg)
    assert got.dtype == bool and np.array_equal(got, want)
    assert np.array_equal(cl.chained_walls(s, cfg), want)
