"""Small C kernels for the hot paths, compiled with gcc on first use and cached.

Why C and not numba or Cython: the project already compiles C on first use (the NMPC's
linearisation, the HPIPM shim, the FMUs) with `controller.nmpc.codegen_cache`, so a kernel
needs no dependency beyond the customer's list and no build step at install; the cache key
is a hash of the source and flags, so an edited kernel is rebuilt and an unchanged one loads
without a compiler. Each kernel is one `.c` file beside the Python that calls it, with a
plain numpy (or filterpy) twin kept as the reference its tests compare against and as the
fallback, with a warning, where nothing can be compiled.
"""

from __future__ import annotations

import ctypes
import subprocess
import warnings
from pathlib import Path

FLAGS = ("-O2", "-ffp-contract=off")
"""-ffp-contract=off: no fused multiply-adds, so a kernel rounds as its numpy twin does."""

_loaded: dict[Path, ctypes.CDLL | None] = {}


def load_kernel(source: Path) -> ctypes.CDLL | None:
    """The compiled library of the C file `source` (cached per process and on disk), or None
    with a warning when it cannot be built or loaded; callers then use their numpy twin."""
    source = Path(source)
    if source in _loaded:
        return _loaded[source]
    from controller.nmpc.codegen_cache import load_cached

    try:
        lib, _, _, _ = load_cached(source.stem, source.read_text(),
                                   lambda path: ctypes.CDLL(str(path)), flags=FLAGS)
    except (OSError, subprocess.CalledProcessError) as exc:
        detail = getattr(exc, "stderr", "") or str(exc)
        warnings.warn(f"cannot compile or load the kernel {source.name}, running its numpy "
                      f"twin instead (slower): {detail.strip()[:300]}", RuntimeWarning,
                      stacklevel=2)
        lib = None
    _loaded[source] = lib
    return lib


def pointer(array) -> int:
    """The address of a C-contiguous numpy array's data, for a kernel's argument (declared
    c_void_p). The caller keeps the array alive for the call."""
    return array.__array_interface__["data"][0]
