"""`canalnav bench fmu`: doStep calls per second through fmpy, FMI 2.0 and 3.0, against the
same simulation with the CasADi model integrated in Python, as ratios measured in one run."""

from __future__ import annotations

import json


def register_bench(bench_sub) -> None:
    p = bench_sub.add_parser(
        "fmu", help="FMU doStep rate (FMI 2.0, 3.0) vs the CasADi model in Python",
        description="Steps the boat FMUs through fmpy (its high-level API and canalnav's "
        "FmuBoat fast path) and the same run with controller.model's CasADi plant step "
        "called from Python; prints one JSON object with rates and ratios.",
    )
    p.add_argument("--steps", type=int, default=3000, help="communication steps (default 3000)")
    p.add_argument("--dt", type=float, default=0.1, help="communication step in s (default 0.1)")
    p.add_argument("--repeat", type=int, default=3, help="best of this many runs (default 3)")
    p.set_defaults(func=run)


def _commands(k: int, dt: float) -> tuple[float, float]:
    t = k * dt
    return (42.0 if t >= 1.0 else 0.0), (50.0 if int(t // 20) % 2 == 0 else -50.0)


def _best_rate(run, steps: int, repeat: int):
    import time

    best, final = float("inf"), None
    for _ in range(repeat):
        start = time.perf_counter()
        final = run()
        best = min(best, time.perf_counter() - start)
    return steps / best, final


def run(args) -> int:
    import math
    import tempfile
    from pathlib import Path

    import numpy as np

    from controller.errors import InputError
    from controller.model import plant_step_function
    from controller.params import IDENTIFIED
    from fmu.build import build_fmu
    from fmu.plant import FmuBoat
    from fmu.variables import DEFAULT_INTERNAL_STEP_S, OUTPUT_NAMES, VR

    if args.steps < 1 or not args.dt > 0 or args.repeat < 1:
        raise InputError("--steps and --repeat must be >= 1 and --dt positive")
    steps, dt = args.steps, args.dt
    rate_max = (10.0, 40.0)
    n_sub = max(1, math.ceil(dt / DEFAULT_INTERNAL_STEP_S - 1e-9))
    result: dict = {"steps": steps, "dt_s": dt, "internal_steps_per_doStep": n_sub}
    finals = {}

    with tempfile.TemporaryDirectory() as tmp:
        paths = {v: build_fmu(Path(tmp) / f"boat{v}.fmu", v) for v in (2, 3)}
        for v, path in paths.items():
            boat = FmuBoat(path)

            def fast(boat=boat):
                boat.reset()
                boat.setup(rate_max=rate_max)
                for k in range(steps):
                    y = boat.step(*_commands(k, dt), dt)
                return y

            rate, finals[f"fmi{v}"] = _best_rate(fast, steps, args.repeat)
            result[f"fmi{v}_fmuboat_steps_per_s"] = round(rate)
            boat.close()

            # fmpy's own high-level API, as any fmpy user would step it
            boat = FmuBoat(path)
            slave = boat._slave
            vr_in, vr_out = [VR["nT"], VR["nS"]], [VR[n] for n in OUTPUT_NAMES]
            set_values = slave.setReal if v == 2 else slave.setFloat64
            get_values = slave.getReal if v == 2 else slave.getFloat64

            def plain(boat=boat, set_values=set_values, get_values=get_values):
                boat.reset()
                boat.setup(rate_max=rate_max)
                t = 0.0
                for k in range(steps):
                    set_values(vr_in, list(_commands(k, dt)))
                    boat._slave.doStep(t, dt)
                    t = (k + 1) * dt
                    y = get_values(vr_out)
                return np.array(y)

            rate, _ = _best_rate(plain, steps, args.repeat)
            result[f"fmi{v}_fmpy_api_steps_per_s"] = round(rate)
            boat.close()

    plant = plant_step_function()
    p = IDENTIFIED.as_vector()
    current = np.zeros(2)
    rates = np.array(rate_max)
    h = dt / n_sub

    def casadi_python():
        x, act = np.zeros(6), np.zeros(2)
        for k in range(steps):
            cmd = np.array(_commands(k, dt))
            for _ in range(n_sub):
                x_next, act_next, _xdot = plant(x, act, cmd, p, current, rates, h)
                x, act = np.asarray(x_next).ravel(), np.asarray(act_next).ravel()
        return x

    rate_casadi, x_casadi = _best_rate(casadi_python, steps, args.repeat)
    result["casadi_python_steps_per_s"] = round(rate_casadi)
    for key in list(result):
        if key.endswith("_steps_per_s") and key != "casadi_python_steps_per_s":
            result[key.replace("_steps_per_s", "_vs_casadi_python")] = round(
                result[key] / rate_casadi, 2)
    result["max_state_difference_vs_casadi_python"] = float(max(
        np.max(np.abs(finals[f"fmi{v}"][:6] - x_casadi)) for v in (2, 3)))
    print(json.dumps(result))
    return 0
