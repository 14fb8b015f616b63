"""The boat FMU as the closed loop's plant: the exact model, stepped through fmpy.

The FMU is built once (fmu.build's cache makes later builds a copy) with the identified
values as start values; the scenario's plant parameters, initial state, current and the
actuators' rate limits are set as FMU parameters, as any FMI tool would.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from controller.params import BoatParams
from scenarios.plants.plant import ActuatorLimits, PlantOutput


class FmuPlant:
    name = "fmu"

    def __init__(self, params: BoatParams, limits: ActuatorLimits, work_dir: Path,
                 fmi_version: int = 2, internal_step_s: float = 0.01):
        from fmu.build import build_fmu
        from fmu.plant import FmuBoat

        self.params = params
        self.limits = limits
        self.internal_step_s = internal_step_s
        path = build_fmu(Path(work_dir) / f"boat-fmi{fmi_version}.fmu", fmi_version)
        self._boat = FmuBoat(path)
        self._fresh = True

    def reset(self, state0, current_ne=(0.0, 0.0)) -> PlantOutput:
        if not self._fresh:
            self._boat.reset()
        self._fresh = False
        out = self._boat.setup(
            params=self.params, state0=np.asarray(state0, float), current=tuple(current_ne),
            rate_max=(self.limits.dnT_max, self.limits.dnS_max),
            internal_step=self.internal_step_s,
        )
        return self._output(out)

    def set_current(self, current_ne) -> None:
        """The current (north, east, m/s) from now on: the FMU's current inputs."""
        self._boat.set_current(float(current_ne[0]), float(current_ne[1]))

    def step(self, command, dt: float) -> PlantOutput:
        nT, nS = np.clip(np.asarray(command, float), -100.0, 100.0)
        return self._output(self._boat.step(float(nT), float(nS), dt))

    def _output(self, out: np.ndarray) -> PlantOutput:
        x = out[:6].copy()
        c, s = np.cos(x[2]), np.sin(x[2])
        xdot = np.array([c * x[3] - s * x[4], s * x[3] + c * x[4], x[5], out[6], out[7], out[8]])
        return PlantOutput(self._boat.time, x, xdot, out[9:11].copy())

    def close(self) -> None:
        self._boat.close()
