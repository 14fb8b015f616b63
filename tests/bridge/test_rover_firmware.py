"""What the real ArduPilot Rover firmware does that a naive bridge misses (issue 19), on the
simulated autopilot that now boots and behaves like it, in lock-step on a virtual clock:

1. parameters read during start-up are not the ones that apply (dead zones set late);
2. the EKF origin is wherever the first GPS fix came, not the scenario's (0, 0);
3. messages must be stamped when they arrive, and the state aged by the autopilot's clock;
4. the throttle input is truncated to whole percent.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from bridge.onboard.loop import BridgeOptions
from scenarios.scenario_file import load_scenario

ROOT = Path(__file__).resolve().parents[2]
ORIGIN = (52.0, 4.0, 0.0)


@pytest.fixture(scope="module")
def straight():
    """straight.toml (starts 2 m off the centre line at 1 m/s), placed on the Earth."""
    s = load_scenario(ROOT / "scenarios" / "straight.toml")
    return replace(s, geodetic_origin=ORIGIN)


@pytest.fixture
def rig(straight, sim_rig):
    """Simulated autopilot <- (relay) -> bridge link (tests/bridge/rigs.py), booting as Rover
    does (3 s) with its first GPS fix at 5 s."""

    def make(scenario=straight, *, seed=4, init_s=3.0, ekf_delay_s=5.0, **kwargs):
        return sim_rig(scenario, seed=seed, init_s=init_s, ekf_delay_s=ekf_delay_s, **kwargs)

    return make


def command(r, nT, nS, seconds=0.3):
    """Send (nT, nS) every 0.1 s for `seconds`; the autopilot's outputs at the end."""
    for _ in range(int(round(seconds / 0.1))):
        r.link.send_commands(nT, nS)
        r.link.wait_until(lambda: False, 0.1)
    return r.autopilot.outputs


# -- 2. the frame is the world's ---------------------------------------------------------------
def test_positions_are_the_worlds_whatever_the_ekf_origin(rig, straight):
    """The boat moves (1 m/s) before its first fix at 5 s: the EKF origin is ~5 m along the
    canal. Placed on the Earth through the geodetic origin, the bridge's state is the truth;
    without an origin it refuses, saying how to give one."""
    from bridge.shared.ardupilot import SITL_DEFAULT_HOME
    from controller.errors import InputError

    no_origin = replace(straight, geodetic_origin=None)  # the simulator puts it at SITL's home
    r = rig(scenario=no_origin)
    with pytest.raises(InputError, match=r"no geodetic origin.*\[origin\].*--origin=LAT,LON"):
        r.prepare()
    r.prepare(origin=SITL_DEFAULT_HOME)
    north, east = r.autopilot.ekf_origin_ne
    assert north > 3.0 and abs(east - 2.0) < 0.7  # where the boat was at the fix
    assert "EKF origin" in r.console.getvalue()
    for _ in range(3):
        r.link.wait_until(lambda: False, 1.0)
        x, y = r.link.state.x, r.link.state.y
        truth = r.autopilot.true_state
        assert abs(x - truth[0]) < 0.8 and abs(y - truth[1]) < 0.8, (x, y, truth[:2])
    # LOCAL_POSITION_NED alone (no GLOBAL_POSITION_INT) is converted with GPS_GLOBAL_ORIGIN
    assert r.link.request_streams(20, messages=("GLOBAL_POSITION_INT",)) == {
        "GLOBAL_POSITION_INT": 0}
    r.link.command_long(511, 33, -1)  # GLOBAL_POSITION_INT off
    r.link.wait_until(lambda: False, 3.0)
    assert r.link.position_source == "LOCAL_POSITION_NED"
    x, y = r.link.state.x, r.link.state.y
    truth = r.autopilot.true_state
    assert abs(x - truth[0]) < 0.8 and abs(y - truth[1]) < 0.8, (x, y, truth[:2])


# -- 3. message times -----------------------------------------------------------------------
def test_link_delay_and_state_age_are_measured_over_a_slow_lossy_link(rig, tmp_path):
    """150 ms each way and 5 % loss: the delay reported is within 20 ms of 150, and each
    step's state age is the real one (the step's time less the autopilot time its state
    describes), not the time since the loop last read the link."""
    r = rig(latency_s=0.15, loss=0.05)
    result, rows, _ = run_loop(r, tmp_path, Constant((20.0, 0.0)), duration_s=20.0)
    assert result.reason == "time limit", result
    steps = [row for row in rows if row["x_m"]][20:]
    delays = np.array([float(row["link_delay_s"]) for row in steps])
    assert np.all(np.abs(delays - 0.150) <= 0.020), (delays.min(), delays.max())
    t0 = r.loop._t0
    ages = np.array([float(row["state_age_s"]) for row in steps])
    real = np.array([t0 + float(row["time_s"]) - r.autopilot.boot_to_clock(float(row["ekf_time_s"]))
                     for row in steps])
    assert np.all(np.abs(ages - real) <= 0.015), np.abs(ages - real).max()
    assert 0.15 <= real.mean() <= 0.25  # 150 ms of link and up to 50 ms between messages
    # the prediction is carried over that age and the command's own trip
    for row in steps[::25]:
        dt = float(row["state_age_s"]) + float(row["link_delay_s"])
        moved = np.hypot(float(row["pred_x_m"]) - float(row["x_m"]),
                         float(row["pred_y_m"]) - float(row["y_m"]))
        speed = np.hypot(float(row["u_mps"]), float(row["v_mps"]))
        assert moved == pytest.approx(speed * dt, rel=0.02, abs=1e-3)


