"""HPIPM's OCP QP solver called directly (`hpipm_shim.c`), with the stage blocks as numpy
arrays: no sparse-matrix conversion, one C call per QP.

The shim is compiled once against the HPIPM and BLASFEO inside the casadi package and cached
like the generated code (see `codegen_cache`).
"""

from __future__ import annotations

import ctypes
import os
from importlib import resources
from pathlib import Path

import casadi as ca
import numpy as np

from .codegen_cache import load_cached

MODES = {"speed_abs": 0, "speed": 1, "balance": 2, "robust": 3}
STATUS = {0: "success", 1: "max_iter", 2: "min_step", 3: "nan", 4: "inconsistent_eq"}

_c_double_p = ctypes.POINTER(ctypes.c_double)
_c_int_p = ctypes.POINTER(ctypes.c_int)


def _casadi_dir() -> Path:
    return Path(os.path.dirname(ca.__file__))


def load_library() -> tuple[ctypes.CDLL, bool, float]:
    """The compiled shim (cache hit or fresh build): (library, cache_hit, compile seconds)."""
    code = resources.files("controller.nmpc").joinpath("hpipm_shim.c").read_text()
    libdir = _casadi_dir()
    lib, _, hit, seconds = load_cached(
        "nmpc_hpipm", code, lambda path: ctypes.CDLL(str(path)),
        flags=("-O2", f"-I{libdir / 'include'}"),
        link=(f"-L{libdir}", "-lhpipm", "-lblasfeo", f"-Wl,-rpath,{libdir}", "-lm"))
    lib.nmpc_qp_create.restype = ctypes.c_void_p
    lib.nmpc_qp_create.argtypes = [ctypes.c_int] * 5 + [_c_int_p, ctypes.c_int, _c_int_p,
                                                         _c_double_p, _c_double_p, ctypes.c_int,
                                                         ctypes.c_int, ctypes.c_double,
                                                         ctypes.c_double]
    lib.nmpc_qp_solve.restype = ctypes.c_int
    lib.nmpc_qp_solve.argtypes = [ctypes.c_void_p] + [_c_double_p] * 14 + [_c_int_p, _c_double_p]
    lib.nmpc_qp_free.restype = None
    lib.nmpc_qp_free.argtypes = [ctypes.c_void_p]
    return lib, hit, seconds


def _ptr(a: np.ndarray):
    return a.ctypes.data_as(_c_double_p)


class HpipmOcpQp:
    """A stagewise QP of fixed size, solved by HPIPM: set the arrays, call `solve()`.

    Stage 0 has no state (x_0 is fixed); the state and input bounds act on fixed indices.
    """

    def __init__(self, N: int, nx: int, nu: int, ng: int, idxbx, idxbu, Q, R,
                 mode: str = "speed_abs", iter_max: int = 50, tol: float = 1e-6,
                 mu0: float = 0.0):
        self.lib, self.cache_hit, self.compile_s = load_library()
        self.N, self.nx, self.nu, self.ng = N, nx, nu, ng
        idxbx = np.ascontiguousarray(idxbx, np.intc)
        idxbu = np.ascontiguousarray(idxbu, np.intc)
        Q = np.ascontiguousarray(Q, float).reshape(N + 1, nx)
        R = np.ascontiguousarray(R, float).reshape(N, nu)
        self._handle = self.lib.nmpc_qp_create(
            N, nx, nu, ng, len(idxbx), idxbx.ctypes.data_as(_c_int_p), len(idxbu),
            idxbu.ctypes.data_as(_c_int_p), _ptr(Q), _ptr(R), MODES[mode], iter_max, tol, mu0)
        if not self._handle:
            raise MemoryError("HPIPM: could not allocate the QP")
        z = np.zeros
        self.A, self.B, self.b = z((N, nx * nx)), z((N, nx * nu)), z((N, nx))
        self.q, self.r = z((N + 1, nx)), z((N, nu))
        self.lbx, self.ubx = z((N + 1, len(idxbx))), z((N + 1, len(idxbx)))
        self.lbu, self.ubu = z((N, len(idxbu))), z((N, len(idxbu)))
        self.C, self.lg, self.ug = z((N + 1, ng * nx)), z((N + 1, ng)), z((N + 1, ng))
        self.x, self.u = z((N + 1, nx)), z((N, nu))
        self.info = np.zeros(2, np.intc)
        self.res = z(4)
        arrays = (self.A, self.B, self.b, self.q, self.r, self.lbx, self.ubx, self.lbu,
                  self.ubu, self.C, self.lg, self.ug, self.x, self.u)
        self._args = [self._handle, *map(_ptr, arrays), self.info.ctypes.data_as(_c_int_p),
                      _ptr(self.res)]

    def solve(self) -> tuple[int, int]:
        """Solve with the arrays as they are now: (status, iterations); x and u hold the result."""
        self.lib.nmpc_qp_solve(*self._args)
        return int(self.info[0]), int(self.info[1])

    def __del__(self):
        handle = getattr(self, "_handle", None)
        if handle:
            self.lib.nmpc_qp_free(handle)
            self._handle = None
