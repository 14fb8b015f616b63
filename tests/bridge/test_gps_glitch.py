"""A GPS glitch the autopilot's EKF takes in (issue 37): its position jumps several metres
and back. The bridge counts and says each jump, and with the LiDAR the boat stays clear of
the walls (they are seen from the boat, so they move with the estimate) and reaches the
goal."""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
import pytest

from bridge.autopilot_sim.ekf import EkfModel, NoiseSpec
from bridge.commands.autopilot_sim import parse_gps_glitches
from bridge.lidar import SimLidarSource
from bridge.onboard.loop import BridgeOptions, OnboardLoop
from bridge.onboard.step_log import StepLog
from bridge.shared.ardupilot import SITL_DEFAULT_HOME
from controller.errors import InputError
from scenarios.loop.controllers import NmpcController
from scenarios.results.metrics import Clearance
from scenarios.scenario_file import load_scenario

from .rigs import SimRig

ROOT = Path(__file__).resolve().parents[2]


def test_a_glitch_moves_the_position_and_nothing_else():
    plain = EkfModel(3, 0.0)
    glitched = EkfModel(3, 0.0, NoiseSpec(gps_glitches=((1.0, 0.5, 0.0, 6.0),)))
    state = (1.0, 2.0, 0.3, 2.0, 0.1, 0.01)
    offsets = []
    for _ in range(200):
        plain.step(0.01)
        glitched.step(0.01)
        a, b = plain.estimate(state), glitched.estimate(state)
        offsets.append((b.north_m - a.north_m, b.east_m - a.east_m))
        assert (a.psi_rad, a.vn_mps, a.ve_mps, a.r_radps) == (b.psi_rad, b.vn_mps, b.ve_mps,
                                                                b.r_radps)
    east = np.array(offsets)[:, 1]
    assert np.count_nonzero(east == 6.0) == 50 and np.count_nonzero(east) == 50


@pytest.mark.parametrize("text", ["60:5:0", "60:0:1,1", "-1:5:1,1", "a:5:1,1"])
def test_a_bad_glitch_is_a_clear_error(text):
    with pytest.raises(InputError, match="--gps-glitch"):
        parse_gps_glitches([text])


def test_glitches_parse():
    assert parse_gps_glitches(["60:5:0,6", "90:2.5:-3,0"]) == ((60.0, 5.0, 0.0, 6.0),
                                                               (90.0, 2.5, -3.0, 0.0))


def _drive(tmp_path, glitches, duration_s=45.0):
    """straight.toml through the bridge with the LiDAR, the EKF taking in `glitches`: the
    truth (boot s, x, y, psi) every clock tick, the link's counters and the console."""
    scenario = load_scenario(ROOT / "scenarios" / "straight.toml")
    rig = SimRig(scenario, tmp_path, seed=2, ekf_delay_s=5.0,
                 ekf_noise=NoiseSpec(gps_glitches=glitches))
    sim, link = rig.autopilot, rig.link
    truth = []
    rig.clock.add_peer(lambda now: truth.append((sim.boot_s, *sim.true_state[:3])))
    log = StepLog(tmp_path)
    console = io.StringIO()
    loop = OnboardLoop(link, scenario, NmpcController(scenario), SimLidarSource(scenario, seed=2),
                       BridgeOptions(mode="MANUAL", arm=True, duration_s=duration_s,
                                     ekf_timeout_s=30.0, origin=SITL_DEFAULT_HOME),
                       console=console, log=log)
    try:
        loop.run()
    finally:
        log.close()
        rig.close()
    return scenario, np.array(truth), link.counters, console.getvalue()


def test_the_bridge_says_each_jump_and_does_not_steer_after_it(tmp_path):
    """5 m east for 6 s: two jumps said (console, steps.csv); the boat's true track within
    0.5 m of the same run without the glitch (the jump is taken out of the state and let
    back in over 30 s), and clear of the walls."""
    glitch = (25.0, 6.0, 0.0, 5.0)  # 20 s after the first fix
    scenario, truth, counters, console = _drive(tmp_path / "glitch", (glitch,))
    _, plain, _, _ = _drive(tmp_path / "plain", ())
    assert counters.position_jumps == 2, console
    assert console.count("the EKF's position jumped 5.") == 2
    assert open(tmp_path / "glitch" / "steps.csv").read().count("position jumped") == 2
    n = min(len(truth), len(plain))
    assert np.array_equal(truth[:n, 0], plain[:n, 0])
    assert np.abs(truth[:n, 2] - plain[:n, 2]).max() < 0.5
    clearance = Clearance(scenario.world.wall_polylines())
    assert min(float(np.min(clearance.of(p))) for p in truth[::10, 1:]) > 3.0


def test_a_jump_that_stays_is_let_in_after_the_hold():
    """The offset taken out of the state: a jump held for `jump_hold_s`, then let in with
    `jump_blend_s`; one that jumps back inside the hold cancels at once."""
    from types import SimpleNamespace

    from bridge.onboard.loop import OnboardLoop

    link = SimpleNamespace(clock=None, jumps_ne=(0.0, 0.0),
                           counters=SimpleNamespace(position_jumps=0))
    controller = SimpleNamespace(step=lambda time_s, state, actuators, segments: None)
    loop = OnboardLoop(link, None, controller, SimpleNamespace(scan=lambda t, p: None),
                       BridgeOptions(jump_hold_s=10.0, jump_blend_s=30.0), console=None)
    offsets = {}
    for k in range(1000):
        t = 0.1 * k
        if k == 100:
            link.jumps_ne = (0.0, 5.0)
        if k == 400:
            link.jumps_ne = (0.0, 5.0 + 3.0)  # and another, that stays
        if k == 450:
            link.jumps_ne = (0.0, 5.0)  # which jumps back at once
        offsets[k] = loop._blend_jumps(t).copy()
    assert offsets[99][1] == 0.0 and offsets[100][1] == 5.0 and offsets[199][1] == 5.0
    assert abs(offsets[300][1] - 5.0 * math.exp(-10.0 / 30.0)) < 1e-9
    assert abs(offsets[449][1] - (5.0 * math.exp(-20.0 / 30.0) + 3.0)) < 1e-9
    assert abs(offsets[450][1] - 5.0 * math.exp(-20.0 / 30.0)) < 1e-9
    assert offsets[450][1] == offsets[549][1]  # the hold restarted at the last jump
