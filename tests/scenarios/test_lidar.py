"""The three-LiDAR simulator, and the detect / bench detection commands built on it."""

import dataclasses
import json
import math

import numpy as np
import pytest

from bridge.main import main
from controller.perception.detection import DEFAULT
from scenarios.commands.bench_detection import run_benchmark
from scenarios.world.demo import demo_canal
from controller.errors import InputError
from controller.perception.detection import detect_segments
from scenarios.sensors.lidar import (BACKDROP, FACE, GROUND, HULL, OBSTACLE, SPRAY, WATER,
                                     HullShape, LidarConfig, LidarMount, LidarNoise,
                                     LidarSimulator, default_mounts)
from scenarios.sensors.perception_pipeline import DelayedLidarPerception
from scenarios.world.canal import CanalWorld, Obstacle, Wall


def straight(width=14.0, obstacles=(), **kw):
    centre = np.column_stack([np.linspace(-150, 150, 151), np.zeros(151)])
    return CanalWorld.from_centre_line(centre, width, obstacles=obstacles, **kw)


def to_world(pose, pts):
    x, y, psi = pose
    c, s = math.cos(psi), math.sin(psi)
    return np.column_stack([x + c * pts[:, 0] - s * pts[:, 1], y + s * pts[:, 0] + c * pts[:, 1]])


@pytest.fixture(scope="module")
def canal_scan():
    world = straight(14.0, wall_height_m=1.5)
    pose = np.array([0.0, 1.0, math.radians(10.0)])
    return world, pose, LidarSimulator(world, seed=3).scan_labelled(pose, speed_mps=2.0)


def test_one_merged_float_cloud_in_the_body_frame(canal_scan):
    world, pose, scan = canal_scan
    pts = scan.points
    assert pts.ndim == 2 and pts.shape[1] == 3 and pts.dtype.kind == "f"
    assert 20_000 < len(pts) < 200_000
    assert set(np.unique(scan.sensor)) == {-1, 0, 1, 2}  # three sensors and the spray


def test_wall_returns_lie_on_the_walls_between_water_and_quay_top(canal_scan):
    world, pose, scan = canal_scan
    face = scan.points[scan.labels == FACE]
    assert len(face) > 1000
    d = world.clearance(to_world(pose, face))
    assert np.percentile(d, 99) < 0.1  # 2 cm range noise, along the beam
    height = -face[:, 2]
    assert height.min() > -0.1 and height.max() < 1.5 + 0.1


def test_quay_tops_and_backdrop_stand_behind_the_walls(canal_scan):
    world, pose, scan = canal_scan
    ground = scan.points[scan.labels == GROUND]
    back = scan.points[scan.labels == BACKDROP]
    assert len(ground) and len(back)
    assert np.allclose(-ground[:, 2], 1.5, atol=0.1)  # the quay top
    lateral = np.abs(to_world(pose, back)[:, 1])
    assert np.all(lateral > 7.0 + 5.0 - 0.2)  # 5 m behind the 7 m walls (default setback)
    assert np.all(-back[:, 2] < 8.0 + 0.2)


def test_water_only_as_sparse_speckle(canal_scan):
    world, pose, scan = canal_scan
    water = scan.points[scan.labels == WATER]
    wall_like = np.isin(scan.labels, (FACE, GROUND, BACKDROP)).sum()
    assert 0 < len(water) < 0.05 * wall_like
    assert np.all(np.abs(water[:, 2]) < 0.15)


def test_own_hull_blocks_the_view_and_returns_the_hull(canal_scan):
    world, pose, scan = canal_scan
    hull = scan.points[scan.labels == HULL]
    assert len(hull) > 0
    assert np.all(np.abs(hull[:, 0]) < 4.1) and np.all(np.abs(hull[:, 1]) < 1.45)
    # The bow unit sees forward only: the cabin behind it hides everything aft of it.
    front = scan.points[(scan.sensor == 0) & (scan.labels != HULL)]
    mount = default_mounts()[0]
    bearing = np.degrees(np.arctan2(front[:, 1] - mount.y_m, front[:, 0] - mount.x_m))
    assert not np.any(np.abs(bearing) > 170.0)


def test_side_units_see_the_wall_beside_the_boat(canal_scan):
    world, pose, scan = canal_scan
    for k, side in ((1, -1.0), (2, 1.0)):
        pts = scan.points[(scan.sensor == k) & (scan.labels == FACE)]
        beside = pts[(np.abs(pts[:, 0]) < 4.0) & (np.sign(pts[:, 1]) == side)]
        assert len(beside) > 20, f"sensor {k} sees no wall abeam"


def test_spray_in_the_wake_only_when_moving():
    world = straight()
    sim = LidarSimulator(world, seed=1)
    at_rest = sim.scan_labelled((0.0, 0.0, 0.0), speed_mps=0.0)
    moving = sim.scan_labelled((0.0, 0.0, 0.0), speed_mps=2.0)
    assert not np.any(at_rest.labels == SPRAY)
    spray = moving.points[moving.labels == SPRAY]
    assert len(spray) > 50
    assert np.all(spray[:, 0] < -3.9) and np.all(-spray[:, 2] <= 1.0 + 1e-6)


def test_ranges_within_the_sensor_limits():
    world = straight(6.0)  # walls within 3 m
    sim = LidarSimulator(world, seed=2)
    scan = sim.scan_labelled((0.0, 0.0, 0.0))
    for k, mount in enumerate(sim.config.mounts):
        pts = scan.points[scan.sensor == k]
        origin = np.array([mount.x_m, mount.y_m, -mount.height_m])
        r = np.linalg.norm(pts - origin, axis=1)
        assert r.min() >= mount.min_range_m - 0.1 and r.max() <= mount.max_range_m + 0.1


