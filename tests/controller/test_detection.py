"""Wall detection on hand-made clouds with known walls, and on bad input."""

import math
import warnings

import numpy as np
import pytest

from controller.perception.detection import DEFAULT, DetectionConfig, crop_mask, detect_segments
from controller.errors import InputError
from controller.geometry import point_segment_distance, segments_to_endpoints

BAND = (0.3, 0.8)  # heights on the wall face inside the default crop band


def wall_points(a, b, rng, spacing=0.05, heights=BAND, noise=0.02):
    """Points on a vertical face from a to b (body frame, metres), z down."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    n = max(int(np.hypot(*(b - a)) / spacing), 2)
    t = rng.uniform(0.0, 1.0, n)
    xy = a + t[:, None] * (b - a)
    d = (b - a) / np.hypot(*(b - a))
    xy += rng.normal(0.0, noise, n)[:, None] * np.array([-d[1], d[0]])
    z = -rng.uniform(*heights, n)
    return np.column_stack([xy, z])


def find(segs, a, b, perp=0.15, angle_deg=1.0):
    """The detected segment lying along the true wall a-b (within perp and angle), or None."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    theta = math.atan2(b[1] - a[1], b[0] - a[0])
    sa, sb = segments_to_endpoints(segs)
    for k, s in enumerate(segs):
        dang = abs((s[2] - theta + math.pi / 2) % math.pi - math.pi / 2)
        ends = point_segment_distance(np.array([sa[k], sb[k]]), a, b)[:, 0]
        if dang <= math.radians(angle_deg) and ends.max() <= perp:
            return s
    return None


