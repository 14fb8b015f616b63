"""The compiled nearest-leg distance and walls abeam against their numpy twins, bit for bit
(the kernels do the twins' arithmetic in the same order)."""

import numpy as np
import pytest

from controller.geometry import nearest_leg_compiled, nearest_leg_distance, point_segment_distance
from controller.nmpc.path_geometry import geometry_kernel
from controller.nmpc.slack_reference import walls_abeam, walls_abeam_numpy


@pytest.mark.skipif(not nearest_leg_compiled(), reason="no C compiler")
@pytest.mark.parametrize("seed", range(20))
def test_nearest_leg_is_the_numpy_minimum(seed):
    rng = np.random.default_rng(300 + seed)
    n, m = int(rng.integers(1, 30)), int(rng.integers(1, 80))
    points = rng.uniform(-50, 50, (n, 2))
    a = rng.uniform(-50, 50, (m, 2))
    b = a + rng.uniform(-10, 10, (m, 2))
    b[0] = a[0]  # a leg of no length
    got = nearest_leg_distance(points, a, b)
    np.testing.assert_array_equal(got, point_segment_distance(points, a, b).min(axis=1))
    assert np.all(nearest_leg_distance(points, a[:0], b[:0]) == np.inf)


@pytest.mark.skipif(geometry_kernel() is None, reason="no C compiler")
@pytest.mark.parametrize("seed", range(20))
def test_walls_abeam_is_its_numpy_twin(seed):
    rng = np.random.default_rng(400 + seed)
    n, m = int(rng.integers(1, 30)), int(rng.integers(1, 40))
    points = rng.uniform(-30, 30, (n, 2))
    points[0] = (500.0, 500.0)  # beyond every wall abeam: inf both sides (within 60 deg of
    # the normal only for some headings, so mostly inf)
    headings = rng.uniform(-np.pi, np.pi, n)
    segments = np.column_stack([rng.uniform(-30, 30, (m, 2)), rng.uniform(-np.pi, np.pi, m),
                                rng.uniform(0.5, 20, m)])
    port, starboard = walls_abeam(points, headings, segments)
    port0, starboard0 = walls_abeam_numpy(points, headings, segments)
    np.testing.assert_array_equal(port, port0)
    np.testing.assert_array_equal(starboard, starboard0)
    assert np.isfinite(port[1:]).any() or n < 5 or m < 5  # walls found, and not found:
    assert np.isinf(port).any() or np.isinf(starboard).any()  # both answers are compared