def test_same_seed_same_scan_other_seed_other_noise():
    world = straight()
    pose = (5.0, 0.5, 0.1)
    a = LidarSimulator(world, seed=7).scan(pose, 2.0)
    b = LidarSimulator(world, seed=7).scan(pose, 2.0)
    c = LidarSimulator(world, seed=8).scan(pose, 2.0)
    assert np.array_equal(a, b)
    assert not (a.shape == c.shape and np.array_equal(a, c))


def test_noise_settings_take_effect():
    world = straight()
    quiet = LidarConfig(noise=LidarNoise(range_sigma_m=0.0, dropout=0.0, water_speckle=0.0,
                                         spray_points=0))
    scan = LidarSimulator(world, quiet, seed=1).scan_labelled((0.0, 0.0, 0.0), 2.0)
    assert not np.any(np.isin(scan.labels, (WATER, SPRAY)))
    face = scan.points[scan.labels == FACE]
    assert np.abs(np.abs(face[:, 1]) - 7.0).max() < 1e-3  # exactly on the walls


def test_obstacle_faces_tops_and_a_bridge_underside():
    boat = Obstacle([[10, 3], [18, 3], [18, 5.6], [10, 5.6]], z_top_m=1.2, kind="boat", name="b")
    bridge = Obstacle([[-2, -20], [2, -20], [2, 20], [-2, 20]], z_top_m=4.0, z_bottom_m=3.0,
                      kind="bridge", name="deck")
    world = straight(14.0, obstacles=(boat, bridge))
    scan = LidarSimulator(world, seed=4).scan_labelled((0.0, 0.0, 0.0))
    obst = scan.points[scan.labels == OBSTACLE]
    xy = to_world((0.0, 0.0, 0.0), obst)
    on_boat = boat.contains(xy) | (world.clearance(xy) < 0.1) & (np.abs(xy[:, 0] - 14) < 4.1)
    assert on_boat.sum() > 50
    assert np.all(-obst[on_boat, 2] < 1.2 + 0.1)
    # Under the bridge the beams going up meet its underside at 3 m.
    under = bridge.contains(xy) & (np.abs(xy[:, 0]) < 1.8) & (-obst[:, 2] > 2.5)
    assert under.sum() > 50 and np.allclose(-obst[under, 2], 3.0, atol=0.1)


def test_mounting_poses_are_configurable():
    world = straight()
    low_front = dataclasses.replace(default_mounts()[0], height_m=0.8, columns=256, channels=16)
    sim = LidarSimulator(world, LidarConfig(mounts=(low_front,)), seed=0)
    scan = sim.scan_labelled((0.0, 0.0, 0.0))
    assert set(np.unique(scan.sensor[scan.labels != SPRAY])) == {0}
    assert len(scan.points) < 16 * 256
    with pytest.raises(Exception, match="min_range_m < max_range_m"):
        LidarMount("bad", 0, 0, 1, 16, min_range_m=5.0, max_range_m=1.0)


def test_bad_pose_is_a_clear_error():
    sim = LidarSimulator(straight(), seed=0)
    with pytest.raises(ValueError, match="pose must be three finite numbers"):
        sim.scan((0.0, np.nan, 0.0))


def test_in_view_respects_hull_field_of_view_and_range():
    sim = LidarSimulator(straight(), seed=0)
    pose = (0.0, 0.0, 0.0)
    view = sim.in_view(pose, [[30.0, 0.0], [-30.0, 0.0], [0.0, 200.0]], 0.5)
    assert view[0, 0]  # the bow unit sees ahead
    assert not view[1, 0]  # ... but not astern: the cabin is in the way
    assert not view[2].any()  # 200 m is beyond every unit's range


# -- accuracy on the demo canal -------------------------------------------------------------
def test_detection_on_simulated_scans_covers_the_walls_quickly():
    result = run_benchmark(demo_canal(), step_m=60.0, seed=5)
    assert result["scans"] == 7
    assert result["coverage"] > 0.9
    assert result["false_positive_fraction"] < 0.02


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_detection_meets_the_accuracy_targets(seed):
    """The issue's target: scans every 10 m, >= 95 % of the visible wall within 50 m covered
    (0.3 m, 3 deg), < 2 % of detected length farther than 1 m from any true surface."""
    result = run_benchmark(demo_canal(), step_m=10.0, seed=seed)
    assert result["coverage"] >= 0.95
    assert result["false_positive_fraction"] < 0.02


@pytest.mark.slow
def test_detection_off_the_centre_line():
    """2.5 m off the centre line the far bank is seen at more glancing angles: where the
    scan has returns the detector still covers the wall; overall it stays close to 95 %."""
    result = run_benchmark(demo_canal(), step_m=10.0, seed=2, offset_m=2.5)
    assert result["coverage_where_sampled"] >= 0.97
    assert result["coverage"] >= 0.94
    assert result["false_positive_fraction"] < 0.02


