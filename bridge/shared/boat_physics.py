"""The boat FMU as an autopilot's physics, built from a scenario in a folder of its own.

The simulated Rover (`autopilot_sim.rover`) and SITL's JSON backend (`sitl.json_physics`)
each own one: the FMU with the scenario's plant parameters and actuator rates, started at
the scenario's initial state in its current, stepped with (nT, nS) percent, and closed with
its temporary folder. Any other plant (`reset`, `step`, `close`) may stand in for the FMU.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np


class BoatPhysics:
    """One plant started from a scenario; `output` is its last `PlantOutput`."""

    def __init__(self, scenario, work_dir=None, *, plant=None, tmp_prefix="canalnav-physics-"):
        self.initial_state = np.asarray(scenario.initial_state, float).copy()
        self.current_ne = tuple(float(c) for c in scenario.current_ne)
        self._tmp = None
        self.plant = None
        try:
            self.plant = plant if plant is not None else self._fmu(scenario, work_dir, tmp_prefix)
            self.output = self.plant.reset(self.initial_state, self.current_ne)
        except BaseException:
            self.close()
            raise

    def _fmu(self, scenario, work_dir, tmp_prefix):
        """The boat FMU with the scenario's plant parameters and actuator rates."""
        from scenarios.plants.fmu import FmuPlant
        from scenarios.plants.plant import ActuatorLimits

        if work_dir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix=tmp_prefix)
            work_dir = self._tmp.name
        return FmuPlant(scenario.plant_params, ActuatorLimits(*scenario.actuator_rates),
                        Path(work_dir))

    def reset(self):
        """Back to the scenario's initial state and current (a reboot of SITL)."""
        self.output = self.plant.reset(self.initial_state, self.current_ne)
        return self.output

    def step(self, commands, dt: float):
        """Hold (nT, nS) percent for `dt` seconds."""
        self.output = self.plant.step(commands, dt)
        return self.output

    def close(self) -> None:
        """Close the plant and remove the FMU's temporary folder (again: nothing)."""
        if self.plant is not None:
            self.plant.close()
            self.plant = None
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None
