"""controller.identification.dataflash and log_runs: a boat's own ArduPilot log (.BIN) as
identification data; logs written here with the simulated autopilot's DataFlash writer."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from bridge.autopilot_sim.dataflash import DataFlashWriter
from controller.errors import InputError
from controller.geodetic import ned_to_geodetic
from controller.identification.dataflash import read_dataflash
from controller.identification.log_runs import Window, cut_windows, find_runs
from controller.identification.maneuvers import QUICK_RUNS, SensorNoise, simulate_run
from controller.pwm import CommandChannels

ORIGIN = (52.0, 4.0, 0.0)
SERVO = {"SERVO1_FUNCTION": 26.0, "SERVO3_FUNCTION": 70.0, "SERVO1_MIN": 1000.0,
         "SERVO1_MAX": 2000.0, "SERVO1_TRIM": 1500.0, "SERVO1_REVERSED": 1.0,
         "SERVO3_MIN": 1000.0, "SERVO3_MAX": 2000.0, "SERVO3_TRIM": 1500.0,  # 5 us a %
         "SERVO3_REVERSED": 0.0, "RCMAP_ROLL": 1.0, "RCMAP_THROTTLE": 3.0}


@pytest.fixture(scope="module")
def trajectory():
    """The quick runs one after the other, exact states at 10 Hz (x, y continuous)."""
    none = SensorNoise(0.0, 0.0, 0.0, 0.0)
    t, states, commands, offset, xy = [], [], [], 0.0, np.zeros(2)
    for k, run in enumerate(QUICK_RUNS):
        log = simulate_run(run, noise=none, run_index=k)
        s = log.states.copy()
        s[:, :2] += xy - s[0, :2]
        t.append(log.time_s + offset)
        states.append(s)
        commands.append(log.commands)
        offset = t[-1][-1] + 0.1
        xy = s[-1, :2] + 1.0
    return np.concatenate(t), np.vstack(states), np.vstack(commands)


def write_log(path, trajectory, drop=(), params=SERVO, xkf_cores=1):
    """A DataFlash log of `trajectory` as ArduPilot writes one (minus the `drop`ped types)."""
    t, states, commands = trajectory
    w = DataFlashWriter(path)
    for name, value in params.items():
        w.write("PARM", 0, name, value, value)
    w.write("MODE", 0, 0, 0, 1)
    w.write("ARM", 0, 1, 0, 0, 0)
    servos = CommandChannels.from_servo_params(SERVO)  # what the outputs carry
    rc = CommandChannels.from_rc_params(SERVO)
    for ti, s, c in zip(t, states, commands):
        us = int(round(ti * 1e6)) + 1_000_000  # one second after boot
        x, y, psi, u, v, r = s
        vn, ve = u * math.cos(psi) - v * math.sin(psi), u * math.sin(psi) + v * math.cos(psi)
        yaw = math.degrees(psi) % 360
        lat, lon = ned_to_geodetic(x, y, ORIGIN)
        if "XKF1" not in drop:
            for core in range(xkf_cores):
                w.write("XKF1", us, core, 0, 0, yaw, vn, ve, 0, 0, x, y, 0, 0, 0, 0, 0)
        if "ATT" not in drop:
            w.write("ATT", us, 0, 0, 0, 0, yaw, yaw, 0, 0, 3)
        if "POS" not in drop:
            w.write("POS", us, lat, lon, 0, 0, 0)
        if "GPS" not in drop:
            crs = math.degrees(math.atan2(ve, vn)) % 360
            w.write("GPS", us, 0, 3, 0, 0, 12, 0.8, lat, lon, 0, math.hypot(vn, ve), crs, 0, 0, 1)
        if "IMU" not in drop:
            w.write("IMU", us, 0, 0, 0, r, 0, 0, -9.8, 0, 0, 25, 1, 1, 1000, 1000)
        for kind, ch in (("RCOU", servos), ("RCIN", rc)):
            if kind not in drop:
                pwm = ch.to_pwm(*c)
                w.write(kind, us, *[pwm.get(n, 0) for n in range(1, 15)])
    w.close()
    return path


def test_state_and_commands_come_back_from_the_log(tmp_path, trajectory):
    t, states, commands = trajectory
    log = read_dataflash(write_log(tmp_path / "a.BIN", trajectory, xkf_cores=2))
    assert log.sources == {"position": "XKF1.PN/PE (core 0)", "velocity": "XKF1.VN/VE",
                           "heading": "XKF1.Yaw", "yaw rate": "IMU.GyrZ - XKF1.GZ",
                           "commands": "RCOU with SERVOn_* (PARM)"}
    assert any("2 EKF cores logged, core 0 used" in n for n in log.notes)
    assert log.n_samples == len(t) and log.time_s[0] == pytest.approx(1.0)
    got = log.states[:-1]
    want = states[:-1]
    assert np.abs(got[:, :2] - want[:, :2]).max() < 1e-3
    assert np.abs(np.angle(np.exp(1j * (got[:, 2] - want[:, 2])))).max() < math.radians(0.02)
    assert np.abs(got[:, 3:5] - want[:, 3:5]).max() < 5e-4  # VN, VE turned by the 0.01 deg yaw
    assert np.abs(got[:, 5] - want[:, 5]).max() < 1e-6
    # commands through 1 us servo steps (0.2 % on 1000-2000 us)
    assert np.abs(log.commands[:-1] - commands[:-1]).max() <= 0.2 + 1e-9
    assert log.armed.all() and (log.mode == 0).all()


def test_fallbacks_when_messages_are_missing(tmp_path, trajectory):
    t, states, commands = trajectory
    path = write_log(tmp_path / "b.BIN", trajectory, drop=("XKF1", "IMU", "RCOU", "POS"))
    log = read_dataflash(path)
    assert log.sources["position"] == "GPS.Lat/Lng (around its first point)"
    assert log.sources["velocity"] == "GPS.Spd/GCrs"
    assert log.sources["heading"] == "ATT.Yaw"
    assert log.sources["yaw rate"] == "heading differentiated"
    assert log.sources["commands"] == "RCIN with RCMAP_*/RCn_* (PARM), MANUAL"
    want_xy = states[:, :2] - states[0, :2]
    assert np.abs(log.states[:-1, :2] - want_xy[:-1]).max() < 0.05
    err = np.abs(log.states[:, 5] - states[:, 5])  # (the runs' headings jump where they meet)
    assert np.percentile(err, 99) < math.radians(0.3)
    assert np.nanmax(np.abs(log.commands[:-1, 0] - commands[:-1, 0])) <= 0.5  # RCIN: whole %
    path = write_log(tmp_path / "c.BIN", trajectory, drop=("XKF1", "GPS", "IMU", "RCOU"))
    log = read_dataflash(path)
    assert log.sources["velocity"] == "position differentiated"
    assert any("velocity differentiated from the position" in n for n in log.notes)


def test_what_is_missing_is_named(tmp_path, trajectory):
    short = (trajectory[0][:50], trajectory[1][:50], trajectory[2][:50])
    path = write_log(tmp_path / "d.BIN", short, drop=("XKF1", "POS", "GPS"))
    with pytest.raises(InputError, match=r"d\.BIN: no position: tried XKF1 \(no records\), "
                                         r"POS \(no records\), GPS \(no records\)"):
        read_dataflash(path)
    path = write_log(tmp_path / "e.BIN", short, drop=("RCOU", "RCIN"))
    with pytest.raises(InputError, match=r"e\.BIN: no commands: tried RCOU \(no records\), "
                                         r"RCIN \(no records\).*SERVOn_FUNCTION"):
        read_dataflash(path)
    no_function = {k: v for k, v in SERVO.items() if k != "SERVO1_FUNCTION"}
    path = write_log(tmp_path / "f.BIN", short, drop=("RCIN",), params={**no_function,
                                                                       "SERVO1_FUNCTION": 0.0})
    with pytest.raises(InputError, match=r"RCOU \(no servo output has SERVOn_FUNCTION = 26 "
                                         r"\(steering\)"):
        read_dataflash(path, sample_s=0.1)
    csv = tmp_path / "g.BIN"
    csv.write_text("time [s],u [m/s]\n")
    with pytest.raises(InputError, match="not an ArduPilot DataFlash log"):
        read_dataflash(csv)


def test_runs_are_found_in_a_long_log_or_cut_by_window(tmp_path, trajectory):
    log = read_dataflash(write_log(tmp_path / "h.BIN", trajectory))
    runs = find_runs(log)
    kinds = [r.meta["maneuver"] for r in runs]
    # the acceleration and deceleration staircases meet without a turn: one straight run
    assert kinds == ["surge", "zigzag", "zigzag"], [r.meta for r in runs]
    surge, zig, held = runs
    assert np.abs(surge.commands[:, 1]).max() <= 1.0 and zig.maneuver == "sway-yaw"
    assert surge.time_s[0] == pytest.approx(1.0) and surge.n_samples > 1300
    n_acc = len(simulate_run(QUICK_RUNS[0], noise=SensorNoise(0, 0, 0, 0)).time_s)
    first = dataclasses.replace(log, time_s=log.time_s[:n_acc], states=log.states[:n_acc],
                                commands=log.commands[:n_acc], mode=log.mode[:n_acc],
                                armed=log.armed[:n_acc])
    assert [r.meta["maneuver"] for r in find_runs(first)] == ["acceleration"]
    assert np.ptp(zig.commands[:, 0]) <= 0.25 and np.abs(zig.commands[:, 1]).max() > 49
    assert zig.meta["window"] == f"{zig.time_s[0]:.1f}:{zig.time_s[-1]:.1f}"
    # a window by hand: its kind from the content
    t0, t1 = zig.time_s[0], zig.time_s[-1]
    (cut,) = cut_windows(log, [Window.parse(f"{t0}:{t1}", "heldout")])
    assert cut.maneuver == "sway-yaw" and cut.heldout and cut.n_samples == zig.n_samples
    # a window ending where the next manoeuvre's steering begins is still a surge run: its
    # last sample's command is the one after it, never applied within the window
    k = int(np.flatnonzero(np.abs(log.commands[:, 1]) > 1.0)[0])
    (edge,) = cut_windows(log, [Window(surge.time_s[0], float(log.time_s[k]))])
    assert edge.maneuver == "surge" and abs(edge.commands[-1, 1]) > 1.0
    with pytest.raises(InputError, match=r"window 10000:20000 s holds no samples \(the log runs"):
        cut_windows(log, [Window(1e4, 2e4)])
    with pytest.raises(InputError, match="expected T0:T1"):
        Window.parse("12-30")


def test_a_gap_in_a_zigzag_and_braking_before_a_staircase(tmp_path, trajectory):
    """Nothing logged for 1.5 s inside the first zigzag (a stalled logger), reverse thrust on
    the straight before the staircase: the zigzag is still found (not measured over the gap)
    and the surge run holds no reverse thrust."""
    t, states, commands = trajectory
    zig0 = find_runs(read_dataflash(write_log(tmp_path / "a.BIN", trajectory)))[1]
    gap0 = 0.5 * (zig0.time_s[0] + zig0.time_s[-1]) - 1.0  # trajectory time = log time - 1 s
    keep = (t < gap0) | (t > gap0 + 1.5)
    cmds = commands.copy()
    cmds[(t > 2.0) & (t < 6.0), 0] = -20.0  # braking, then the staircase from rest
    log = read_dataflash(write_log(tmp_path / "b.BIN", (t[keep], states[keep], cmds[keep])))
    runs = find_runs(log)
    assert [r.meta["maneuver"] for r in runs] == ["surge", "zigzag", "zigzag"]
    surge, zig, _ = runs
    # from where the reverse thrust ends (log time 7 s): braking straight ahead needs no
    # settling, only a turn does
    assert surge.commands[:, 0].min() >= 0.0 and surge.time_s[0] == pytest.approx(7.0, abs=0.11)
    assert zig.time_s[0] == pytest.approx(zig0.time_s[0]) and zig.n_samples == zig0.n_samples
    missing = ~np.isfinite(zig.states[:, 0])
    assert 10 <= missing.sum() <= 16  # the gap, not measured


def test_sysid_reads_a_bin_log_from_the_command_line(tmp_path, trajectory, capsys):
    """`canalnav sysid LOG.BIN --window ...`: the surge stage from the boat's own log."""
    from bridge.main import main
    from controller.params import IDENTIFIED

    path = write_log(tmp_path / "i.BIN", trajectory)
    truth = tmp_path / "truth.toml"
    IDENTIFIED.save_toml(truth)
    t_end = float(trajectory[0][len(simulate_run(QUICK_RUNS[0], noise=SensorNoise(0, 0, 0, 0)).time_s) - 1])
    code = main(["sysid", str(path), "--window", f"0:{t_end + 1.0:.1f}", "--truth", str(truth)])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "position from XKF1.PN/PE (core 0)" in out and "commands from RCOU" in out
    assert "fit: surge selected in" in out
    rows = {line.split()[0]: line for line in out.splitlines() if line[:3] in ("Xu ", "Xuu", "c  ")}
    for name in ("Xu", "Xuu", "c"):
        ratio = float(rows[name].split("%")[0].split()[-1])
        assert abs(ratio) < 1.0, rows[name]  # exact data: the truth, up to the servo's 1 us
    assert "no sway-yaw run among the logs" in out
    assert main(["sysid", str(path), "--window", "5:2"]) == 2
    assert "need T0 < T1" in capsys.readouterr().err


def test_a_truncated_log_says_so(tmp_path, trajectory):
    """Issue 35: a .BIN cut short (mid-record) was read with no word of it."""
    whole = write_log(tmp_path / "whole.BIN", trajectory)
    data = whole.read_bytes()
    cut = tmp_path / "cut.BIN"
    cut.write_bytes(data[: 2 * len(data) // 3 + 7])
    assert not any("cut short" in n for n in read_dataflash(whole).notes)
    notes = read_dataflash(cut).notes
    assert any("ends in the middle of a record" in n and "cut short" in n for n in notes)