# -- the commands --------------------------------------------------------------------------
def test_detect_writes_a_png(tmp_path, capsys):
    out = tmp_path / "scan.png"
    assert main(["detect", "--at", "95", "-o", str(out), "--seed", "1"]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    text = capsys.readouterr().out
    assert "segments" in text and "covered" in text


def test_detect_takes_the_canal_of_a_scenario_file(tmp_path, capsys):
    path = tmp_path / "short.toml"
    path.write_text('[scenario]\nname = "short"\nduration_s = 60\n\n[canal]\n'
                    'centre_line = [[0, 0], [120, 0]]\nwidth_m = 14\n\n'
                    '[route]\nwaypoints = [[0, 0], [120, 0]]\n')
    out = tmp_path / "short.png"
    assert main(["detect", "--scenario", str(path), "--at", "60", "-o", str(out)]) == 0
    assert out.exists() and "segments" in capsys.readouterr().out


def test_detect_names_a_missing_scenario_file(tmp_path, capsys):
    missing = tmp_path / "canal.toml"
    assert main(["detect", "--scenario", str(missing), "--at", "10", "-o",
                 str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert str(missing) in err and "no such scenario file" in err and "Traceback" not in err


def test_detect_rejects_a_distance_off_the_canal(tmp_path, capsys):
    assert main(["detect", "--at", "5000", "-o", str(tmp_path / "x.png")]) == 2
    assert "5000" in capsys.readouterr().err


def test_bench_detection_prints_one_json_object(capsys):
    assert main(["bench", "detection", "--step", "200"]) == 0
    result = json.loads(capsys.readouterr().out)
    for key in ("coverage", "coverage_where_sampled", "false_positive_fraction",
                "false_positive_m", "points_per_scan", "simulation_ms", "detection_ms"):
        assert key in result
    assert set(result["simulation_ms"]) >= {"mean", "p99"}
    assert set(result["detection_ms"]) >= {"mean", "p99"}
    assert result["detection_ms"]["mean"] > 0 and result["points_per_scan"]["mean"] > 0


def test_default_band_is_below_the_demo_quays():
    assert DEFAULT.max_height_m < min(w.height_m for w in demo_canal().walls)


def test_ordered_keys_keep_the_order_of_the_floats():
    from scenarios.sensors.lidar import _ordered
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.normal(0, 1, 500), rng.normal(0, 1e-6, 100),
                        [0.0, -0.0, np.inf, -np.inf, 1e-38, -1e-38, 3e38]]).astype(np.float32)
    k = _ordered(x)
    for i in range(0, len(x), 7):  # every comparison agrees with the floats'
        assert np.array_equal(k[i] < k, x[i] < x) and np.array_equal(k[i] == k, x[i] == x)


def test_beam_search_matches_per_beam_comparisons():
    """The bins' beam counts at or below a (bin, tan) key, found with most keys answered
    without a search, equal a plain binary search: ties, infinities and -0 included."""
    from scenarios.sensors.lidar import _ordered
    sim = LidarSimulator(straight(), seed=0)
    beams = sim._beams
    n_bins = len(sim._bin_height)
    rng = np.random.default_rng(1)
    pool = np.concatenate([beams.tan_el, rng.uniform(-0.7, 0.7, 1000).astype(np.float32),
                           np.float32([np.inf, -np.inf, -0.0, 0.0])])
    col = np.repeat(np.arange(n_bins), 6)
    tan = np.sort(rng.choice(pool, (n_bins, 6)), axis=1).ravel()
    key = (col.astype(np.int64) << 32) + _ordered(tan)
    got = sim._beams_at_or_below(key, col)
    assert np.array_equal(got, np.searchsorted(sim._keys, key, "right"))
    inside = (tan >= beams.tan_el.min()) & (tan <= beams.tan_el.max())
    assert inside.sum() > 1000  # the searched path is taken, not only the shortcuts


def test_full_dropout_leaves_no_returns():
    world = straight()
    cfg = LidarConfig(noise=LidarNoise(dropout=1.0, spray_points=0))
    scan = LidarSimulator(world, cfg, seed=1).scan_labelled((0.0, 0.0, 0.0), 2.0)
    assert scan.points.shape == (0, 3)


def test_scan_rows_are_points_whatever_the_memory_layout():
    world = straight()
    scan = LidarSimulator(world, seed=5).scan_labelled((0.0, 0.0, 0.0), 2.0)
    pts = scan.points
    assert pts.dtype == np.float32 and pts.ndim == 2 and pts.shape[1] == 3
    assert len(pts) == len(scan.labels) == len(scan.sensor)
    c = np.ascontiguousarray(pts)
    assert np.array_equal(c, pts) and np.array_equal(c[:, 2], pts[:, 2])


# -- every surface a beam reaches (issue 16) ------------------------------------------------
def box(x0, x1, y0, y1, z_bottom=0.0, z_top=1.0, kind="pier", name="box", **kw):
    return Obstacle([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], z_top_m=z_top,
                    z_bottom_m=z_bottom, kind=kind, name=name, **kw)


def long_canal(width=18.0, obstacles=(), **kw):
    """A straight canal long enough that no beam passes the walls' ends (where the land
    behind a wall is not defined)."""
    centre = np.column_stack([np.linspace(-400, 400, 161), np.zeros(161)])
    return CanalWorld.from_centre_line(centre, width, obstacles=obstacles, **kw)


BRIDGE_X = 40.0
PIERS = (box(BRIDGE_X, BRIDGE_X + 2, -9, -4.5, 0, 3.5, name="pier west"),
         box(BRIDGE_X, BRIDGE_X + 2, 4.5, 9, 0, 3.5, name="pier east"))
DECK = box(BRIDGE_X - 1, BRIDGE_X + 3, -20, 20, 3.5, 4.5, kind="bridge", name="deck")
QUIET = LidarConfig(noise=LidarNoise(range_sigma_m=0.0, dropout=0.0, water_speckle=0.0,
                                     spray_points=0))


def first_hits(sim, pose, time_s=None, extra=()):
    """The renderer's distance (horizontal metres) and label for every world-facing beam."""
    scene = sim._scene_at(time_s, extra)
    return sim._distances(scene, *sim._cast(scene, sim.sensor_positions(pose), pose[2]))


def box_hits(sim, pose, boxes):
    """An independent reference: each beam cast in 3-D against axis-aligned boxes (x0, x1,
    y0, y1, z0, z1, face label, top label) by the slab method; the first box entered wins."""
    beams = sim._beams
    x, y, psi = pose
    c, s = math.cos(psi), math.sin(psi)
    o = (x + c * beams.origin[0] - s * beams.origin[1],
         y + s * beams.origin[0] + c * beams.origin[1], -beams.origin[2].astype(float))
    vx, vy = beams.vec[0].astype(float), beams.vec[1].astype(float)
    d = (c * vx - s * vy, s * vx + c * vy, beams.tan_el.astype(float))  # per horizontal m
    best, label = np.full(len(o[0]), np.inf), np.full(len(o[0]), -1)
    for x0, x1, y0, y1, z0, z1, face, top in boxes:
        lo, hi = (x0, y0, z0), (x1, y1, z1)
        near, far = np.full(len(best), -np.inf), np.full(len(best), np.inf)
        axis = np.zeros(len(best), int)
        with np.errstate(divide="ignore", invalid="ignore"):
            for k in range(3):
                inside = (o[k] >= lo[k]) & (o[k] <= hi[k])
                t1 = np.where(d[k] == 0, np.where(inside, -np.inf, np.inf), (lo[k] - o[k]) / d[k])
                t2 = np.where(d[k] == 0, np.inf, (hi[k] - o[k]) / d[k])
                t_in = np.minimum(t1, t2)
                axis = np.where(t_in > near, k, axis)
                near, far = np.maximum(near, t_in), np.minimum(far, np.maximum(t1, t2))
        t = np.where((near <= far) & (far > 0), np.maximum(near, 0.0), np.inf)
        better = t < best
        best = np.where(better, t, best)
        label = np.where(better, np.where(axis == 2, top, face), label)
    return best, label


def canal_boxes(half=9.0, wall=1.5, setback=5.0, back=8.0, obstacles=()):
    big = 1e4
    out = [(-big, big, -big, big, -big, 0.0, WATER, WATER)]
    for sign in (-1, 1):
        out.append((-400, 400, *sorted((sign * half, sign * (half + setback))), -big, wall,
                    FACE, GROUND))
        out.append((-400, 400, *sorted((sign * (half + setback), sign * big)), -big, back,
                    BACKDROP, BACKDROP))
    for ob in obstacles:
        (x0, y0), (x1, y1) = ob.outline.min(axis=0), ob.outline.max(axis=0)
        out.append((x0, x1, y0, y1, ob.z_bottom_m, ob.z_top_m, OBSTACLE, OBSTACLE))
    return out


def mismatches(sim, pose, boxes, **kw):
    """Beams whose first hit (within range) differs from the reference: (distance, label)."""
    pose = np.asarray(pose, float)
    t_ref, l_ref = box_hits(sim, pose, boxes)
    t_sim, l_sim = first_hits(sim, pose, **kw)
    cap = sim._beams.max_h.astype(float) + 1.0
    t_ref, t_sim = np.minimum(t_ref, cap), np.minimum(t_sim.astype(float), cap)
    counted = (t_ref < cap) | (t_sim < cap)
    far = counted & (np.abs(t_ref - t_sim) > 1e-3 + 1e-4 * t_ref)
    other = counted & ~far & (l_ref != l_sim)
    assert counted.sum() > 50_000
    return int(far.sum()), int(other.sum())


BOAT_UNDER = box(10, 22, 5.5, 8.9, 0, 1.0, kind="boat", name="moored")
OVERHANG = box(8, 25, 6.5, 9.5, 1.2, 1.5, kind="other", name="overhang")


@pytest.mark.parametrize("pose", [(0.0, 0.0, 0.0), (38.6, 2.0, 0.3), (15.0, 3.0, -0.2),
                                  (-30.0, -1.0, 0.05), (41.3, -0.7, 2.9), (60.0, 1.0, 3.1)])
def test_every_beam_meets_the_nearest_surface_a_3d_ray_cast_finds(pose):
    """Piers under a deck, a boat moored under a quay overhang, walls, quay tops and
    backdrops: the column renderer and a per-beam 3-D cast against boxes agree on every
    beam, distance and label (poses include sensors under the deck)."""
    obstacles = PIERS + (DECK, BOAT_UNDER, OVERHANG)
    sim = LidarSimulator(long_canal(obstacles=obstacles), seed=0)
    assert mismatches(sim, pose, canal_boxes(obstacles=obstacles)) == (0, 0)


def test_walls_behind_walls_and_concave_outlines_match_a_3d_ray_cast():
    """A low quay (0.5 m, open land) with a taller wall (3 m, then a backdrop) 12 m behind
    it, an L-shaped pier and a U-shaped overhang: every beam as the 3-D cast finds it."""
    xs = np.linspace(-400, 400, 81)
    line = lambda y: np.column_stack([xs, np.full_like(xs, y)])  # noqa: E731
    walls = (Wall(line(-7.0), height_m=0.5, setback_m=5.0, backdrop_height_m=0.0, name="low"),
             Wall(line(-19.0), height_m=3.0, setback_m=4.0, backdrop_height_m=10.0, name="tall"),
             Wall(line(7.0)[::-1], height_m=1.5, name="east"))
    ell = Obstacle([[30, 3], [36, 3], [36, 4], [31, 4], [31, 7], [30, 7]], z_top_m=2.0, name="L")
    u = Obstacle([[50, -6.9], [60, -6.9], [60, -2], [58, -2], [58, -5], [52, -5], [52, -2],
                  [50, -2]], z_bottom_m=1.8, z_top_m=2.3, kind="other", name="U")
    sim = LidarSimulator(CanalWorld.from_walls(walls, obstacles=(ell, u)), seed=0)
    big = 1e4
    boxes = [(-big, big, -big, big, -big, 0.0, WATER, WATER),
             (-400, 400, -big, -7, -big, 0.5, FACE, GROUND),
             (-400, 400, -23, -19, -big, 3.0, FACE, GROUND),
             (-400, 400, -big, -23, -big, 10.0, BACKDROP, BACKDROP),
             (-400, 400, 7, 12, -big, 1.5, FACE, GROUND),
             (-400, 400, 12, big, -big, 8.0, BACKDROP, BACKDROP),
             (30, 36, 3, 4, 0, 2.0, OBSTACLE, OBSTACLE), (30, 31, 3, 7, 0, 2.0, OBSTACLE, OBSTACLE),
             (50, 60, -6.9, -5, 1.8, 2.3, OBSTACLE, OBSTACLE),
             (50, 52, -6.9, -2, 1.8, 2.3, OBSTACLE, OBSTACLE),
             (58, 60, -6.9, -2, 1.8, 2.3, OBSTACLE, OBSTACLE)]
    for pose in [(0.3, 0.2, 0.01), (44.7, -3.1, -0.4), (55.3, -3.3, 1.3), (80.2, 2.3, 3.0),
                 (-11.4, -4.5, -0.7), (109.9, 1.5, -1.6)]:
        assert mismatches(sim, pose, boxes) == (0, 0), pose


def test_a_ray_through_a_vertex_does_not_turn_the_column_inside_out():
    """A bin's ray that meets a pier's corner exactly (two legs, entering and leaving at one
    point) passes it: everything behind stays as it is, no beam is swallowed at the
    sensor. Only the corner's own vertical line, of no width, goes unrendered."""
    sim = LidarSimulator(long_canal(obstacles=PIERS + (DECK,)), seed=0)
    pose = np.array([41.0, 0.0, 0.0])  # bow unit at (44.5, 0): the corners at 135 and 225 deg
    t_ref, _ = box_hits(sim, pose, canal_boxes(obstacles=PIERS + (DECK,)))
    t_sim, _ = first_hits(sim, pose)
    cap = sim._beams.max_h + 1.0
    differ = np.abs(np.minimum(t_ref, cap) - np.minimum(t_sim, cap)) > 1e-3 + 1e-4 * t_ref
    corner = math.hypot(4.5, 4.5)
    assert set(np.unique(sim._beams.bin[differ])) == {384, 640}  # the two corner columns
    assert np.allclose(t_ref[differ], corner)  # the reference grazes the corner ...
    assert np.all(t_sim[differ] > corner)  # ... the renderer sees what is behind it


def world_points(scan, pose, label):
    """(x, y, height) in the world frame of a scan's points with one label."""
    pts = scan.points[scan.labels == label]
    return np.column_stack([to_world(pose, pts), -pts[:, 2]])


def test_piers_under_a_deck_are_seen_from_40_m_and_the_deck_too():
    world = long_canal(obstacles=PIERS + (DECK,))
    pose = world.pose_at(400.0 + BRIDGE_X - 45.0)  # 45 m before the piers, bow 41 m
    scan = LidarSimulator(world, seed=3).scan_labelled(pose, 2.0)
    obst = world_points(scan, pose, OBSTACLE)
    face = obst[(np.abs(obst[:, 0] - BRIDGE_X) < 0.15) & (obst[:, 2] < 3.4)]
    assert len(face) > 20
    assert np.all((np.abs(face[:, 1]) >= 4.4) & (np.abs(face[:, 1]) <= 9.1))  # on the piers
    deck = obst[(obst[:, 2] > 3.4) & (obst[:, 2] < 4.6)]
    assert len(deck) > 20 and np.all(np.abs(deck[:, 0] - BRIDGE_X - 1.0) < 2.1)


def test_piers_under_a_deck_are_detected_40_m_ahead():
    """The issue's case: detection finds a segment on the piers' faces from 40 m and more
    (without the fix nothing came back from the piers until about 3 m)."""
    world = long_canal(obstacles=PIERS + (DECK,))
    sim = LidarSimulator(world, seed=0)
    for ahead in (40.0, 45.0, 50.0, 55.0):
        pose = world.pose_at(400.0 + BRIDGE_X - ahead)
        segs = detect_segments(sim.scan(pose, 2.0), pose)
        on_pier = ((np.abs(segs[:, 0] - BRIDGE_X) < 0.3)
                   & (np.abs(np.abs(segs[:, 2]) - math.pi / 2) < math.radians(3.0))
                   & (np.abs(segs[:, 1]) > 4.0) & (np.abs(segs[:, 1]) < 9.5))
        assert on_pier.any(), f"no segment on the piers {ahead} m ahead"


def test_under_a_deck_the_underside_is_above_and_the_piers_and_walls_around():
    deck = box(-6, 6, -20, 20, 3.5, 4.5, kind="bridge", name="deck")
    piers = (box(-1, 1, -9, -5, 0, 3.5, name="w"), box(-1, 1, 5, 9, 0, 3.5, name="e"))
    world = long_canal(obstacles=piers + (deck,))
    pose = np.array([0.5, 0.0, 0.0])  # all three sensors under the deck
    assert deck.contains(LidarSimulator(world).sensor_positions(pose)).all()
    scan = LidarSimulator(world, seed=2).scan_labelled(pose)
    obst = world_points(scan, pose, OBSTACLE)
    at_piers = (np.abs(obst[:, 0]) < 1.15) & (np.abs(obst[:, 1]) > 4.85)
    under = obst[~at_piers]
    assert len(under) > 200 and np.allclose(under[:, 2], 3.5, atol=0.1)  # only the underside
    assert np.all((np.abs(under[:, 0]) < 6.1) & (np.abs(under[:, 1]) < 20.1))  # the deck's
    on_piers = obst[at_piers]
    assert len(on_piers) > 50 and on_piers[:, 2].max() < 3.6
    # In the same columns: the underside above, the piers below.
    sim = LidarSimulator(world, QUIET, seed=0)
    t, label = first_hits(sim, pose)
    height = sim._beams.height + sim._beams.tan_el * t
    deck_hit = (label == OBSTACLE) & (np.abs(height - 3.5) < 1e-3) & (sim._beams.tan_el > 0)
    pier_hit = (label == OBSTACLE) & (height < 3.4)
    both = np.intersect1d(sim._beams.bin[deck_hit], sim._beams.bin[pier_hit])
    assert len(both) > 20
    walls = world_points(scan, pose, FACE)
    assert len(walls) > 500 and (np.abs(walls[:, 0]) > 6.0).any()  # beyond the deck too


def test_a_pier_behind_a_moored_boat_in_the_same_columns():
    """A low boat in front of a taller pier: beams over the boat reach the pier (the old
    renderer drew only the nearest obstacle of each column)."""
    boat = box(20, 30, 1.5, 6.9, 0, 0.8, kind="boat", name="boat")
    pier = box(40, 42, 3.5, 6.5, 0, 3.0, name="pier")
    world = long_canal(14.0, obstacles=(boat, pier))
    scan = LidarSimulator(world, seed=1).scan_labelled((0.0, 0.0, 0.0))
    bow = dataclasses.replace(scan, points=scan.points[scan.sensor == 0],
                              labels=scan.labels[scan.sensor == 0])
    obst = world_points(bow, (0.0, 0.0, 0.0), OBSTACLE)
    on_pier = obst[np.abs(obst[:, 0] - 40.0) < 0.15]
    on_boat = obst[np.abs(obst[:, 0] - 20.0) < 0.15]
    assert len(on_pier) > 20 and len(on_boat) > 20
    # From the bow unit (3.5 m forward) the pier lies wholly behind the boat.
    bearing = lambda p: np.arctan2(p[:, 1], p[:, 0] - 3.5)  # noqa: E731
    assert bearing(on_boat).min() < bearing(on_pier).min()
    assert bearing(on_pier).max() < bearing(on_boat).max()
    assert on_pier[:, 2].max() > 2.0  # seen over the boat, up to near its top


def test_a_boat_moored_under_a_quay_overhang():
    world = long_canal(obstacles=(BOAT_UNDER, OVERHANG))
    scan = LidarSimulator(world, seed=5).scan_labelled((0.0, 0.0, 0.0))
    obst = world_points(scan, (0.0, 0.0, 0.0), OBSTACLE)
    boat = obst[obst[:, 2] <= 1.05]
    under = boat[OVERHANG.contains(boat[:, :2])]  # the part under the overhang
    assert len(under) > 10 and np.all(under[:, 1] > 6.4)
    # Its bow end under the overhang, seen by beams passing below the overhang's edge.
    assert ((np.abs(under[:, 0] - 10.0) < 0.15) & (under[:, 1] > 6.6)).sum() > 5
    overhang = obst[(obst[:, 2] >= 1.15) & (obst[:, 2] <= 1.55)]
    assert len(overhang) > 20
    assert np.all((overhang[:, 0] > 7.9) & (overhang[:, 0] < 25.1) & (overhang[:, 1] > 6.4))


def test_a_backdrop_behind_a_low_quay():
    world = long_canal(14.0, wall_height_m=0.5, backdrop_height_m=6.0)
    scan = LidarSimulator(world, seed=6).scan_labelled((0.0, 0.0, 0.0))
    ground = world_points(scan, (0.0, 0.0, 0.0), GROUND)
    back = world_points(scan, (0.0, 0.0, 0.0), BACKDROP)
    assert len(ground) > 100 and np.allclose(ground[:, 2], 0.5, atol=0.1)
    assert len(back) > 1000 and np.all(np.abs(back[:, 1]) > 7.0 + 5.0 - 0.2)
    assert back[:, 2].max() > 5.0 and back[:, 2].max() < 6.2


def test_a_taller_wall_behind_a_low_one():
    xs = np.linspace(-400, 400, 81)
    line = lambda y: np.column_stack([xs, np.full_like(xs, y)])  # noqa: E731
    walls = (Wall(line(-7.0), height_m=0.5, backdrop_height_m=0.0, name="low"),
             Wall(line(-19.0), height_m=3.0, backdrop_height_m=0.0, name="tall"),
             Wall(line(7.0)[::-1], height_m=1.5, name="east"))
    world = CanalWorld.from_walls(walls)
    scan = LidarSimulator(world, seed=7).scan_labelled((0.0, 0.0, 0.0))
    face = world_points(scan, (0.0, 0.0, 0.0), FACE)
    behind = face[np.abs(face[:, 1] + 19.0) < 0.1]
    assert len(behind) > 100 and behind[:, 2].max() > 2.5 and behind[:, 2].max() < 3.1
    assert behind[:, 2].min() > 0.5 - 0.1  # its foot is hidden by the low quay


def test_an_obstacle_removed_at_a_time_is_not_rendered_after_it():
    barge = box(15, 30, 2.0, 6.5, 0, 1.2, kind="boat", name="barge", remove_at_s=10.0)
    world = long_canal(14.0, obstacles=(barge,))
    sim = LidarSimulator(world, seed=8)

    def on_barge(time_s):
        return (sim.scan_labelled((0.0, 0.0, 0.0), time_s=time_s).labels == OBSTACLE).sum()

    assert on_barge(None) > 100 and on_barge(9.9) > 100
    assert on_barge(10.0) == 0 and on_barge(60.0) == 0 and on_barge(5.0) > 100


@pytest.mark.parametrize("parallel", [False, True])
def test_lidar_perception_passes_the_time_so_a_removed_barge_leaves_the_scans(parallel):
    barge = box(15, 17, -6.9, 6.9, 0, 1.2, kind="boat", name="barge", remove_at_s=1.0)
    world = long_canal(14.0, obstacles=(barge,))
    state = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0])

    def across(segs):  # a segment across the canal at the barge's near side
        return ((np.abs(segs[:, 0] - 15.0) < 0.3)
                & (np.abs(np.abs(segs[:, 2]) - math.pi / 2) < math.radians(3.0))).any()

    with DelayedLidarPerception(world, seed=1, parallel=parallel) as p:
        seen = [across(p.segments(t, state, state[:3])) for t in (0.0, 0.5, 1.0, 1.5)]
    assert seen == [True, True, True, False]  # each scan is used one period later


