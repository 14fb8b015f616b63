"""`canalnav sitl-physics --scenario FILE`: the boat FMU as ArduPilot SITL's JSON physics."""

from __future__ import annotations

import logging
import signal
import sys
from pathlib import Path

PARM_FILE = Path(__file__).resolve().parent.parent / "sitl" / "sitl_boat.parm"


def register(sub) -> None:
    p = sub.add_parser(
        "sitl-physics",
        help="serve ArduPilot SITL's JSON physics (--model JSON) with the boat FMU",
        description="Run the boat FMU as the vehicle of ArduPilot's own SITL: answer SITL's "
        "servo packets (UDP, port 9002 + 10 per instance) in lock-step with its frame "
        "counter, with the boat's state as JSON. The boat starts at the scenario's initial "
        "state, in its current, with its plant parameters and actuator rates. Start SITL "
        "as printed (ArduRover as a boat, bridge/sitl/sitl_boat.parm), then drive it with "
        "`canalnav bridge`. See bridge/sitl/README.md. Ctrl-C or SIGTERM stops it, with a summary.",
    )
    p.add_argument("--scenario", required=True, help="scenario file (TOML)")
    p.add_argument("--port", type=int, default=None,
                   help="UDP port to listen on (default 9002 + 10 x --instance)")
    p.add_argument("--instance", type=int, default=0,
                   help="SITL instance number (sim_vehicle.py -I), picks the port (default 0)")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to bind (default 127.0.0.1; 0.0.0.0 when SITL runs on "
                   "another machine: any sender on the port then drives the boat)")
    p.add_argument("--steering-channel", type=int, default=1,
                   help="servo output of the steering (SERVOn_FUNCTION 26; default 1)")
    p.add_argument("--throttle-channel", type=int, default=3,
                   help="servo output of the throttle (SERVOn_FUNCTION 70; default 3)")
    p.add_argument("--duration", type=float, default=None, metavar="SECONDS",
                   help="stop after this much wall time (default: until Ctrl-C)")
    p.add_argument("--verbose", action="store_true", help="log SITL connections")
    p.set_defaults(func=run)


def run(args) -> int:
    from controller.errors import InputError
    from scenarios.scenario_file import load_scenario

    from bridge.sitl.json_physics import DEFAULT_PORT, SitlPhysicsServer, bridge_command, sitl_command

    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="canalnav sitl-physics: %(message)s")
    if args.instance < 0:
        raise InputError(f"--instance must be 0 or more, got {args.instance}")
    port = args.port if args.port is not None else DEFAULT_PORT + 10 * args.instance
    scenario = load_scenario(args.scenario)
    server = SitlPhysicsServer(scenario, port=port, steering_channel=args.steering_channel,
                               throttle_channel=args.throttle_channel, host=args.host)
    try:
        host, bound = server.open()
        start = sitl_command(PARM_FILE, bound, args.host, scenario.geodetic_origin)
        print(f"boat FMU ({scenario.name}) serving SITL JSON physics on udp {host}:{bound}; "
              f"start SITL with: {start}", flush=True)
        print(f"then drive it with: {bridge_command(args.scenario, scenario.geodetic_origin)}",
              flush=True)
        # SIGTERM (a supervisor, a script, `kill`) ends it as Ctrl-C does, with the summary
        previous = signal.signal(signal.SIGTERM, lambda signum, frame: server.stop())
        try:
            server.serve(args.duration)
        except KeyboardInterrupt:
            pass
        finally:
            signal.signal(signal.SIGTERM, previous)
        out = server.output
        print(f"stopped: {server.frames} frames, {server.repeats} repeated, "
              f"{server.restarts} SITL restarts, {sum(server.rejected.values())} datagrams "
              f"ignored; boat at t = {out.time_s:.2f} s, x = {out.state[0]:.2f} m, "
              f"y = {out.state[1]:.2f} m", file=sys.stderr)
    finally:
        server.close()
    return 0
