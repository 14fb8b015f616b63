"""`canalnav bench detection`: accuracy and speed of LiDAR simulation and wall detection.

Scans every `--step` metres along a canal; for each, how much of the wall the sensors can
see within `--radius` is covered by a detected segment (within 0.3 m and 3 deg), how much
detected length lies farther than 1 m from any true surface, and the time the simulator
and the detector take per scan (and the two together: `perception_ms`), after one untimed
warm-up scan. Prints one JSON object.
"""

from __future__ import annotations


def run_benchmark(world, step_m: float = 10.0, radius_m: float = 50.0, seed: int = 0,
                  speed_mps: float = 2.0, offset_m: float = 0.0, lidar_config=None,
                  detection_config=None) -> dict:
    """Scan, detect and score every `step_m` along the centre line; the benchmark's JSON."""
    import time

    import numpy as np

    from controller.perception.detection import DEFAULT, detect_segments

    from ..results.detection_score import (COVER_ANGLE_DEG, COVER_PERP_M, FALSE_FAR_M,
                                           SAMPLED_POINTS, SAMPLED_RADIUS_M, score_scan)
    from ..sensors.lidar import LidarSimulator

    detection_config = detection_config or DEFAULT
    sim = LidarSimulator(world, lidar_config, seed=seed)
    stations = np.arange(0.0, world.length_m + 1e-9, step_m)
    # Warm-up (not timed, own simulator so the scored scans keep their noise): the first
    # call pays one-off costs such as importing OpenCV, which are no part of a scan's time.
    warm_pose = world.pose_at(0.0, offset_m)
    detect_segments(LidarSimulator(world, lidar_config, seed=seed).scan(warm_pose, speed_mps),
                    warm_pose, detection_config)
    sim_s, det_s, n_points, n_segments, scores = [], [], [], [], []
    sim_cpu, det_cpu = [], []
    for s in stations:
        pose = world.pose_at(float(s), offset_m)
        t0, c0 = time.perf_counter(), time.process_time()
        cloud = sim.scan(pose, speed_mps)
        t1, c1 = time.perf_counter(), time.process_time()
        segs = detect_segments(cloud, pose, detection_config)
        t2, c2 = time.perf_counter(), time.process_time()
        sim_s.append(t1 - t0)
        det_s.append(t2 - t1)
        sim_cpu.append(c1 - c0)
        det_cpu.append(c2 - c1)
        n_points.append(len(cloud))
        n_segments.append(len(segs))
        scores.append(score_scan(world, sim, pose, segs, detection_config, radius_m,
                                 cloud=cloud))
    visible = sum(x.visible_m for x in scores)
    sampled = sum(x.sampled_m for x in scores)
    sampled_covered = sum(x.sampled_covered_m for x in scores)
    covered = sum(x.covered_m for x in scores)
    detected = sum(x.detected_m for x in scores)
    false = sum(x.false_m for x in scores)
    worst = int(np.argmin([x.covered_m / x.visible_m if x.visible_m else 1.0 for x in scores]))

    def ms(values):
        v = np.asarray(values) * 1e3
        return {"mean": round(float(v.mean()), 2), "p99": round(float(np.percentile(v, 99)), 2),
                "max": round(float(v.max()), 2)}

    return {
        "scenario": world.name,
        "scans": len(stations),
        "step_m": step_m,
        "radius_m": radius_m,
        "seed": seed,
        "coverage": round(covered / visible, 4) if visible else None,
        "coverage_criterion": {"perpendicular_m": COVER_PERP_M, "angle_deg": COVER_ANGLE_DEG},
        "visible_wall_m": round(visible, 1),
        "covered_wall_m": round(covered, 1),
        "coverage_where_sampled": round(sampled_covered / sampled, 4) if sampled else None,
        "sampled_criterion": {"returns": SAMPLED_POINTS, "within_m": SAMPLED_RADIUS_M},
        "sampled_wall_m": round(sampled, 1),
        "worst_scan": {"at_m": float(stations[worst]),
                       "coverage": round(scores[worst].covered_m / scores[worst].visible_m, 4)
                       if scores[worst].visible_m else None},
        "detected_m": round(detected, 1),
        "false_positive_m": round(false, 2),
        "false_positive_fraction": round(false / detected, 4) if detected else 0.0,
        "false_positive_criterion_m": FALSE_FAR_M,
        "points_per_scan": {"mean": round(float(np.mean(n_points))), "min": int(np.min(n_points)),
                            "max": int(np.max(n_points))},
        "segments_per_scan": {"mean": round(float(np.mean(n_segments)), 1),
                              "max": int(np.max(n_segments))},
        "simulation_ms": ms(sim_s),
        "detection_ms": ms(det_s),
        "perception_ms": ms(np.add(sim_s, det_s)),  # simulation + detection per scan
        "simulation_cpu_ms_mean": round(1e3 * float(np.mean(sim_cpu)), 2),
        "detection_cpu_ms_mean": round(1e3 * float(np.mean(det_cpu)), 2),
        # Peers in the same run: the 100 ms between scans (10 Hz) and control steps.
        "simulation_faster_than_real_time": round(0.1 / float(np.mean(sim_s)), 1),
        "detection_share_of_control_period": round(float(np.mean(det_s)) / 0.1, 3),
    }


def register_bench(sub) -> None:
    p = sub.add_parser(
        "detection", help="LiDAR wall detection: coverage, false positives, time per scan",
        description="Scans a canal (the demo canal by default) every STEP metres with the simulated LiDARs, "
        "detects wall segments, and prints JSON: coverage of the visible wall within RADIUS "
        "(within 0.3 m and 3 deg), detected length farther than 1 m from any true surface, "
        "points and segments per scan, and simulation and detection time per scan.",
    )
    p.add_argument("--scenario", default="demo", metavar="FILE",
                   help="scenario file (TOML) whose canal to scan; 'demo' (default): the "
                   "built-in demo canal")
    p.add_argument("--step", type=float, default=10.0, help="metres between scans (10)")
    p.add_argument("--radius", type=float, default=50.0, help="range scored, metres (50)")
    p.add_argument("--offset", type=float, default=0.0,
                   help="boat's offset from the centre line, metres, starboard positive (0)")
    p.add_argument("--speed", type=float, default=2.0, help="boat speed for wake spray, m/s (2)")
    p.add_argument("--seed", type=int, default=0, help="noise seed (0)")
    p.set_defaults(func=run)


def run(args) -> int:
    import json

    from controller.errors import InputError

    from ..scenario_file import load_world

    if not args.step > 0:
        raise InputError(f"--step must be positive, got {args.step}")
    if not args.radius > 0:
        raise InputError(f"--radius must be positive, got {args.radius}")
    world = load_world(args.scenario)
    print(json.dumps(run_benchmark(world, args.step, args.radius, args.seed, args.speed,
                                   args.offset)))
    return 0
