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

class Kernel:
    """The compiled library of one C file, built, loaded and its functions typed on the
    first call (then kept for the process; on disk by `codegen_cache`), or None with a
    warning when that cannot be done: callers then use their numpy twin.

    `signatures`: {function name: (restype, [argtypes])}."""

    def __init__(self, source: Path, signatures: dict):
        self.source, self.signatures = Path(source), signatures
        self._lib: ctypes.CDLL | None = None
        self._tried = False

    def __call__(self) -> ctypes.CDLL | None:
        if not self._tried:
            self._tried = True
            self._lib = self._load()
        return self._lib

    def _load(self) -> ctypes.CDLL | None:
        from controller.nmpc.codegen_cache import load_cached

        try:
            lib, _, _, _ = load_cached(self.source.stem, self.source.read_text(),
                                       lambda path: ctypes.CDLL(str(path)), flags=FLAGS)
        except (OSError, subprocess.CalledProcessError) as exc:
            detail = getattr(exc, "stderr", "") or str(exc)
            warnings.warn(f"cannot compile or load the kernel {self.source.name}, running its "
                          f"numpy twin instead (slower): {detail.strip()[:300]}",
                          RuntimeWarning, stacklevel=3)
            return None
        for name, (restype, argtypes) in self.signatures.items():
            function = getattr(lib, name)
            function.restype, function.argtypes = restype, list(argtypes)
        return lib


def pointer(array) -> int:
    """The address of a C-contiguous numpy array's data, for a kernel's argument (declared
    c_void_p). The caller keeps the array alive for the call. Through the buffer protocol
    (a quarter of the time of numpy's `__array_interface__`, which builds a dict; a step
    asks for about forty addresses), numpy's way for what that refuses: a read-only or an
    empty array."""
    if array.nbytes:
        try:
            return _addressof(_c_char.from_buffer(array))
        except (TypeError, ValueError, BufferError):
            pass
    return array.__array_interface__["data"][0]


_addressof, _c_char = ctypes.addressof, ctypes.c_char
