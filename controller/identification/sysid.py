"""System identification: the paper's NLP (eq. SI) over manoeuvre logs, IPOPT through CasADi.

    P* = argmin_P  sum_i (x_i - x̄_i)' W (x_i - x̄_i)   s.t.  x_{i+1} = f_d(x_i, ū_i, P)

with f_d the RK4 discretisation of `controller.model.boat_ode` over each log's own sample
intervals (multiple shooting: every sample's state is a variable, tied by the dynamics).
Decoupled as in the paper: surge first (acceleration and deceleration runs, W = diag(0,0,0,1,0,0),
parameters m11 Xu Xuu c), then sway-yaw (zigzags, W = diag(1,1,100,0,100,100), parameters
m22 m33 Yv Yr Nv Nr Yvv Yrr Nvv Nrr) with the surge part fixed. The surge stage fits the
surge equation alone (straight running: nS, v, r taken as zero). A sample whose state was not
measured has zero weight; each run's initial state is estimated with the parameters (a
position the stage does not fit is held at its first measurement).

Noise weighting (`noise_model="ar1"`, the default): each stage is solved with W, then again
with each channel W fits weighted by its own residual noise: the first fit's residuals of each
channel modelled as AR(1), e_k = rho e_(k-1) + w_k, and the cost the sum of the whitened
residuals squared over sigma_w^2 (generalised least squares; Prais-Winsten at the start of each
measured stretch). An EKF's errors are coloured (position wandering over tens of seconds,
velocity noise near the sway speed itself); with W the wandering position steers the fit, and
whitened each channel counts for what it carries. Every solve shares one CPU-time budget
(`max_cpu_s`; CPU, not wall time, so that a busy computer slows the identification without
failing it): past it, a SolverTimeLimit says so, never a hang. IPOPT's own max_cpu_time is
checked between iterations only, and one iteration of a solve gone astray can spend half an
hour in MUMPS; so each solve runs in a forked child whose CPU time the kernel caps
(RLIMIT_CPU) where the platform allows.

One zigzag at one speed does not separate the quadratic and cross sway-yaw terms from the
linear ones (with realistic noise their standard errors exceed their size, and fitting them
all at once trades Y_v against Y_v|v| and N_r against N_r|r|). So the sway-yaw stage fits the
linear core m22 m33 Yv Nr first, then tries each optional term (OPTIONAL_TERMS) in turn and
keeps it only if its estimate exceeds SELECT_T standard errors (forward selection); the others
stay 0 and are reported with the trial fit's estimate and standard error. `select=False` fits
all ten at once. SELECT_T is 3.14, a family-wise 1 % over the six tries (Bonferroni): at two
standard errors each, six tries let a term that is not there in about a quarter of the time,
and on EKF logs such a term (a cross term of 3 SE on a boat that has none) takes Y_v with it.

Scale: the model is unchanged when every force-like parameter is multiplied by one factor, so
logs fix the parameters only up to that factor. One surge parameter anchors it: by default m11,
from the weight plus Söding's surge added-mass estimate; `fixed` can name another.
Initial guesses come from the boat's dimensions only (`initial_guess`), never from known values.
Standard errors: Gauss-Newton approximation at the optimum, H ≈ J'WJ with J the sensitivity of
the simulated states to the parameters and to each run's initial state, and the residual
variance estimated per channel (sandwich form, since W is not the inverse noise covariance).
They assume white measurement noise and are conditional on the earlier stage.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from statistics import NormalDist

import numpy as np

from ..errors import InputError, SolverError, where
from .logs import STATE_COLUMNS, ManeuverLog
from ..params import PARAM_INFO, PARAM_NAMES, BoatParams

SURGE_PARAMS = ("m11", "Xu", "Xuu", "c")
SWAY_YAW_PARAMS = ("m22", "m33", "Yv", "Yr", "Nv", "Nr", "Yvv", "Yrr", "Nvv", "Nrr")
KNOWN_PARAMS = ("thrust_scale", "ly", "delta_max")
"""Geometry and units, not identified: they keep their values unless fixed otherwise."""
SURGE_WEIGHTS = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0)
SWAY_YAW_WEIGHTS = (1.0, 1.0, 100.0, 0.0, 100.0, 100.0)
MIN_SAMPLES = 20
MIN_DURATION_S = 2.0
POSITIVE = ("m11", "m22", "m33", "c")
DISSIPATIVE = ("Xu", "Xuu", "Yv", "Nr", "Yvv", "Nrr")
"""Bounds: masses and thrust positive, the diagonal damping derivatives not positive."""
POOR_RELATIVE_SE = 0.25
OPTIONAL_TERMS = ("Yvv", "Nrr", "Yr", "Nv", "Yrr", "Nvv")
"""Sway-yaw terms beyond the linear diagonal core (m22 m33 Yv Nr), added one at a time in
this order and kept only when the data tell them from zero (forward selection)."""
FAMILY_ALPHA = 0.01
SELECT_T = NormalDist().inv_cdf(1.0 - FAMILY_ALPHA / (2 * len(OPTIONAL_TERMS)))
"""An optional term is kept when |estimate| > SELECT_T standard errors (3.14): the chance that
any of the six, none of them really there, gets in is then at most FAMILY_ALPHA."""
NOISE_MODELS = ("ar1", "fixed")
RHO_MAX = 0.999
"""AR(1) noise model: a residual channel's lag-one correlation is kept below this."""
NEGLIGIBLE_RATIO = 1e-3
"""A true value below this fraction of the parameter's typical size (its guess) counts as
zero: no ratio error is shown for it."""
"""Sway-yaw cross terms: the sway-yaw stage first fits without them, then with them."""


# -- initial guesses from the dimensions -----------------------------------------------------
@dataclass(frozen=True)
class BoatDimensions:
    """What is known before any test: the paper's boat (1,700 kg, 7.9 m, 2.6 m) by default.

    The draft follows from the displacement with an assumed block coefficient; the speed
    scales the speed-dependent linear derivatives.
    """

    mass_kg: float = 1700.0
    length_m: float = 7.9
    breadth_m: float = 2.6
    water_density_kgm3: float = 1000.0  # fresh water (canal)
    block_coefficient: float = 0.5
    design_speed_mps: float = 2.0
    resistance_coefficient: float = 0.0035  # C_T: ITTC-57 friction at Re ~ 1.6e7 plus form
    crossflow_drag_coefficient: float = 1.0

    @property
    def displacement_m3(self) -> float:
        return self.mass_kg / self.water_density_kgm3

    @property
    def draft_m(self) -> float:
        return self.displacement_m3 / (self.block_coefficient * self.length_m * self.breadth_m)


def surge_added_mass(dims: BoatDimensions) -> float:
    """Söding (1982) surge added mass, -X_udot = 2.7 rho V^(5/3) / L^2 (Fossen, Handbook §6)."""
    return 2.7 * dims.water_density_kgm3 * dims.displacement_m3 ** (5 / 3) / dims.length_m**2


def default_m11(dims: BoatDimensions) -> float:
    """The default scale anchor: the weight plus Söding's surge added mass."""
    return dims.mass_kg + surge_added_mass(dims)


