"""The water current and the rest of the model's error, estimated on line from what the boat
already measures: the navigation filter's state and the actuators' positions.

Every `window_s` (1 s) the identified model (`controller.model`, with the current and a
body-frame acceleration bias b = [b_u, b_v, b_r] as inputs) is run from the state estimated at
the start of the window over the actuator positions logged through it; the difference between
the predicted and the estimated body velocities [u, v, r] at its end is the innovation of an
extended Kalman filter (filterpy) whose states are theta = [V_north, V_east, b_u, b_v, b_r],
each a random walk. The Jacobian comes from the same CasADi expressions as the prediction.
A window rather than one 0.1 s step: the current moves the velocity by ~1 cm/s per (m/s) of
current in 0.1 s, no more than the estimate's own noise; over 1 s ten times as much.

What the measurements can tell apart, and what not:
- A current across the boat is seen at once: sway through the water is heavily damped
  (Y_v = -3.6e3), so any steady sway over ground is the current.
- A current along the boat and a surge-model error (drag, thrust) look alike on a straight
  run at constant speed: both are a steady surge force. What separates them is turning (the
  current is fixed in the NED frame and turns in the body frame as the heading changes, a
  model error turns with the boat) and speed changes (drag errors grow with speed, a
  constant current shifts the speed through the water by the same amount at every speed).
  The filter divides what it cannot separate by the prior: the current walks faster
  (`current_walk`) than the bias (`bias_walk`), so on a straight run a surge error is first
  read as a current along the canal, and put right at the next bend. A drag and a thrust
  error of the same size (as in `plant_mismatch`) cancel in steady running: nothing to read.
- The bias in yaw takes what no current explains: a yaw-damping or rudder error in a turn.

Only quasi-steady windows are used (the surge speed and the yaw rate change little over
them): while the boat speeds up or starts a turn, a mass or inertia error (20 % in
`plant_mismatch`) would otherwise read as a current of a metre a second.

Run-time data never stop it: a window with a non-finite value, a state that jumped (a filter
reset) or an innovation beyond `gate_sigma` standard deviations is skipped and counted. When
`reopen_after` windows in a row fail the gate, it is the water that changed (the boat runs
into a side inflow), not the data: the current's spread goes back to its prior and the
filter follows.
"""

from __future__ import annotations

import functools
import math
from collections import deque
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from .errors import InputError
from .model import EXACT, NP, boat_ode, rk4
from .params import IDENTIFIED, BoatParams

N_THETA = 5  # V_north, V_east, b_u, b_v, b_r


