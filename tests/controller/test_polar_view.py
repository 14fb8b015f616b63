"""The compiled polar images of `free_space` against their numpy twins, bit for bit: numpy's
own arctan2 gives the bins, the kernels the offsets and the least or greatest value per bin."""

import numpy as np
import pytest

from controller.perception.polar_view import (N_BINS, HullView, OccluderView,
                                              hull_slope_numpy, nearest_numpy, polar_kernel)

pytestmark = pytest.mark.skipif(polar_kernel() is None, reason="no C compiler")


def _viewpoints(rng):
    """An origin row (height not known, as when the LiDARs are not placed) and LiDAR units."""
    units = np.column_stack([rng.uniform(-4, 4, 3), rng.uniform(-1.3, 1.3, 3),
                             rng.uniform(1.0, 3.0, 3)])
    return np.vstack([[0.0, 0.0, np.nan], units])


def _assert_asked_bins_are(ask, image, rng):
    """`ask(k, bins)` gives the numpy image's row k at those bins: 40 drawn (one twice), and
    all of them."""
    asked = rng.integers(0, N_BINS, 40)
    asked[1] = asked[0]
    for k in range(len(image)):
        np.testing.assert_array_equal(ask(k, asked), image[k, asked])
        np.testing.assert_array_equal(ask(k, np.arange(N_BINS)), image[k])


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("seed", range(8))
def test_nearest_returns_asked_are_the_numpy_image(seed, dtype):
    rng = np.random.default_rng(700 + seed)
    cloud = rng.uniform(-60, 60, (int(rng.integers(1, 5000)), 3)).astype(dtype)
    cloud[:5, :2] = 0.0  # returns on a viewpoint's axis and at the origin
    occluders = cloud[:, :2]  # a strided view, as the tracker's crop hands it over
    view = _viewpoints(rng)
    view[1, :2] = occluders[1]
    image = nearest_numpy(occluders, view)
    _assert_asked_bins_are(OccluderView(occluders, view).nearest, image, rng)
    assert np.isinf(image).any() and np.isfinite(image).any()


@pytest.mark.parametrize("seed", range(8))
def test_hull_slopes_asked_are_the_numpy_image(seed):
    rng = np.random.default_rng(800 + seed)
    hull = np.column_stack([rng.uniform(-4, 4, 3000), rng.uniform(-1.3, 1.3, 3000),
                            rng.uniform(0.0, 2.5, 3000)])
    view = _viewpoints(rng)
    hull[0] = (*view[1, :2], 1.0)  # on a unit's axis: no bearing, left out
    image = hull_slope_numpy(hull, view)
    _assert_asked_bins_are(HullView(hull, view).slope, image, rng)
    assert np.all(image[0] == -np.inf)  # no height known: nothing cuts the view
    assert np.isfinite(image[1:]).any() and (image[1:] == -np.inf).any()


def test_empty_inputs_see_nothing():
    view = np.array([[0.0, 0.0, np.nan], [1.0, 0.5, 2.0]])
    assert np.all(OccluderView(np.zeros((0, 2), np.float32), view).nearest(0, np.arange(5))
                  == np.inf)
    assert np.all(HullView(np.zeros((0, 3)), view).slope(1, np.arange(5)) == -np.inf)