def initial_guess(dims: BoatDimensions = BoatDimensions()) -> BoatParams:
    """Every parameter from the dimensions alone, by textbook rules of thumb.

    m11: weight + Söding. m22, m33 and Yv Yr Nv Nr: Clarke et al. (1983) slender-body
    regressions (added mass and linear derivatives at the design speed), m33 with the dry
    inertia of a uniform box m (L^2 + B^2) / 12. Surge: resistance 0.5 rho S C_T U^2 at the
    design speed, S = L (B + 2T), split 80 % quadratic, 20 % linear. c: full throttle (100 %)
    reaches the displacement hull speed 1.34 sqrt(L in ft) kn. Yvv, Nrr: cross-flow drag over
    the hull (C_D = 1); the cross terms Yrr, Nvv: zero (fore-aft symmetry).
    """
    rho, L, B, T = dims.water_density_kgm3, dims.length_m, dims.breadth_m, dims.draft_m
    U, m, cb = dims.design_speed_mps, dims.mass_kg, dims.block_coefficient
    k = math.pi * (T / L) ** 2
    Yv_dot = -k * (1 + 0.16 * cb * B / T - 5.1 * (B / L) ** 2) * 0.5 * rho * L**3
    Nr_dot = -k * (1 / 12 + 0.017 * cb * B / T - 0.33 * B / L) * 0.5 * rho * L**5
    Yv = -k * (1 + 0.40 * cb * B / T) * 0.5 * rho * L**2 * U
    Yr = -k * (-0.5 + 2.2 * B / L - 0.080 * B / T) * 0.5 * rho * L**3 * U
    Nv = -k * (0.5 + 2.4 * T / L) * 0.5 * rho * L**3 * U
    Nr = -k * (0.25 + 0.039 * B / T - 0.56 * B / L) * 0.5 * rho * L**4 * U
    wetted = L * (B + 2 * T)
    resistance = 0.5 * rho * wetted * dims.resistance_coefficient * U**2
    Xuu = -0.8 * resistance / U**2
    Xu = -0.2 * resistance / U
    hull_speed = 1.34 * math.sqrt(L / 0.3048) * 1852 / 3600
    thrust_scale = BoatParams().thrust_scale
    c_eff = (-Xu * hull_speed - Xuu * hull_speed**2) / 100.0**2
    crossflow = 0.5 * rho * T * dims.crossflow_drag_coefficient
    return BoatParams().replace(
        m11=default_m11(dims),
        m22=m - Yv_dot,
        m33=m * (L**2 + B**2) / 12 - Nr_dot,
        Xu=Xu, Yv=Yv, Yr=Yr, Nv=Nv, Nr=Nr, Xuu=Xuu,
        Yvv=-crossflow * L, Yrr=0.0, Nvv=0.0, Nrr=-crossflow * L**4 / 32,
        c=c_eff / thrust_scale**2,
    )


# -- configuration and results ------------------------------------------------------------------
@dataclass(frozen=True)
class SysidConfig:
    """How to identify: dimensions for the guesses, fixed parameters, weights, solver."""

    dimensions: BoatDimensions = BoatDimensions()
    fixed: Mapping[str, float] = field(default_factory=dict)
    surge_weights: tuple[float, ...] = SURGE_WEIGHTS
    sway_yaw_weights: tuple[float, ...] = SWAY_YAW_WEIGHTS
    n_sub: int = 2  # RK4 sub-steps per log sample in f_d
    smooth_eps: float = 1e-6  # |z| ~ sqrt(z^2 + eps) in the NLP (at most 1e-3 off)
    max_iter: int = 300
    tol: float = 1e-8
    select: bool = True  # forward selection of OPTIONAL_TERMS; False fits all at once
    select_se: float = SELECT_T  # an optional term is kept when |estimate| > this many SE
    noise_model: str = "ar1"  # "ar1": residuals whitened and weighted by their noise; "fixed": W
    max_cpu_s: float = 300.0  # CPU time of all solves together: then a clear SolverError
    heading_bias: bool = True  # sway-yaw: each run's heading bias estimated with the parameters

    def __post_init__(self) -> None:
        for name, value in self.fixed.items():
            if name not in PARAM_NAMES:
                raise InputError(f"--fix {name}: unknown parameter (known: {', '.join(PARAM_NAMES)})")
            if not math.isfinite(value):
                raise InputError(f"--fix {name}: value {value!r} is not finite")
        if self.noise_model not in NOISE_MODELS:
            raise InputError(f"--noise-model {self.noise_model!r}: expected one of "
                             f"{', '.join(NOISE_MODELS)}")
        if not (math.isfinite(self.select_se) and self.select_se > 0):
            raise InputError(f"--select-se must be a positive number of standard errors, got "
                             f"{self.select_se!r}")
        if not (math.isfinite(self.max_cpu_s) and self.max_cpu_s > 0):
            raise InputError(f"--time-limit must be a positive number of seconds, got "
                             f"{self.max_cpu_s!r}")

    @property
    def anchor(self) -> str:
        """The surge parameter that sets the common scale: the first one fixed, else m11."""
        return next((n for n in SURGE_PARAMS if n in self.fixed), "m11")


@dataclass(frozen=True)
class ParameterReport:
    """One row of the table. `std_error` is NaN when fixed or not identified."""

    name: str
    guess: float
    estimate: float
    std_error: float
    role: str  # "estimated", "fixed", "known", "not identified"
    note: str = ""
    true: float | None = None
    ratio_error: float | None = None  # (est/anchor) / (true/anchor_true) - 1


@dataclass(frozen=True)
class StageReport:
    """One stage of the decoupled identification."""

    name: str
    logs: tuple[str, ...]
    free: tuple[str, ...]
    n_samples: int
    iterations: int
    status: str
    cost: float
    rms: Mapping[str, float]  # per weighted channel, display units
    build_s: float
    solve_s: float
    covariance_s: float
    passes: int = 1  # NLPs solved: the core, then one trial per optional term
    noise: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    """Per fitted channel (display name): the residual noise's standard deviation (SI) and
    correlation time (s) of the AR(1) model the fit weighted by; empty with fixed weights."""
    heading_bias_deg: tuple[float, ...] = ()
    """Each run's heading bias estimated with the parameters (degrees), if it was."""


@dataclass(frozen=True)
class FitReport:
    """A simulation of a parameter set against a log: RMS errors over the measured samples."""

    source: str
    heading_rms_deg: float
    speed_rms_mps: float
    yaw_rate_rms_degps: float
    n_samples: int
    duration_s: float


@dataclass(frozen=True)
class SysidResult:
    params: BoatParams
    guess: BoatParams
    anchor: str
    anchor_note: str
    parameters: tuple[ParameterReport, ...]
    stages: tuple[StageReport, ...]
    heldout: tuple[FitReport, ...]
    heldout_truth: tuple[FitReport, ...]
    truth: BoatParams | None
    notes: tuple[str, ...]
    heldout_s: float = 0.0


# -- the discretised model and the data ------------------------------------------------------------
def discrete_step(variant, n_sub: int):
    """f_d(x, u, p, h): RK4 of `boat_ode` over a step of length h (no current)."""
    import casadi as ca

    from .. import model

    x = ca.SX.sym("x", model.NX)
    u = ca.SX.sym("u", model.NU)
    p = ca.SX.sym("p", model.NP)
    h = ca.SX.sym("h")
    x_next = model.rk4(lambda z: model.boat_ode(z, u, p, (0.0, 0.0), variant), x, h, n_sub)
    return ca.Function("f_d", [x, u, p, h], [x_next], ["x", "u", "p", "h"], ["x_next"])


