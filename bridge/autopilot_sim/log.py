"""The simulated autopilot's onboard log: what ArduPilot Rover would write to its SD card.

One DataFlash file per boot (00000001.BIN, ... in the log folder, as ArduPilot numbers them):
every parameter (PARM, with its default) at the start and each change as it happens, MODE,
ARM and MSG (the STATUSTEXTs) when they happen, ORGN when the EKF sets its origin, and at
fixed rates of the autopilot's clock: RCIN and RCOU at 50 Hz (the loop rate Rover logs them
at), the EKF's XKF1, ATT, IMU and POS at 25 Hz, GPS at 5 Hz. XKF1 and POS begin with the
position estimate (at the first GPS fix). The values are the simulator's EKF estimate (truth
plus its coloured errors), its servo outputs and RC inputs; the IMU's accelerations are the
boat's. Flushed every second and on every event, so a killed run loses at most a second.
"""

from __future__ import annotations

import math
from pathlib import Path

from .dataflash import DataFlashWriter, next_log_path

RATES_HZ = {"rc": 50.0, "ekf": 25.0, "gps": 5.0}
FLUSH_S = 1.0
GRAVITY = 9.80665
GPS_WEEK, GPS_WEEK_MS = 2369, 201_600_000  # a fixed date for GPS time (2025-06-04 08:00 UTC)
MODE_REASON_GCS = 2  # ModeReason::GCS_COMMAND
MODE_REASON_INIT = 1  # ModeReason::INITIALISED


class AutopilotLog:
    """DataFlash logging of an `AutopilotSim` (it calls these as things happen)."""

    def __init__(self, directory: str | Path):
        self.directory = Path(directory)
        self.paths: list[Path] = []
        self._w: DataFlashWriter | None = None
        self._due: dict[str, float] = {}
        self._flush_due = 0.0

    @property
    def path(self) -> Path | None:
        """The file being written (None before the first boot or after closing)."""
        return None if self._w is None else self._w.path

    def start(self, sim) -> None:
        """A (re)boot: a new file, the parameters, the mode."""
        self.close()
        path = next_log_path(self.directory)
        self._w = DataFlashWriter(path)
        self.paths.append(path)
        self._due = {k: 0.0 for k in RATES_HZ}
        self._flush_due = 0.0
        defaults = sim.param_defaults
        for name, value in sorted(sim.params.items()):
            self._w.write("PARM", 0, name, value, defaults.get(name, value))
        self.mode(sim, MODE_REASON_INIT)

    def _us(self, sim) -> int:
        return max(0, int(round(sim.boot_s * 1e6)))

    def param(self, sim, name: str, value: float) -> None:
        if self._w is not None:
            self._w.write("PARM", self._us(sim), name, value, sim.param_defaults.get(name, value))
            self._w.flush()

    def mode(self, sim, reason: int = MODE_REASON_GCS) -> None:
        if self._w is not None:
            self._w.write("MODE", self._us(sim), sim.mode, sim.mode, reason)
            self._w.flush()

    def arm(self, sim, forced: bool) -> None:
        if self._w is not None:
            self._w.write("ARM", self._us(sim), int(sim.armed), 0, int(forced), 0)
            self._w.flush()

    def text(self, sim, text: str) -> None:
        if self._w is not None:
            self._w.write("MSG", self._us(sim), text[:64])

    def origin(self, sim) -> None:
        if self._w is not None and sim.ekf_origin is not None:
            lat, lon, alt = sim.ekf_origin
            self._w.write("ORGN", self._us(sim), 0, lat, lon, alt)  # Type 0: the EKF origin
            self._w.flush()

    def update(self, sim) -> None:
        """Write what is due at the autopilot's time now."""
        if self._w is None:
            return
        t = sim.boot_s
        us = self._us(sim)
        for group, rate in RATES_HZ.items():
            if t + 1e-9 < self._due[group]:
                continue
            nxt = self._due[group] + 1.0 / rate
            self._due[group] = nxt if nxt > t else t + 1.0 / rate
            getattr(self, f"_write_{group}")(sim, us)
        if t >= self._flush_due:
            self._flush_due = t + FLUSH_S
            self._w.flush()

    def _write_rc(self, sim, us: int) -> None:
        self._w.write("RCIN", us, *sim.rc_inputs(14))
        self._w.write("RCOU", us, *sim.servo_outputs(14))

    def _write_ekf(self, sim, us: int) -> None:
        e = sim.estimate
        yaw = math.degrees(e.psi_rad) % 360.0
        self._w.write("ATT", us, 0.0, 0.0, 0.0, 0.0, yaw, yaw, 0.0, 0.0, 3)
        out = sim.last_plant_output
        x, y, psi, u, v, r = (float(s) for s in out.state)
        ax = float(out.state_dot[3]) - r * v  # specific force, body axes
        ay = float(out.state_dot[4]) + r * u
        self._w.write("IMU", us, 0, 0.0, 0.0, e.r_radps, ax, ay, -GRAVITY, 0, 0, 25.0, 1, 1,
                      1000, 1000)
        if not sim.ekf_ready or sim.ekf_origin is None:
            return
        north, east = sim.local_position(e)
        alt = sim.ekf_origin[2]
        self._w.write("XKF1", us, 0, 0.0, 0.0, yaw, e.vn_mps, e.ve_mps, 0.0, 0.0, north, east,
                      0.0, 0.0, 0.0, 0.0, alt)
        lat, lon = sim.geodetic_position(e)
        self._w.write("POS", us, lat, lon, alt, 0.0, 0.0)

    def _write_gps(self, sim, us: int) -> None:
        e = sim.estimate
        fixed = sim.ekf_ready
        lat, lon = sim.geodetic_position(e) if fixed else (0.0, 0.0)
        speed = math.hypot(e.vn_mps, e.ve_mps) if fixed else 0.0
        course = math.degrees(math.atan2(e.ve_mps, e.vn_mps)) % 360.0 if fixed else 0.0
        gms = (GPS_WEEK_MS + us // 1000) % 604_800_000
        self._w.write("GPS", us, 0, 3 if fixed else 1, gms, GPS_WEEK, 12 if fixed else 0,
                      0.8 if fixed else 99.99, lat, lon,
                      sim.ekf_origin[2] if fixed and sim.ekf_origin else 0.0, speed, course, 0.0,
                      0.0, 1)

    def close(self) -> None:
        if self._w is not None:
            self._w.close()
            self._w = None
