"""The compiled path geometry against its numpy twins: the path frame of points and the
forced slack, on random paths, points and walls (narrow stretches included, so that the
slack is forced), within an ulp's worth of the sines and cosines."""

import numpy as np
import pytest

from controller.nmpc.path_geometry import geometry_kernel
from controller.nmpc.reference import waypoint_path
from controller.nmpc.slack_reference import forced_slack_at, forced_slack_at_numpy

pytestmark = pytest.mark.skipif(geometry_kernel() is None, reason="no C compiler")


def _random_path(rng):
    steps = rng.uniform(5.0, 40.0, size=(rng.integers(2, 8), 1))
    turns = np.cumsum(rng.uniform(-1.0, 1.0, size=len(steps)))
    legs = steps * np.column_stack([np.cos(turns), np.sin(turns)])
    return waypoint_path(np.vstack([[0.0, 0.0], np.cumsum(legs, axis=0)]))


@pytest.mark.parametrize("seed", range(20))
def test_path_frame_is_its_numpy_twin(seed):
    rng = np.random.default_rng(seed)
    path = _random_path(rng)
    points = rng.uniform(-30.0, 120.0, size=(rng.integers(1, 60), 2))
    for s_min, s_max in ((0.0, None), (rng.uniform(0, path.length), None),
                         (5.0, path.length * 0.6), (path.length + 5, None)):
        s, d = path.frame(points, s_min, s_max)
        s0, d0 = path.frame_numpy(points, s_min, s_max)
        np.testing.assert_allclose(s, s0, rtol=0, atol=1e-9)
        np.testing.assert_allclose(d, d0, rtol=0, atol=1e-9)


@pytest.mark.parametrize("seed", range(30))
def test_forced_slack_is_its_numpy_twin(seed):
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(1, 50))
    # walls either side of a line along x, some of them closer than 2.5 margins
    width = rng.uniform(4.0, 16.0)
    xs = np.repeat(rng.uniform(-10.0, 60.0, size=int(rng.integers(1, 7))), 2)
    side = np.tile([-1.0, 1.0], len(xs) // 2)  # a wall each side at each place
    segs = np.column_stack([xs, side * width / 2 + rng.normal(0, 0.5, len(xs)),
                            rng.normal(0, 0.3, len(xs)), rng.uniform(10.0, 30.0, len(xs))])
    points = np.column_stack([rng.uniform(-5.0, 55.0, n), rng.normal(0.0, 1.0, n)])
    headings = rng.normal(0.0, 0.2, n)
    margin, slack_min = 5.0, -4.9
    got = forced_slack_at(points, headings, segs, margin, slack_min)
    want = forced_slack_at_numpy(points, headings, segs, margin, slack_min)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    if width < 8.0:
        assert (want < 0).any()  # the narrow cases do force a slack


def test_forced_slack_of_no_walls_or_far_walls_is_zero():
    points = np.zeros((3, 2))
    assert not forced_slack_at(points, np.zeros(3), np.zeros((0, 4)), 5.0, -4.9).any()
    far = np.array([[0.0, 30.0, 0.0, 10.0]])
    assert not forced_slack_at(points, np.zeros(3), far, 5.0, -4.9).any()


@pytest.mark.parametrize("seed", range(20))
def test_rays_crossing_is_its_numpy_twin(seed):
    from controller.nmpc.path_geometry import rays_crossing, rays_crossing_numpy

    rng = np.random.default_rng(200 + seed)
    n, m = int(rng.integers(1, 40)), int(rng.integers(0, 30))
    p, q = rng.uniform(-20, 20, (n, 2)), rng.uniform(-20, 20, (n, 2))
    a = rng.uniform(-20, 20, (m, 2))
    b = a + rng.uniform(-6, 6, (m, 2))  # short walls: some lines cross one, some none
    if m > 2:  # touches: a ray ending on a wall's end, a wall through a ray's start
        q[0], a[1] = a[0], p[min(1, n - 1)]
    for closed in (False, True):
        want = rays_crossing_numpy(p, q, a, b, closed)
        np.testing.assert_array_equal(rays_crossing(p, q, a, b, closed), want)
        np.testing.assert_array_equal(rays_crossing(p[0], q, a, b, closed),
                                      rays_crossing_numpy(p[0], q, a, b, closed))
    assert 0 < want.sum() < n or n < 8 or m < 8  # both answers occur


@pytest.mark.parametrize("seed", range(20))
def test_slot_distances_are_their_numpy_twin(seed):
    from controller.nmpc.path_geometry import slot_distances, slot_distances_numpy

    rng = np.random.default_rng(500 + seed)
    k, m = int(rng.integers(1, 30)), int(rng.integers(1, 40))
    points = rng.uniform(-40, 40, (k, 2))
    segments = np.column_stack([rng.uniform(-40, 40, (m, 2)), rng.uniform(-np.pi, np.pi, m),
                                rng.uniform(0.5, 20, m)])
    for got, want in zip(slot_distances(points, segments),
                         slot_distances_numpy(points, segments)):
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("seed", range(40))
def test_walk_slabs_is_its_numpy_twin(seed):
    from controller.nmpc.passage import walk_slabs, walk_slabs_numpy

    rng = np.random.default_rng(600 + seed)
    n_slabs = int(rng.integers(1, 40))
    n = int(rng.integers(0, 200))
    slab = rng.integers(0, n_slabs + 1, n)  # (n_slabs itself: a point at the sweep's end)
    d = np.round(rng.uniform(-30, 30, n), int(rng.integers(0, 3)))  # some equal offsets
    order = np.lexsort((d, slab))
    slab, d = slab[order], d[order]
    args = (n_slabs, 30.0, 6.0, 3.0, rng.choice([3.0, 5.0]), rng.uniform(-5, 5))
    got, want = walk_slabs(slab, d, *args), walk_slabs_numpy(slab, d, *args)
    assert got[0] == want[0]
    assert got[1] == want[1]


@pytest.mark.parametrize("seed", range(20))
def test_side_rays_are_their_numpy_twin(seed):
    from controller.nmpc.blind_openings import side_rays, side_rays_numpy
    from controller.nmpc.reference import waypoint_path

    rng = np.random.default_rng(700 + seed)
    path = waypoint_path(np.cumsum(rng.uniform(-30, 60, (int(rng.integers(2, 8)), 2)), axis=0))
    s = np.arange(-5.0, path.length + 5.0, 2.0)  # past both ends too: clamped
    m = int(rng.integers(0, 40))
    a = rng.uniform(-60, 250, (m, 2))
    b = a + rng.uniform(-40, 40, (m, 2))
    boat = path.at(rng.uniform(0, path.length))[0][0]
    far, open_ = side_rays(path, s, boat, a, b, 25.0, 60.0)
    want_far, want_open = side_rays_numpy(path, s, boat, a, b, 25.0, 60.0)
    np.testing.assert_allclose(far, want_far, rtol=0, atol=1e-12)  # sines: an ulp apart
    np.testing.assert_array_equal(open_, want_open)
    assert far.shape == (2, len(s), 2) and open_.dtype == bool


@pytest.mark.parametrize("seed", range(20))
def test_forced_slack_stages_are_their_numpy_twin(seed):
    from controller.nmpc.reference import waypoint_path
    from controller.nmpc.slack_reference import forced_slack, forced_slack_numpy

    rng = np.random.default_rng(800 + seed)
    path = waypoint_path(np.cumsum(rng.uniform(5, 40, (int(rng.integers(2, 6)), 2)), axis=0))
    walls = []  # quays 3-6 m either side of the path's legs, with gaps
    for a, b in zip(path.polyline.points[:-1], path.polyline.points[1:]):
        u = (b - a) / np.hypot(*(b - a))
        for side in (1.0, -1.0):
            c = 0.5 * (a + b) + side * rng.uniform(3.0, 6.0) * np.array([-u[1], u[0]])
            walls.append([*c, np.arctan2(u[1], u[0]) + rng.normal(0, 0.2),
                          rng.uniform(5, np.hypot(*(b - a)))])
    segments = np.array(walls)
    lo = np.sort(rng.uniform(-5, path.length, 20))
    hi = lo + rng.uniform(0, 8, 20)
    sway = rng.uniform(-2, 2)
    for offset in (None, lambda s: np.zeros_like(s), lambda s: sway * np.sin(s / 7.0)):
        got = forced_slack(path, lo, hi, segments, 5.0, -4.9, offset=offset)
        want = forced_slack_numpy(path, lo, hi, segments, 5.0, -4.9, offset=offset)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)  # sines: an ulp apart
    assert (want < 0).any()  # walls close enough to force a slack