def test_extra_obstacles_are_rendered_for_one_scan():
    world = long_canal(14.0)
    sim = LidarSimulator(world, seed=9)
    vessel = box(25, 33, -4.0, -1.5, 0, 1.5, kind="boat", name="passing")
    deck = box(50, 54, -30, 30, 3.0, 4.0, kind="bridge", name="temporary bridge")
    with_it = sim.scan_labelled((0.0, 0.0, 0.0), extra_obstacles=[vessel, deck])
    obst = world_points(with_it, (0.0, 0.0, 0.0), OBSTACLE)
    on_vessel = obst[(np.abs(obst[:, 0] - 25.0) < 0.15) & (obst[:, 2] < 1.6)]
    on_deck = obst[obst[:, 2] > 2.9]
    assert len(on_vessel) > 20 and len(on_deck) > 20
    without = sim.scan_labelled((0.0, 0.0, 0.0))
    assert not (without.labels == OBSTACLE).any()  # gone with the next scan
    # Rendered exactly as the world's own obstacles would be.
    own = LidarSimulator(long_canal(14.0, obstacles=(vessel, deck)), QUIET, seed=0)
    extra = LidarSimulator(world, QUIET, seed=0)
    a = own.scan_labelled((1.0, 0.5, 0.1))
    b = extra.scan_labelled((1.0, 0.5, 0.1), extra_obstacles=(vessel, deck))
    assert np.array_equal(a.points, b.points) and np.array_equal(a.labels, b.labels)
    with pytest.raises(InputError, match="extra_obstacles must be Obstacle"):
        sim.scan((0.0, 0.0, 0.0), extra_obstacles=[[[0, 0], [1, 0], [1, 1]]])
    with pytest.raises(InputError, match="time_s must be a finite number"):
        sim.scan((0.0, 0.0, 0.0), time_s=float("nan"))


