"""HPIPM's OCP QP solver called directly (`hpipm_shim.c`), with the stage blocks as numpy
arrays: no sparse-matrix conversion, one C call per group of blocks and one per solve.

Two builds of HPIPM and BLASFEO can serve it (`HPIPM_BUILDS`):
- "tuned": a BLASFEO with kernels for the CPU (AVX2/FMA), from the `comma-deps-acados`
  wheel on PyPI (acados' libraries). That wheel also carries a casadi of its own, so it is
  installed beside the project, never into its environment:
  `pip install --no-deps --target ~/.local/share/canalnav/hpipm comma-deps-acados`
  (or anywhere, named by $CANALNAV_HPIPM_DIR);
- "casadi": the generic one inside the casadi package (always there).
"auto" takes the tuned build when it is installed and its CPU features are present, else
casadi's. The shim is compiled once per build against that build's headers and cached like
the generated code (see `codegen_cache`).
"""

from __future__ import annotations

import ctypes
import os
from dataclasses import dataclass
from functools import lru_cache
from importlib import resources
from pathlib import Path

import casadi as ca
import numpy as np

from ..errors import InputError
from .codegen_cache import cache_dir, load_cached

MODES = {"speed_abs": 0, "speed": 1, "balance": 2, "robust": 3}
STATUS = {0: "success", 1: "max_iter", 2: "min_step", 3: "nan", 4: "inconsistent_eq"}
HPIPM_BUILDS = ("auto", "tuned", "casadi")

SET_DYNAMICS, SET_CONSTRAINTS, SET_BOUNDS, SET_GRADIENT, SET_LOWER_CONSTRAINTS = 1, 2, 4, 8, 16
"""Groups of blocks `HpipmOcpQp.set` copies into the QP (the shim's SET_ flags)."""

_c_double_p = ctypes.POINTER(ctypes.c_double)
_c_int_p = ctypes.POINTER(ctypes.c_int)


@dataclass(frozen=True)
class HpipmBuild:
    """One HPIPM + BLASFEO: the two libraries and the folders of their headers."""

    name: str  # "tuned" or "casadi"
    hpipm: Path
    blasfeo: Path
    includes: tuple[Path, ...]
    target: str  # BLASFEO's target (from blasfeo_target.h), e.g. X64_INTEL_HASWELL


def tuned_dir() -> Path:
    """Where the tuned build is looked for: $CANALNAV_HPIPM_DIR, else
    $XDG_DATA_HOME/canalnav/hpipm (~/.local/share/canalnav/hpipm)."""
    given = os.environ.get("CANALNAV_HPIPM_DIR")
    if given:
        return Path(given).expanduser()
    base = os.environ.get("XDG_DATA_HOME") or os.path.join(os.path.expanduser("~"), ".local",
                                                          "share")
    return Path(base) / "canalnav" / "hpipm"


def _blasfeo_target(includes) -> str:
    for folder in includes:
        header = Path(folder) / "blasfeo_target.h"
        if header.exists():
            for line in header.read_text().splitlines():
                if line.startswith("#define TARGET_") and "FEATURE" not in line:
                    return line.split()[1][len("TARGET_"):]
    return "unknown"


def _cpu_flags() -> set[str]:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("flags"):
                return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


_TARGET_NEEDS = {"X64_INTEL_HASWELL": {"avx2", "fma"}, "X64_INTEL_SKYLAKE_X": {"avx512f"},
                 "X64_INTEL_SANDY_BRIDGE": {"avx"}, "X64_INTEL_CORE": {"sse3"}}


def casadi_build() -> HpipmBuild:
    libdir = Path(os.path.dirname(ca.__file__))
    includes = (libdir / "include",)
    return HpipmBuild("casadi", libdir / "libhpipm.so", libdir / "libblasfeo.so", includes,
                      _blasfeo_target(includes))


def find_tuned(folder: Path | None = None) -> HpipmBuild | None:
    """The tuned build under `folder` (default `tuned_dir()`), or None: acados' layout
    (acados/install/lib, acados/install/include/{hpipm,blasfeo}/include) or a plain one
    (lib/, include/)."""
    root = Path(folder) if folder is not None else tuned_dir()
    for base in (root / "acados" / "install", root):
        lib = base / "lib"
        inc = [base / "include" / "hpipm" / "include", base / "include" / "blasfeo" / "include",
               base / "include"]
        inc = tuple(p for p in inc if (p / "hpipm_d_ocp_qp.h").exists()
                    or (p / "blasfeo_target.h").exists())
        if (lib / "libhpipm.so").exists() and (lib / "libblasfeo.so").exists() and inc:
            return HpipmBuild("tuned", lib / "libhpipm.so", lib / "libblasfeo.so", inc,
                              _blasfeo_target(inc))
    return None


