"""Fault tests over loopback: the bridge's onboard loop and the simulated autopilot with a
seeded relay between them, all in lock-step on a virtual clock (deterministic).

Link cut, autopilot restart, garbage, strangers and unsigned messages: nothing crashes, the
autopilot and the bridge fail safe as ArduPilot users expect, and the step log keeps every
step up to the fault.
"""

from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from bridge.shared.ardupilot import SITL_DEFAULT_HOME
from bridge.lidar import SimLidarSource
from bridge.autopilot_sim.lossy_relay import TO_AUTOPILOT, TO_BRIDGE
from bridge.onboard.loop import EXIT_GOAL, EXIT_STOPPED, BridgeOptions, OnboardLoop
from bridge.onboard.step_log import StepLog
from scenarios.loop.controllers import NmpcController
from scenarios.scenario_file import load_scenario

from .rigs import SimRig

ROOT = Path(__file__).resolve().parents[2]
KEY = bytes(range(32))
EKF_DELAY_S = 2.0


@pytest.fixture(scope="module")
def scenario():
    s = load_scenario(ROOT / "scenarios" / "straight.toml")
    return replace(s, waypoints=np.array([[0.0, 0.0], [50.0, 0.0], [90.0, 0.0]]))


class Rig(SimRig):
    """Autopilot <- relay -> bridge link (tests/bridge/rigs.py), the onboard loop, and events
    on the clock."""

    def __init__(self, scenario, tmp_path, *, signing=False, resume=False, duration_s=120.0,
                 stale_s=1.0):
        key = KEY if signing else None
        super().__init__(scenario, tmp_path, seed=4, relay=True, signing_key=key,
                         ekf_delay_s=EKF_DELAY_S,
                         link_kwargs={"signing_key": key, "tlog_path": tmp_path / "mavlink.tlog",
                                      "stale_s": stale_s})
        self.events: list = []  # (time, action)
        self.outputs: list = []  # (time, autopilot's (nT, nS))
        self.clock.add_peer(self._events)
        self.log = StepLog(tmp_path)
        self.loop = OnboardLoop(
            self.link, scenario, NmpcController(scenario), SimLidarSource(scenario, seed=4),
            BridgeOptions(mode="MANUAL", arm=True, duration_s=duration_s, resume=resume,
                          ekf_timeout_s=30.0, stale_s=stale_s,
                          origin=SITL_DEFAULT_HOME),  # where the simulator puts straight.toml
            console=self.console, log=self.log)
        self.tmp_path = tmp_path

    def at(self, t: float, action) -> None:
        self.events.append((t, action))

    def _events(self, now: float) -> None:
        self.outputs.append((now, tuple(self.autopilot.outputs)))
        for t, action in [e for e in self.events if e[0] <= now + 1e-9]:
            self.events.remove((t, action))
            action(now)

    def run(self, then_s: float = 0.0):
        """The loop to its end, then `then_s` more seconds of the autopilot on its own."""
        try:
            result = self.loop.run()
            self.clock.sleep(then_s)
            return result
        finally:
            self.log.close()
            self.close()

    def output_at(self, t: float):
        return min(self.outputs, key=lambda o: abs(o[0] - t))[1]

    def step_rows(self):
        with (self.tmp_path / "steps.csv").open() as fh:
            return list(csv.DictReader(fh))


def _packed(msg, system_id: int) -> bytes:
    """A MAVLink 2 frame from `system_id`, unsigned."""
    return msg.pack(mavlink2.MAVLink(None, srcSystem=system_id, srcComponent=1))


