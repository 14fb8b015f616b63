"""Checks an FMU of ours must pass: fmpy's validation, a self-contained binary, a short run,
and the lifecycle (FMU state round trip and reset bit for bit, two instances side by side)."""

from __future__ import annotations

import subprocess
import zipfile
from pathlib import Path

from controller.errors import InputError

ALLOWED_SYSTEM_LIBRARIES = ("linux-vdso", "libc.so", "libm.so", "ld-linux")


def binary_problems(path: Path) -> list[str]:
    """The platform binary must need nothing but the C runtime (libc, libm)."""
    import tempfile

    problems = []
    with zipfile.ZipFile(path) as archive, tempfile.TemporaryDirectory() as tmp:
        binaries = [n for n in archive.namelist() if n.startswith("binaries/") and n.endswith(".so")]
        if not binaries:
            return ["no shared library under binaries/"]
        for name in binaries:
            target = Path(archive.extract(name, tmp))
            try:
                out = subprocess.run(["ldd", str(target)], capture_output=True, text=True).stdout
            except FileNotFoundError:
                continue  # no ldd here: nothing to say
            for line in out.splitlines():
                lib = line.strip().split(" ")[0]
                if lib and not Path(lib).name.startswith(ALLOWED_SYSTEM_LIBRARIES):
                    problems.append(f"{name} needs {lib}, which is not in the FMU")
    return problems


CHECKS = (
    "fmpy validation of modelDescription.xml",
    "binary needs nothing outside the FMU but libc/libm",
    "10 s simulation with fmpy.simulate_fmu",
    "get/set FMU state round trip reproduces 60 s bit for bit",
    "reset reproduces the first run bit for bit",
    "two instances with different parameters run side by side",
)


def _commands(k: int) -> tuple[float, float]:
    return (45.0 if k > 5 else 0.0), (40.0 if (k // 100) % 2 == 0 else -40.0)


def _run(boat, k0: int, n: int):
    import numpy as np

    return np.array([boat.step(*_commands(k), 0.1) for k in range(k0, k0 + n)])


def lifecycle_problems(path: Path) -> list[str]:
    """State round trip and reset bit for bit; two instances with different masses agree
    with their solo runs."""
    import numpy as np

    from controller.params import IDENTIFIED

    from .plant import FmuBoat

    problems = []
    setup = dict(rate_max=(10.0, 40.0), current=(0.2, -0.1))
    with FmuBoat(path) as boat:
        boat.setup(**setup)
        first = _run(boat, 0, 300)
        snapshot = boat.get_state()
        later = _run(boat, 300, 600)
        boat.set_state(snapshot)
        if not np.array_equal(_run(boat, 300, 600), later):
            problems.append("get/set FMU state: the replayed trajectory differs")
        boat.free_state(snapshot)
        boat.reset()
        if boat.get_values(["time"])[0] != 0.0:
            problems.append("reset: time is not back at 0")
        boat.setup(**setup)
        if not np.array_equal(_run(boat, 0, 300), first):
            problems.append("reset: the second run differs from the first")
    heavy = IDENTIFIED.replace(m11=2 * IDENTIFIED.m11)
    with FmuBoat(path, "light") as a, FmuBoat(path, "heavy") as b:
        a.setup(IDENTIFIED, **setup)
        b.setup(heavy, **setup)
        side = [(a.step(*_commands(k), 0.1), b.step(*_commands(k), 0.1)) for k in range(300)]
    with FmuBoat(path, "heavy alone") as c:
        c.setup(heavy, **setup)
        alone = _run(c, 0, 300)
    if not np.array_equal(np.array([s[0] for s in side]), first):
        problems.append("two instances: the first differs from its solo run")
    if not np.array_equal(np.array([s[1] for s in side]), alone):
        problems.append("two instances: the second differs from its solo run")
    if np.array_equal(alone, first):
        problems.append("two instances: different parameters gave the same run")
    return problems


def check_fmu(path: str | Path, simulate_s: float = 10.0) -> list[str]:
    """Problems found (empty when fine): the CHECKS above, in order."""
    from fmpy import simulate_fmu
    from fmpy.validation import validate_fmu

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such FMU file")
    try:
        with zipfile.ZipFile(path) as archive:
            archive.getinfo("modelDescription.xml")
    except (zipfile.BadZipFile, KeyError) as exc:
        raise InputError(f"{path}: not an FMU: {exc}") from None
    problems = [f"validation: {p}" for p in validate_fmu(str(path))]
    problems += binary_problems(path)
    if not problems:
        try:
            result = simulate_fmu(str(path), stop_time=simulate_s, output_interval=0.1,
                                  start_values={"nT": 42.0, "nS": 20.0})
            if not (abs(result["time"][-1] - simulate_s) < 1e-9 and result["u"][-1] > 0):
                problems.append("simulation: the boat did not move forward under 42 % throttle")
        except Exception as exc:
            problems.append(f"simulation failed: {exc}")
    if not problems:
        problems += lifecycle_problems(path)
    return problems
