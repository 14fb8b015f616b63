"""Generate C for a CasADi Function, compile it once, and keep the shared library in the
user's cache folder.

The key is a hash of the generated code, the compiler flags and the CasADi version: a new
model, structure or flag gives a new library, an unchanged one is loaded without compiling,
and without needing a compiler (a boat computer may carry the cache but no gcc). With no
library and no compiler (or a failing one, or a library that does not load) the interpreted
Function is used, with a warning: slower, same results. CasADi's own `jit` recompiles at every
start; this does not.
"""

from __future__ import annotations

import hashlib
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import casadi as ca

DEFAULT_FLAGS = ("-O2",)
"""-O2: measured 4.0 s of gcc for the NMPC's linearisation, 149 us a call; -O3 4.4 s and
147 us; -O1 3.0 s and 149 us. The generated code is straight-line arithmetic, so -O2 is
all it needs."""


def cache_dir() -> Path:
    """$XDG_CACHE_HOME/canalnav, or ~/.cache/canalnav."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "canalnav"


def compiler() -> str | None:
    """The C compiler: $CC, else cc or gcc on the PATH; None when there is none."""
    for name in (os.environ.get("CC"), "cc", "gcc"):
        if name and shutil.which(name):
            return name
    return None


@dataclass(frozen=True)
class CompiledFunction:
    """A Function ready to call, and where it came from."""

    function: ca.Function
    compiled: bool  # False: the interpreted fallback
    cache_hit: bool  # the library was already in the cache
    library: Path | None
    compile_s: float  # gcc's time in this process (0 on a hit)


def generate_c(function: ca.Function) -> str:
    """The C source of `function` (one file, no header)."""
    gen = ca.CodeGenerator(f"{function.name()}.c", {"with_header": False})
    gen.add(function)
    return gen.dump()


def cache_key(code: str, flags: list[str]) -> str:
    """24 hex digits of the code, the compiler flags, the CasADi version and the platform (a
    cache folder copied from another machine must not hand over a foreign library)."""
    h = hashlib.sha256()
    for part in (code, "\0".join(flags), ca.__version__, sys.platform, platform.machine()):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()[:24]


def library_path(name: str, code: str, flags: tuple[str, ...] = DEFAULT_FLAGS,
                 link: tuple[str, ...] = ("-lm",), directory: Path | None = None) -> Path:
    """Where the library of `code` built with `flags` and `link` lives in the cache."""
    options = ["-shared", "-fPIC", *flags, *link]
    return (directory or cache_dir()) / f"{name}-{cache_key(code, options)}.so"


def build_library(name: str, code: str, flags: tuple[str, ...] = DEFAULT_FLAGS,
                  link: tuple[str, ...] = ("-lm",), directory: Path | None = None,
                  rebuild: bool = False) -> tuple[Path, bool, float]:
    """Compile C `code` into a cached shared library: (path, cache_hit, compile seconds);
    `rebuild` compiles over a cached one (that did not load).

    Raises OSError or CalledProcessError when it is not cached and there is no compiler or
    it fails.
    """
    directory = directory or cache_dir()
    library = library_path(name, code, flags, link, directory)
    if library.exists() and not rebuild:
        return library, True, 0.0
    cc = compiler()
    if cc is None:
        raise OSError("no C compiler found (set CC, or install gcc)")
    command = [cc, "-shared", "-fPIC", *flags]
    t0 = time.perf_counter()
    directory.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=directory) as tmp:
        source = Path(tmp) / f"{name}.c"
        source.write_text(code)
        built = Path(tmp) / library.name
        subprocess.run([*command, "-o", str(built), str(source), *link], check=True,
                       capture_output=True, text=True)
        os.replace(built, library)  # atomic: a concurrent process sees all or nothing
    return library, False, time.perf_counter() - t0


def load_cached(name: str, code: str, load, flags: tuple[str, ...] = DEFAULT_FLAGS,
                link: tuple[str, ...] = ("-lm",), directory: Path | None = None):
    """`load(path)` of the cached library of `code`, built first if needed, and rebuilt once
    if a cached one does not load (a broken file) and a compiler is there:
    (loaded, path, cache_hit, compile seconds). Raises what `build_library` or `load` raise."""
    path, hit, seconds = build_library(name, code, flags, link, directory)
    try:
        return load(path), path, hit, seconds
    except (OSError, RuntimeError):
        if not hit or compiler() is None:
            raise
    path, hit, seconds = build_library(name, code, flags, link, directory, rebuild=True)
    return load(path), path, hit, seconds


_LOADED: dict = {}  # (id(function), flags, directory) -> (function, CompiledFunction)


def compile_cached(function: ca.Function, flags: tuple[str, ...] = DEFAULT_FLAGS,
                   directory: Path | None = None) -> CompiledFunction:
    """`function` as a compiled library from the cache, compiling it first if needed; the
    interpreted `function` itself, with a warning, when that is impossible. A Function
    already loaded in this process is handed back without generating its C again (the
    code's hash is the cache's key, and generating it costs ~25 ms a Function)."""
    directory = directory or cache_dir()
    key = (id(function), tuple(flags), directory)
    known = _LOADED.get(key)
    if known is not None and known[0] is function:
        return known[1]
    result = _compile_cached(function, flags, directory)
    if result.compiled:
        if len(_LOADED) >= 64:
            _LOADED.clear()
        _LOADED[key] = (function, result)  # (the Function kept: its id is not reused)
    return result


def _compile_cached(function: ca.Function, flags: tuple[str, ...],
                    directory: Path | None) -> CompiledFunction:
    name = function.name()
    try:
        loaded, library, hit, seconds = load_cached(
            name, generate_c(function), lambda path: ca.external(name, str(path)), flags,
            directory=directory)
    except (OSError, RuntimeError, subprocess.CalledProcessError) as exc:
        detail = getattr(exc, "stderr", "") or str(exc)
        warnings.warn(f"cannot compile or load {function.name()}, running it interpreted "
                      f"(slower): {detail.strip()[:300]}", RuntimeWarning, stacklevel=2)
        return CompiledFunction(function, False, False, None, 0.0)
    return CompiledFunction(loaded, True, hit, library, seconds)
