"""ArduPilot Rover facts the bridge and the simulated autopilot share (no behaviour here).

Sources: ArduPilot Rover documentation (flight modes, RC input, parameters) and its
source (`Rover/mode.h`, `RC_Channel`, `GCS_MAVLink`). Newer firmware renamed some
parameters; `PARAM_ALIASES` lists the old and new names of each.
"""

from __future__ import annotations

# Rover mode numbers (custom_mode of the heartbeat).
MODES = {
    "MANUAL": 0, "ACRO": 1, "STEERING": 3, "HOLD": 4, "LOITER": 5, "FOLLOW": 6,
    "SIMPLE": 7, "DOCK": 8, "CIRCLE": 9, "AUTO": 10, "RTL": 11, "SMART_RTL": 12,
    "GUIDED": 15, "INITIALISING": 16,
}
MODE_NAMES = {v: k for k, v in MODES.items()}

# RC_OPTIONS bits (RC_Channels::Option).
RC_OPTION_IGNORE_RECEIVER = 1 << 0
RC_OPTION_IGNORE_OVERRIDES = 1 << 1  # "Ignore MAVLink Overrides"

# Parameter names, old (up to 4.5) and new (4.6 and later): accept either.
PARAM_ALIASES = {
    "gcs_sysid": ("SYSID_MYGCS", "MAV_GCS_SYSID"),
    "arming_check": ("ARMING_CHECK", "ARMING_SKIPCHK"),
}

OVERRIDE_RELEASE = 0  # RC_CHANNELS_OVERRIDE value that hands a channel back to the receiver
OVERRIDE_IGNORE = 65535  # ... that leaves a channel as it is (MAVLink 1 meaning of UINT16_MAX)

# Defaults of the parameters the bridge reads (ArduPilot Rover).
DEFAULT_PARAMS = {
    "RCMAP_ROLL": 1.0,  # steering channel
    "RCMAP_THROTTLE": 3.0,
    "RC_OVERRIDE_TIME": 3.0,  # s; stale overrides end after this
    "RC_OPTIONS": 0.0,
    "SYSID_THISMAV": 1.0,
    "MAV_GCS_SYSID": 255.0,
    "ARMING_SKIPCHK": 0.0,
    **{f"RC{n}_{k}": v for n in range(1, 17)
       for k, v in (("MIN", 1100.0), ("MAX", 1900.0), ("TRIM", 1500.0), ("DZ", 0.0),
                    ("REVERSED", 0.0))},
    # A running Rover: the steering and throttle channels have a dead zone of 30 us.
    "RC1_DZ": 30.0,
    "RC3_DZ": 30.0,
    # Servo outputs (SRV_Channel): 1100-1900 us, trim 1500; output 1 steers (GroundSteering,
    # 26) and output 3 throttles (Throttle, 70), Rover's defaults; the others are disabled.
    **{f"SERVO{n}_{k}": v for n in range(1, 17)
       for k, v in (("FUNCTION", 0.0), ("MIN", 1100.0), ("MAX", 1900.0), ("TRIM", 1500.0),
                    ("REVERSED", 0.0))},
    "SERVO1_FUNCTION": 26.0,
    "SERVO3_FUNCTION": 70.0,
}

ROVER_INIT_DEAD_ZONE_US = 30.0
"""`Rover::init_rc_in()` gives the steering and throttle channels (RCMAP_ROLL, RCMAP_THROTTLE)
a dead-zone default of 30 us late in start-up (after the barometer calibration); until then,
and on every other channel, an RCn_DZ not stored reads 0 (RC_Channel's own default). MAVLink
answers during start-up, so a parameter read then is not the one that applies."""

# HEARTBEAT.system_status values (MAV_STATE) that mean the autopilot is not yet running;
# Rover reports MAV_STATE_CALIBRATING, in mode INITIALISING, until its start-up is over.
MAV_STATE_STARTING = {0: "UNINIT", 1: "BOOT", 2: "CALIBRATING"}

# RC_CHANNELS_OVERRIDE, channels 9..18: 0 and UINT16_MAX leave a channel as it is, this value
# hands it back to the receiver (MAVLink spec; channels 1..8 use OVERRIDE_RELEASE = 0).
OVERRIDE_RELEASE_HIGH = 65534

# MAV_CMD_COMPONENT_ARM_DISARM param2 that forces arming/disarming past the checks.
FORCE_ARM_MAGIC = 21196

# Arming-check bits (AP_Arming::Check). ARMING_CHECK (old) lists the checks to DO, with bit 0
# meaning all of them; ARMING_SKIPCHK (new) lists the checks to SKIP (-1: skip everything).
ARMING_CHECK_ALL = 1 << 0
ARMING_CHECK_GPS = 1 << 3  # Rover runs its AHRS/position-estimate check with the GPS checks

# Defaults of the old names: ARMING_CHECK = 1 does every check.
LEGACY_DEFAULTS = {"SYSID_MYGCS": 255.0, "ARMING_CHECK": 1.0}

# ArduPilot SITL's default home (CMAC, Canberra): lat deg, lon deg, alt m.
SITL_DEFAULT_HOME = (-35.363261, 149.165230, 584.0)
