"""The one test rig of a simulated autopilot: `AutopilotSim` <- (a seeded `LossyRelay`) ->
the bridge's `AutopilotLink`, all peers of one virtual clock, so that a whole MAVLink
exchange runs deterministically in the test's thread over loopback UDP.

`sim_rig` (tests/bridge/conftest.py) makes rigs and closes them after the test.
"""

from __future__ import annotations

import io

from bridge.autopilot_sim.lossy_relay import LossyRelay
from bridge.autopilot_sim.plant import free_udp_port
from bridge.autopilot_sim.rover import AutopilotSim
from bridge.onboard.link import AutopilotLink
from bridge.onboard.loop import BridgeOptions, prepare_link
from bridge.shared.clock import VirtualClock


class SimRig:
    """A simulated autopilot on `port`, a relay in front of it when asked (`relay`, or any
    `latency_s` / `loss`), and a link to whichever is in front (`link=False`: none, for tests
    that speak to the autopilot with their own clients). `seed` seeds both the autopilot and
    the relay; the other keywords go to `AutopilotSim`."""

    def __init__(self, scenario, work_dir, *, tick_s=0.01, seed=0, relay=False, latency_s=0.0,
                 loss=0.0, link=True, link_kwargs=None, **autopilot_kwargs):
        self.scenario = scenario
        self.clock = VirtualClock(tick_s)
        self.port = free_udp_port()
        self.relay = None
        self.link = None
        self.console = io.StringIO()
        self._closed = False
        self.autopilot = AutopilotSim(scenario, f"udpin:127.0.0.1:{self.port}", self.clock,
                                      seed=seed, work_dir=work_dir, **autopilot_kwargs)
        self.clock.add_peer(self.autopilot.pump)
        front = self.port
        if relay or latency_s or loss:
            self.relay = LossyRelay(("127.0.0.1", self.port), self.clock, latency_s=latency_s,
                                    loss=loss, seed=seed)
            self.clock.add_peer(self.relay.pump)
            front = self.relay.port
        self.link_url = f"udpout:127.0.0.1:{front}"
        if link:
            self.link = AutopilotLink(self.link_url, self.clock, **(link_kwargs or {}))

    def prepare(self, **options):
        """The bridge's start-up on this link (MANUAL, armed unless told otherwise)."""
        options = {"mode": "MANUAL", "arm": True, "ekf_timeout_s": 30.0, **options}
        return prepare_link(self.link, self.scenario, BridgeOptions(**options), self.console)

    def close(self) -> None:
        """Close the link, the relay and the autopilot (again: nothing); what they hold
        stays readable."""
        if self._closed:
            return
        self._closed = True
        for part in (self.link, self.relay, self.autopilot):
            if part is not None:
                part.close()