def test_same_seed_same_scan_with_obstacles_time_and_extras():
    barge = box(15, 30, 2.0, 6.5, 0, 1.2, kind="boat", name="barge", remove_at_s=10.0)
    world = long_canal(obstacles=PIERS + (DECK, barge))
    vessel = box(25, 33, -4.0, -1.5, 0, 1.5, kind="boat", name="passing")

    def scans(seed):
        sim = LidarSimulator(world, seed=seed)
        return [sim.scan_labelled((5.0, 0.5, 0.1), 2.0, time_s=t, extra_obstacles=(vessel,))
                for t in (0.0, 20.0)]

    a, b, c = scans(11), scans(11), scans(12)
    for x, y in zip(a, b):
        assert np.array_equal(x.points, y.points) and np.array_equal(x.labels, y.labels)
    assert not any(x.points.shape == z.points.shape and np.array_equal(x.points, z.points)
                   for x, z in zip(a, c))


def test_nothing_in_range_is_an_empty_float32_cloud():
    """Far from any wall, with no hull in view and no speckle: an empty (0, 3) cloud."""
    cfg = LidarConfig(hull=HullShape(boxes=((-0.1, 0.1, -0.1, 0.1, -20.0, -19.0),)),
                      noise=LidarNoise(water_speckle=0.0, spray_points=0))
    sim = LidarSimulator(long_canal(14.0), cfg, seed=0)
    scan = sim.scan_labelled((0.0, 3000.0, 0.0), 2.0)
    assert scan.points.shape == (0, 3) and scan.points.dtype == np.float32
    assert len(scan.labels) == 0 and len(scan.sensor) == 0