@dataclass(frozen=True, eq=False)
class _Data:
    """A log ready for fitting: psi unwrapped, a first guess of every state at every sample."""

    log: ManeuverLog
    measured: np.ndarray  # (N, 6) bool
    values: np.ndarray  # (N, 6) measured values, NaN where not measured; psi unwrapped
    filled: np.ndarray  # (N, 6) interpolated where missing, 0 where never measured

    @classmethod
    def of(cls, log: ManeuverLog) -> "_Data":
        values = log.states.copy()
        measured = np.isfinite(values)
        psi = measured[:, 2]
        values[psi, 2] = np.unwrap(values[psi, 2])
        filled = np.zeros_like(values)
        for c in range(values.shape[1]):
            if measured[:, c].any():
                filled[:, c] = np.interp(log.time_s, log.time_s[measured[:, c]],
                                         values[measured[:, c], c])
        return cls(log, measured, values, filled)

    def first(self, c: int) -> float:
        """The first measured value of channel c (0 if never measured)."""
        idx = np.flatnonzero(self.measured[:, c])
        return float(self.values[idx[0], c]) if idx.size else 0.0


def _check_length(data: _Data, weights: Sequence[float], stage: str) -> None:
    """Refuse a log that cannot inform the stage: too few weighted samples or too short."""
    log = data.log
    used = [c for c in range(6) if weights[c] > 0 and data.measured[:, c].any()]
    if not used:
        names = [STATE_COLUMNS[c] for c in range(6) if weights[c] > 0]
        raise InputError(f"{log.source}: column(s) {', '.join(repr(n) for n in names)}: no "
                         f"values; the {stage} stage fits these")
    best = max(used, key=lambda c: data.measured[:, c].sum())
    rows = np.flatnonzero(data.measured[:, best])
    duration = log.time_s[rows[-1]] - log.time_s[rows[0]]
    if rows.size < MIN_SAMPLES or duration < MIN_DURATION_S:
        first, last = log.line_of(int(rows[0])), log.line_of(int(rows[-1]))
        span = f" (lines {first}-{last})" if first is not None else ""
        raise InputError(
            f"{where(log.source, first, STATE_COLUMNS[best])}too short to identify anything: "
            f"{rows.size} measured sample(s) over {duration:.1f} s{span}; the {stage} stage "
            f"needs at least {MIN_SAMPLES} samples over {MIN_DURATION_S:g} s"
        )


# -- one stage ------------------------------------------------------------------------------------
def _scales(guess: BoatParams) -> dict[str, float]:
    """Typical magnitude of each parameter, so the NLP's variables are of order one."""
    floor = {"Yrr": 100.0, "Nvv": 100.0}
    return {n: max(abs(getattr(guess, n)), floor.get(n, 1e-12)) for n in PARAM_NAMES}


def _theta_bounds(name: str) -> tuple[float, float]:
    if name in POSITIVE:
        return 0.05, np.inf
    if name in DISSIPATIVE:
        return -np.inf, 0.0
    return -np.inf, np.inf


@dataclass(frozen=True)
class _StageSolution:
    params: BoatParams
    cov_theta: np.ndarray  # covariance of the free parameters (SI)
    info_theta: np.ndarray  # J'WJ in the scaled variables (for determinability)
    report: StageReport
    x0: list[np.ndarray]
    trajectories: list[np.ndarray]
    biases: list[float] | None = None  # each run's heading bias (rad), when estimated


BIAS_SCALE_RAD = 0.01  # the NLP's heading-bias variables are in these units
MAX_BIAS_RAD = math.radians(20.0)


def _as_measured(X, bias):
    """The states `X` (6, N) as a heading off by `bias` reports them: the heading plus the
    bias, and the velocity over ground resolved along that heading (u, v turned by -bias).

    A compass's bias misleads an EKF's heading, not its velocity over ground (GPS), so the
    body-frame velocity a log holds is the true one turned by the bias: on a straight run at
    2 m/s, 2 deg of bias reads as a sway of -0.07 m/s, which the boat's dynamics cannot make
    and which a fit without the bias explains with its sway-yaw parameters."""
    import casadi as ca

    c, s = ca.cos(bias), ca.sin(bias)
    return ca.vertcat(X[0, :], X[1, :], X[2, :] + bias, c * X[3, :] + s * X[4, :],
                      -s * X[3, :] + c * X[4, :], X[5, :])


def _stage_step(step, active: Sequence[int]):
    """f_d restricted to the `active` states, the others held at zero.

    The surge stage uses active = (u,) with nS = 0: straight running, v = r = 0, where the
    model reduces to its surge equation (the paper's decoupling); x, y, psi do not enter the
    dynamics without a current. The sway-yaw stage uses all six states.
    """
    import casadi as ca

    if tuple(active) == tuple(range(6)):
        return step
    xa = ca.SX.sym("xa", len(active))
    u = ca.SX.sym("u", 2)
    p = ca.SX.sym("p", step.size1_in(2))
    h = ca.SX.sym("h")
    full = [0.0] * 6
    for k, c in enumerate(active):
        full[c] = xa[k]
    x_next = step(ca.vertcat(*full), u, p, h)
    return ca.Function("f_d_reduced", [xa, u, p, h], [x_next[list(active)]])


def _pinned(data: _Data, active: Sequence[int], wa: np.ndarray) -> list[int]:
    """Indices (into `active`) of initial states held at their first measurement.

    Every initial state is estimated with the parameters except a position the stage does
    not fit (weight 0 or never measured): without a current it influences nothing else.
    """
    return [k for k, c in enumerate(active)
            if c in (0, 1) and (wa[k] == 0 or not data.measured[:, c].any())]


def _stage_commands(log: ManeuverLog, straight: bool) -> np.ndarray:
    """(2, N-1) commands over each interval; nS = 0 for straight (surge) runs."""
    commands = log.commands[:-1].T.copy()
    if straight:
        commands[1] = 0.0
    return commands


@dataclass(frozen=True)
class _Noise:
    """AR(1) model of one channel's residuals, e_k = rho e_(k-1) + w_k with w white of
    standard deviation sigma_w; `weight` multiplies the whitened squares in the cost."""

    rho: float
    sigma_w: float
    weight: float

    def stationary_sd(self) -> float:
        return self.sigma_w / math.sqrt(1.0 - self.rho**2)

    def correlation_time(self, dt: float) -> float:
        return math.inf if self.rho >= 1 else (0.0 if self.rho <= 0 else -dt / math.log(self.rho))