def covered_length(segs, a, b, perp=0.3, angle_deg=3.0, step=0.05):
    """Fraction of the true wall a-b within perp and angle of some detected segment."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    theta = math.atan2(b[1] - a[1], b[0] - a[0])
    n = int(np.hypot(*(b - a)) / step)
    pts = a + (np.arange(n) + 0.5)[:, None] / n * (b - a)
    sa, sb = segments_to_endpoints(segs)
    dist = point_segment_distance(pts, sa, sb)
    dang = np.abs((segs[:, 2] - theta + np.pi / 2) % np.pi - np.pi / 2)
    return float(((dist <= perp) & (dang[None, :] <= math.radians(angle_deg))).any(axis=1).mean())


def test_straight_wall_is_one_segment_in_place():
    rng = np.random.default_rng(1)
    cloud = wall_points((-30, 6), (30, 6), rng)
    segs = detect_segments(cloud, (0.0, 0.0, 0.0))
    assert len(segs) == 1
    xc, yc, theta, length = segs[0]
    assert abs(yc - 6.0) < 0.02 and abs(xc) < 0.2
    assert abs(theta) < math.radians(0.2)
    assert 59.5 < length <= 60.1


def test_segments_are_in_the_inertial_frame():
    rng = np.random.default_rng(2)
    cloud = wall_points((-20, 6), (20, 6), rng)
    pose = (100.0, -50.0, math.radians(30.0))
    segs = detect_segments(cloud, pose)
    assert len(segs) == 1
    # The wall's middle is 6 m to starboard of the boat: at psi + 90 deg.
    psi = pose[2]
    expect = np.array([pose[0] - 6 * math.sin(psi), pose[1] + 6 * math.cos(psi)])
    assert np.hypot(*(segs[0, :2] - expect)) < 0.3
    assert abs((segs[0, 2] - psi + math.pi / 2) % math.pi - math.pi / 2) < math.radians(0.3)
    assert -math.pi / 2 <= segs[0, 2] < math.pi / 2


def test_corner_gives_two_segments_meeting_at_the_corner():
    rng = np.random.default_rng(3)
    cloud = np.vstack([wall_points((0, 6), (20, 6), rng), wall_points((20, 6), (20, -12), rng)])
    segs = detect_segments(cloud, (0.0, 0.0, 0.0))
    along = find(segs, (0, 6), (20, 6))
    across = find(segs, (20, 6), (20, -12))
    assert along is not None and across is not None
    assert len(segs) == 2
    for seg, corner in ((along, (20, 6)), (across, (20, 6))):
        ends = np.array(segments_to_endpoints(seg)).reshape(2, 2)
        assert np.hypot(*(ends - corner).T).min() < 0.4  # each reaches the corner


def test_two_parallel_walls_12_m_apart():
    rng = np.random.default_rng(4)
    cloud = np.vstack([wall_points((-40, -6), (40, -6), rng), wall_points((-40, 6), (40, 6), rng)])
    segs = detect_segments(cloud, (0.0, 0.0, 0.0))
    assert len(segs) == 2
    assert sorted(np.round(segs[:, 1], 1)) == [-6.0, 6.0]
    assert np.all(np.abs(segs[:, 2]) < math.radians(0.2))
    assert np.all(segs[:, 3] > 79.0)


def test_short_pier_faces_are_found_beside_the_wall():
    rng = np.random.default_rng(5)
    # Wall at y = -7 with a pier 3 m out of it, 2 m wide, at x = 10..12.
    faces = [((10, -7), (10, -4)), ((10, -4), (12, -4)), ((12, -4), (12, -7))]
    cloud = np.vstack([wall_points((-20, -7), (10, -7), rng), wall_points((12, -7), (40, -7), rng)]
                      + [wall_points(a, b, rng) for a, b in faces])
    segs = detect_segments(cloud, (0.0, 0.0, 0.0))
    for a, b in faces:
        seg = find(segs, a, b, perp=0.2, angle_deg=3.0)
        assert seg is not None, f"pier face {a}-{b} not found in {np.round(segs, 2)}"
        assert abs(seg[3] - np.hypot(*np.subtract(b, a))) < 0.4
    assert covered_length(segs, (-20, -7), (10, -7)) > 0.97
    assert covered_length(segs, (12, -7), (40, -7)) > 0.97


def test_a_bend_becomes_a_chain_of_chords_close_to_the_wall():
    rng = np.random.default_rng(6)
    # A quarter circle of radius 40 m around (0, 46): the wall bends away to starboard.
    phi = np.linspace(0, np.pi / 2, 400)
    arc = np.column_stack([40 * np.sin(phi), 46 - 40 * np.cos(phi)])
    cloud = np.vstack([wall_points(arc[i], arc[i + 1], rng, spacing=0.03)
                       for i in range(len(arc) - 1)])
    segs = detect_segments(cloud, (0.0, 0.0, 0.0))
    assert len(segs) >= 8  # a chain, not one long chord
    sa, sb = segments_to_endpoints(segs)
    # Every chord hugs the arc: ends within 0.1 m of the radius, direction within 3 deg of
    # the tangent at its middle.
    for k in range(len(segs)):
        for p in (sa[k], sb[k]):
            assert abs(np.hypot(p[0], p[1] - 46) - 40) < 0.1
        mid = segs[k, :2]
        tangent = math.atan2(mid[0], 46 - mid[1])  # the arc's direction at angle phi is phi
        assert abs((segs[k, 2] - tangent + math.pi / 2) % math.pi - math.pi / 2) < math.radians(3)
    along = [covered_length(segs, arc[i], arc[i + 1]) for i in range(0, len(arc) - 1, 7)]
    assert np.mean(along) > 0.97


def test_sparse_far_wall_is_bridged():
    rng = np.random.default_rng(7)
    # Returns every 3 m at 40-50 m range, as a glancing far wall gives them.
    x = np.arange(32.0, 52.0, 3.0)
    cloud = np.column_stack([x, np.full_like(x, 9.0) + rng.normal(0, 0.02, len(x)),
                             np.full_like(x, -0.5)])
    segs = detect_segments(cloud, (0.0, 0.0, 0.0))
    assert len(segs) == 1 and abs(segs[0, 1] - 9.0) < 0.1


def test_water_quay_tops_hull_and_wake_are_cropped():
    rng = np.random.default_rng(8)
    water = wall_points((-30, 10), (30, 10), rng, heights=(-0.05, 0.05))  # z ~ 0
    quay = wall_points((-30, 14), (30, 14), rng, heights=(1.5, 1.6))  # above the band
    hull = wall_points((-3.9, 1.2), (3.9, 1.2), rng)  # own hull side
    wake = wall_points((-17, 0.0), (-5, 0.0), rng)  # spray line behind the stern
    for cloud in (water, quay, hull, wake):
        assert not crop_mask(cloud).any()
        assert detect_segments(cloud, (0.0, 0.0, 0.0)).shape == (0, 4)


def test_same_cloud_same_segments():
    rng = np.random.default_rng(9)
    cloud = np.vstack([wall_points((0, 6), (30, 6), rng), wall_points((30, 6), (30, -20), rng)])
    first = detect_segments(cloud, (1.0, 2.0, 0.3))
    again = detect_segments(cloud.copy(), (1.0, 2.0, 0.3))
    assert np.array_equal(first, again)


def test_float32_and_float64_clouds_agree():
    rng = np.random.default_rng(10)
    cloud = wall_points((-20, 5), (20, 5), rng)
    a = detect_segments(cloud, (0, 0, 0))
    b = detect_segments(cloud.astype(np.float32), (0, 0, 0))
    assert a.shape == b.shape and np.allclose(a, b, atol=0.02)


# -- bad input ----------------------------------------------------------------------------
@pytest.mark.parametrize("empty", [np.zeros((0, 3)), np.zeros((0, 3), np.float32), [], np.zeros(0)])
def test_empty_cloud_gives_no_segments(empty):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        segs = detect_segments(empty, (0.0, 0.0, 0.0))
    assert segs.shape == (0, 4)


def test_nan_and_inf_rows_are_dropped_and_counted():
    rng = np.random.default_rng(11)
    cloud = wall_points((-20, 6), (20, 6), rng)
    clean = detect_segments(cloud, (0, 0, 0))
    dirty = np.vstack([cloud, [[np.nan, 1.0, -0.5], [2.0, np.inf, -0.5], [1.0, 1.0, -np.inf]]])
    with pytest.warns(RuntimeWarning, match=r"dropped 3 of %d points with NaN or inf" % len(dirty)):
        segs = detect_segments(dirty, (0, 0, 0))
    assert np.array_equal(segs, clean)


@pytest.mark.parametrize("shape", [(10, 2), (10, 4), (30,), (2, 5, 3)])
def test_wrong_shape_is_a_clear_error(shape):
    with pytest.raises(InputError, match=r"shape \(N, 3\).*got \(" + str(shape[0])):
        detect_segments(np.zeros(shape), (0, 0, 0))


@pytest.mark.parametrize("cloud", [np.array([["a", "b", "c"]]), np.zeros((3, 3), dtype=object),
                                   np.zeros((3, 3), dtype=bool), np.zeros((3, 3), complex)])
def test_wrong_dtype_is_a_clear_error(cloud):
    with pytest.raises(InputError, match="numeric .*got dtype"):
        detect_segments(cloud, (0, 0, 0))


@pytest.mark.parametrize("pose", [(0, 0), (0, 0, np.nan), "north", (0, 0, 0, 0)])
def test_bad_pose_is_a_clear_error(pose):
    with pytest.raises(InputError, match="pose must be"):
        detect_segments(np.zeros((5, 3)), pose)


@pytest.mark.parametrize("field,value", [("cell_m", 0.0), ("max_gap_m", -1.0),
                                         ("inlier_m", float("nan")), ("gap_per_range", -0.1)])
def test_bad_config_is_a_clear_error(field, value):
    with pytest.raises(InputError, match=field):
        DetectionConfig(**{field: value})


def test_height_band_must_be_ordered():
    with pytest.raises(InputError, match="min_height_m must be below max_height_m"):
        DetectionConfig(min_height_m=1.0, max_height_m=0.5)


def test_defaults_crop_below_the_lowest_quay():
    # The paper's walls stand 1-3 m above the water: the band stays under 1 m.
    assert 0.0 < DEFAULT.min_height_m < DEFAULT.max_height_m < 1.0


def test_column_major_cloud_gives_the_same_segments():
    rng = np.random.default_rng(11)
    cloud = np.vstack([wall_points((-20, 6), (25, 6), rng), wall_points((5, -7), (30, -9), rng)])
    cloud = cloud.astype(np.float32)
    pose = (3.0, 4.0, 0.4)
    a = detect_segments(np.ascontiguousarray(cloud), pose)
    b = detect_segments(np.asfortranarray(cloud), pose)
    assert len(a) == 2 and np.array_equal(a, b)
    assert np.array_equal(crop_mask(np.asfortranarray(cloud)), crop_mask(cloud))


def test_near_chords_and_principal_match_simple_references():
    """The one-table chord test and the moment fit against plain per-chord, per-point maths."""
    from controller.perception.detection import _near_chords, _principal

    rng = np.random.default_rng(7)
    pts = rng.uniform(-5.0, 5.0, (300, 2))
    chords = [((-4.0, -1.0), (3.0, 2.0)), ((1.0, 1.0), (1.0, 1.0)), ((0.0, 4.0), (0.0, -4.0))]
    a = np.array([c[0] for c in chords])
    b = np.array([c[1] for c in chords])
    dist = point_segment_distance(pts, a, b)
    for band in (0.1, 0.5, 1.5):
        np.testing.assert_array_equal(_near_chords(pts, chords, band), (dist <= band).any(axis=1))
    line = pts[:40] * np.array([1.0, 0.0]) + np.array([2.0, -3.0])
    line[:, 1] += 0.5 * line[:, 0] + rng.normal(0.0, 0.01, 40)
    cx, cy, vx, vy = _principal(line)
    centred = line - line.mean(axis=0)
    w, v = np.linalg.eigh(centred.T @ centred)
    major = v[:, np.argmax(w)]
    assert (cx, cy) == pytest.approx(tuple(line.mean(axis=0)), abs=1e-12)
    assert abs(vx * major[1] - vy * major[0]) < 1e-9 and math.hypot(vx, vy) == pytest.approx(1.0)


def test_going_astern_the_wake_box_is_not_cropped():
    from controller.perception.detection import DEFAULT, for_surge

    assert for_surge(DEFAULT, 2.0) is DEFAULT and for_surge(DEFAULT, -0.05) is DEFAULT
    astern = for_surge(DEFAULT, -0.5)
    assert astern.wake_length_m == 0.0 and astern.hull_x_m == DEFAULT.hull_x_m
