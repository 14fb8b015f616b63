"""Shared for the LiDAR tests: simulated canal sweeps of a level VLP-16 at the bow, and how
close two sets of detected segments are."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bridge.lidar import velodyne_packets as vp
from scenarios.scenario_file import load_scenario
from scenarios.sensors.lidar import LidarConfig, LidarNoise, LidarSimulator

ROOT = Path(__file__).resolve().parents[2]
BOW = (3.5, 0.0, 1.3)  # x, y (m, body) and height above the water of the unit
# the unit upright at the bow: sensor frame x forward, y left, z up
BOW_MOUNT = (3.5, 0.0, -1.3, np.pi, 0.0, 0.0)
QUIET = LidarNoise(range_sigma_m=0.0, dropout=0.0, water_speckle=0.0, spray_points=0)


def simulator(scenario=None, seed=1, noise=QUIET):
    scenario = scenario or load_scenario(ROOT / "scenarios" / "sbend.toml")
    mounts = vp.simulator_mounts("front", *BOW)
    return LidarSimulator(scenario.world, LidarConfig(mounts=mounts, noise=noise), seed=seed)


def sweep_ros(sim, pose) -> np.ndarray:
    """One sweep in the unit's own frame (x forward, y left, z up), own hull left out."""
    scan = sim.scan_labelled(pose)
    keep = scan.labels != 5  # HULL
    return vp.body_to_sensor_ros(np.asarray(scan.points, float)[keep], *BOW)


def segment_gap_m(a, b, step_m: float = 0.5) -> float:
    """How far the walls of `a` lie from those of `b`: each segment of `a` sampled every
    `step_m`, the mean distance of its samples to the nearest segment of `b`; the largest
    over the segments of `a` (a wall cut into other pieces, or a shorter one, still matches)."""
    from controller.geometry import point_segment_distance, segments_to_endpoints

    pa, qa = segments_to_endpoints(np.asarray(a, float).reshape(-1, 4))
    pb, qb = segments_to_endpoints(np.asarray(b, float).reshape(-1, 4))
    worst = 0.0
    for p, q in zip(pa, qa):
        n = max(2, int(np.linalg.norm(q - p) / step_m) + 1)
        samples = p + np.linspace(0, 1, n)[:, None] * (q - p)
        gaps = [float(point_segment_distance(x, pb, qb).min()) for x in samples]
        worst = max(worst, float(np.mean(gaps)))
    return worst
