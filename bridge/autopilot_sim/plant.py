"""`canalnav run --plant mavlink-sim`: the scenario's boat behind MAVLink, as a scenario plant.

The closed loop's commands go out through the bridge's `AutopilotLink` as RC overrides to the
simulated ArduRover autopilot (`AutopilotSim`, the boat FMU inside), over loopback UDP and
optionally a lossy relay; the controller's state is the autopilot's EKF state as the link
received it, carried forward over its age and the measured link delay, exactly as
`canalnav bridge` does. Everything runs in one thread on a virtual clock ticking with the
loop, so the same seed gives the same run. The autopilot keeps the true state for metrics.
"""

from __future__ import annotations

import socket
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bridge.shared.ardupilot import SITL_DEFAULT_HOME
from bridge.shared.clock import VirtualClock
from scenarios.plants.plant import PlantFailure, PlantOutput

OVERRIDE_PERIOD_S = 0.1  # overrides go out at the control rate (and whenever they change)


@dataclass(frozen=True)
class LinkFaults:
    """The relay between bridge and autopilot (none when all are zero)."""

    loss: float = 0.0  # probability that a datagram is lost, each way
    latency_s: float = 0.0  # one-way delay
    seed: int = 0

    @property
    def any(self) -> bool:
        return self.loss > 0 or self.latency_s > 0


def free_udp_port(host: str = "127.0.0.1") -> int:
    """A UDP port nobody on `host` is bound to right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


class MavlinkSimPlant:
    """The Plant protocol over MAVLink: bridge link <-> (relay) <-> simulated autopilot."""

    name = "mavlink-sim"

    def __init__(self, scenario, out_dir, *, faults: LinkFaults = LinkFaults(),
                 ekf_delay_s: float = 5.0, signing_key: bytes | None = None,
                 tick_s: float = 0.01):
        from bridge.autopilot_sim.rover import AutopilotSim
        from bridge.onboard.link import AutopilotLink
        from bridge.autopilot_sim.lossy_relay import LossyRelay

        self.scenario = scenario
        self.out_dir = Path(out_dir) if out_dir is not None else Path(tempfile.mkdtemp())
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.clock = VirtualClock(tick_s)
        port = free_udp_port()
        self.autopilot = AutopilotSim(scenario, f"udpin:127.0.0.1:{port}", self.clock,
                                      seed=scenario.seed, signing_key=signing_key,
                                      ekf_delay_s=ekf_delay_s, work_dir=self.out_dir)
        self.clock.add_peer(self.autopilot.pump)
        self.relay = None
        if faults.any:
            self.relay = LossyRelay(("127.0.0.1", port), self.clock, loss=faults.loss,
                                    latency_s=faults.latency_s, seed=faults.seed)
            self.clock.add_peer(self.relay.pump)
            port = self.relay.port
        # the simulator puts a scenario without [origin] at SITL's home: so does the link
        self.origin = scenario.geodetic_origin or SITL_DEFAULT_HOME
        self.link = AutopilotLink(f"udpout:127.0.0.1:{port}", self.clock,
                                  signing_key=signing_key,
                                  tlog_path=self.out_dir / "mavlink.tlog",
                                  geodetic_origin=self.origin)
        self.clock.add_peer(lambda now: self.link.pump())
        self._t0 = 0.0
        self._last_sent = (None, -np.inf)

    def reset(self, state0, current_ne=(0.0, 0.0)) -> PlantOutput:
        """Handshake, pre-flight checks, EKF wait, MANUAL and arming, as `canalnav bridge`."""
        from bridge.onboard.loop import BridgeOptions, prepare_link

        if not np.allclose(state0, self.autopilot.true_state, atol=1e-9) or \
                not np.allclose(current_ne, self.scenario.current_ne):
            raise ValueError("the simulated autopilot starts where its scenario says; "
                             "reset() must be given that initial state and current")
        prepare_link(self.link, self.scenario,
                     BridgeOptions(mode="MANUAL", arm=True, origin=self.origin))
        self._t0 = self.clock.now()
        return self._output()

    def step(self, command, dt: float) -> PlantOutput:
        nT, nS = (float(v) for v in np.clip(np.asarray(command, float), -100.0, 100.0))
        now = self.clock.now()
        last, when = self._last_sent
        if last != (nT, nS) or now - when >= OVERRIDE_PERIOD_S - 1e-9:
            self.link.send_commands(nT, nS)
            self._last_sent = ((nT, nS), now)
        self.clock.sleep(dt)
        if not self.link.alive:
            raise PlantFailure(f"MAVLink link lost: nothing from the autopilot for "
                               f"{self.link.silence_s:.1f} s")
        if not self.link.state_fresh:
            raise PlantFailure(f"EKF state stale: newest is {self.link.state_age_s:.1f} s old")
        return self._output()

    def _output(self) -> PlantOutput:
        from bridge.onboard.ekf_state import predict_vector

        out = self.autopilot.last_plant_output
        st = self.link.state
        est = None
        if st is not None:
            est = predict_vector(st.vector, self.link.state_age_s + self.link.link_delay_s)
        return PlantOutput(self.clock.now() - self._t0, out.state.copy(), out.state_dot.copy(),
                           out.actuators.copy(), estimate=est)

    def close(self) -> None:
        for part in (self.link, self.relay, self.autopilot):
            if part is not None:
                try:
                    part.close()
                except Exception:  # closing must not hide the run's own outcome
                    pass


def mavlink_sim_plant(scenario, out_dir) -> MavlinkSimPlant:
    """The `PLANTS` factory of `scenarios.loop.runner`."""
    return MavlinkSimPlant(scenario, out_dir)
