"""RC input of the simulated autopilot: a receiver held at trim, and MAVLink overrides.

ArduPilot semantics (RC_Channels / GCS_MAVLINK::handle_rc_channels_override): channels 1-8
take 0 as "release" and UINT16_MAX as "leave as is"; channels 9-18 take 0 and UINT16_MAX as
"leave as is" and UINT16_MAX-1 as "release". Each channel's override lasts RC_OVERRIDE_TIME
seconds after its last update (0: overrides disabled, negative: no timeout); RC_OPTIONS bit
"ignore MAVLink overrides" drops them all. Who may override (the GCS sysid) is checked by
the caller.
"""

from __future__ import annotations

from dataclasses import dataclass

from bridge.shared import ardupilot

N_CHANNELS = 18  # RC_CHANNELS_OVERRIDE carries 18; ArduPilot has 16 RCn_ parameter sets
UINT16_MAX = ardupilot.OVERRIDE_IGNORE


@dataclass
class Override:
    pwm: int
    time_s: float  # when it was last set (boot clock of the caller)


class RcInput:
    """Per-channel overrides with their times; `pwm(channel, ...)` is what the firmware reads."""

    def __init__(self):
        self._overrides: dict[int, Override] = {}

    def clear(self) -> None:
        self._overrides.clear()

    def apply(self, values: list[int], now_s: float, ignore_overrides: bool) -> None:
        """One RC_CHANNELS_OVERRIDE's chan1..chan18 raw values, received at `now_s`."""
        if ignore_overrides:
            return
        for i, raw in enumerate(values[:N_CHANNELS]):
            ch = i + 1
            raw = int(raw)
            if ch <= 8:
                if raw == UINT16_MAX:
                    continue
                value = raw  # 0 releases
            else:
                if raw in (0, UINT16_MAX):
                    continue
                value = 0 if raw == ardupilot.OVERRIDE_RELEASE_HIGH else raw
            if value == ardupilot.OVERRIDE_RELEASE:
                self._overrides.pop(ch, None)
            else:
                self._overrides[ch] = Override(value, now_s)

    def active(self, channel: int, now_s: float, timeout_s: float, ignore_overrides: bool) -> int | None:
        """The override PWM of `channel` if one is in force, else None."""
        ov = self._overrides.get(channel)
        if ov is None or ignore_overrides or timeout_s == 0:
            return None
        if timeout_s > 0 and now_s - ov.time_s >= timeout_s:
            return None
        return ov.pwm

    def pwm(self, channel: int, params, now_s: float) -> int:
        """What the firmware reads on `channel`: the override, else the receiver (at trim)."""
        ignore = bool(int(params.get("RC_OPTIONS", 0)) & ardupilot.RC_OPTION_IGNORE_OVERRIDES)
        ov = self.active(channel, now_s, float(params.get("RC_OVERRIDE_TIME", 3.0)), ignore)
        if ov is not None:
            return ov
        return int(params.get(f"RC{channel}_TRIM", 1500))

    def channels(self, params, now_s: float, n: int = N_CHANNELS) -> list[int]:
        return [self.pwm(ch, params, now_s) for ch in range(1, n + 1)]
