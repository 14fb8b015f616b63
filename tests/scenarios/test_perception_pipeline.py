"""LiDAR perception one control period behind, in this process or in a worker process."""

import math

import numpy as np
import pytest

from controller.errors import InputError
from scenarios.sensors.perception import LidarPerception
from scenarios.sensors.perception_pipeline import DelayedLidarPerception, PerceptionWorkerError
from scenarios.world.canal import CanalWorld


@pytest.fixture(scope="module")
def world():
    centre = np.column_stack([np.linspace(-150, 150, 151), np.zeros(151)])
    return CanalWorld.from_centre_line(centre, 14.0, wall_height_m=1.5)


def poses(n=6):
    """A boat going down the canal, 0.2 m and a little heading per step, with a small
    estimate error (so the true and estimated poses differ, as in the loop)."""
    out = []
    for k in range(n):
        true = np.array([0.2 * k, 0.5, math.radians(2.0 * k), 2.0, 0.0, 0.0])
        est = true[:3] + (0.05, -0.03, 0.002)
        out.append((0.1 * k, true, est))
    return out


def test_segments_are_those_of_the_previous_scan(world):
    direct = LidarPerception(world, seed=4)
    delayed = DelayedLidarPerception(world, seed=4, parallel=False)
    steps = poses()
    expected = [direct.segments(*steps[0])]  # the first step waits for its own scan ...
    expected += [direct.segments(*s) for s in steps[:-1]]  # ... then one period behind
    got = [delayed.segments(*s) for s in steps]
    assert len(got[0]) >= 2  # both walls seen
    for e, g in zip(expected, got):
        np.testing.assert_array_equal(e, g)
    assert not np.array_equal(got[1], got[-1])  # the scans do move with the boat
    assert len(delayed.points_per_scan) == len(steps)
    assert delayed.time_s["lidar_scan"] > 0 and delayed.time_s["detection"] > 0


def test_worker_process_gives_the_same_segments_bit_for_bit(world):
    serial = DelayedLidarPerception(world, seed=9, parallel=False)
    with DelayedLidarPerception(world, seed=9, parallel=True) as parallel:
        for step in poses():
            np.testing.assert_array_equal(serial.segments(*step), parallel.segments(*step))
        assert parallel.points_per_scan == serial.points_per_scan
        proc = parallel._worker._proc
    assert proc.poll() is not None  # closed: the worker has exited


def test_an_error_in_the_worker_reaches_the_caller_with_its_message(world):
    with DelayedLidarPerception(world, seed=1, parallel=True) as p:
        t, true, est = poses(1)[0]
        p.segments(t, true, est)
        p.segments(t, true, [np.nan, 0.0, 0.0])  # this scan is detected at the next call
        with pytest.raises(InputError, match="pose must be three finite numbers") as info:
            p.segments(t, true, est)
        assert "perception worker" in "".join(getattr(info.value, "__notes__", []))


def test_a_dead_worker_is_reported_not_waited_for(world):
    with DelayedLidarPerception(world, seed=1, parallel=True) as p:
        step = poses(1)[0]
        p.segments(*step)
        p._worker._proc.kill()
        p._worker._proc.wait()
        with pytest.raises(PerceptionWorkerError, match="stopped answering"):
            p.segments(*step)


def test_a_run_gives_the_same_files_with_the_worker_or_without(tmp_path):
    from dataclasses import replace
    from pathlib import Path

    from scenarios.loop.runner import run_scenario
    from scenarios.scenario_file import load_scenario

    root = Path(__file__).resolve().parents[2]
    scenario = replace(load_scenario(root / "scenarios" / "straight.toml"), duration_s=15.0)
    assert scenario.perception == "lidar"
    runs = {}
    for parallel in (False, True):
        out = tmp_path / str(parallel)
        result = run_scenario(scenario, out, plots=False, parallel_perception=parallel)
        assert result.timing["perception"]["parallel"] is parallel
        assert result.timing["perception"]["scans"] == result.summary["steps"]
        runs[parallel] = [(out / f).read_bytes() for f in ("summary.json", "segments.csv")]
        runs[parallel].append(_without_column((out / "log.csv").read_text(), "solve_ms"))
    assert runs[False] == runs[True]