@pytest.mark.parametrize("stale_s, first", [(1.0, "state stale"), (10.0, "link lost")])
def test_link_cut_for_5_s_autopilot_times_out_and_the_bridge_fails_safe(scenario, tmp_path,
                                                                        stale_s, first):
    """The state goes stale after 1 s, before the link counts as lost (3 s): whichever comes
    first ends the run, neutral and release are sent, and the console says why."""
    rig = Rig(scenario, tmp_path, stale_s=stale_s)
    cut = []
    rig.at(EKF_DELAY_S + 12.0, lambda now: (cut.append(now), rig.relay.cut(now, now + 5.0)))
    result = rig.run(then_s=6.0)
    assert result.exit_code == EXIT_STOPPED and result.reason.startswith(first), result
    assert f"FAILSAFE {first}" in rig.console.getvalue()
    t_cut = cut[0]
    assert rig.output_at(t_cut - 0.5)[0] > 20.0  # driving before the cut
    # ArduPilot's RC_OVERRIDE_TIME (3 s): the autopilot stops obeying stale overrides
    assert rig.output_at(t_cut + 2.5)[0] > 20.0
    assert rig.output_at(t_cut + 3.5) == (0.0, 0.0)
    rows = rig.step_rows()
    steps = [r for r in rows if r["x_m"]]
    assert len(steps) == result.steps >= 100  # every step up to the fault was logged
    assert any(first in r["status"] for r in rows if not r["x_m"])  # and the failsafe


def test_link_cut_with_resume_reaches_the_goal(scenario, tmp_path):
    rig = Rig(scenario, tmp_path, resume=True)
    rig.at(EKF_DELAY_S + 12.0, lambda now: rig.relay.cut(now, now + 5.0))
    result = rig.run()
    assert result.exit_code == EXIT_GOAL and result.reached_goal, result
    assert len(result.failsafes) == 1 and result.failsafes[0].startswith("state stale")
    assert "canalnav: resumed control" in rig.autopilot.received_statustext


def test_autopilot_restart_is_noticed_and_survived(scenario, tmp_path):
    rig = Rig(scenario, tmp_path, resume=True)
    rig.at(EKF_DELAY_S + 10.0, lambda now: rig.autopilot.restart())
    result = rig.run()
    assert rig.link.counters.autopilot_restarts == 1
    assert result.failsafes, "a rebooted, disarmed autopilot must stop the loop"
    assert result.exit_code == EXIT_GOAL, result  # --resume: prepared, armed again, went on
    assert rig.autopilot.armed


def test_garbage_strangers_and_unsigned_messages_are_ignored(scenario, tmp_path):
    rig = Rig(scenario, tmp_path, signing=True)
    rng = np.random.default_rng(7)
    stranger_override = _packed(mavlink2.MAVLink_rc_channels_override_message(
        1, 1, *([1100] * 8), *([0] * 10)), 77)  # full reverse from a stranger
    spoofed_override = _packed(mavlink2.MAVLink_rc_channels_override_message(
        1, 1, *([1900] * 8), *([0] * 10)), 255)  # GCS id, but unsigned
    spoofed_attitude = _packed(mavlink2.MAVLink_attitude_message(
        10_000, 0.0, 0.0, 3.0, 0.0, 0.0, 0.5), 1)  # "the autopilot", unsigned

    def flood(now):
        if EKF_DELAY_S + 5.0 <= now <= EKF_DELAY_S + 15.0:
            rig.relay.inject(rng.integers(0, 256, 300, dtype=np.uint8).tobytes(), TO_AUTOPILOT)
            rig.relay.inject(rng.integers(0, 256, 300, dtype=np.uint8).tobytes(), TO_BRIDGE)
            rig.relay.inject(stranger_override, TO_AUTOPILOT)
            rig.relay.inject(spoofed_override, TO_AUTOPILOT)
            rig.relay.inject(spoofed_attitude, TO_BRIDGE)
            rig.relay.inject(_packed(mavlink2.MAVLink_attitude_message(
                10_000, 0.0, 0.0, -2.0, 0.0, 0.0, -0.5), 77), TO_BRIDGE)

    rig.clock.add_peer(flood)
    result = rig.run()
    assert result.exit_code == EXIT_GOAL and not result.failsafes, result
    assert rig.autopilot.counters.bad_data > 0 and rig.link.counters.bad_data > 0
    assert rig.autopilot.counters.rejected_signature > 0  # the unsigned override
    assert rig.link.counters.rejected_signature > 0  # the unsigned attitude
    psi = np.array([float(r["psi_rad"]) for r in rig.step_rows() if r["x_m"]])
    assert np.max(np.abs(psi)) < 0.3  # never took the spoofed 3 rad or -2 rad heading
