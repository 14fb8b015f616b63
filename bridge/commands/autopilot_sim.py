"""`canalnav autopilot-sim`: a simulated ArduPilot Rover (boat) on MAVLink, the FMU as physics."""

from __future__ import annotations

import signal
import sys


def register(sub) -> None:
    p = sub.add_parser(
        "autopilot-sim", help="simulated ArduPilot Rover (boat) speaking MAVLink 2, FMU physics",
        description="Serve a simulated ArduPilot Rover (boat frame) on a MAVLink connection: "
        "heartbeat, parameters, arming, modes, RC overrides, EKF-style state streams, with the "
        "boat FMU started from the scenario's initial state. Starts up like Rover (INITIALISING "
        "for --init-delay seconds, the RC dead zones set at its end), then MANUAL, disarmed; "
        "the first GPS fix (and the EKF origin, wherever the boat is then) comes --ekf-delay "
        "seconds after boot. With --log it writes ArduPilot DataFlash logs (.BIN) as it goes. "
        "Ctrl-C or SIGTERM stops it.",
    )
    p.add_argument("--listen", required=True, metavar="URL",
                   help="pymavlink connection string, e.g. udpin:127.0.0.1:14550 (the bridge "
                   "then connects with udpout:127.0.0.1:14550) or tcpin:127.0.0.1:5760")
    p.add_argument("--scenario", required=True, metavar="FILE", help="scenario file (TOML)")
    p.add_argument("--speedup", type=float, default=1.0, metavar="K",
                   help="run K times faster than real time (default 1)")
    p.add_argument("--seed", type=int, default=None, metavar="N",
                   help="EKF noise seed (default: the scenario's)")
    p.add_argument("--signing-key", metavar="FILE",
                   help="MAVLink 2 signing key file: 32 raw bytes, 64 hex characters, or a "
                   "passphrase (its SHA-256); unsigned messages are then ignored")
    p.add_argument("--ekf-delay", type=float, default=20.0, metavar="S",
                   help="seconds after boot to the first GPS fix, when the position estimate is "
                   "ready and the EKF origin is set (default 20)")
    p.add_argument("--init-delay", type=float, default=3.0, metavar="S",
                   help="seconds the start-up takes (mode INITIALISING; default 3)")
    p.add_argument("--log", metavar="DIR",
                   help="write the onboard DataFlash log here, one file per boot "
                   "(00000001.BIN, ...: PARM, MODE, ARM, MSG, ORGN, XKF1, ATT, POS, GPS, IMU, "
                   "RCIN, RCOU), for `canalnav sysid LOG.BIN`")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="set an autopilot parameter at boot (repeatable), e.g. RC1_MIN=1000")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="stop after S simulated seconds (default: until Ctrl-C)")
    p.add_argument("--legacy-param-names", action="store_true",
                   help="use the parameter names of ArduPilot 4.5 (SYSID_MYGCS, ARMING_CHECK)")
    p.add_argument("--system-id", type=int, default=1, metavar="N",
                   help="the autopilot's MAVLink system id (default 1)")
    p.add_argument("--heading-bias", type=float, default=0.0, metavar="DEG",
                   help="a constant bias of the EKF's heading, degrees (a badly calibrated "
                   "compass); the velocity over ground stays the GPS's")
    p.add_argument("--heading-wander", type=float, default=0.0, metavar="DEG",
                   help="and a slow seeded wander of it (standard deviation, degrees; time "
                   "constant 300 s)")
    p.add_argument("--clock-fault", action="append", default=[], metavar="AT:STEP",
                   help="the autopilot's clock stalls at AT seconds after start for STEP "
                   "seconds and stays that far behind (a negative STEP: it jumps ahead), as "
                   "SITL's under load; repeatable, e.g. --clock-fault 60:0.6")
    p.add_argument("--gps-glitch", action="append", default=[], metavar="AT:SECONDS:NORTH,EAST",
                   help="the EKF takes in a GPS glitch: from AT seconds after start, for SECONDS, "
                   "its position is off by NORTH, EAST metres (jumping there and back, as "
                   "ArduPilot's EKF resetting to a GPS that jumped); repeatable, e.g. "
                   "--gps-glitch 60:5:0,6")
    p.set_defaults(func=run)