def test_a_direction_with_nothing_in_it_has_no_returns_but_the_water():
    """Out of the canal's open end nothing stands: the bow unit's beams straight ahead go to
    the sky above the horizon and to the water below it."""
    world = long_canal(14.0)
    sim = LidarSimulator(world, QUIET, seed=0)
    t_all, label = first_hits(sim, np.array([395.0, 0.0, 0.0]))
    ahead = sim._beams.bin == 0  # the bow unit's first column: straight ahead
    up = ahead & (sim._beams.tan_el >= 0)
    assert up.sum() > 10 and np.all(np.isinf(t_all[up]))
    down = ahead & (sim._beams.tan_el < 0)
    assert np.all(label[down] == WATER)
    assert np.allclose(t_all[down], 1.3 / -sim._beams.tan_el[down], rtol=1e-5)


# -- the compiled cast and profile kernels against their numpy twins (issue 33) --------------------------
def _random_world(seed):
    """A canal with random walls, piers, moored boats, decks and overhangs, some concave."""
    rng = np.random.default_rng(seed)
    obstacles = []
    for k in range(int(rng.integers(3, 12))):
        x, y = rng.uniform(-60, 60), rng.uniform(-8, 8)
        w, h = rng.uniform(0.5, 8), rng.uniform(0.5, 5)
        floating = rng.uniform() < 0.3
        z0 = rng.uniform(1.0, 3.0) if floating else 0.0
        obstacles.append(box(x, x + w, y, y + h, z0, z0 + rng.uniform(0.3, 3), name=f"b{k}",
                             kind="bridge" if floating else "pier"))
    obstacles.append(Obstacle([[5, 3], [11, 3], [11, 4], [6, 4], [6, 7], [5, 7]], z_top_m=2.0,
                              name="L"))
    return long_canal(width=float(rng.uniform(12, 30)), obstacles=tuple(obstacles),
                      wall_height_m=float(rng.uniform(0.3, 3.0)))