def choose_build(which: str = "auto") -> HpipmBuild:
    """The build for `which` ("auto", "tuned", "casadi"). "tuned" without one installed, or on a
    CPU without its instructions, is an InputError naming the install command."""
    if which not in HPIPM_BUILDS:
        raise InputError(f"HPIPM build {which!r}: choose one of {', '.join(HPIPM_BUILDS)}")
    if which == "casadi":
        return casadi_build()
    tuned = find_tuned()
    usable = tuned is not None and _TARGET_NEEDS.get(tuned.target, set()) <= _cpu_flags()
    if usable:
        return tuned
    if which == "tuned":
        why = (f"none in {tuned_dir()}" if tuned is None else
               f"its BLASFEO target {tuned.target} needs CPU features this CPU lacks")
        raise InputError(
            f"HPIPM build 'tuned': {why}; install it with `pip install --no-deps --target "
            f"{tuned_dir()} comma-deps-acados` (or set CANALNAV_HPIPM_DIR), or use 'casadi'")
    return casadi_build()


_casadi_hpipm = None


def load_library(build: HpipmBuild | None = None) -> tuple[ctypes.CDLL, bool, float]:
    """The compiled shim for `build` (default casadi's) with its HPIPM opened: (library,
    cache_hit, compile seconds); once per build and cache folder in a process."""
    return _load_library(build or casadi_build(), cache_dir())


@lru_cache(maxsize=None)
def _load_library(build: HpipmBuild, directory: Path) -> tuple[ctypes.CDLL, bool, float]:
    # casadi's HPIPM first, whichever build is asked for: libraries that name libhpipm.so
    # (casadi's conic plugin) get the first one loaded under that soname, and must get theirs
    global _casadi_hpipm
    _casadi_hpipm = _casadi_hpipm or ctypes.CDLL(str(casadi_build().hpipm), mode=os.RTLD_LOCAL)
    code = resources.files("controller.nmpc").joinpath("hpipm_shim.c").read_text()
    flags = ("-O2", *(f"-I{p}" for p in build.includes))
    lib, _, hit, seconds = load_cached(f"nmpc_hpipm_{build.name}", code,
                                       lambda path: ctypes.CDLL(str(path)), flags=flags,
                                       link=("-ldl", "-lm"), directory=directory)
    lib.nmpc_qp_load.restype = ctypes.c_int
    lib.nmpc_qp_load.argtypes = [ctypes.c_char_p, ctypes.c_char_p]
    lib.nmpc_qp_load_error.restype = ctypes.c_char_p
    code = lib.nmpc_qp_load(str(build.blasfeo).encode(), str(build.hpipm).encode())
    if code:
        detail = lib.nmpc_qp_load_error()
        raise OSError(f"cannot open HPIPM ({build.name}, {build.hpipm}): "
                      f"{detail.decode() if detail else code}")
    lib.nmpc_qp_create.restype = ctypes.c_void_p
    lib.nmpc_qp_create.argtypes = [ctypes.c_int] * 5 + [_c_int_p, ctypes.c_int, _c_int_p,
                                                         _c_double_p, _c_double_p, ctypes.c_int,
                                                         ctypes.c_int, ctypes.c_double,
                                                         ctypes.c_double, ctypes.c_int,
                                                         ctypes.c_double, ctypes.c_double,
                                                         ctypes.c_int, _c_int_p,
                                                         ctypes.c_double, ctypes.c_double]
    lib.nmpc_qp_soft_weights.restype = None
    lib.nmpc_qp_soft_weights.argtypes = [ctypes.c_void_p, _c_double_p, _c_double_p]
    lib.nmpc_qp_slack.restype = ctypes.c_void_p
    lib.nmpc_qp_slack.argtypes = [ctypes.c_void_p]
    lib.nmpc_qp_bound_slack.restype = ctypes.c_void_p
    lib.nmpc_qp_bound_slack.argtypes = [ctypes.c_void_p]
    lib.nmpc_qp_bind.restype = None
    lib.nmpc_qp_bind.argtypes = [ctypes.c_void_p] + [_c_double_p] * 14 + [_c_int_p, _c_double_p]
    lib.nmpc_qp_set.restype = None
    lib.nmpc_qp_set.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_int, ctypes.c_int]
    lib.nmpc_qp_solve.restype = ctypes.c_int
    lib.nmpc_qp_solve.argtypes = [ctypes.c_void_p]
    lib.nmpc_qp_free.restype = None
    lib.nmpc_qp_free.argtypes = [ctypes.c_void_p]
    return lib, hit, seconds


def _ptr(a: np.ndarray):
    return a.ctypes.data_as(_c_double_p)


