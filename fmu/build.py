"""Build a co-simulation FMU: generate the C, compile it with gcc, zip binary + sources.

The FMI headers come from the installed fmpy package; the archive carries every source a tool
on another platform needs (FMI 2.0 <SourceFiles>, FMI 3.0 sources/buildDescription.xml).
Builds are cached by the hash of everything that goes into them.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
import uuid
import zipfile
from dataclasses import dataclass
from pathlib import Path

from controller.errors import InputError
from controller.params import IDENTIFIED, BoatParams

from . import codegen
from .model_description import MODEL_IDENTIFIER, build_description_xml, fmi2_xml, fmi3_xml
from .variables import variables

C_DIR = Path(__file__).with_name("c")
WRAPPER_SOURCES = ("model.h", "model.c")
CFLAGS = ("-std=c99", "-O2", "-fPIC", "-fvisibility=hidden", "-Wall")
LDFLAGS = ("-shared", "-static-libgcc", "-Wl,--no-undefined", "-lm")
FMI_VERSIONS = (2, 3)


@dataclass(frozen=True)
class Sources:
    """A generated source tree: the folder, the files to compile and the build's identity."""

    folder: Path
    compile_files: tuple[str, ...]  # .c files, in compile order
    all_files: tuple[str, ...]  # everything shipped under sources/
    token: str  # GUID / instantiationToken, derived from the content hash
    digest: str
    table: tuple  # the variable table (fmu.variables.Variable) with this build's start values


def fmi_headers_dir() -> Path:
    """Where the installed fmpy keeps fmi2Functions.h / fmi3Functions.h."""
    import fmpy

    folder = Path(fmpy.__file__).parent / "c-code"
    if not (folder / "fmi2Functions.h").is_file() or not (folder / "fmi3Functions.h").is_file():
        raise InputError(f"{folder}: the FMI headers are missing from the installed fmpy")
    return folder


def _fmpy_version() -> str:
    import fmpy

    return getattr(fmpy, "__version__", "unknown")


def platform_folder(fmi_version: int) -> str:
    """binaries/<folder> for the building platform: linux64 (FMI 2.0), x86_64-linux (3.0)."""
    import fmpy

    return fmpy.platform if fmi_version == 2 else fmpy.platform_tuple


def _check_version(fmi_version: int) -> int:
    if fmi_version not in FMI_VERSIONS:
        raise InputError(f"--fmi-version: expected 2 or 3, got {fmi_version!r}")
    return fmi_version


def generate_sources(folder: Path, fmi_version: int, params: BoatParams = IDENTIFIED) -> Sources:
    """Write every C source of the FMU into `folder` (generated and hand-written)."""
    _check_version(fmi_version)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    wrapper = f"fmi{fmi_version}_wrapper.c"
    generated = codegen.generate_dynamics(folder)
    copied = []
    for name in (*WRAPPER_SOURCES, wrapper):
        shutil.copyfile(C_DIR / name, folder / name)
        copied.append(folder / name)
    table = variables(params)
    digest = codegen.source_hash(
        generated + copied,
        extra=f"fmi{fmi_version}|{params.as_vector().tobytes().hex()}|{CFLAGS}|{LDFLAGS}"
              f"|fmpy headers {_fmpy_version()}",
    )
    token = "{" + str(uuid.UUID(digest[:32])) + "}"
    (folder / codegen.CONFIG_H).write_text(codegen.config_header(table, token))
    compile_files = (codegen.DYNAMICS_C, "model.c", wrapper)
    all_files = (codegen.DYNAMICS_C, codegen.DYNAMICS_H, codegen.CONFIG_H, "model.h",
                 "model.c", wrapper)
    return Sources(folder, compile_files, all_files, token, digest, table)


def compile_shared_library(sources: Sources, fmi_version: int, out: Path, cc: str = "gcc"
                           ) -> Path:
    """gcc the sources into one shared object that needs nothing outside the FMU but libc/libm."""
    if shutil.which(cc) is None:
        raise InputError(f"C compiler {cc!r} not found on PATH (the FMU build needs gcc)")
    command = [cc, *CFLAGS, f"-I{sources.folder}", f"-I{fmi_headers_dir()}",
               f"-DFMI_VERSION={fmi_version}", "-o", str(out),
               *(str(sources.folder / f) for f in sources.compile_files), *LDFLAGS]
    result = subprocess.run(command, capture_output=True, text=True)
    if result.returncode != 0:
        raise InputError(f"compiling the FMU failed ({' '.join(command)}):\n{result.stderr}")
    return out


def assemble(sources: Sources, fmi_version: int, library: Path, out: Path) -> Path:
    """Zip modelDescription.xml, the binary and the sources into `out` (.fmu)."""
    if fmi_version == 2:
        description = fmi2_xml(sources.table, sources.token, list(sources.compile_files))
    else:
        description = fmi3_xml(sources.table, sources.token)
    out.parent.mkdir(parents=True, exist_ok=True)
    partial = out.with_name(out.name + ".partial")
    with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("modelDescription.xml", description)
        archive.write(library, f"binaries/{platform_folder(fmi_version)}/{MODEL_IDENTIFIER}.so")
        for name in sources.all_files:
            archive.write(sources.folder / name, f"sources/{name}")
        if fmi_version == 3:
            archive.writestr("sources/buildDescription.xml",
                             build_description_xml(list(sources.compile_files)))
    os.replace(partial, out)
    return out


def cache_dir() -> Path:
    """$XDG_CACHE_HOME/canalnav/fmu (or ~/.cache/canalnav/fmu)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "canalnav" / "fmu"


def build_fmu(out: str | Path, fmi_version: int = 2, params: BoatParams = IDENTIFIED,
              use_cache: bool = True, cc: str = "gcc") -> Path:
    """Build the boat FMU for `fmi_version` with `params` as start values; return its path.

    With `use_cache`, an identical earlier build (same generated code, wrappers, parameters,
    flags) is copied from the cache instead of compiled again.
    """
    _check_version(fmi_version)
    out = Path(out)
    with tempfile.TemporaryDirectory(prefix="canalnav-fmu-") as tmp:
        sources = generate_sources(Path(tmp) / "sources", fmi_version, params)
        cached = cache_dir() / f"boat-fmi{fmi_version}-{sources.digest[:24]}.fmu"
        if use_cache and cached.is_file():
            if cached.resolve() != out.resolve():
                out.parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(cached, out)
            return out
        library = compile_shared_library(sources, fmi_version, Path(tmp) / "boat.so", cc)
        assemble(sources, fmi_version, library, out)
    if use_cache:
        try:
            cached.parent.mkdir(parents=True, exist_ok=True)
            partial = cached.with_name(cached.name + f".{os.getpid()}.partial")
            shutil.copyfile(out, partial)
            os.replace(partial, cached)
        except OSError:
            pass  # a read-only cache only costs a rebuild next time
    return out
