"""The identification session of `canalnav maneuvers --connect` against the simulated autopilot
(its EKF noise on, its DataFlash log written) in lock-step on a virtual clock: the control loop
at exactly 10 Hz of autopilot time whatever the computer's load, the same code and MAVLink over
UDP as the two commands. Not a test: a tool for the figure of issue 19 where a loaded computer
cannot keep `autopilot-sim --speedup` and `maneuvers --speedup` in real time.

    python tests/bridge/lockstep_maneuvers.py OUT SCENARIO SEED [HOLD_S [OVERSHOOTS]]

then `canalnav sysid OUT/ap/00000001.BIN --window ...` with the windows it prints."""

import sys
from pathlib import Path

from bridge.autopilot_sim.rover import AutopilotSim
from bridge.shared.clock import VirtualClock
from bridge.onboard.link import AutopilotLink
from bridge.autopilot_sim.plant import free_udp_port
from bridge.onboard.loop import BridgeOptions
from bridge.onboard.maneuvers import ManeuverSession
from controller.identification.maneuvers import PAPER_RUNS, with_overshoots
from scenarios.scenario_file import load_scenario


def main(argv):
    out, scenario_path, seed = Path(argv[0]), argv[1], int(argv[2])
    hold = float(argv[3]) if len(argv) > 3 else 60.0
    overshoots = int(argv[4]) if len(argv) > 4 else None
    scenario = load_scenario(scenario_path)
    tick = 0.02  # 50 Hz: the autopilot's RCOU logging rate
    clock = VirtualClock(tick)
    port = free_udp_port()
    ap = AutopilotSim(scenario, f"udpin:127.0.0.1:{port}", clock, seed=seed, ekf_delay_s=5.0,
                      init_s=3.0, work_dir=out / "work", log_dir=out / "ap", physics_step_s=tick)
    clock.add_peer(ap.pump)
    link = AutopilotLink(f"udpout:127.0.0.1:{port}", clock,
                         geodetic_origin=scenario.geodetic_origin)
    try:
        result = ManeuverSession(link, scenario, with_overshoots(PAPER_RUNS, overshoots),
                                 BridgeOptions(mode="MANUAL", arm=True, ekf_timeout_s=30.0),
                                 out / "boat", console=sys.stdout, hold_s=hold).run()
    finally:
        link.close()
        ap.close()
    print(result.exit_code, result.reason)
    return result.exit_code


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