def _whitening_index(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For the measured sample indices `rows` (increasing): the positions (into rows) that
    directly follow their predecessor, whitened as e_j - rho e_(j-1); and the others, the
    first of each measured stretch, scaled by sqrt(1 - rho^2) (Prais-Winsten)."""
    adjacent = np.flatnonzero(np.diff(rows) == 1) + 1
    return adjacent, np.setdiff1d(np.arange(rows.size), adjacent)


def _whiten(a: np.ndarray, rows: np.ndarray, rho: float) -> np.ndarray:
    """The AR(1) whitening filter along axis 0 of `a` (one entry per measured sample)."""
    adjacent, _ = _whitening_index(rows)
    out = math.sqrt(1.0 - rho**2) * a
    out[adjacent] = a[adjacent] - rho * a[adjacent - 1]
    return out


def _estimate_noise(datas: Sequence[_Data], trajectories, active: Sequence[int],
                    wa: np.ndarray, cost: float) -> dict[int, _Noise]:
    """Each fitted channel's residual noise as AR(1), from a fit's residuals: an EKF's errors
    wander (position over tens of seconds), and weighting every channel by its own noise,
    whitened, is what the likelihood asks for; fixed weights let a wandering channel steer the
    fit. The weights are scaled so that the cost keeps the size it had (`cost`)."""
    found, n_terms = {}, 0
    for k, c in enumerate(active):
        if wa[k] <= 0:
            continue
        num = den = 0.0
        pieces = []
        for data, X in zip(datas, trajectories):
            rows = np.flatnonzero(data.measured[:, c])
            if rows.size < 2:
                continue
            e = X[k, rows] - data.values[rows, c]
            adjacent, _ = _whitening_index(rows)
            num += float(e[adjacent] @ e[adjacent - 1])
            den += float(e[adjacent - 1] @ e[adjacent - 1])
            pieces.append((e, rows))
        if not pieces:
            continue
        rho = float(np.clip(num / den, 0.0, RHO_MAX)) if den > 0 else 0.0
        w = np.concatenate([_whiten(e, rows, rho) for e, rows in pieces])
        sigma_w = float(np.sqrt(np.mean(w**2)))
        if sigma_w > 0:
            found[c] = (rho, sigma_w)
            n_terms += w.size
    if not found:
        return {}
    scale = max(cost, 1e-12) / n_terms  # each whitened term is ~1 after dividing by sigma_w^2
    return {c: _Noise(rho, sw, scale / sw**2) for c, (rho, sw) in found.items()}


def cpu_time_s() -> float:
    """CPU seconds of this process and of the solves' children it has waited for."""
    import resource

    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + kids.ru_utime + kids.ru_stime


def solve_capped(solver, args: dict, limit_s: float) -> tuple[dict, dict]:
    """`solver(**args)` (a CasADi nlpsol) and the stats sysid reads, in a forked child
    killed by the kernel past `limit_s` CPU seconds (stats["capped"] then); in this process
    where there is no fork."""
    import multiprocessing as mp
    import resource

    def answer() -> tuple[dict, dict]:
        sol = solver(**args)
        stats = solver.stats()
        return ({k: np.asarray(v) for k, v in sol.items()},
                {k: stats.get(k) for k in ("return_status", "iter_count", "success")})

    if "fork" not in mp.get_all_start_methods():
        return answer()
    ctx = mp.get_context("fork")
    receive, send = ctx.Pipe(duplex=False)

    def child() -> None:
        seconds = max(int(math.ceil(limit_s)), 1)
        resource.setrlimit(resource.RLIMIT_CPU, (seconds, seconds + 5))
        try:
            send.send(answer())
        except BaseException as exc:  # noqa: BLE001 - handed to the parent as it is
            send.send(exc)

    worker = ctx.Process(target=child, daemon=True)
    worker.start()
    send.close()
    try:
        got = receive.recv()
    except EOFError:  # the child died: past its CPU limit (SIGXCPU), or killed
        got = None
    worker.join()
    receive.close()
    if got is None:
        return {}, {"return_status": "Maximum_CpuTime_Exceeded", "iter_count": None,
                    "success": False, "capped": True}
    if isinstance(got, BaseException):
        raise got
    return got


class SolverTimeLimit(SolverError):
    """The identification ran out of its CPU-time budget (SysidConfig.max_cpu_s)."""


def _solve_stage(name: str, datas: Sequence[_Data], free: Sequence[str], start: BoatParams,
                 scales: Mapping[str, float], weights: Sequence[float],
                 config: SysidConfig, step, trajectories=None,
                 straight: bool = False, noise: Mapping[int, _Noise] | None = None,
                 deadline: float | None = None, biases=None) -> _StageSolution:
    """One NLP (eq. SI) over the stage's runs by multiple shooting; then its covariance.
    With `noise` the cost is each channel's AR(1)-whitened residuals over its noise instead
    of the weights W (the channels W leaves out stay out). With `config.heading_bias` (not
    the surge stage) each run's heading bias is a variable too (`_as_measured`), started
    from `biases`."""
    import casadi as ca

    t0 = time.perf_counter()
    c0 = cpu_time_s()
    limit = config.max_cpu_s if deadline is None else deadline - c0
    if limit <= 0:
        raise SolverTimeLimit(f"sysid {name} stage: the time limit, {config.max_cpu_s:g} s of "
                              "CPU, is used up; raise it with --time-limit S")
    active = [3] if straight else list(range(6))
    na = len(active)
    f_d = _stage_step(step, active)
    wa = np.asarray(weights, float)[active]
    n_free = len(free)
    theta = ca.MX.sym("theta", n_free)
    p = ca.vertcat(*[scales[n] * theta[free.index(n)] if n in free else getattr(start, n)
                     for n in PARAM_NAMES])
    use_bias = config.heading_bias and not straight
    n_bias = len(datas) if use_bias else 0
    beta = ca.MX.sym("beta", n_bias)
    w, g, cost = [theta, beta], [], 0
    w0 = [np.array([getattr(start, n) / scales[n] for n in free]),
          np.asarray(biases if biases is not None else np.zeros(n_bias), float)[:n_bias]
          / BIAS_SCALE_RAD]
    lbw = [np.array([_theta_bounds(n)[0] for n in free]),
           np.full(n_bias, -MAX_BIAS_RAD / BIAS_SCALE_RAD)]
    ubw = [np.array([_theta_bounds(n)[1] for n in free]),
           np.full(n_bias, MAX_BIAS_RAD / BIAS_SCALE_RAD)]
    for i, data in enumerate(datas):
        n = data.log.n_samples
        X = ca.MX.sym(f"X_{i}", na, n)
        X_next = f_d.map(n - 1)(X[:, :-1], _stage_commands(data.log, straight),
                                ca.repmat(p, 1, n - 1), np.diff(data.log.time_s))
        g.append(ca.vec(X_next - X[:, 1:]))
        Y = _as_measured(X, BIAS_SCALE_RAD * beta[i]) if use_bias else X
        if noise is None:
            measured = data.measured[:, active]
            root_w = (np.sqrt(wa)[None, :] * measured).T  # (na, N): zero where not measured
            target = np.where(measured, data.values[:, active], 0.0).T
            cost = cost + ca.sumsqr(root_w * (Y - target))
        else:
            for k, c in enumerate(active):
                rows = np.flatnonzero(data.measured[:, c])
                if c not in noise or not rows.size:
                    continue
                nz = noise[c]
                e = ca.vec(Y[k, rows.tolist()]) - data.values[rows, c]
                adjacent, starts = _whitening_index(rows)
                terms = 0
                if adjacent.size:
                    terms = terms + ca.sumsqr(e[adjacent.tolist()]
                                              - nz.rho * e[(adjacent - 1).tolist()])
                if starts.size:
                    terms = terms + (1.0 - nz.rho**2) * ca.sumsqr(e[starts.tolist()])
                cost = cost + nz.weight * terms
        w.append(ca.vec(X))
        lo, hi = np.full((na, n), -np.inf), np.full((na, n), np.inf)
        guess_traj = (data.filled[:, active].T if trajectories is None
                      else trajectories[i]).copy()
        for k in _pinned(data, active, wa):
            lo[k, 0] = hi[k, 0] = guess_traj[k, 0] = data.first(active[k])
        lbw.append(lo.ravel(order="F"))
        ubw.append(hi.ravel(order="F"))
        w0.append(guess_traj.ravel(order="F"))
    nlp = {"x": ca.vertcat(*w), "f": cost, "g": ca.vertcat(*g)}
    opts = {
        "ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False,
        "show_eval_warnings": False,  # IPOPT backs off from a trial step that overflows
        "ipopt.max_iter": config.max_iter, "ipopt.tol": config.tol,
        "ipopt.max_cpu_time": max(limit - (cpu_time_s() - c0), 1e-3),
    }
    solver = ca.nlpsol("sysid_" + name.replace("-", "_"), "ipopt", nlp, opts)
    t1 = time.perf_counter()
    sol, stats = solve_capped(solver, dict(x0=np.concatenate(w0), lbx=np.concatenate(lbw),
                                           ubx=np.concatenate(ubw), lbg=0, ubg=0),
                              limit - (cpu_time_s() - c0))
    t2 = time.perf_counter()
    status = str(stats.get("return_status", "?"))
    if stats.get("capped"):
        runs = ", ".join(d.log.source + (f" (--window {d.log.meta['window']})"
                                         if d.log.meta.get("window") else "") for d in datas)
        raise SolverTimeLimit(f"sysid {name} stage: the solve was stopped at the time limit, "
                              f"{config.max_cpu_s:g} s of CPU for the whole identification, "
                              f"inside one IPOPT iteration, on the runs {runs} (a solve that "
                              "takes this long has usually gone astray from its start); try: "
                              + STAGE_HINTS.get(name, "leave a run out")
                              + "; or raise the limit with --time-limit S")
    wopt = np.asarray(sol["x"]).ravel()
    if status == "Maximum_CpuTime_Exceeded":
        raise SolverTimeLimit(f"sysid {name} stage: IPOPT stopped at the time limit, "
                              f"{config.max_cpu_s:g} s of CPU for the whole identification "
                              f"({stats.get('iter_count')} iterations, not converged), on "
                              + _blame(name, datas, wopt, n_free + n_bias, na, active, wa, f_d,
                                       p, theta, straight)
                              + "; or raise the limit with --time-limit S")
    if not stats.get("success", False) and status != "Solved_To_Acceptable_Level":
        raise SolverError(f"sysid {name} stage: IPOPT did not converge ({status}, "
                          f"{stats.get('iter_count')} iterations) on "
                          + _blame(name, datas, wopt, n_free + n_bias, na, active, wa, f_d, p,
                                   theta, straight))
    est = start.replace(**{n: float(scales[n] * wopt[k]) for k, n in enumerate(free)})
    x0s, trajs, offset = [], [], n_free + n_bias
    bias_values = list(BIAS_SCALE_RAD * wopt[n_free:n_free + n_bias]) if use_bias else None
    for data in datas:
        n = data.log.n_samples
        trajs.append(wopt[offset:offset + na * n].reshape((na, n), order="F"))
        x0s.append(trajs[-1][:, 0].copy())
        offset += na * n
    cov, info, rms = _covariance(datas, free, est, scales, wa, x0s, f_d, active, straight,
                                 noise, bias_values)
    t3 = time.perf_counter()
    report = StageReport(
        name=name, logs=tuple(d.log.source for d in datas), free=tuple(free),
        n_samples=int(sum(d.log.n_samples for d in datas)),
        iterations=int(stats.get("iter_count", -1)), status=status,
        cost=float(sol["f"].reshape(-1)[0]), rms=rms, build_s=t1 - t0, solve_s=t2 - t1,
        covariance_s=t3 - t2,
        noise=_noise_report(noise, datas),
        heading_bias_deg=tuple(math.degrees(b) for b in bias_values or ()),
    )
    return _StageSolution(est, cov, info, report, x0s, trajs, bias_values)


STAGE_HINTS = {
    "surge": "check that the run is straight running ahead at steady throttle steps; leave "
             "it out (--window T0:T1 around the others), or give --actuator-rates 10,40 if "
             "the servo outputs jump",
    "sway-yaw": "leave it out (--window T0:T1 around the others, or --heldout-window T0:T1 "
                "to only check it), drive longer zigzags (maneuvers --overshoots 10), give "
                "--actuator-rates 10,40 if the servo outputs jump, or try --noise-model fixed",
}


def _blame(name: str, datas, wopt, offset: int, na: int, active, wa, f_d, p, theta,
           straight: bool) -> str:
    """Which run the last iterate of a solve that did not converge fits worst, and what to
    try: the run whose trajectory breaks the dynamics most (the largest step between the
    model's prediction and the next state, relative to the run's spread), else the one with
    the largest weighted misfit per sample."""
    import casadi as ca

    p_num = ca.Function("p_of_theta", [theta], [p])(wopt[:theta.size1()])
    rows = []
    for data in datas:
        n = data.log.n_samples
        X = wopt[offset:offset + na * n].reshape((na, n), order="F")
        offset += na * n
        pred = np.asarray(f_d.map(n - 1)(X[:, :-1], _stage_commands(data.log, straight),
                                         ca.repmat(p_num, 1, n - 1), np.diff(data.log.time_s)))
        spread = np.maximum(np.ptp(X, axis=1), 1e-6)[:, None]
        defect = float(np.max(np.abs(pred - X[:, 1:]) / spread))
        m = data.measured[:, active].T
        err = np.where(m, X - np.nan_to_num(data.values[:, active].T), 0.0)
        misfit = float(np.sum(wa[:, None] * err**2) / max(m.sum(), 1))
        rows.append((defect, misfit, data.log))
    by_defect = max(rows, key=lambda r: r[0])
    worst = by_defect if by_defect[0] > 1e-3 else max(rows, key=lambda r: r[1])
    log = worst[2]
    where_ = log.meta.get("window")
    run = log.source + (f" (--window {where_})" if where_ else "")
    why = ("its trajectory still breaks the model's dynamics" if worst is by_defect
           and by_defect[0] > 1e-3 else "it fits worst")
    others = ", ".join(d.log.source for d in datas if d.log is not log)
    return (f"the run {run}{' (with ' + others + ')' if others else ''}: {why}; try: "
            + STAGE_HINTS.get(name, "leave that run out"))


def _measured(sol: _StageSolution) -> list[np.ndarray]:
    """The solution's trajectories as the logs measure them (its heading biases applied)."""
    if sol.biases is None:
        return sol.trajectories
    import casadi as ca

    return [np.asarray(_as_measured(ca.DM(X), b)) for X, b in zip(sol.trajectories, sol.biases)]


def _noise_report(noise, datas) -> dict[str, tuple[float, float]]:
    if not noise:
        return {}
    dt = float(np.median(np.concatenate([np.diff(d.log.time_s) for d in datas])))
    return {STATE_COLUMNS[c]: (nz.stationary_sd(), nz.correlation_time(dt))
            for c, nz in sorted(noise.items())}


def _merge_passes(passes: Sequence[StageReport], last: StageReport) -> StageReport:
    """One report for a stage solved in several passes (`last` the one kept): times and
    iterations add up."""
    return StageReport(
        name=last.name, logs=last.logs, free=last.free, n_samples=last.n_samples,
        iterations=sum(p.iterations for p in passes), status=last.status, cost=last.cost,
        rms=last.rms, build_s=sum(p.build_s for p in passes),
        solve_s=sum(p.solve_s for p in passes),
        covariance_s=sum(p.covariance_s for p in passes), passes=len(passes), noise=last.noise,
        heading_bias_deg=last.heading_bias_deg,
    )


def _safe_inverse(A: np.ndarray, floor: float = 1e-12) -> np.ndarray:
    """Inverse of a symmetric information matrix, scaled to unit diagonal first; directions
    it cannot see get huge variances (eigenvalues floored), never the zero variance that a
    pseudo-inverse would give them."""
    d = np.sqrt(np.clip(np.diag(A), 1e-300, None))
    vals, vecs = np.linalg.eigh(A / np.outer(d, d))
    inv = (vecs / np.maximum(vals, floor)) @ vecs.T
    return inv / np.outer(d, d)


def _covariance(datas, free, est: BoatParams, scales, wa, x0s, f_d, active, straight,
                noise=None, biases=None):
    """Gauss-Newton covariance of the free parameters, each run's fitted x0 a nuisance.

    J = d(simulated measured states)/d(theta, x0) at the optimum; A = J'WJ;
    cov = A^-1 J'W S W J A^-1 with S the residual variance of each channel. With a noise
    model, J and the residuals are whitened as in the cost and W is its weights.
    """
    import casadi as ca

    n_free = len(free)
    theta = ca.MX.sym("theta", n_free)
    p = ca.vertcat(*[scales[n] * theta[free.index(n)] if n in free else getattr(est, n)
                     for n in PARAM_NAMES])
    theta_hat = np.array([getattr(est, n) / scales[n] for n in free])
    blocks, resid_rows, chan_rows, weight_rows, series_rows, n_nuisance = [], [], [], [], [], []
    raw_rows = []  # the residuals before whitening, for the RMS shown
    n_series = 0
    for i, (data, x0) in enumerate(zip(datas, x0s)):
        n = data.log.n_samples
        rows = [(k, np.flatnonzero(data.measured[:, c])) for k, c in enumerate(active)
                if wa[k] > 0]
        rows = [(k, r) for k, r in rows if r.size and (noise is None or active[k] in noise)]
        pinned = _pinned(data, active, wa)
        free_x0 = [k for k in range(len(active)) if k not in pinned]
        n_b = 1 if biases is not None else 0  # the run's heading bias: a nuisance too
        z = ca.MX.sym("z", len(free_x0) + n_b)
        x0_sym = ca.vertcat(*[z[free_x0.index(k)] if k in free_x0 else x0[k]
                              for k in range(len(active))])
        traj = f_d.mapaccum(n - 1)(x0_sym, _stage_commands(data.log, straight),
                                   ca.repmat(p, 1, n - 1), np.diff(data.log.time_s))
        X = ca.horzcat(x0_sym, traj)
        if n_b:
            X = _as_measured(X, z[len(free_x0)])
        pred = ca.vertcat(*[X[k, r.tolist()].T for k, r in rows])
        f = ca.Function("sens", [theta, z], [pred, ca.jacobian(pred, ca.vertcat(theta, z))])
        pred_v, jac = f(theta_hat, np.concatenate([x0[free_x0], [biases[i]] if n_b else []]))
        resid = np.asarray(pred_v).ravel() - np.concatenate([data.values[r, active[k]]
                                                             for k, r in rows])
        jac = np.asarray(jac)
        raw_rows.append(resid.copy())
        if noise is not None:
            at = 0
            for k, r in rows:
                sl = slice(at, at + r.size)
                resid[sl] = _whiten(resid[sl], r, noise[active[k]].rho)
                jac[sl] = _whiten(jac[sl], r, noise[active[k]].rho)
                at += r.size
        resid_rows.append(resid)
        chan_rows.append(np.concatenate([np.full(r.size, active[k]) for k, r in rows]))
        weight_rows.append(np.concatenate([
            np.full(r.size, wa[k] if noise is None else noise[active[k]].weight)
            for k, r in rows]))
        series_rows.append(np.concatenate([np.full(r.size, n_series + j)
                                           for j, (_, r) in enumerate(rows)]))
        n_series += len(rows)
        blocks.append(jac)
        n_nuisance.append(len(free_x0) + n_b)
    # J: shared parameter columns, then a block of initial-state columns per run
    n_cols = n_free + sum(n_nuisance)
    J = np.zeros((sum(b.shape[0] for b in blocks), n_cols))
    row, col = 0, n_free
    for b, k in zip(blocks, n_nuisance):
        J[row:row + b.shape[0], :n_free] = b[:, :n_free]
        J[row:row + b.shape[0], col:col + k] = b[:, n_free:]
        row, col = row + b.shape[0], col + k
    resid, chan = np.concatenate(resid_rows), np.concatenate(chan_rows)
    raw = np.concatenate(raw_rows)
    wrow = np.concatenate(weight_rows)
    dof_factor = resid.size / max(resid.size - n_cols, 1)
    sigma2 = np.zeros(resid.size)
    rms = {}
    for c in np.unique(chan):
        sel = chan == c
        sigma2[sel] = float(np.mean(resid[sel] ** 2)) * dof_factor
        var = float(np.mean(raw[sel] ** 2))
        unit = {0: "m", 1: "m", 2: "deg", 3: "m/s", 4: "m/s", 5: "deg/s"}[int(c)]
        rms[f"{STATE_COLUMNS[c]} [{unit}]"] = (math.degrees(math.sqrt(var)) if c in (2, 5)
                                               else math.sqrt(var))
    A = J.T @ (wrow[:, None] * J)
    B = J.T @ ((wrow**2 * sigma2)[:, None] * J)
    B += _autocorrelation_terms(J, resid * wrow, np.concatenate(series_rows))
    try:
        if not (np.all(np.isfinite(A)) and np.all(np.isfinite(B))):
            raise np.linalg.LinAlgError("non-finite sensitivities")
        A_inv = _safe_inverse(A)
        S = np.array([scales[n] for n in free])
        cov = (A_inv @ B @ A_inv)[:n_free, :n_free] * np.outer(S, S)
        # information about the parameters with the initial states profiled out (Schur
        # complement)
        Att, Atz, Azz = A[:n_free, :n_free], A[:n_free, n_free:], A[n_free:, n_free:]
        info = Att - Atz @ _safe_inverse(Azz) @ Atz.T if Azz.size else Att
    except np.linalg.LinAlgError:
        # The data say nothing usable about these parameters at this optimum (a degenerate
        # or diverged fit): unknown spreads, so a trial term is not kept on them.
        return np.diag(np.full(n_free, np.inf)), np.zeros((n_free, n_free)), rms
    return cov, info, rms


def _bandwidth(e: np.ndarray) -> int:
    """Lags over which a residual series is correlated: 0 for white residuals, else three
    times the lag where its autocorrelation falls below 1/e (at most half the series)."""
    n = len(e)
    power = float(e @ e)
    if n < 4 or power <= 0:
        return 0
    for lag in range(1, n // 2):
        if float(e[lag:] @ e[:-lag]) / power < math.exp(-1.0):
            return 0 if lag == 1 else min(n // 2, 3 * lag)
    return n // 2


def _autocorrelation_terms(J: np.ndarray, weighted_resid: np.ndarray,
                           series: np.ndarray) -> np.ndarray:
    """The cross-lag part of the scores' long-run covariance (Newey-West, Bartlett weights)
    within each run's channel: an EKF's errors wander, and many correlated samples carry less
    information than as many independent ones. Zero for white residuals."""
    out = np.zeros((J.shape[1], J.shape[1]))
    for sid in np.unique(series):
        sel = np.flatnonzero(series == sid)  # in time order
        e = weighted_resid[sel]
        L = _bandwidth(e)
        if L == 0:
            continue
        scores = e[:, None] * J[sel]
        for lag in range(1, L + 1):
            g = scores[lag:].T @ scores[:-lag]
            out += (1.0 - lag / (L + 1.0)) * (g + g.T)
    return out


def _determinability(free: Sequence[str], est: BoatParams, cov: np.ndarray,
                     info: np.ndarray) -> dict[str, str]:
    """Notes on parameters the data cannot determine (or only poorly)."""
    notes: dict[str, str] = {}
    # near-null directions of the (correlation-normalised) information matrix
    d = np.sqrt(np.clip(np.diag(info), 1e-300, None))
    corr = info / np.outer(d, d)
    vals, vecs = np.linalg.eigh(corr)
    for val, vec in zip(vals, vecs.T):
        if val < 1e-8:
            members = [free[k] for k in np.flatnonzero(np.abs(vec) > 0.3)]
            for m in members:
                notes[m] = "not determined: the logs do not separate " + "/".join(members)
    for k, n in enumerate(free):
        if n in notes:
            continue
        value, se = getattr(est, n), math.sqrt(max(cov[k, k], 0.0))
        if np.diag(info)[k] <= 0:
            notes[n] = "not determined: no sensitivity in these logs"
        elif se >= abs(value):
            notes[n] = "not determined: cannot be told from zero (SE >= |estimate|)"
        elif se > POOR_RELATIVE_SE * abs(value):
            notes[n] = f"poorly determined (SE {100 * se / abs(value):.0f} % of the estimate)"
    return notes


# -- held-out check -----------------------------------------------------------------------------
def simulate_log(params: BoatParams, log: ManeuverLog, n_sub: int = 4) -> np.ndarray:
    """The exact model driven by the log's commands from its first measured state: (N, 6)."""
    from ..model import EXACT

    data = _Data.of(log)
    step = discrete_step(EXACT, n_sub)
    x0 = np.array([data.first(c) for c in range(6)])
    n = log.n_samples
    traj = step.mapaccum(n - 1)(x0, log.commands[:-1].T, np.tile(params.as_vector()[:, None],
                                                                  (1, n - 1)),
                                np.diff(log.time_s))
    return np.column_stack([x0, np.asarray(traj)]).T


def fit_report(params: BoatParams, log: ManeuverLog) -> FitReport:
    """RMS of heading, surge speed and yaw rate between the log and a simulation of `params`."""
    data = _Data.of(log)
    sim = simulate_log(params, log)

    def rms(c):
        m = data.measured[:, c]
        return float(np.sqrt(np.mean((sim[m, c] - data.values[m, c]) ** 2))) if m.any() else math.nan

    return FitReport(
        source=log.source, heading_rms_deg=math.degrees(rms(2)), speed_rms_mps=rms(3),
        yaw_rate_rms_degps=math.degrees(rms(5)), n_samples=log.n_samples,
        duration_s=float(log.time_s[-1] - log.time_s[0]),
    )


# -- the whole identification ---------------------------------------------------------------------
def split_logs(logs: Sequence[ManeuverLog]):
    """(surge runs, sway-yaw runs, held-out runs) by header tags, else by content."""
    surge, sway_yaw, heldout = [], [], []
    for log in logs:
        if log.heldout:
            heldout.append(log)
        elif log.maneuver == "surge":
            surge.append(log)
        else:
            sway_yaw.append(log)
    return surge, sway_yaw, heldout


def _common_truth(logs: Sequence[ManeuverLog]) -> BoatParams | None:
    truths = [log.truth() for log in logs]
    if not truths or any(t is None for t in truths):
        return None
    first = truths[0].as_vector()
    return truths[0] if all(np.allclose(t.as_vector(), first) for t in truths) else None


def identify(logs: Sequence[ManeuverLog], config: SysidConfig = SysidConfig()) -> SysidResult:
    """Surge then sway-yaw identification from the fit logs; held-out logs only checked."""
    from ..model import Variant

    surge_logs, sway_logs, heldout_logs = split_logs(logs)
    notes: list[str] = []
    dims = config.dimensions
    guess = initial_guess(dims)
    anchor = config.anchor
    if anchor in config.fixed:
        anchor_note = f"{anchor} = {config.fixed[anchor]:g} fixed by the user (sets the scale)"
    else:
        anchor_note = (f"m11 fixed at {default_m11(dims):.1f} kg = weight {dims.mass_kg:g} kg + "
                       f"Söding surge added mass {surge_added_mass(dims):.1f} kg "
                       "(2.7 rho V^(5/3)/L^2); override with --fix")
    fixed = dict(config.fixed)
    if anchor not in fixed:
        fixed["m11"] = default_m11(dims)
    start = guess.replace(**fixed)
    scales = _scales(start)
    step = discrete_step(Variant(smooth=True, eps=config.smooth_eps), config.n_sub)

    surge_free = [n for n in SURGE_PARAMS if n not in fixed]
    sway_free = [n for n in SWAY_YAW_PARAMS if n not in fixed]
    if not surge_logs and surge_free:
        raise InputError(
            "no surge run among the logs (acceleration/deceleration with nS = 0, or a "
            "'# maneuver: acceleration' header): the surge parameters "
            + ", ".join(surge_free) + " and the scale cannot be identified"
        )
    stages, roles, se, det, dropped, failed = [], {}, {}, {}, {}, {}
    params = start
    deadline = cpu_time_s() + config.max_cpu_s
    for stage, stage_logs, free, weights in (
        ("surge", surge_logs, surge_free, config.surge_weights),
        ("sway-yaw", sway_logs, sway_free, config.sway_yaw_weights),
    ):
        if not free:
            continue
        if not stage_logs:
            notes.append(f"no {stage} run among the logs: {', '.join(free)} keep their initial "
                         "guesses (not identified)")
            for n in free:
                roles[n] = "not identified"
            continue
        datas = [_Data.of(log) for log in stage_logs]
        for data in datas:
            _check_length(data, weights, stage)
        straight = stage == "surge"
        extras = [n for n in free if n in OPTIONAL_TERMS] if config.select else []
        core = [n for n in free if n not in extras]
        # the core model first, the optional terms held at zero
        sol = _solve_stage(stage, datas, core, params.replace(**{n: 0.0 for n in extras}),
                           scales, weights, config, step, straight=straight, deadline=deadline)
        passes = [sol.report]
        noise = None
        if config.noise_model == "ar1":
            # again, each channel weighted by its own residual noise (AR(1), whitened)
            active = [3] if straight else list(range(6))
            wa = np.asarray(weights, float)[active]
            noise = _estimate_noise(datas, _measured(sol), active, wa, sol.report.cost) or None
            if noise is not None:
                sol = _solve_stage(stage, datas, core, sol.params, scales, weights, config,
                                   step, sol.trajectories, straight=straight, noise=noise,
                                   deadline=deadline, biases=sol.biases)
                passes.append(sol.report)
        free = list(core)
        for i, n in enumerate(extras):
            # forward selection: keep a term only if the data tell it from zero (> select_se SE)
            try:
                trial = _solve_stage(stage, datas, free + [n],
                                     sol.params.replace(**{n: getattr(start, n)}), scales,
                                     weights, config, step, sol.trajectories, straight=straight,
                                     noise=noise, deadline=deadline, biases=sol.biases)
            except SolverTimeLimit:  # out of time: the model so far stands, the rest untried
                for m in extras[i:]:
                    failed[m] = "not tried: the time limit ran out"
                notes.append(f"the {config.max_cpu_s:g} s time limit ran out during the "
                             f"{stage} stage's trials: {', '.join(extras[i:])} not tried "
                             "(raise it with --time-limit S)")
                break
            except SolverError as exc:  # a trial that fails leaves its term out, not the run
                failed[n] = str(exc)
                continue
            passes.append(trial.report)
            value = getattr(trial.params, n)
            sd = math.sqrt(max(trial.cov_theta[-1, -1], 0.0))
            if abs(value) > config.select_se * sd:
                sol, free = trial, free + [n]
            else:
                dropped[n] = (value, sd)
        params = sol.params
        stages.append(_merge_passes(passes, sol.report))
        for k, n in enumerate(free):
            roles[n] = "estimated"
            se[n] = math.sqrt(max(sol.cov_theta[k, k], 0.0))
        det.update(_determinability(free, params, sol.cov_theta, sol.info_theta))
        for n, (value, sd) in dropped.items():
            roles[n] = "left out"
            se[n] = sd
            det[n] = (f"not determined (trial fit {value:.4g} ± {sd:.3g}, "
                      f"< {config.select_se:.3g} SE): kept at 0")
        for n, why in failed.items():
            roles[n] = "left out"
            det[n] = f"not determined (the trial fit with it failed: {why}): kept at 0"

    truth = _common_truth([*surge_logs, *sway_logs])
    t_h = time.perf_counter()
    heldout = tuple(fit_report(params, log) for log in heldout_logs)
    heldout_truth = ()
    if heldout_logs:
        truths = [log.truth() for log in heldout_logs]
        if all(t is not None for t in truths):
            heldout_truth = tuple(fit_report(t, log) for t, log in zip(truths, heldout_logs))
    heldout_s = time.perf_counter() - t_h
    if not heldout_logs:
        notes.append("no held-out run (header '# use: heldout'): the fit is not checked on "
                     "data it did not see")

    rows = []
    for n in PARAM_NAMES:
        role = roles.get(n)
        if n in fixed:
            role = "fixed"
        elif n in KNOWN_PARAMS:
            role = "known"
        note = det.get(n, "")
        if n == anchor:
            note = "sets the scale"
        true_value = ratio_error = None
        if truth is not None:
            true_value = getattr(truth, n)
            if (n not in KNOWN_PARAMS and n != anchor
                    and abs(true_value) > NEGLIGIBLE_RATIO * scales[n]):
                ratio_error = (getattr(params, n) / getattr(params, anchor)) / (
                    true_value / getattr(truth, anchor)) - 1.0
        rows.append(ParameterReport(
            name=n, guess=getattr(guess, n) if n not in KNOWN_PARAMS else getattr(start, n),
            estimate=getattr(params, n), std_error=se.get(n, math.nan), role=role or "known",
            note=note, true=true_value, ratio_error=ratio_error,
        ))
    return SysidResult(params, guess, anchor, anchor_note, tuple(rows), tuple(stages), heldout,
                       heldout_truth, truth, tuple(notes), heldout_s)


# -- presentation ---------------------------------------------------------------------------------
def _display(channel: str, value: float) -> str:
    """A channel's SI value with its display unit (angles in degrees)."""
    if channel in ("psi", "r"):
        return f"{math.degrees(value):.3g} {'deg' if channel == 'psi' else 'deg/s'}"
    return f"{value:.3g} {'m' if channel in ('x', 'y') else 'm/s'}"


def format_table(result: SysidResult) -> str:
    """The human report: stages, the parameter table, the held-out fit, notes."""
    out = []
    for st in result.stages:
        rms = ", ".join(f"{k} {v:.4g}" for k, v in st.rms.items())
        out.append(f"{st.name} stage: {len(st.logs)} run(s), {st.n_samples} samples, "
                   f"{st.iterations} IPOPT iterations ({st.status}), fit RMS {rms}")
        out.append("  runs: " + ", ".join(st.logs))
        if st.noise:
            out.append("  weighted by the residual noise, AR(1) (sd, correlation time): " + ", ".join(
                f"{k} {_display(k, sd)} {tau:.2g} s" for k, (sd, tau) in st.noise.items()))
        if st.heading_bias_deg:
            out.append("  heading bias of each run (the log's heading less the fitted one): "
                       + ", ".join(f"{b:+.2f} deg" for b in st.heading_bias_deg))
    out.append(f"scale: {result.anchor_note}")
    out.append("")
    has_truth = result.truth is not None
    head = f"{'param':<12} {'unit':<7} {'guess':>11} {'estimate':>11} {'std err':>10}"
    if has_truth:
        head += f" {'true':>11} {'ratio err':>9}"
    out.append(head + "  note")
    out.append("-" * (len(head) + 30))
    for row in result.parameters:
        se = "" if math.isnan(row.std_error) else f"{row.std_error:10.4g}"
        line = (f"{row.name:<12} {PARAM_INFO[row.name].unit:<7} {row.guess:11.5g} "
                f"{row.estimate:11.5g} {se:>10}")
        if has_truth:
            ratio = ("" if row.true is None or row.name in KNOWN_PARAMS or row.name == result.anchor
                     else "true ~0" if row.ratio_error is None
                     else f"{100 * row.ratio_error:+8.2f}%")
            line += f" {row.true:11.5g} {ratio:>9}"
        note = row.note if row.role == "estimated" else (row.role + (f"; {row.note}" if row.note else ""))
        out.append(line + "  " + note)
    if has_truth:
        out.append(f"ratio err: (estimate/{result.anchor}) / (true/{result.anchor}) - 1; "
                   "the logs fix the parameters only up to a common scale")
    for k, fit in enumerate(result.heldout):
        out.append("")
        out.append(f"held-out {fit.source} ({fit.duration_s:.0f} s, not in the fit): "
                   f"heading RMS {fit.heading_rms_deg:.3f} deg, surge speed RMS "
                   f"{fit.speed_rms_mps:.4f} m/s, yaw rate RMS {fit.yaw_rate_rms_degps:.3f} deg/s")
        if k < len(result.heldout_truth):
            t = result.heldout_truth[k]
            out.append(f"  (true model on the same log: {t.heading_rms_deg:.3f} deg, "
                       f"{t.speed_rms_mps:.4f} m/s, {t.yaw_rate_rms_degps:.3f} deg/s: the noise floor)")
    for note in result.notes:
        out.append(f"note: {note}")
    return "\n".join(out)


def result_to_dict(result: SysidResult) -> dict:
    """A JSON-ready summary of the result (SI units, angles of the fit report in degrees)."""

    def clean(v):
        return None if v is None or (isinstance(v, float) and not math.isfinite(v)) else v

    return {
        "anchor": result.anchor,
        "anchor_note": result.anchor_note,
        "parameters": [
            {"name": r.name, "unit": PARAM_INFO[r.name].unit, "guess": r.guess,
             "estimate": r.estimate, "std_error": clean(r.std_error), "role": r.role,
             "note": r.note, "true": clean(r.true), "ratio_error": clean(r.ratio_error)}
            for r in result.parameters
        ],
        "stages": [
            {"name": s.name, "logs": list(s.logs), "free": list(s.free), "samples": s.n_samples,
             "ipopt_iterations": s.iterations, "status": s.status, "cost": s.cost,
             "fit_rms": dict(s.rms), "build_s": s.build_s, "solve_s": s.solve_s,
             "covariance_s": s.covariance_s, "passes": s.passes,
             "heading_bias_deg": list(s.heading_bias_deg),
             "noise": {k: {"sd": sd, "correlation_time_s": clean(tau)}
                       for k, (sd, tau) in s.noise.items()}}
            for s in result.stages
        ],
        "heldout": [
            {"log": f.source, "heading_rms_deg": f.heading_rms_deg,
             "speed_rms_mps": f.speed_rms_mps, "yaw_rate_rms_degps": f.yaw_rate_rms_degps,
             "samples": f.n_samples}
            for f in result.heldout
        ],
        "notes": list(result.notes),
    }