@pytest.mark.parametrize("seed", range(6))
def test_compiled_profile_matches_its_numpy_twin_bit_for_bit(seed):
    """Random worlds and poses (some inside obstacles, some on a vertex's line): every
    beam's first hit and label, and the noisy scans that follow, identical."""
    world = _random_world(seed)
    rng = np.random.default_rng(100 + seed)
    compiled, twin = (LidarSimulator(world, seed=seed, compiled=c) for c in (True, False))
    for _ in range(5):
        pose = np.array([rng.uniform(-70, 70), rng.uniform(-6, 6), rng.uniform(-np.pi, np.pi)])
        a, b = first_hits(compiled, pose), first_hits(twin, pose)
        assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
        sa, sb = compiled.scan_labelled(pose, 2.0), twin.scan_labelled(pose, 2.0)
        assert np.array_equal(sa.points, sb.points) and np.array_equal(sa.labels, sb.labels)


def test_compiled_profile_at_a_vertex_and_under_a_deck_matches_the_twin():
    sim_c = LidarSimulator(long_canal(obstacles=PIERS + (DECK, BOAT_UNDER, OVERHANG)), seed=0)
    sim_n = LidarSimulator(sim_c.world, seed=0, compiled=False)
    for pose in [(41.0, 0.0, 0.0), (38.6, 2.0, 0.3), (41.3, -0.7, 2.9), (15.0, 3.0, -0.2)]:
        a, b = first_hits(sim_c, np.array(pose)), first_hits(sim_n, np.array(pose))
        assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


