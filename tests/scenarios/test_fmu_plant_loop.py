"""The FMU plant in the closed loop agrees with the Python model it was generated from."""

import numpy as np
import pytest

from controller.params import IDENTIFIED
from scenarios.plants.fmu import FmuPlant
from scenarios.plants.plant import ActuatorLimits, ModelPlant


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_fmu_plant_matches_model_plant(tmp_path, fmi_version):
    params = IDENTIFIED.replace(m11=2100.0)  # set as FMU parameters, not build-time start values
    limits = ActuatorLimits(10.0, 40.0)
    fmu = FmuPlant(params, limits, tmp_path, fmi_version=fmi_version)
    ref = ModelPlant(params, limits, internal_step_s=0.01)
    x0 = [1.0, 2.0, 0.3, 1.0, 0.0, 0.0]
    for run in range(2):  # the second run goes through FMI reset
        a, b = fmu.reset(x0, (0.2, -0.1)), ref.reset(x0, (0.2, -0.1))
        for k in range(600):
            cmd = [45.0, 60.0 * np.sign(np.sin(k / 100))]
            a, b = fmu.step(cmd, 0.01), ref.step(cmd, 0.01)
        assert a.time_s == pytest.approx(6.0)
        np.testing.assert_allclose(a.state, b.state, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(a.state_dot[3:], b.state_dot[3:], rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(a.actuators, b.actuators, atol=1e-12)
    fmu.close()
