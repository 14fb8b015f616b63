"""Pre-flight checks: would the autopilot obey the bridge's overrides? Pure functions.

Each refusal names the parameter (or message field) and its value, and says what to change.
The checks follow ArduPilot Rover: RC_CHANNELS_OVERRIDE is obeyed only from the GCS system id
(`SYSID_MYGCS`, renamed `MAV_GCS_SYSID`, optionally a range up to `MAV_GCS_SYSID_HI`), not at
all with RC_OPTIONS bit 1 or RC_OVERRIDE_TIME = 0, and only MANUAL passes the sticks straight
to the servos.
"""

from __future__ import annotations

from bridge.shared.ardupilot import MODE_NAMES, MODES, PARAM_ALIASES, RC_OPTION_IGNORE_OVERRIDES
from controller.pwm import CommandChannels

MAV_TYPE_GROUND_ROVER = 10
MAV_TYPE_SURFACE_BOAT = 11
BOAT_OR_ROVER = {MAV_TYPE_SURFACE_BOAT: "MAV_TYPE_SURFACE_BOAT", MAV_TYPE_GROUND_ROVER: "MAV_TYPE_GROUND_ROVER"}
PILOT_INPUT_MODES = ("MANUAL", "ACRO", "STEERING")
"""Rover modes that take the sticks (hence overrides) as the pilot's input; MANUAL maps them
straight to the servos, ACRO and STEERING read them as turn rate / steering and speed."""

GCS_SYSID_NAMES = PARAM_ALIASES["gcs_sysid"]  # ("SYSID_MYGCS", "MAV_GCS_SYSID")
GCS_SYSID_HIGH = "MAV_GCS_SYSID_HI"  # 4.6+: a range of GCS ids (ignored when <= MAV_GCS_SYSID)
BASE_PARAMS = ("RCMAP_ROLL", "RCMAP_THROTTLE", "RC_OPTIONS", "RC_OVERRIDE_TIME")
RC_FIELDS = ("MIN", "MAX", "TRIM", "DZ", "REVERSED")


def channel_params(params: dict) -> tuple[str, ...]:
    """The RCn_* calibration parameters of the steering and throttle channels."""
    names = []
    for key in ("RCMAP_ROLL", "RCMAP_THROTTLE"):
        try:
            ch = int(params.get(key, 0))
        except (TypeError, ValueError):
            continue
        if 1 <= ch <= 16:
            names += [f"RC{ch}_{f}" for f in RC_FIELDS]
    return tuple(dict.fromkeys(names))


def gcs_sysid(params: dict) -> tuple[str, int] | None:
    """(name, value) of the GCS system id parameter under whichever name the firmware uses."""
    for name in reversed(GCS_SYSID_NAMES):  # the new name first
        if name in params:
            return name, int(params[name])
    return None


def vehicle_refusals(heartbeat) -> list[str]:
    """The heartbeat's vehicle type must be a boat or a rover."""
    if heartbeat.type in BOAT_OR_ROVER:
        return []
    return [f"HEARTBEAT.type = {heartbeat.type}: system {heartbeat.system_id} is not a boat or "
            f"rover (MAV_TYPE_SURFACE_BOAT = {MAV_TYPE_SURFACE_BOAT}, MAV_TYPE_GROUND_ROVER = "
            f"{MAV_TYPE_GROUND_ROVER}); the bridge drives ArduPilot Rover only"]


def refusals(heartbeat, params: dict, *, system_id: int, requested_mode: str | None = None) -> list[str]:
    """Every reason the bridge must not take control (empty: go)."""
    out = vehicle_refusals(heartbeat)
    for name in BASE_PARAMS:
        if name not in params:
            out.append(f"{name}: not read from the autopilot (no PARAM_VALUE answered)")

    options = params.get("RC_OPTIONS")
    if options is not None and int(options) & RC_OPTION_IGNORE_OVERRIDES:
        out.append(f"RC_OPTIONS = {int(options)} has bit 1 ({RC_OPTION_IGNORE_OVERRIDES}, 'Ignore "
                   "MAVLink Overrides') set: the autopilot would ignore every command; clear it")

    timeout = params.get("RC_OVERRIDE_TIME")
    if timeout is not None and float(timeout) == 0:
        out.append("RC_OVERRIDE_TIME = 0 disables RC overrides; set it to a few seconds "
                   "(3, ArduPilot's default)")

    gcs = gcs_sysid(params)
    if gcs is None:
        out.append(f"{' / '.join(GCS_SYSID_NAMES)}: not read from the autopilot; cannot tell "
                   "whether it obeys overrides from this system id")
    else:
        name, low = gcs
        high = int(params.get(GCS_SYSID_HIGH, 0))
        if high > low and name == "MAV_GCS_SYSID":
            if not low <= system_id <= high:
                out.append(f"MAV_GCS_SYSID = {low}, {GCS_SYSID_HIGH} = {high}: overrides from "
                           f"system id {system_id} will be ignored; use --system-id {low}")
        elif low != system_id:
            out.append(f"{name} = {low}: overrides from system id {system_id} will be ignored; "
                       f"use --system-id {low}")

    out += _mode_refusals(heartbeat, requested_mode)

    if all(k in params for k in ("RCMAP_ROLL", "RCMAP_THROTTLE")):
        try:
            CommandChannels.from_rc_params(params)
        except (TypeError, ValueError) as exc:
            out.append(f"RC mapping: {exc}")
        else:
            missing = [n for n in channel_params(params) if n not in params]
            if missing:
                out.append(f"{', '.join(missing)}: not read from the autopilot (needed to map "
                           "commands to PWM)")
    return out


def _mode_refusals(heartbeat, requested_mode: str | None) -> list[str]:
    if requested_mode is not None:
        name = requested_mode.upper()
        if name not in MODES:
            return [f"--mode {requested_mode}: not a Rover mode (one of {', '.join(MODES)})"]
        if name not in PILOT_INPUT_MODES:
            return [f"--mode {name}: ArduPilot ignores RC overrides as steering and throttle in "
                    f"{name}; use MANUAL (or {', '.join(PILOT_INPUT_MODES[1:])})"]
        return []
    current = MODE_NAMES.get(heartbeat.custom_mode, f"mode {heartbeat.custom_mode}")
    if current != "MANUAL":
        return [f"HEARTBEAT.custom_mode = {heartbeat.custom_mode} ({current}): the autopilot is "
                "not in MANUAL and --mode was not given; ArduPilot passes overrides straight to "
                "the servos only in MANUAL: switch it to MANUAL or pass --mode MANUAL"]
    return []


def notes(heartbeat, params: dict, *, arm: bool = False, requested_mode: str | None = None) -> list[str]:
    """Things worth saying that do not stop the bridge."""
    out = []
    timeout = params.get("RC_OVERRIDE_TIME")
    if timeout is not None and float(timeout) < 0:
        out.append(f"RC_OVERRIDE_TIME = {float(timeout):g}: overrides never time out; if the "
                   "bridge dies without releasing them, the last command stays")
    if requested_mode and requested_mode.upper() in PILOT_INPUT_MODES[1:]:
        out.append(f"--mode {requested_mode.upper()}: ArduPilot reads the overrides as pilot "
                   "inputs of that mode, not as servo outputs")
    if not arm and not heartbeat.armed:
        out.append("the autopilot is disarmed and --arm was not given: the boat moves only "
                   "once someone arms it")
    return out