class HpipmOcpQp:
    """A stagewise QP of fixed size, solved by HPIPM: fill the arrays, `set` the groups that
    changed for the stages that changed, then `solve()`.

    Stage 0 has no state (x_0 is fixed); the state and input bounds act on fixed indices.
    soft_l1 > 0 makes the general rows soft (`soft_weights`); `soft_bounds` (positions in
    idxbx) makes those state bounds soft in any case, at soft_bound_l1 per unit plus
    soft_bound_l2 / 2 per unit squared (`bound_slack`: their upper slacks).
    """

    def __init__(self, N: int, nx: int, nu: int, ng: int, idxbx, idxbu, Q, R,
                 mode: str = "speed_abs", iter_max: int = 50, tol: float = 1e-6,
                 mu0: float = 0.0, warm_start: int = 0, build: HpipmBuild | None = None,
                 soft_l1: float = 0.0, soft_l2: float = 0.0, soft_bounds=(),
                 soft_bound_l1: float = 0.0, soft_bound_l2: float = 0.0):
        self.build = build or casadi_build()
        self.lib, self.cache_hit, self.compile_s = load_library(self.build)
        self.N, self.nx, self.nu, self.ng = N, nx, nu, ng
        idxbx = np.ascontiguousarray(idxbx, np.intc)
        idxbu = np.ascontiguousarray(idxbu, np.intc)
        Q = np.ascontiguousarray(Q, float).reshape(N + 1, nx)
        R = np.ascontiguousarray(R, float).reshape(N, nu)
        soft_bounds = np.ascontiguousarray(soft_bounds, np.intc).reshape(-1)
        if soft_bounds.size and not ((soft_bounds >= 0) & (soft_bounds < len(idxbx))).all():
            raise ValueError("HPIPM: soft_bounds must be positions in idxbx")
        self._handle = self.lib.nmpc_qp_create(
            N, nx, nu, ng, len(idxbx), idxbx.ctypes.data_as(_c_int_p), len(idxbu),
            idxbu.ctypes.data_as(_c_int_p), _ptr(Q), _ptr(R), MODES[mode], iter_max, tol, mu0,
            int(warm_start), float(soft_l1), float(soft_l2), len(soft_bounds),
            soft_bounds.ctypes.data_as(_c_int_p), float(soft_bound_l1), float(soft_bound_l2))
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
        self.res = z(5)  # HPIPM's largest residuals, then the solution's largest entry
        arrays = (self.A, self.B, self.b, self.q, self.r, self.lbx, self.ubx, self.lbu,
                  self.ubu, self.C, self.lg, self.ug, self.x, self.u)
        self.lib.nmpc_qp_bind(self._handle, *map(_ptr, arrays),
                              self.info.ctypes.data_as(_c_int_p), _ptr(self.res))
        self._set, self._solve = self.lib.nmpc_qp_set, self.lib.nmpc_qp_solve
        # the soft rows' slacks of the last solve, (N+1) x ng (stage 0: 0), read in place
        address = self.lib.nmpc_qp_slack(self._handle)
        self.slack = (np.ctypeslib.as_array((ctypes.c_double * ((N + 1) * ng)).from_address(
            address)).reshape(N + 1, ng) if address else None)
        # the soft state bounds' upper slacks, (N+1) x len(soft_bounds), likewise
        address = self.lib.nmpc_qp_bound_slack(self._handle)
        n = len(soft_bounds)
        self.bound_slack = (np.ctypeslib.as_array((ctypes.c_double * ((N + 1) * n))
                                                  .from_address(address)).reshape(N + 1, n)
                            if address else None)

    def share_arrays(self, other: "HpipmOcpQp") -> None:
        """Read the blocks from `other`'s arrays and write the solution and status into
        them (a QP of the same sizes): what is set there is what this one solves, once
        `set` copies it in."""
        names = ("A", "B", "b", "q", "r", "lbx", "ubx", "lbu", "ubu", "C", "lg", "ug", "x", "u")
        for name in names + ("info", "res"):
            mine, theirs = getattr(self, name), getattr(other, name)
            if mine.shape != theirs.shape:
                raise ValueError(f"HPIPM QPs of other sizes ({name})")
            setattr(self, name, theirs)
        self.lib.nmpc_qp_bind(self._handle, *(_ptr(getattr(self, n)) for n in names),
                              self.info.ctypes.data_as(_c_int_p), _ptr(self.res))

    def soft_weights(self, l1, l2) -> None:
        """Per-row penalties of the soft rows (ng each, the same at every stage)."""
        l1 = np.ascontiguousarray(l1, float).reshape(self.ng)
        l2 = np.ascontiguousarray(l2, float).reshape(self.ng)
        self.lib.nmpc_qp_soft_weights(self._handle, _ptr(l1), _ptr(l2))

    def set(self, what: int, first: int = 0, stop: int | None = None) -> None:
        """Copy the groups `what` (SET_ flags, summed) of stages first..stop-1 into the QP."""
        self._set(self._handle, what, first, self.N + 1 if stop is None else stop)

    def solve(self) -> tuple[int, int]:
        """Solve the QP as set: (status, iterations); x and u hold the result."""
        self._solve(self._handle)
        return int(self.info[0]), int(self.info[1])

    def largest_entry(self) -> float:
        """The last solution's largest |x_i|, |u_i| (NaN when one is NaN): the size of an
        SQP step, found in C as the solution is copied out."""
        return float(self.res[4])

    def __del__(self):
        handle = getattr(self, "_handle", None)
        if handle:
            self.lib.nmpc_qp_free(handle)
            self._handle = None