# -- 4. throttle in whole percent ---------------------------------------------------------------
def test_throttle_reaches_the_autopilot_as_the_whole_percent_meant(rig):
    """Rover truncates its throttle input to whole percent: each command arrives as the
    nearest whole percent (the identification levels included), never a point low."""
    r = rig()
    r.prepare()
    for nT in (31.0, 34.9, 38.6, 41.0, 50.6, 39.4, 20.0, 42.0, 7.5, 0.7, -12.3, -99.6):
        out_nT, _ = command(r, nT, 0.0, seconds=0.2)
        meant = float(np.sign(nT) * np.floor(abs(nT) + 0.5))
        assert out_nT == meant, (nT, out_nT)


# -- 1. parameters after start-up ------------------------------------------------------------
def test_rc_parameters_are_read_after_start_up_so_small_steering_moves_the_rudder(rig):
    r = rig()
    r.prepare()
    steer = r.link.rc_mapping.steering
    assert steer.dz == 30, "read before Rover's start-up set the dead zone"
    assert r.autopilot.initialised
    # a 2 % correction either way reaches the autopilot (it is within trim +- 30 us if the
    # dead zone is not known: 2 % of 400 us is 8 us)
    for nS in (2.0, -2.0):
        nT_out, nS_out = command(r, 20.0, nS)
        assert nS_out == pytest.approx(nS, abs=0.3), (nS, nS_out)
    assert command(r, 20.0, 100.0)[1] == pytest.approx(100.0)  # the largest stays at the end


class Constant:
    """A controller that always asks for the same command."""

    name = "constant"

    def __init__(self, command):
        self.command = np.asarray(command, float)

    def step(self, time_s, state, actuators, segments):
        from scenarios.loop.closed_loop import Decision

        return Decision(command=self.command.copy())


class NoLidar:
    def scan(self, time_s, pose):
        return None


def run_loop(r, tmp_path, controller, at_steps=None, **options):
    """The onboard loop on the rig; `at_steps` = {step: action(rig)} applied as it runs."""
    from bridge.onboard.loop import OnboardLoop
    from bridge.onboard.step_log import StepLog

    log = StepLog(tmp_path)
    options = {"mode": "MANUAL", "arm": True, "ekf_timeout_s": 30.0, "duration_s": 8.0, **options}
    loop = OnboardLoop(r.link, r.scenario, controller, NoLidar(), BridgeOptions(**options),
                       console=r.console, log=log)
    pending = dict(at_steps or {})
    outputs = []

    def script(now):
        for k in [k for k in pending if loop.steps >= k]:
            pending.pop(k)(r)
        outputs.append((loop.steps, r.autopilot.outputs))

    r.clock.add_peer(script)
    try:
        result = loop.run()
    finally:
        log.close()
    import csv

    with (tmp_path / "steps.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    r.loop = loop
    return result, rows, outputs


def test_a_parameter_changed_during_the_run_is_applied_and_logged(rig, tmp_path):
    r = rig()
    result, rows, outputs = run_loop(
        r, tmp_path, Constant((20.0, 5.0)),
        at_steps={20: lambda r: r.autopilot.set_param("RC1_DZ", 60),
                  40: lambda r: r.autopilot.set_param("RC1_REVERSED", 1)})
    assert result.reason == "time limit" and not result.failsafes
    events = [row["status"] for row in rows if not row["x_m"]]
    assert any(e.startswith("parameter RC1_DZ changed from 30 to 60: RC mapping updated")
               and "dead zone 60" in e for e in events), events
    assert any(e.startswith("parameter RC1_REVERSED changed from 0 to 1") and "reversed" in e
               for e in events), events
    pwm = [int(row["steering_pwm_us"]) for row in rows if row["x_m"]]
    assert pwm[5] < 1500 - 30 and pwm[30] < 1500 - 60 < pwm[5]  # port turn: below trim
    assert pwm[-1] > 1500 + 60  # reversed: the same port turn is above trim
    # the autopilot read 5 % to port throughout (apart from the step each change took)
    read = [nS for k, (nT, nS) in outputs if 10 <= k <= 75 and k not in range(19, 23)
            and k not in range(39, 43)]
    assert read and all(abs(nS - 5.0) < 0.5 for nS in read), sorted(set(read))
    assert "bridge: parameter RC1_DZ changed from 30 to 60" in r.console.getvalue()


def test_a_parameter_change_that_makes_the_autopilot_ignore_us_fails_safe(rig, tmp_path):
    r = rig()
    result, rows, _ = run_loop(r, tmp_path, Constant((20.0, 0.0)),
                               at_steps={10: lambda r: r.autopilot.set_param("RC_OPTIONS", 2)})
    assert result.failsafes and result.failsafes[0].startswith(
        "parameter change: RC_OPTIONS = 2 has bit 1"), result
    assert rows[-1]["status"].startswith("FAILSAFE parameter change")
