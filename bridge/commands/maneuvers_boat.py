"""`canalnav maneuvers --connect URL --scenario FILE`: the identification runs on the boat.

No subcommand of its own: adds the on-boat options to `canalnav maneuvers` (which belongs to
`controller`, which may not import `bridge`) and the function that runs them.
"""


def register(sub) -> None:
    p = sub.choices.get("maneuvers")
    if p is None:
        return
    g = p.add_argument_group(
        "on the boat (--connect)",
        "Drive the same runs on a real (or simulated) ArduPilot Rover boat over MAVLink, with "
        "the bridge's start-up waits, pre-flight checks and failsafes: each throttle level "
        "held --hold seconds, commands no faster than the scenario's actuator rates, the boat "
        "first turned to the most open water; a run that would leave the scenario's water "
        "(or --radius around the start) is cut short. Writes a CSV log per run (the EKF state "
        "and the servo outputs, in the autopilot's time, with the window of its .BIN log), "
        "session.csv and mavlink.tlog to -o DIR. Exit status: 0 done, 1 failsafe, 2 bad input "
        "or no answer, 3 refused, 130 Ctrl-C.")
    g.add_argument("--connect", metavar="URL",
                   help="pymavlink connection, as canalnav bridge (e.g. udp:127.0.0.1:14550)")
    g.add_argument("--scenario", metavar="FILE",
                   help="the water to stay in, the actuator rates, the origin")
    g.add_argument("--radius", type=float, metavar="M",
                   help="also stay within M metres of where the boat starts")
    g.add_argument("--hold", type=float, default=60.0, metavar="S",
                   help="seconds each throttle level is held (default 60)")
    g.add_argument("--arm", action="store_true", help="arm the autopilot (never without this)")
    g.add_argument("--mode", metavar="NAME",
                   help="switch to this mode (MANUAL) first, HOLD at the end and on a failsafe")
    g.add_argument("--origin", metavar="LAT,LON[,ALT]",
                   help="where the scenario's (0, 0) is (default: its [origin]); write "
                   "--origin=-35.3,149.2 when the latitude is negative")
    g.add_argument("--signing-key", metavar="FILE", help="MAVLink 2 signing key")
    g.add_argument("--system-id", type=int, default=255, metavar="N",
                   help="our system id (default 255, the GCS id whose overrides Rover obeys)")
    g.add_argument("--target-system", type=int, metavar="N",
                   help="the autopilot's system id (default: the first heard)")
    g.add_argument("--ekf-timeout", type=float, default=120.0, metavar="S",
                   help="give up if the EKF has no usable position after S seconds")
    g.add_argument("--speedup", type=float, default=1.0, metavar="K",
                   help="run the clock K times faster (against a sped-up simulated autopilot)")
    p.set_defaults(connect_func=run)


def run(args) -> int:
    from bridge.onboard.maneuvers import run_on_boat

    return run_on_boat(args)
