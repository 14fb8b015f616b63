"""FMU outputs against solve_ivp on the same equations: the 1e-5-of-range criterion."""

import numpy as np
import pytest

from controller.model import EXACT, ode_function
from controller.params import IDENTIFIED
from fmu.plant import OUTPUT_INDEX, FmuBoat
from fmu.variables import OUTPUT_NAMES
from fmu.verify import Script, actuator_grid, fmu_outputs, reference_outputs

SCRIPT = Script()


@pytest.fixture(scope="module")
def references():
    return {}


def reference(references, script, step):
    key = (script, step)
    if key not in references:
        references[key] = reference_outputs(script, step)
    return references[key]


def relative_errors(ours, ref):
    span = np.ptp(ref, axis=0)
    assert np.all(span > 0), "every output must move in the scripted run"
    return np.max(np.abs(ours - ref), axis=0) / span


@pytest.mark.parametrize("step", [0.1, 1.0])
def test_300_s_run_matches_solve_ivp_to_1e_5_of_each_range(fmu_path, step, references):
    ours = fmu_outputs(fmu_path, SCRIPT, step)
    ref = reference(references, SCRIPT, step)
    assert ours.shape == ref.shape == (int(round(300 / step)) + 1, len(OUTPUT_NAMES))
    errors = relative_errors(ours, ref)
    worst = {n: float(e) for n, e in zip(OUTPUT_NAMES, errors)}
    assert max(worst.values()) < 1e-5, worst


@pytest.mark.parametrize("step", [0.07, 0.33])
def test_steps_that_do_not_divide_the_internal_step_are_exact_too(fmus, step, references):
    script = Script(duration_s=60.06 if step == 0.07 else 59.73)
    ref = reference(references, script, step)
    for path in fmus.values():
        assert max(relative_errors(fmu_outputs(path, script, step), ref)) < 1e-5


def test_scripted_run_exercises_rate_limits_reverse_and_zigzag():
    starts, lengths, acts = actuator_grid(SCRIPT, 0.1)
    assert acts[:, 0].min() == -30.0 and acts[:, 1].max() == 50.0 and acts[:, 1].min() == -50.0
    # throttle moves at most 10 %/s, steering 40 %/s
    assert np.max(np.abs(np.diff(acts[:, 0]))) == pytest.approx(10 * 0.05)
    assert np.max(np.abs(np.diff(acts[:, 1]))) == pytest.approx(40 * 0.05)
    assert np.allclose(np.diff(starts), lengths[:-1])


def test_outputs_belong_to_the_end_of_the_step_not_the_start(fmu_path):
    """No shift by one step: after doStep(t, H) the outputs are those at t + H."""
    f = ode_function(EXACT)
    p = IDENTIFIED.as_vector()
    with FmuBoat(fmu_path) as boat:
        y0 = boat.setup(state0=[0, 0, 0, 1.0, 0, 0], current=(0.2, 0.1))
        y1 = boat.step(60.0, 30.0, 2.0)
        # no rate limit: the actuators follow the command over the first step
        assert y1[OUTPUT_INDEX["nT_actual"]] == 60.0 and y0[OUTPUT_INDEX["nT_actual"]] == 0.0
        assert y1[OUTPUT_INDEX["x"]] > 2.0
        x1, act1 = y1[:6], y1[9:11]
        accel = np.asarray(f(x1, act1, p, [0.2, 0.1])).ravel()[3:]
        assert np.allclose(y1[6:9], accel, rtol=1e-12, atol=1e-15)
        assert y1[OUTPUT_INDEX["u_dot"]] != y0[OUTPUT_INDEX["u_dot"]]