@pytest.mark.parametrize("seed", range(20))
def test_path_points_and_projection_are_their_numpy_twins(seed):
    from controller.nmpc.reference import waypoint_path

    rng = np.random.default_rng(900 + seed)
    path = waypoint_path(np.cumsum(rng.uniform(-20, 40, (int(rng.integers(2, 9)), 2)), axis=0))
    s = np.concatenate([rng.uniform(-10, path.length + 10, 40), path.cumulative, [np.nan]])
    for got, want in zip(path.at(s), path.at_numpy(s)):
        np.testing.assert_array_equal(got, want)
    for point in rng.uniform(-40, 120, (30, 2)):
        lo = rng.uniform(1, path.length)  # (a window wholly before the path has no point)
        for window in ((0.0, None), (lo, lo + rng.uniform(0, 50)), (lo, lo - 1.0), (-3, 0)):
            assert path.project(point, *window) == path.project_numpy(point, *window)


@pytest.mark.parametrize("seed", range(30))
def test_slots_kept_in_place_are_their_numpy_twin(seed):
    from controller.nmpc.segment_slots import kept_in_place, kept_in_place_numpy

    rng = np.random.default_rng(1000 + seed)
    n = 16
    pool = np.column_stack([rng.integers(-3, 3, (24, 4)).astype(float), np.ones(24)])
    pool[:, :4] *= 1.0 - 2.0 * (rng.random((24, 4)) < 0.1)  # some -0.0 beside 0.0
    prev = pool[rng.choice(24, n)]  # repeats too: two rows for one slot
    slots = pool[rng.choice(24, n)]
    for rows in (prev, slots):
        rows[rng.random(n) < 0.3, 4] = 0.0  # inactive rows
    got, want = kept_in_place(slots, prev), kept_in_place_numpy(slots, prev)
    np.testing.assert_array_equal(got, want)  # (seeds 1000-1029: 13 rearranged, 17 kept)
