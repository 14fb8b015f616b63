"""Check an FMU's outputs against an independent integration of the same equations.

The reference integrates `controller.model.ode_function()` (exact variant) with scipy's
`solve_ivp` at tight tolerances, driven by the same actuator signal: commands held over each
communication step, the rate limit applied per internal step (re-implemented here in numpy),
the actuators held over each internal step. The scripted run has throttle steps (reverse
included), a steering zigzag, a water current and the real rate limits on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from controller.params import IDENTIFIED, BoatParams

from .variables import DEFAULT_INTERNAL_STEP_S, OUTPUT_NAMES


@dataclass(frozen=True)
class Script:
    """A scripted run: commands change only at whole seconds, so any step <= 1 s meets them."""

    duration_s: float = 300.0
    current_mps: tuple[float, float] = (0.25, -0.15)  # toward north, toward east
    rate_max: tuple[float, float] = (10.0, 40.0)  # %/s, the real actuators
    state0: tuple[float, ...] = (0.0, 0.0, 0.3, 0.5, 0.0, 0.0)
    actuators0: tuple[float, float] = (0.0, 0.0)
    internal_step_s: float = DEFAULT_INTERNAL_STEP_S
    params: BoatParams = IDENTIFIED

    def commands(self, t: float) -> tuple[float, float]:
        """Throttle steps (31, 50.6, 20, -30 reverse, 42 %) and a 50 % steering zigzag."""
        s = math.floor(t + 1e-9)
        throttle = 0.0
        for start, value in ((2, 31.0), (50, 50.6), (120, 20.0), (170, -30.0), (200, 42.0)):
            if s >= start:
                throttle = value
        steering = 0.0
        if 30 <= s < 270:
            steering = 50.0 if ((s - 30) // 20) % 2 == 0 else -50.0
        return throttle, steering


def actuator_grid(script: Script, comm_step: float):
    """The internal grid of an FMU run: start times, lengths and the actuator values held.

    Mirrors the FMU's rule: each communication step H is cut into ceil(H / h) equal steps; at
    the start of each, the actuators move toward the command by at most rate * step.
    """
    n_comm = int(round(script.duration_s / comm_step))
    act = np.clip(np.asarray(script.actuators0, float), -100, 100)
    rate = np.asarray(script.rate_max, float)
    starts, lengths, values = [], [], []
    for k in range(n_comm):
        t_comm = k * comm_step
        cmd = np.asarray(script.commands(t_comm), float)
        n_sub = max(1, math.ceil(comm_step / script.internal_step_s - 1e-9))
        dt = comm_step / n_sub
        for j in range(n_sub):
            limited = act + np.clip(cmd - act, -rate * dt, rate * dt)
            act = np.clip(np.where(rate > 0, limited, cmd), -100, 100)
            starts.append(t_comm + j * dt)
            lengths.append(dt)
            values.append(act.copy())
    return np.array(starts), np.array(lengths), np.array(values)


def reference_outputs(script: Script, comm_step: float, rtol: float = 1e-11,
                      atol: float = 1e-11) -> np.ndarray:
    """Outputs (OUTPUT_NAMES columns) at every communication point, from solve_ivp."""
    from scipy.integrate import solve_ivp

    from controller.model import EXACT, ode_function

    f = ode_function(EXACT)
    p = script.params.as_vector()
    current = np.asarray(script.current_mps, float)

    def accel(x, act):
        return np.asarray(f(x, act, p, current)).ravel()

    starts, lengths, acts = actuator_grid(script, comm_step)
    n_comm = int(round(script.duration_s / comm_step))
    comm_times = np.arange(n_comm + 1) * comm_step  # the FMU's k * H
    x = np.asarray(script.state0, float)
    act = np.clip(np.asarray(script.actuators0, float), -100, 100)
    rows = [np.concatenate([x, accel(x, act)[3:], act])]
    # one solve_ivp per stretch of constant actuators; communication points inside a stretch
    # come from the integrator's dense output (7th order, within the tolerances)
    i, n = 0, len(starts)
    while i < n:
        j = i
        while j + 1 < n and np.array_equal(acts[j + 1], acts[i]):
            j += 1
        t0, t1, act = starts[i], starts[j] + lengths[j], acts[i]
        inside = comm_times[len(rows):]
        inside = inside[inside <= t1 + 1e-9 * comm_step]
        sol = solve_ivp(lambda t, z, a=act: accel(z, a), (t0, t1), x, method="DOP853",
                        rtol=rtol, atol=atol, dense_output=len(inside) > 0)
        if not sol.success:
            raise RuntimeError(f"reference integration failed at t = {t0}: {sol.message}")
        for t in inside:
            z = sol.y[:, -1] if abs(t - t1) <= 1e-9 * comm_step else sol.sol(t)
            rows.append(np.concatenate([z, accel(z, act)[3:], act]))
        x = sol.y[:, -1]
        i = j + 1
    return np.array(rows)


def fmu_outputs(fmu_path: str | Path, script: Script, comm_step: float) -> np.ndarray:
    """Outputs at every communication point of the scripted run through the FMU (fmpy)."""
    from .plant import FmuBoat

    n_comm = int(round(script.duration_s / comm_step))
    with FmuBoat(fmu_path) as boat:
        rows = [boat.setup(script.params, script.state0, script.actuators0,
                           script.current_mps, script.rate_max, script.internal_step_s,
                           stop_time=script.duration_s)]
        for k in range(n_comm):
            rows.append(boat.step(*script.commands(k * comm_step), comm_step))
    return np.array(rows)


def compare(fmu_path: str | Path, comm_step: float, script: Script = Script()) -> dict:
    """Largest error of each output over the run, relative to that output's range."""
    ours = fmu_outputs(fmu_path, script, comm_step)
    ref = reference_outputs(script, comm_step)
    result = {}
    for i, name in enumerate(OUTPUT_NAMES):
        span = float(np.ptp(ref[:, i]))
        err = float(np.max(np.abs(ours[:, i] - ref[:, i])))
        result[name] = {"max_error": err, "range": span,
                        "relative": err / span if span > 0 else (0.0 if err == 0 else math.inf)}
    return result
