"""`canalnav fmu build|check`: the boat as FMI 2.0 / 3.0 co-simulation FMUs."""

from __future__ import annotations

import json
import os
from pathlib import Path


def register(sub) -> None:
    p = sub.add_parser(
        "fmu", help="build and check the boat's co-simulation FMUs (FMI 2.0 and 3.0)",
        description="Build the identified boat model as a co-simulation FMU (CasADi-generated C "
        "plus a small FMI wrapper, compiled with gcc, sources included), or check one.",
    )
    actions = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    p.canalnav_actions = actions  # for packages above fmu to add theirs (`fmu_actions`)

    b = actions.add_parser(
        "build", help="build boat.fmu for this platform (binary + sources)",
        description="Generate the C code of the boat model, compile it with gcc and pack a "
        "co-simulation FMU with the binary for this platform and all sources.",
    )
    b.add_argument("--fmi-version", type=int, choices=(2, 3), default=2,
                   help="FMI version (default 2)")
    b.add_argument("--params", help="boat parameter file (TOML, see `canalnav params`); its "
                   "values become the FMU's start values (default: the paper's identified set)")
    b.add_argument("-o", "--out", default=None,
                   help="output file (default boat-fmi<version>.fmu)")
    b.add_argument("--no-cache", action="store_true",
                   help="compile even if an identical build is in the cache")
    b.set_defaults(func=run_build)

    c = actions.add_parser(
        "check", help="validate an FMU (fmpy), check its binary, run it; optionally compare",
        description="fmpy validation, binary dependencies and a 10 s run; with --compare, the "
        "outputs of a scripted 300 s run against scipy solve_ivp on the same equations.",
    )
    c.add_argument("fmu", help="the .fmu file")
    c.add_argument("--compare", action="store_true",
                   help="also compare with solve_ivp over 300 s (prints JSON; takes a while)")
    c.add_argument("--step", type=float, action="append", default=None,
                   help="communication step(s) in s for --compare (default 0.1 and 1.0)")
    c.set_defaults(func=run_check)


def fmu_actions(sub):
    """The `fmu` command's ACTION subparsers, for a package above fmu to add FMU actions that
    need what fmu may not import (scenarios: build-controller and system read scenarios)."""
    return sub.choices["fmu"].canalnav_actions


def run_build(args) -> int:
    from controller.params import IDENTIFIED, BoatParams
    from fmu.build import build_fmu

    params = BoatParams.from_toml(args.params) if args.params else IDENTIFIED
    out = args.out or f"boat-fmi{args.fmi_version}.fmu"
    path = build_fmu(out, args.fmi_version, params, use_cache=not args.no_cache)
    print(f"wrote {path} (FMI {args.fmi_version}.0 co-simulation)")
    return 0


def run_check(args) -> int:
    from controller.errors import InputError
    from fmu.check import CHECKS, check_fmu

    # fmpy changes into the FMU's folder to load its binary and, when that fails, leaves the
    # process in a folder it then deletes: the path is made absolute and the folder restored
    cwd = os.getcwd()
    path = str(Path(args.fmu).resolve())
    try:
        problems = check_fmu(path)
    finally:
        os.chdir(cwd)
    for problem in problems:
        print(f"{args.fmu}: {problem}")
    if not problems:
        for check in CHECKS:
            print(f"{args.fmu}: ok: {check}")
        print(f"{args.fmu}: no problems found")
    if args.compare:
        from fmu.verify import compare

        steps = args.step or [0.1, 1.0]
        for step in steps:
            if not step > 0:
                raise InputError(f"--step: must be positive, got {step!r}")
        report = {}
        for step in steps:
            try:
                result = compare(path, step)
            except InputError:
                raise
            except Exception as exc:  # a binary that does not load or run: fmpy's own errors
                problems.append(f"comparison at step {step:g} failed: {exc}")
                print(f"{args.fmu}: comparison at step {step:g} failed: {exc}")
                continue
            finally:
                os.chdir(cwd)
            worst = max(result.values(), key=lambda r: r["relative"])["relative"]
            report[f"{step:g}"] = {
                "worst_relative_error": float(f"{worst:.3g}"),
                "passes_1e-5": worst < 1e-5,
                "relative_error": {k: float(f"{v['relative']:.3g}") for k, v in result.items()},
                "range": {k: float(f"{v['range']:.4g}") for k, v in result.items()},
            }
            if worst >= 1e-5:
                problems.append(f"comparison at step {step}: error {worst:.3g} of the range")
        print(json.dumps({"fmu": args.fmu, "comparison": report}))
    return 1 if problems else 0