@dataclass(frozen=True)
class WaterEstimatorConfig:
    """Noise and timing of the estimator; SI units (biases in m/s^2 and rad/s^2)."""

    window_s: float = 1.0  # each update predicts the motion over this long
    period_s: float = 0.1  # how often `update` is called (the control period)
    # The noise of [u, v, r] at a window's end given its start (the navigation's own and
    # the model's error over a window; m/s, m/s, rad/s), learnt from the innovations
    # (`noise_learning`: each window's weight), from `velocity_sigma` (also its cap: an
    # autopilot's EKF, velocity noise ~0.05 m/s correlated over a second) down to
    # `velocity_sigma_floor` as a quieter source shows itself (a navigation filter's own).
    velocity_sigma: tuple[float, float, float] = (0.07, 0.07, 0.005)
    velocity_sigma_floor: tuple[float, float, float] = (0.01, 0.01, 0.002)
    noise_learning: float = 0.1
    current_walk: float = 0.004  # m/s per sqrt(s): how fast the current along the boat may
    # change (slowly: it is read from the surge, where a model error looks the same) ...
    current_walk_across: float = 0.02  # ... and across it (sway sees it at once, so the
    # filter may follow a side inflow as fast as the boat runs into it; at 0.03 an autopilot
    # EKF's sway noise moved the estimate by 0.03 m/s rms in still water, at 0.01 a current
    # met in a bend was followed too slowly: fuzz cases came 2 m closer to a kayak)
    bias_walk: tuple[float, float, float] = (2e-4, 3e-3, 2e-3)  # per sqrt(s): in sway and yaw faster, so
    # that errors of the model in turns (masses, yaw damping) go to the bias, not the current
    current_sigma0: float = 0.5  # m/s, prior spread of the current
    bias_sigma0: tuple[float, float, float] = (0.003, 0.01, 0.002)
    gate_sigma: float = 6.0  # innovations beyond this many standard deviations are skipped ...
    reopen_after: int = 2  # ... unless this many windows in a row are: then the water has
    # changed (a side inflow), and the filter starts again from its prior spread
    max_jump_m: float = 5.0  # a position jump larger than this over a window: skip it
    steady_du_mps: float = 0.1  # windows in which the surge speed changes more than this ...
    steady_dr_radps: float = 0.02  # ... or the yaw rate more than this are not used: there
    # the model's mass and inertia errors (which neither a current nor a constant bias can
    # stand for) outweigh what the window says about the water
    steady_dnT_pct: float = 3.0  # a window in which the throttle moves more than this says
    # nothing through its surge: while it ramps (a start, a stop), the thrust's lag behind
    # the command (the link, the autopilot's whole percents, the actuator's own rate) reads
    # as a current of tenths of a metre a second along the boat; its sway and yaw still count
    boat: BoatParams = field(default=IDENTIFIED)

    def __post_init__(self) -> None:
        for name in ("window_s", "period_s", "current_walk", "current_walk_across",
                     "current_sigma0", "gate_sigma",
                     "max_jump_m", "steady_du_mps", "steady_dr_radps", "steady_dnT_pct",
                     "noise_learning"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or v <= 0:
                raise InputError(f"water estimator: {name} must be a positive number, got {v!r}")
        for name in ("velocity_sigma", "velocity_sigma_floor", "bias_walk", "bias_sigma0"):
            v = getattr(self, name)
            if len(v) != 3 or not all(isinstance(x, (int, float)) and math.isfinite(x) and x >= 0
                                      for x in v):
                raise InputError(f"water estimator: {name} needs three numbers >= 0, got {v!r}")
        if min(self.velocity_sigma) <= 0 or min(self.velocity_sigma_floor) <= 0:
            raise InputError("water estimator: velocity_sigma and its floor must be positive")
        if any(f > v for f, v in zip(self.velocity_sigma_floor, self.velocity_sigma)):
            raise InputError("water estimator: velocity_sigma_floor must not exceed "
                             "velocity_sigma")
        if self.noise_learning > 1:
            raise InputError(f"water estimator: noise_learning must be in (0, 1], got "
                             f"{self.noise_learning!r}")
        if self.window_s < self.period_s:
            raise InputError("water estimator: window_s must be at least period_s")

    @property
    def steps(self) -> int:
        """Control periods per window."""
        return max(1, int(round(self.window_s / self.period_s)))


@dataclass(frozen=True)
class WaterEstimate:
    """The current (NED, m/s), the body-frame acceleration bias, their 1-sigma spreads."""

    current_ne: np.ndarray  # (2,)
    bias: np.ndarray  # (3,) [b_u m/s^2, b_v m/s^2, b_r rad/s^2]
    current_sigma: np.ndarray  # (2,)
    bias_sigma: np.ndarray  # (3,)
    updates: int  # windows used so far
    skipped: int  # windows skipped (non-finite, jumped, gated)
    reopened: int = 0  # times the water changed faster than the filter's random walk
    current_cov: np.ndarray | None = None  # (2, 2) the current's covariance (NED)


def usable_current(estimate: WaterEstimate, heading_rad: float, prior_sigma: float,
                   along_sigma: float = 0.1, settle_windows: int = 10) -> np.ndarray:
    """The current to hand the controller: the estimate along and across the boat, each
    part weighted by the evidence behind it.

    Across the boat (what keeps the boat on its line, and what a heading bias of the
    autopilot's EKF looks like), sway sees a current at once: the part is weighted by the
    share of the prior's spread the data have explained, w = 1 - (sigma / prior_sigma)^2,
    and, through the first `settle_windows` windows, by how far it stands out of its own
    spread: from none at one sigma to all of it at two. A current of tenths of a metre a
    second is handed over in full after a window or two, while one window of an autopilot
    EKF's sway noise (correlated over about a second) is no longer steered by as a side
    current of 0.07 m/s at the start. After that the part is used in full (a significance
    test there held back part of a heading bias's stand-in in bends), so no offset is left.
    Along the boat a current looks like a drag error and a second's window tells little
    (sigma ~0.2 m/s after ten windows of an autopilot's EKF): handed over early, the
    navigation's noise steered the boat as a head current of 0.3 m/s; so that part counts
    only as it becomes known to `along_sigma`, w = 1 - (sigma / along_sigma)^2. What is not handed over there only changes the speed,
    which the NMPC's feedback holds."""
    cov = estimate.current_cov
    if cov is None:
        return np.asarray(estimate.current_ne, float)
    c, s = math.cos(heading_rad), math.sin(heading_rad)
    rot = np.array([[c, s], [-s, c]])  # NED -> (along, across)
    body = rot @ np.asarray(estimate.current_ne, float)
    var = np.einsum("ij,jk,ik->i", rot, cov, rot)
    weight = np.clip(1.0 - var / np.array([along_sigma, prior_sigma]) ** 2, 0.0, 1.0)
    if estimate.updates < settle_windows:
        z = abs(body[1]) / math.sqrt(var[1]) if var[1] > 0 else math.inf
        weight[1] *= min(1.0, max(0.0, z - 1.0))
    return rot.T @ (weight * body)


@functools.lru_cache(maxsize=8)
def window_prediction(steps: int, dt: float) -> ca.Function:
    """`predict(x0[6], act[2, steps], theta[5], p[NP]) -> (nu_end[3], d nu_end / d theta)`:
    the exact model (RK4, one step per control period) with each period's actuators held.
    Built once per (steps, dt) in a process (a Function is immutable; building it costs
    ~70 ms)."""
    x0 = ca.SX.sym("x0", 6)
    act = ca.SX.sym("act", 2, steps)
    theta = ca.SX.sym("theta", N_THETA)
    p = ca.SX.sym("p", NP)
    x = x0
    for k in range(steps):
        u = act[:, k]
        x = rk4(lambda z: boat_ode(z, u, p, theta[0:2], EXACT, theta[2:5]), x, dt, 1)
    nu = x[3:6]
    return ca.Function("water_window", [x0, act, theta, p], [nu, ca.jacobian(nu, theta)],
                       ["x0", "act", "theta", "p"], ["nu", "dnu_dtheta"])


class WaterEstimator:
    """Call `update(state, actuators, time_s)` every `period_s`; it returns the current
    estimate."""

    def __init__(self, config: WaterEstimatorConfig = WaterEstimatorConfig()):
        self.config = config
        self._predict = window_prediction(config.steps, config.period_s)
        self._p = config.boat.as_vector()
        self.reset()

    def reset(self, current_ne=(0.0, 0.0)) -> None:
        """Start again from `current_ne` (e.g. a known current) and the prior spreads."""
        c = self.config
        ekf = ExtendedKalmanFilter(dim_x=N_THETA, dim_z=3)
        ekf.x = np.array([current_ne[0], current_ne[1], 0.0, 0.0, 0.0], float)
        ekf.P = np.diag([c.current_sigma0**2] * 2 + [s * s for s in c.bias_sigma0])
        ekf.F = np.eye(N_THETA)
        ekf.Q = c.window_s * np.diag([c.current_walk**2] * 2 + [s * s for s in c.bias_walk])
        ekf.R = np.diag([s * s for s in c.velocity_sigma])
        self._ekf = ekf
        self._noise = np.array([s * s for s in c.velocity_sigma])  # running estimate of R
        self._buffer: deque = deque(maxlen=c.steps + 1)
        self.updates = 0
        self.skipped = 0
        self.off_period = 0  # samples that came off the period (`update`'s time_s)
        self._last_time = None
        self.reopened = 0  # times the water changed faster than the random walk allows
        self.unsteady = 0  # windows left out because the boat sped up or started a turn
        self._gated_in_row = 0

    @property
    def estimate(self) -> WaterEstimate:
        x, P = self._ekf.x, self._ekf.P
        sigma = np.sqrt(np.maximum(np.diag(P), 0.0))
        return WaterEstimate(x[0:2].copy(), x[2:5].copy(), sigma[0:2], sigma[2:5],
                             self.updates, self.skipped, self.reopened, P[:2, :2].copy())

    def update(self, state, actuators, time_s: float | None = None) -> WaterEstimate:
        """Add this period's state estimate [x, y, psi, u, v, r] and actuator positions
        [nT, nS] (%); once a window is full, fold it into the filter. `time_s` (the caller's
        clock): a sample that does not come one period after the last (a loop that fell
        behind, a pause) starts a new window, and is counted in `off_period`: the window's
        prediction assumes `period_s` between samples, and a loop's own lateness would
        otherwise read as a current."""
        try:
            x = np.asarray(state, float).reshape(-1)[:6]
            a = np.asarray(actuators, float).reshape(-1)[:2]
        except (TypeError, ValueError):
            x = a = np.zeros(0)
        if x.shape != (6,) or a.shape != (2,) or not (np.isfinite(x).all() and np.isfinite(a).all()):
            self.skipped += 1
            self._buffer.clear()  # a hole in the data: start a new window
            return self.estimate
        if time_s is not None:
            t, last = float(time_s), self._last_time
            self._last_time = t
            period = self.config.period_s
            if last is not None and self._buffer and abs(t - last - period) > 0.25 * period:
                self.off_period += 1
                self._buffer.clear()
        self._buffer.append((x, a))
        if len(self._buffer) == self._buffer.maxlen:
            self._fold()
            self._buffer = deque([self._buffer[-1]], maxlen=self._buffer.maxlen)
        return self.estimate

    def _fold(self) -> None:
        c = self.config
        states = np.array([s for s, _ in self._buffer])
        acts = np.array([a for _, a in self._buffer])
        if np.hypot(*(states[-1, :2] - states[0, :2])) > c.max_jump_m:
            self.skipped += 1  # the estimate jumped (a filter reset, a GPS glitch)
            return
        if abs(states[-1, 3] - states[0, 3]) > c.steady_du_mps \
                or abs(states[-1, 5] - states[0, 5]) > c.steady_dr_radps:
            self.unsteady += 1  # speeding up, slowing down, starting a turn: not used
            self._set_walk(states[0, 2])
            self._ekf.predict()  # (the water may still change meanwhile)
            return
        held = 0.5 * (acts[:-1] + acts[1:])  # the actuators move linearly within a period
        ekf = self._ekf
        self._set_walk(states[0, 2])
        ekf.predict()
        nu, jac = self._predict(states[0], held.T, ekf.x, self._p)
        nu, H = np.asarray(nu).ravel(), np.asarray(jac)
        y = states[-1, 3:6] - nu
        ramp = abs(acts[-1, 0] - acts[0, 0]) > c.steady_dnT_pct
        learnt = ekf.R.copy()
        if ramp:  # the surge of this window is the throttle's lag, not the water
            ekf.R[0, 0] = 1e4
        S = H @ ekf.P @ H.T + ekf.R
        if float(y @ np.linalg.solve(S, y)) > c.gate_sigma**2:
            self._gated_in_row += 1
            if self._gated_in_row < c.reopen_after:
                self.skipped += 1
                ekf.R = learnt
                return
            self._reopen()
        # theta enters nu nonlinearly; one EKF step linearised at the prior mean
        prior = ekf.x.copy()
        ekf.update(states[-1, 3:6], lambda _x: H, lambda _x: nu)
        ekf.R = learnt
        self.updates += 1
        self._gated_in_row = 0
        if not ramp:
            residual = y - H @ (ekf.x - prior)
            self._learn_noise(residual, np.einsum("ij,jk,ik->i", H, ekf.P, H))

    def _learn_noise(self, residual: np.ndarray, explained: np.ndarray) -> None:
        """The measurement noise from the residuals after each update (Mehra's residual
        form of covariance matching, which stays positive while the filter still learns):
        R = E[residual^2] + H P H', between the floor and the start value."""
        c = self.config
        sample = residual**2 + explained
        self._noise += c.noise_learning * (sample - self._noise)
        lo = np.square(c.velocity_sigma_floor)
        hi = np.square(c.velocity_sigma)
        self._ekf.R = np.diag(np.clip(self._noise, lo, hi))

    def _set_walk(self, heading_rad: float) -> None:
        """The current's random walk over one window, along and across the boat's heading."""
        c = self.config
        ch, sh = math.cos(heading_rad), math.sin(heading_rad)
        rot = np.array([[ch, -sh], [sh, ch]])  # body (along, across) to NED
        walk = rot @ np.diag([c.current_walk**2, c.current_walk_across**2]) @ rot.T
        self._ekf.Q[:2, :2] = c.window_s * walk

    def _reopen(self) -> None:
        """The water changed: widen the current's spread back to its prior (the estimates
        stay as the start; the bias keeps its spread, or it would take the change)."""
        c = self.config
        P = self._ekf.P.copy()
        P[:2, :] = P[:, :2] = 0.0
        P[0, 0] = P[1, 1] = max(c.current_sigma0**2, self._ekf.P[0, 0], self._ekf.P[1, 1])
        self._ekf.P = P
        self.reopened += 1