@pytest.mark.parametrize("seed", range(4))
def test_compiled_cast_matches_its_numpy_twin_bit_for_bit(seed):
    """The 2-D cast's crossings (bin, distance, solid, entering), in the same order: random
    worlds and poses, headings on a bin's ray and vertices on a sensor's line among them,
    with too little room for the crossings at first (the kernel asks for more)."""
    world = _random_world(seed)
    rng = np.random.default_rng(200 + seed)
    compiled, twin = (LidarSimulator(world, seed=seed, compiled=c) for c in (True, False))
    compiled._cast_room = 1
    poses = [np.array([rng.uniform(-70, 70), rng.uniform(-6, 6), rng.uniform(-np.pi, np.pi)])
             for _ in range(6)] + [np.array([5.0, 0.0, 0.0]), np.array([11.0, -5.0, np.pi / 2]),
                                   np.array([0.0, 3.0, compiled._bin_step[0] * 7])]
    for pose in poses:
        for extra in ((), (box(pose[0] + 3, pose[0] + 6, pose[1] - 1, pose[1] + 1),)):
            scene = compiled._scene_at(None, extra)
            origins = compiled.sensor_positions(pose)
            a = compiled._cast(scene, origins, pose[2])
            b = twin._cast(scene, origins, pose[2])
            for x, y in zip(a, b):
                assert x.dtype.kind == y.dtype.kind and np.array_equal(x, y)


def test_compiled_column_order_is_the_stable_argsort_of_bin_and_distance():
    """`lidar_columns` orders crossings as numpy's stable argsort of bin * scale + t: equal
    distances and distances that round to one key keep their order."""
    from scenarios.sensors.lidar import _profile_kernel

    lib = _profile_kernel()
    rng = np.random.default_rng(5)
    n_bins, scale = 300, 256.0
    for n in (0, 1, 50, 4000):
        gbin = rng.integers(0, n_bins, n).astype(np.int64)
        t = rng.uniform(0.0, 130.0, n)
        t[::3] = np.round(t[::3])  # exact ties
        t[1::5] = t[::5][:len(t[1::5])] + rng.uniform(0, 1e-11, len(t[1::5]))  # one key
        owner = np.arange(n, dtype=np.int64)
        enter = rng.integers(0, 2, n).astype(np.uint8)
        first = np.empty(n_bins + 1, np.int64)
        t_out, owner_out, enter_out = np.empty(n), np.empty(n, np.int64), np.empty(n, np.uint8)
        p = lambda x: x.ctypes.data  # noqa: E731
        assert lib.lidar_columns(n, p(gbin), p(t), p(owner), p(enter), n_bins, scale, p(first),
                                 p(t_out), p(owner_out), p(enter_out)) == 0
        order = np.argsort(gbin * scale + t, kind="stable")
        assert np.array_equal(owner_out, order) and np.array_equal(t_out, t[order])
        assert np.array_equal(enter_out, enter[order])
        assert np.array_equal(first[1:], np.cumsum(np.bincount(gbin, minlength=n_bins)))


def test_detect_on_a_simulated_scan_takes_detect_set_and_csv(tmp_path, capsys):
    """Issue 35: on a simulated scan, --detect-set and --csv were silently ignored. A typo or
    a bad value is an error naming it; --csv writes the segments in the boat's frame."""
    png, csv = tmp_path / "d.png", tmp_path / "d.csv"
    assert main(["detect", "--at", "30", "--detect-set", "hough_vots=8", "-o", str(png)]) == 2
    assert "--detect-set 'hough_vots=8'" in capsys.readouterr().err
    assert main(["detect", "--at", "30", "--detect-set", "hough_votes=abc", "-o", str(png)]) == 2
    assert "hough_votes takes a number" in capsys.readouterr().err
    assert main(["detect", "--at", "30", "--detect-set", "hough_votes=8", "--csv", str(csv),
                 "-o", str(png)]) == 0
    rows = csv.read_text().splitlines()
    assert rows[0] == "x_c_m,y_c_m,theta_rad,length_m" and len(rows) > 2
    ys = [abs(float(r.split(",")[1])) for r in rows[1:]]
    assert max(ys) < 60.0  # the boat's frame, near it: not the canal's coordinates