def _without_column(csv_text: str, name: str) -> list:
    """The rows of a CSV text without one column (a wall-clock figure)."""
    rows = [line.split(",") for line in csv_text.splitlines()]
    k = rows[0].index(name)
    return [row[:k] + row[k + 1:] for row in rows]


def test_bench_loop_prints_both_modes_and_their_ratio(capsys):
    import json
    from pathlib import Path

    from bridge.main import main

    straight = Path(__file__).resolve().parents[2] / "scenarios" / "straight.toml"
    assert main(["bench", "loop", str(straight), "--duration", "3"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["steps"] == 30 and report["same_summary"] is True
    for mode in ("worker", "serial"):
        assert report[mode]["real_time_factor"] > 0
        assert set(report[mode]["loop_ms_per_step"]) >= {"plant", "navigation", "perception",
                                                         "controller"}
        assert report[mode]["lidar_ms_per_step"]["lidar_scan"] > 0
        assert report[mode]["cpu_s"] > 0 and report[mode]["cpu_real_time_factor"] > 0
    assert report["serial_over_worker_wall"] > 0


def test_the_scenarios_lidar_noise_reaches_the_simulator(tmp_path):
    """[sensors.lidar] dropout = 0.5 loses about half the returns of the default 0.03."""
    from scenarios.loop.runner import make_perception
    from scenarios.scenario_file import parse_scenario

    text = """
[scenario]
duration_s = 10
[canal]
centre_line = [[0, 0], [200, 0]]
width_m = 14
[route]
waypoints = [[10, 0], [190, 0]]
[sensors]
perception = "lidar"
{extra}
"""
    counts = []
    for extra in ("", "[sensors.lidar]\ndropout = 0.5"):
        scenario = parse_scenario(text.format(extra=extra), "noise.toml")
        perception = make_perception(scenario, parallel=False)
        perception.segments(0.0, np.array([20.0, 0, 0, 2.0, 0, 0]), np.array([20.0, 0, 0]))
        counts.append(perception.points_per_scan[-1])
    assert 0.4 < counts[1] / counts[0] * 0.97 < 0.6


def test_going_astern_the_wall_behind_is_detected_not_cropped_as_wake():
    """Ahead, the box behind the stern is the wake's (spray, foam) and is cropped; astern it
    is where the boat goes: a quay end 8 m astern across the canal must become a segment."""
    from scenarios.world.canal import Obstacle

    quay = Obstacle([[-13.0, -8.0], [-12.0, -8.0], [-12.0, 8.0], [-13.0, 8.0]], z_top_m=1.5,
                    name="quay end")
    centre = np.column_stack([np.linspace(-60, 150, 106), np.zeros(106)])
    canal = CanalWorld.from_centre_line(centre, 20.0, obstacles=(quay,))

    def astern_segments(u):
        p = LidarPerception(canal, seed=1, tracking=False)
        state = np.array([0.0, 0.0, 0.0, u, 0.0, 0.0])
        segs = p.segments(0.0, state, state)
        mid = segs[:, :2] if segs is not None else np.zeros((0, 2))
        return np.count_nonzero((np.abs(mid[:, 0] + 12.5) < 1.5) & (np.abs(mid[:, 1]) < 4.0))

    assert astern_segments(2.0) == 0  # ahead: cropped with the wake
    assert astern_segments(-0.5) >= 1  # astern: seen


def test_a_run_gets_a_perception_worker_by_default_only_with_a_core_to_spare(monkeypatch):
    from scenarios.sensors import perception_pipeline as pp

    monkeypatch.setattr(pp.os, "cpu_count", lambda: 4)
    monkeypatch.delenv(pp.WORKER_ENV, raising=False)
    assert pp.spare_core()
    monkeypatch.setenv(pp.WORKER_ENV, "0")  # several runs side by side
    assert not pp.spare_core()
    monkeypatch.setenv(pp.WORKER_ENV, "1")
    assert pp.spare_core()
    monkeypatch.setattr(pp.os, "cpu_count", lambda: 1)
    assert not pp.spare_core()
