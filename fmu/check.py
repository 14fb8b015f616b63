"""Checks an FMU of ours must pass: fmpy's validation, a self-contained binary, a short run."""

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


def check_fmu(path: str | Path, simulate_s: float = 10.0) -> list[str]:
    """Problems found (empty when fine): fmpy validation, binary dependencies, a 10 s run."""
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
    return problems