def parse_gps_glitches(items: list[str]) -> tuple:
    """AT:SECONDS:NORTH,EAST strings to (at, duration, north, east); InputError names the bad
    item."""
    import math

    from controller.errors import InputError

    out = []
    for item in items:
        parts = item.replace(",", ":").split(":")
        try:
            if len(parts) != 4:
                raise ValueError
            at, duration, north, east = (float(v) for v in parts)
            if not (at >= 0 and duration > 0 and math.isfinite(at + duration + north + east)):
                raise ValueError
        except ValueError:
            raise InputError(f"--gps-glitch {item!r}: expected AT:SECONDS:NORTH,EAST (seconds "
                             "after start >= 0, a positive duration, metres), e.g. 60:5:0,6") \
                from None
        out.append((at, duration, north, east))
    return tuple(out)


def _ekf_noise(args):
    """The EKF's errors with the heading bias asked for (None: the defaults)."""
    import math

    from controller.errors import InputError

    from bridge.autopilot_sim.ekf import NoiseSpec

    if not (math.isfinite(args.heading_bias) and math.isfinite(args.heading_wander)
            and args.heading_wander >= 0):
        raise InputError(f"--heading-bias {args.heading_bias} / --heading-wander "
                         f"{args.heading_wander}: finite degrees needed, the wander >= 0")
    glitches = parse_gps_glitches(getattr(args, "gps_glitch", []))
    if not args.heading_bias and not args.heading_wander and not glitches:
        return None
    return NoiseSpec(heading_bias_rad=math.radians(args.heading_bias),
                     heading_wander_sigma_rad=math.radians(args.heading_wander),
                     gps_glitches=glitches)


def parse_clock_faults(items: list[str]) -> list[tuple[float, float]]:
    """AT:STEP strings to pairs; InputError names the bad item."""
    from controller.errors import InputError

    out = []
    for item in items:
        at, sep, step = item.partition(":")
        try:
            if not sep:
                raise ValueError
            out.append((float(at), float(step)))
        except ValueError:
            raise InputError(f"--clock-fault {item!r}: expected AT:STEP in seconds, e.g. "
                             "60:0.6") from None
    return out


def parse_params(items: list[str]) -> dict[str, float]:
    """NAME=VALUE strings to a dict; InputError names the bad item."""
    from controller.errors import InputError

    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        name = name.strip().upper()
        if not sep or not name:
            raise InputError(f"--param {item!r}: expected NAME=VALUE")
        try:
            out[name] = float(value)
        except ValueError:
            raise InputError(f"--param {item!r}: {value.strip()!r} is not a number") from None
    return out


def run(args) -> int:
    from controller.errors import InputError
    from scenarios.scenario_file import load_scenario

    from bridge.autopilot_sim.rover import AutopilotSim
    from bridge.shared.clock import RealClock
    from bridge.shared.signing import load_signing_key

    if not args.speedup > 0:
        raise InputError(f"--speedup must be positive, got {args.speedup}")
    if args.ekf_delay < 0:
        raise InputError(f"--ekf-delay must be >= 0, got {args.ekf_delay}")
    if not args.init_delay >= 0:
        raise InputError(f"--init-delay must be >= 0, got {args.init_delay}")
    scenario = load_scenario(args.scenario)
    key = load_signing_key(args.signing_key) if args.signing_key else None
    params = parse_params(args.param)
    seed = scenario.seed if args.seed is None else args.seed
    clock = RealClock(args.speedup)
    sim = AutopilotSim(scenario, args.listen, clock, seed=seed, signing_key=key, params=params,
                       ekf_delay_s=args.ekf_delay, legacy_param_names=args.legacy_param_names,
                       system_id=args.system_id, init_s=args.init_delay, log_dir=args.log,
                       clock_faults=parse_clock_faults(args.clock_fault),
                       ekf_noise=_ekf_noise(args))

    def terminate(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, terminate)  # a script's kill ends it as Ctrl-C
    try:
        print(f"autopilot-sim: ArduPilot Rover (simulated), system {args.system_id}, listening "
              f"on {args.listen}, scenario {scenario.name}, {args.speedup:g}x real time"
              f"{', signed' if key else ''}", flush=True)
        sim.serve(args.duration)
    except KeyboardInterrupt:
        print("autopilot-sim: stopped", file=sys.stderr)
    finally:
        signal.signal(signal.SIGTERM, previous)
        sim.close()
        if sim.log_paths:
            print("autopilot-sim: DataFlash log(s): " + ", ".join(map(str, sim.log_paths)),
                  file=sys.stderr)
    return 0
