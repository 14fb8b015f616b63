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
from scenarios.sensors.lidar import (BACKDROP, FACE, GROUND, HULL, OBSTACLE, SPRAY, WATER, LidarConfig,
                             LidarMount, LidarNoise, LidarSimulator, default_mounts)
from scenarios.world.canal import CanalWorld, Obstacle


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


def test_beam_classes_match_per_beam_comparisons():
    """The run-based classes equal (tan >= t1) + (tan > t2) + (tan >= t3) + (tan > t4) per
    beam, ties and infinities included."""
    sim = LidarSimulator(straight(), seed=0)
    beams = sim._beams
    n_bins = len(sim._bin_height)
    rng = np.random.default_rng(1)
    # Thresholds drawn from the beams' own tans (exact ties), random values, +-inf and -0.
    pool = np.concatenate([beams.tan_el, rng.uniform(-0.7, 0.7, 1000).astype(np.float32),
                           np.float32([np.inf, -np.inf, -0.0, 0.0])])
    t = np.sort(rng.choice(pool, (4, n_bins)), axis=0).astype(float)
    t[2, ::5] = t[1, ::5]  # t2 == t3: a beam at the tie counts twice
    cls, runs = sim._classes(*t)
    tan, b = beams.tan_el, beams.bin
    t32 = t.astype(np.float32)
    expect = ((tan >= t32[0][b]).astype(int) + (tan > t32[1][b]) + (tan >= t32[2][b])
              + (tan > t32[3][b]))
    assert np.array_equal(cls, expect)
    assert runs.sum() == len(tan)


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
