"""The NMPC as a controller: called every control period with the state estimate, the
actuators, the segments and the waypoints; returns the commands and the plan.

Per step: reference (forward from the previous progress), segment slots, warm start (the
previous plan shifted by one control period), the slack's reference (what a stretch narrower
than 2 (R_b + d_p) forces, `slack_reference`), one solve (RTI by default), then the command
`nT_0 + dnT_0 * dt`, `nS_0 + dnS_0 * dt`. A failed or non-finite solve is never passed on:
the controller retries once from a safe guess (the reference itself), else follows the
shifted previous plan, and after `max_failures` failed steps in a row raises `SolverError`:
the caller must stop the boat.
"""

from __future__ import annotations

import math
import operator
import time
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from ..errors import InputError, SolverError, finite_number
from ..geometry import wrap_angle
from .problem import (NU, NX, NX_BOAT, NmpcConfig, ParamLayout, build_ocp, pack_params,
                      surge_cap)
from .reference import Reference, WaypointPath, reference_trajectory, waypoint_path
from .rti import QpOptions, QpStep, SqpResult, sqp
from .blind_openings import ask_below_cap, blind_opening_ahead, blind_speed_cap
from .passage import WayAhead
from .seamanship import Shaping, assess
from .segment_slots import SLOT_FIELDS, check_segments, kept_in_place, select_checked
from .slack_reference import forced_slack
from .vessel_slots import at_rest, predict_vessels, rest_outlines

METHODS = ("rti", "sqp", "ipopt")
STUCK_SQP_ITERATIONS = 10
"""SQP iterations of a restart for a boat held at rest (`NmpcController._stuck`)."""
BACKING_OFF = "backing off"
"""What the rules' reason says while the boat backs off, held at rest (`_back_off`)."""
PLAUSIBLE_TOL = 1e-3
"""How far past its bounds a solved plan may lie before it counts as garbage."""


@dataclass(frozen=True)
class SolverStats:
    """What one control step's solve did and what it cost (seconds of wall clock)."""

    method: str
    ok: bool  # the plan is a fresh solution (False: a fallback plan was used)
    converged: bool  # SQP/IPOPT reached their tolerance (RTI: False by design)
    status: str
    fallback: str  # "", "safe_guess" (retry succeeded), "shifted_plan" or "hold" (no plan yet)
    sqp_iterations: int
    qp_iterations: int
    consecutive_failures: int
    time_total_s: float
    time_linearisation_s: float
    time_qp_s: float
    cpu_time_s: float  # this thread's CPU time for the step: the wall time less preemption
    segments_dropped: int = 0  # segments within range that found no slot
    dropped_nearest_m: float = float("inf")  # the closest of those to the planned path
    command_clipped: bool = False  # the plan's first move had to be cut to the bounds (> 1e-6)
    waiting: str = ""  # why the reference stops the boat ("way blocked at 23 m"), "" going on
    blocked_at_m: float | None = None  # arc length along the path of the obstruction
    vessels: tuple = ()  # ids of the tracks in the vessel slots
    vessels_dropped: int = 0  # vessels in range that found no slot
    rules: str = ""  # what the rules of the road ask ("meeting 3: keep to starboard")
    time_feedback_s: float = 0.0  # state in to command out (the feedback phase)
    time_preparation_s: float = 0.0  # the preparation of this step (done after a command)
    fed_back: bool = False  # the feedback used the prepared QP (False: linearised anew)
    set_up_in_preparation: bool = False  # the reference, slots and gradient were the
    # preparation's, made at the predicted state: the feedback only embedded the state
    elastic_segments: float = 0.0  # the last QP's largest violation of a segment row (h)
    elastic_vessels: float = 0.0  # ... and of a vessel row (exact-penalty rows; 0: none)
    surge_over_mps: float = 0.0  # how far the plan's surge went above its soft ceiling
    # (`NmpcConfig.surge_margin_mps`), the most over stages 1..Np
    restarted: bool = False  # solved again from the reference: the plan from the last one
    # broke obstacle rows by more than `NmpcConfig.restart_elastic_h`, and that did less
    backing_off: bool = False  # backing off along the path, the plans having held the boat
    # at rest though restarted (`NmpcConfig.back_off_m`)

    @property
    def time_glue_s(self) -> float:
        """Everything else: reference, segment slots, warm start, Python."""
        return self.time_total_s - self.time_linearisation_s - self.time_qp_s

    @property
    def time_feedback_glue_s(self) -> float:
        """The feedback's own Python: reference, slots, command (its linearisation and QP
        aside)."""
        return self.time_feedback_s - self.time_linearisation_s - self.time_qp_s


@dataclass(frozen=True)
class NmpcStep:
    """One control step: the commands to send now and the plan behind them."""

    command: np.ndarray  # [nT, nS] in %, to send now
    rates: np.ndarray  # [dnT_0, dnS_0] in %/s
    states: np.ndarray  # predicted [x, y, psi, u, v, r, nT, nS] at stages 0..Np, (Np+1, 8)
    inputs: np.ndarray  # planned [dnT, dnS] at stages 0..Np-1, (Np, 2)
    slack_m: np.ndarray  # s_1..s_Np in m (<= 0: how much the clearance was given up)
    reference: Reference
    stats: SolverStats

    @property
    def max_slack_m(self) -> float:
        """The largest clearance given up over the horizon, in m (>= 0)."""
        return float(-self.slack_m.min()) if self.slack_m.size else 0.0


def _moving(vessels) -> tuple:
    """The tracks the controller keeps: moving ones (a vessel slot, the rules of the road)
    and vessels at rest (`vessel_slots.at_rest`: walls grown by `rest_keep_m`); any other
    track not moving is an obstacle like a wall, its sides among the segments."""
    return tuple(v for v in vessels if getattr(v, "moving", True)
                 or getattr(v, "vessel", False))


class _Inputs(NamedTuple):
    """A step's inputs but the state: what a prepared setup was made from, and a key that is
    equal for equal inputs (the arrays' bytes, the path and the tracks as objects: tracks
    are frozen, so the same objects are the same tracks)."""

    segs: np.ndarray
    vessels: tuple
    path: WaypointPath
    speed: float
    current: np.ndarray
    bias: np.ndarray
    blind: bool
    key: tuple

    @staticmethod
    def of(segs, vessels, path, speed, current, bias, blind,
           known: "_Inputs | None" = None) -> "_Inputs":
        """Copies of the arrays (a caller may refill its own in place for the next step);
        `known`: earlier inputs whose segments `segs` is (already a copy, its bytes known),
        themselves when all the rest is equal too (the prepared step's: no copies, no key)."""
        if known is not None and segs is known.segs:
            if (path is known.path and speed == known.speed and blind == known.blind
                    and len(vessels) == len(known.vessels)
                    and all(map(operator.is_, vessels, known.vessels))
                    and current.tobytes() == known.key[2] and bias.tobytes() == known.key[3]):
                return known
            seg_bytes = known.key[1]
        else:
            segs = np.array(segs)
            seg_bytes = segs.tobytes()
        current, bias = current.copy(), bias.copy()
        key = (segs.shape, seg_bytes, current.tobytes(), bias.tobytes(), speed, blind,
               id(path), tuple(map(id, vessels)))
        return _Inputs(segs, vessels, path, speed, current, bias, blind, key)

    def same(self, other: "_Inputs") -> bool:
        # ids stand for identity here: both inputs hold their path and tracks alive
        return self.key == other.key


@dataclass
class _Buffers:
    """Arrays a step's setup is written into (two sets: the step's and the prepared one)."""

    p: np.ndarray
    w_ref: np.ndarray
    lbw: np.ndarray
    ubw: np.ndarray
    surge_cap: np.ndarray  # the plan's soft surge ceiling per stage (`problem.surge_cap`)


@dataclass
class _Setup:
    """A step set up for its solve (`NmpcController._setup`)."""

    reference: Reference
    selection: object  # segment_slots.SegmentSelection
    stop: object  # passage.Stop | None
    rules: Shaping
    vessel_sel: object  # vessel_slots.VesselSelection
    slack_ref: np.ndarray
    p: np.ndarray
    w_ref: np.ndarray
    lbw: np.ndarray
    ubw: np.ndarray
    surge_cap: np.ndarray
    memory: tuple = ()  # the controller's memory after it (`NmpcController._memory`)


@dataclass
class _Prepared:
    """A preparation: for which elapsed time, the shifted plan, and the step set up for it."""

    elapsed_s: float
    guess: np.ndarray
    inputs: _Inputs
    setup: _Setup | None  # None: only linearised (the inputs change every step)


def steady_throttle(speed_mps, boat) -> np.ndarray:
    """nT (%) that holds a surge speed in still water: c_eff nT^2 = -(X_u u + X_u|u| u|u|)."""
    u = np.maximum(np.asarray(speed_mps, float), 0.0)
    drag = -(boat.Xu * u + boat.Xuu * u * u)
    return np.sqrt(np.maximum(drag, 0.0) / boat.c_eff)


def _finite_vector(value, size: int, what: str) -> np.ndarray:
    if type(value) is np.ndarray and value.shape == (size,) and value.dtype == np.float64:
        if math.isfinite(sum(value.tolist())):  # the common case, in a sixth of the time
            return value  # (a NaN or an infinity makes the sum one; so may an overflow,
            # which the check below then clears) as np.asarray would: the same array
    elif type(value) is tuple and len(value) == size and all(type(v) is float for v in value):
        if math.isfinite(sum(value)):  # (the defaults: tuples of floats)
            return np.array(value)
    try:
        arr = np.asarray(value, float)
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected {size} numbers, got {value!r}") from None
    if arr.ndim > 1:
        arr = arr.squeeze()
    if arr.ndim != 1 or arr.size != size:
        raise InputError(f"{what}: expected {size} numbers, got shape {np.shape(value)}")
    if not np.isfinite(arr).all():
        raise InputError(f"{what}: contains NaN or infinity: {arr.tolist()}")
    return arr


def _unwrap_near(angle: float, reference: float) -> float:
    """`geometry.unwrap_near` for two floats, without numpy's overhead."""
    return reference + ((angle - reference + math.pi) % (2.0 * math.pi) - math.pi)


def top_speed_mps(boat, throttle_pct: float = 100.0) -> float:
    """Steady surge speed at `throttle_pct` in still water (c_eff nT^2 = drag)."""
    a, b, f = -boat.Xuu, -boat.Xu, boat.c_eff * float(throttle_pct)**2
    return float((-b + np.sqrt(b * b + 4 * a * f)) / (2 * a)) if a > 0 else f / max(b, 1e-9)


class NmpcController:
    """The paper's NMPC, solved by real-time iteration ("rti"), SQP to convergence ("sqp")
    or IPOPT ("ipopt"). `compiled` uses the cached C linearisation (RTI, SQP). `split`: RTI
    in two phases (`prepare` after each command, `feedback` when the state comes), on by
    default: the preparation sets the next step up at the state the plan predicts, so the
    command leaves after the state's embedding and one QP; the answer is the one-phase
    step's within the QP's tolerance (0.2 mm on the bench; it differs only where the
    reference made at the predicted state differs from one made at the state given).
    `split=False` does the whole step in `feedback`."""

    def __init__(self, config: NmpcConfig = NmpcConfig(), method: str = "rti",
                 qp: QpOptions = QpOptions(), compiled: bool = True, sqp_max_iter: int = 50,
                 sqp_tol: float = 1e-3, max_failures: int = 3,
                 reference_search_ahead_m: float = 50.0, split: bool = True):
        if method not in METHODS:
            raise InputError(f"NMPC method {method!r}: choose one of {', '.join(METHODS)}")
        if max_failures < 1:
            raise InputError(f"max_failures: must be at least 1, got {max_failures!r}")
        self.config, self.method = config, method
        self.split = bool(split)  # step() prepares the next step after each (RTI, direct hpipm)
        self.max_failures, self.sqp_max_iter, self.sqp_tol = max_failures, sqp_max_iter, sqp_tol
        self.search_ahead_m = reference_search_ahead_m
        self.ocp = build_ocp(config)
        # what does not change from step to step, computed once
        self._layout = ParamLayout.of(config)
        self._params = pack_params(config, np.zeros((config.segment_slots, len(SLOT_FIELDS))))
        self._lbw, self._ubw = self.ocp.bounds(np.zeros(NX_BOAT))
        # the plausible plan's box (`_plausible`), all but x_0 fixed (the steps' bounds are
        # these, x_0's set to the state, which a plan's x_0 then equals): for the feedback
        self._plausible_lo, self._plausible_hi = self._lbw - PLAUSIBLE_TOL, self._ubw + PLAUSIBLE_TOL
        self._plausible_lo[:NX_BOAT], self._plausible_hi[:NX_BOAT] = -np.inf, np.inf
        self._x0_at = self.ocp.states_at[0]
        self._xy_at = self.ocp.states_at[:, :2]
        self._ref_at = self.ocp.states_at[:, :NX_BOAT]
        self._psi_at = self.ocp.states_at[:, 2]
        self._slack_ref_at = self.ocp.states_at[1:, NX - 1]
        self._top_speed = top_speed_mps(config.boat, config.nT_max)
        self._way = WayAhead(config.min_passage_m, config.stop_short_m, config.stop_decel_mps2,
                             config.resume_after_s,
                             clearance_m=config.hull_radius_m + config.separation_m)
        self.compiled_info = None
        if method == "ipopt":
            from .ipopt import IpoptSolver

            self._ipopt = IpoptSolver(self.ocp)
        else:
            linearisation = self.ocp.linearisation
            compile = None
            if compiled:
                from .codegen_cache import compile_cached

                self.compiled_info = compile_cached(linearisation)
                linearisation = self.compiled_info.function
                compile = lambda f: compile_cached(f).function  # noqa: E731
            self._qp = QpStep(self.ocp, linearisation, qp, compile)
        self._act_lo = np.array([-config.nT_max, -config.nS_max])
        self._act_hi = -self._act_lo
        self._rate_max = np.array([config.dnT_max, config.dnS_max])
        self._rate_max_f, self._act_hi_f = self._rate_max.tolist(), self._act_hi.tolist()
        self._x0_boat = slice(0, NX_BOAT)  # x_0 leads w (`_start_at`): slices index in a
        # third of the time of index arrays
        assert (self._x0_at[:NX_BOAT] == np.arange(NX_BOAT)).all()
        self._x1_xy_at = self.ocp.states_at[1:, :2]
        self._u_at = self.ocp.states_at[:, 3]
        self._surge_over = 0.0
        self._ceiling = config.surge_margin_mps is not None  # (off: no work a step for it)
        self._xy_buffer = np.zeros((config.horizon + 1, 2))
        u0 = self.ocp.inputs_at[0]
        self._u0_rates = slice(int(u0[0]), int(u0[0]) + 2)
        assert (u0[:2] == np.arange(u0[0], u0[0] + 2)).all()
        self._states_boat_at = self.ocp.states_at[:, :NX_BOAT]
        self._inputs_rates_at = self.ocp.inputs_at[:, :2]
        self._stages = np.arange(1, config.horizon + 1, dtype=float)
        self._widen_m = max(abs(o) for o in config.hull_offsets_m)
        self._shift_cache: dict[float, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._buffers = [_Buffers(self._params.copy(), np.zeros(self.ocp.nw), self._lbw.copy(),
                                  self._ubw.copy(), np.zeros(config.horizon + 1))
                         for _ in range(2)]
        self.reset()

    def reset(self) -> None:
        """Forget the plan, the progress along the path and the failure count."""
        self._plan: np.ndarray | None = None
        self._solved = False  # a plan came from a successful solve since the reset
        self.last_qp_inputs: tuple | None = None
        self._progress_m: float | None = None  # None: not yet located on the path
        self._place_m: float | None = None  # the boat's own, which may go back (`_setup`)
        self._path: WaypointPath | None = None
        self._waypoints_given: np.ndarray | None = None
        self.consecutive_failures = 0
        self._way.reset()
        self._rules_stop: Shaping | None = None
        self._giving_way: frozenset = frozenset()  # track ids given way to last period
        self._overtaking: dict = {}  # track id: the side overtaken on last period
        self._restart_rest = 0  # steps left before another restart from the reference
        self._stuck_s = 0.0  # how long the plan has held the boat at rest (`_stuck`)
        self._broken_s = 0.0  # how long the QPs' rows have broken past restart_broken_h
        self._back_to: float | None = None  # backing off to this arc length (`_stuck`)
        self._surge_line: float | None = None  # the braking line's surge now (`_surge_cap`)
        self._backed: tuple[int, float] = (0, 0.0)  # back-offs in a row, where the last began
        self._elastic: tuple | None = None  # this step's rows' violation, if a restart chose
        self._rules_clear_s = 0.0
        self._prepared: _Prepared | None = None
        self._inputs: _Inputs | None = None  # the last step's, for the next preparation
        self._steady = False  # the last step's inputs were the ones before it
        self._last_p: np.ndarray | None = None  # the last step's parameters
        self._slots_prev: np.ndarray | None = None
        self._preparation_s = 0.0

    # -- the step ---------------------------------------------------------------------------
    def step(self, state, actuators, segments, waypoints, target_speed_mps: float,
             current=(0.0, 0.0), elapsed_s: float | None = None,
             blind: bool = False, bias=(0.0, 0.0, 0.0), vessels=()) -> NmpcStep:
        """One control period: `feedback` for this state, then `prepare` for the next (with
        `split`; the stats count both). Arguments as `feedback`."""
        if not self.split:
            return self.feedback(state, actuators, segments, waypoints, target_speed_mps,
                                 current, elapsed_s, blind, bias, vessels)
        done = self._feedback(state, actuators, segments, waypoints, target_speed_mps,
                              current, elapsed_s, blind, bias, vessels)
        return self._output(*done, self.prepare())

    def prepare(self, elapsed_s: float | None = None, segments=None, vessels=None) -> float:
        """The preparation phase of the real-time iteration, right after a command is sent:
        for the state the plan predicts `elapsed_s` ahead (default: the control period; the
        next `feedback` must be called with the same), everything the next step needs but
        the state itself: the reference, the segment and vessel slots, the slack's reference,
        the way ahead and the rules of the road, the linearisation and the QP. The next
        `feedback` then embeds its state and solves, if it brings the same segments,
        vessels, waypoints, speed, current, bias and blindness; otherwise it sets the step up
        itself at its state (using the prepared linearisation where it still holds). While
        every step brings other inputs (a new scan each period), the preparation only
        linearises: a setup would go unused. `segments`, `vessels`: perception newer than
        the last step's (a scan that arrived after the command), for the preparation to set
        the step up with. Returns its seconds. Does nothing for SQP and IPOPT or before a
        first plan."""
        t0 = time.perf_counter()
        self._prepared = None
        if self.method != "rti" or self._plan is None or self._inputs is None:
            self._preparation_s = 0.0
            return 0.0
        c = self.config
        elapsed = c.control_period_s if elapsed_s is None else finite_number(elapsed_s,
                                                                             "elapsed_s")
        guess = self._shifted_plan(elapsed)
        inputs = self._inputs
        if segments is not None or vessels is not None:
            inputs = _Inputs.of(
                check_segments(segments) if segments is not None else inputs.segs,
                _moving(vessels) if vessels is not None else inputs.vessels, *inputs[2:7])
        setup = None
        if self._steady or segments is not None or vessels is not None:
            # inputs that repeat (or a scan handed in): set the step up for them
            x = guess[self._x0_at]
            before = self._memory()
            try:
                setup = self._setup(x[:6], inputs, elapsed, guess, self._buffers[1])
                setup.memory = self._memory()
            finally:
                self._restore(before)  # the step's own memory moves on only when it is used
        # else each step brings other inputs (a new scan every period): a setup made now
        # would go unused; linearise with the last step's parameters alone
        p, w_ref = (self._last_p, None) if setup is None else (setup.p, setup.w_ref)
        if setup is not None and self._ceiling:
            self._qp.surge_cap[:] = setup.surge_cap
        if self._qp.prepare(guess, p, self._lbw, self._ubw, w_ref):
            self._prepared = _Prepared(elapsed, guess, inputs, setup)
        self._preparation_s = time.perf_counter() - t0
        return self._preparation_s

    def feedback(self, state, actuators, segments, waypoints, target_speed_mps: float,
                 current=(0.0, 0.0), elapsed_s: float | None = None,
                 blind: bool = False, bias=(0.0, 0.0, 0.0), vessels=()) -> NmpcStep:
        """The feedback phase: this state in, the command out (after a `prepare`, the QP is
        mostly set up; without one, the whole step is done here).

        state: [x, y, psi, u, v, r] (NED m, rad, body m/s, rad/s); actuators: the current
        [nT, nS] in %; segments: (M, 4) rows (x_c, y_c, theta, length); waypoints: (K, 2)
        (the same list keeps the progress along it, a new one restarts it); current: water
        current [north, east] in m/s; elapsed_s: time since the previous call, by which the
        warm start is shifted (default: the control period; e.g. 1.0 for a 1 Hz planner);
        blind: perception has had no usable scan for too long (`perception.feed`); bias: the
        model error as a body-frame acceleration [b_u, b_v, b_r] (m/s^2, rad/s^2), added to
        the prediction model (`water_estimator` estimates it with the current); vessels:
        tracks of other vessels (`perception.tracking.Track`), each moving one avoided at every
        stage as predicted from its track (`vessel_slots`) and met by the rules of the road; a
        track that is not moving (`moving` False) is an obstacle like a wall, its sides among
        the segments, and takes neither a slot nor a rule; one known for a vessel (`vessel`:
        under way once) is a wall grown by `rest_keep_m`, passed 2 m off hull to hull.
        Where the segments leave no passage along the route, or when blind, the reference
        slows the boat to a stop short of it and holds (`passage`); `stats.waiting` says why.
        """
        done = self._feedback(state, actuators, segments, waypoints, target_speed_mps,
                              current, elapsed_s, blind, bias, vessels)
        preparation, self._preparation_s = self._preparation_s if done[-2] else 0.0, 0.0
        return self._output(*done, preparation)

    def _feedback(self, state, actuators, segments, waypoints, target_speed_mps: float,
                  current, elapsed_s, blind, bias, vessels) -> tuple:
        """The feedback up to the command; returns what `_output` needs (ends with whether the
        step used a preparation and whether it was solved again from the reference)."""
        cpu0 = time.thread_time()  # read outside the wall clock's window: a loaded machine
        t0 = time.perf_counter()  # can take the CPU away in this system call
        c = self.config
        x = _finite_vector(state, 6, "state [x, y, psi, u, v, r]")
        act = _finite_vector(actuators, 2, "actuators [nT, nS]")
        act = np.minimum(np.maximum(act, self._act_lo), self._act_hi)
        current = _finite_vector(current, 2, "current [north, east]")
        bias = _finite_vector(bias, 3, "bias [b_u, b_v, b_r]")
        self._set_path(waypoints)
        speed = finite_number(target_speed_mps, "target_speed_mps")
        if not 0.0 <= speed <= self._top_speed:
            raise InputError(f"target_speed_mps: must lie in [0, {self._top_speed:.2f}] m/s "
                             f"(the boat's top speed at {c.nT_max:g} % throttle), got {speed:g}")
        elapsed = c.control_period_s if elapsed_s is None else finite_number(elapsed_s, "elapsed_s")
        if elapsed < 0:
            raise InputError(f"elapsed_s: must be a non-negative number of s, got {elapsed:g}")
        prepared, self._prepared = self._prepared, None
        segs = prepared.inputs.segs if prepared is not None else None
        if not (type(segments) is np.ndarray and segs is not None and segments.dtype == float
                and segments.shape == segs.shape and segments.tobytes() == segs.tobytes()):
            segs = check_segments(segments)  # (the prepared ones were checked)
        inputs = _Inputs.of(segs, _moving(vessels), self._path, speed, current, bias,
                            bool(blind), None if prepared is None else prepared.inputs)
        if prepared is not None and prepared.elapsed_s == elapsed:
            guess = prepared.guess
        else:
            prepared, guess = None, self._shifted_plan(elapsed)
        if guess is not None:
            x[2] = _unwrap_near(x.item(2), guess.item(2))  # (x_0 leads w)
        x_init = np.concatenate([x, act])

        fallback = ""
        fed_back = set_up = False
        from_safe_guess = guess is None  # no plan to start from: a retry would be the same
        self._steady = self._inputs is not None and self._inputs.same(inputs)
        if prepared is not None and prepared.setup is not None and prepared.inputs.same(inputs):
            # the step the preparation set up: only the state is new
            setup, set_up = prepared.setup, True
            self._restore(setup.memory)
            self._buffers.reverse()  # its buffers are now the step's; the next prepare
            # writes into the others
            setup.lbw[self._x0_boat] = setup.ubw[self._x0_boat] = x_init
            start = self._start_at(guess, x_init)  # the prepared QP's w but for x_0, and
            # its parameters: nothing to check
            result, fed_back = self._feed_back(start, setup.p, None), True
        else:
            setup = self._setup(x, inputs, elapsed, guess, self._buffers[0])
            setup.lbw[self._x0_boat] = setup.ubw[self._x0_boat] = x_init
            if self._ceiling and self.method != "ipopt":
                self._qp.surge_cap[:] = setup.surge_cap
            if guess is None:
                guess = self._safe_guess(x_init, setup.reference, setup.slack_ref)
                result = self._solve(self._start_at(guess, x_init), setup.p, setup.w_ref,
                                     setup.lbw, setup.ubw)
            else:
                start = self._start_at(guess, x_init)
                if prepared is not None and self._qp.can_feed_back(start, setup.p):
                    result, fed_back = self._feed_back(start, setup.p, setup.w_ref), True
                else:
                    result = self._solve(start, setup.p, setup.w_ref, setup.lbw, setup.ubw)
        self._inputs = inputs
        p, w_ref, lbw, ubw, reference = setup.p, setup.w_ref, setup.lbw, setup.ubw, setup.reference
        self._last_p = p
        self.last_qp_inputs = (p, w_ref, guess)  # what this step's OCP was given (its
        # parameters, reference and warm start; buffers reused by later steps): for peers
        restarted = False
        self._elastic = None  # (the QP's own, unless a restart chose between two)
        if result.ok and not from_safe_guess:
            result, restarted = self._restart_from_reference(result, x_init, reference, setup,
                                                         elapsed)
        if not result.ok and not from_safe_guess:
            retry = self._solve(self._safe_guess(x_init, reference, setup.slack_ref), p, w_ref,
                                lbw, ubw)
            result = self._merge(result, retry)
            fallback = "safe_guess" if retry.ok else ""
        if result.ok:
            self.consecutive_failures = 0
            self._solved = True
            plan = result.w
        else:
            self.consecutive_failures += 1
            if self.consecutive_failures >= self.max_failures:
                self._plan = None
                raise SolverError(
                    f"NMPC ({self.method}) failed {self.consecutive_failures} steps in a row "
                    f"(last: {result.status}); stop the boat")
            if not self._solved:  # no solved plan yet to follow: hold the actuators
                fallback, plan = "hold", self._hold(guess, x_init)
            else:
                fallback, plan = "shifted_plan", self._start_at(guess, x_init)
        self._plan = plan
        self._progress_m = reference.progress_m
        if self._ceiling:
            over = plan[self._u_at[1:]] - setup.surge_cap[1:]
            self._surge_over = max(float(over.max()), 0.0)
        command = self._command(plan, act)  # what leaves now: the feedback ends here
        wall = time.perf_counter() - t0
        times = wall, time.thread_time() - cpu0
        return (plan, command, reference, result, fallback, times, setup.selection,
                setup.stop, setup.vessel_sel, setup.rules, fed_back, set_up,
                prepared is not None, restarted)

    def _restart_from_reference(self, result: SqpResult, x_init, reference, setup,
                            elapsed_s: float):
        """RTI follows the plan it has: one that passes a vessel on the wrong side of its
        predicted hull (ahead of a kayak crossing, not stopping short as the rules ask) stays
        that plan step after step, breaking obstacle rows by more and more. Where the QP's
        rows broke by more than `restart_elastic_h`, or have broken by more than
        `restart_broken_h` at every step for `restart_broken_s`, the step is solved again from
        the reference (the rules' plan, `_safe_guess`) and the one that breaks them less (by
        at least half) is kept. A plan can also hold the boat at rest for good, the way on
        beside a stopped kayak needing a swing no single step from it finds: after
        `restart_stuck_s` of that, SQP to convergence from the reference, kept where it goes
        further and breaks the rows no more. (result, whether it was the restart's)."""
        c = self.config
        qp = getattr(self, "_qp", None)
        if qp is None or not (c.restart_elastic_h or c.restart_broken_s or c.restart_stuck_s):
            return result, False
        first = qp.elastic()
        stuck = bool(c.restart_stuck_s) and self._stuck(result.w, x_init, reference, setup,
                                                        elapsed_s)
        level = max(first)
        self._broken_s = self._broken_s + elapsed_s if level > c.restart_broken_h else 0.0
        broken = (bool(c.restart_elastic_h) and level > c.restart_elastic_h
                  or bool(c.restart_broken_s) and self._broken_s >= c.restart_broken_s - 1e-9)
        if not (broken or stuck):
            return result, False
        if self._restart_rest > 0:  # the last restart did no better: not again for a second
            self._restart_rest -= 1
            return result, False
        guess = self._safe_guess(x_init, reference, setup.slack_ref)
        if broken:
            retry = self._solve(guess, setup.p, setup.w_ref, setup.lbw, setup.ubw)
        else:
            retry = sqp(self._qp, guess, setup.p, setup.w_ref, setup.lbw, setup.ubw,
                        STUCK_SQP_ITERATIONS, self.sqp_tol)
        second = qp.elastic()
        if retry.ok and (max(second) < 0.5 * max(first) if broken else
                         max(second) <= max(first) + 1e-9
                         and self._travel(retry.w) > self._travel(result.w) + 1.0):
            self._elastic = second
            self._stuck_s = self._broken_s = 0.0
            return self._merge(result, retry), True
        self._elastic = first
        self._restart_rest = int(round(1.0 / self.config.control_period_s))
        return replace(result, sqp_iterations=result.sqp_iterations + retry.sqp_iterations,
                       qp_iterations=result.qp_iterations + retry.qp_iterations,
                       time_linearisation_s=result.time_linearisation_s
                       + retry.time_linearisation_s,
                       time_qp_s=result.time_qp_s + retry.time_qp_s), False

    def _travel(self, w: np.ndarray) -> float:
        """How far a plan goes: from x_0 to x_N, straight."""
        at = self._xy_at
        return float(np.hypot(*(w[at[-1]] - w[at[0]])))

    def _stuck(self, w, x_init, reference, setup, elapsed_s: float) -> bool:
        """The plan has held the boat at rest (under 0.2 m/s) for `restart_stuck_s`, going
        less than a quarter of the reference's way over the horizon, while the reference
        asks for more than 0.5 m/s and nothing asks the boat to wait. (Asked only while
        `restart_stuck_s` is set.)"""
        c = self.config
        want = float(reference.states[-1, 3])
        if (setup.stop is None and x_init[3] < 0.2 and want > 0.5
                and self._travel(w) < 0.25 * want * c.horizon * c.step_s):
            self._stuck_s += elapsed_s
        else:
            self._stuck_s = 0.0
        if c.back_off_m and self._stuck_s >= 2.0 * c.restart_stuck_s:
            self._back_off()
        return self._stuck_s >= c.restart_stuck_s

    def _back_off(self) -> None:
        """Held at rest though restarted: back off along the path, by `back_off_m` the first
        time and one more each time held again before getting `back_off_m` past where the
        last back-off began (at most three), to come on again with room to swing round what
        held the boat (a kayak stopped across the canal, the way on in the gap beside it)."""
        count, began = self._backed
        place = float(self._place_m)
        count = count + 1 if count and place < began + self.config.back_off_m else 1
        self._backed = (count, place)
        self._back_to = max(place - min(count, 3) * self.config.back_off_m, 0.0)
        self._stuck_s = 0.0

    # -- pieces -----------------------------------------------------------------------------
    def _setup(self, x: np.ndarray, inputs: "_Inputs", elapsed: float,
               guess: np.ndarray | None, buffers: "_Buffers") -> "_Setup":
        """Everything a step sets up before its solve, for a boat at x (the state): the
        way ahead, the rules, the reference, the slots, the parameters, the bounds and the
        slack's reference, written into `buffers`. Moves the step's memory on (progress
        search, way ahead, rules, slots)."""
        c = self.config
        segs, vessels, speed = inputs.segs, inputs.vessels, inputs.speed
        if self._progress_m is None:  # a new path: where the boat is along all of it (a
            # forward search from 0 put a boat that starts 60 m along at 50 m, 10 m off)
            self._progress_m = self._path.project(x[:2])[0]
        # The boat's place for the way ahead and the rules: searched forward from the last
        # progress, and back by as far as the boat went astern since, so that a boat backing
        # away from a blocked way is found where it is (held at the progress, its offset was
        # its distance from there, 30 m "across" the canal, and the way looked open through
        # the bank: fuzz seed 1 case 102). The reference keeps to the progress, forward only
        # (going back with a boat backing away from a vessel met, it let it go on astern)
        if self._place_m is None:
            self._place_m = self._progress_m
        astern = max(-float(x[3]), 0.0) * elapsed
        start = max(self._place_m - (1.5 * astern + 0.1 if astern > 0.0 else 0.0), 0.0)
        s, d = self._path.frame(x[None, :2], start,
                                start + self.search_ahead_m)  # the boat on the path
        self._place_m = float(s[0])
        resting = at_rest(vessels)
        if resting:  # vessels at rest: walls grown by rest_keep_m, not slots or rules
            vessels = tuple(v for v in vessels if v not in resting)
            if c.rest_keep_m > 0:  # (0: their sides are walls as they are)
                circles = x[:2] + np.outer(c.hull_offsets_m, (np.cos(x[2]), np.sin(x[2])))
                segs = np.vstack([segs, rest_outlines(resting, c.rest_keep_m, circles,
                                                      c.hull_radius_m)])
        stop = self._stop(float(s[0]), float(d[0]), x, segs, elapsed, inputs.blind)
        rules = self._rules(float(s[0]), float(d[0]), vessels, segs, speed, elapsed)
        stop_at = None if stop is None else stop.at_m
        if rules.stop_at_m is not None:
            stop_at = rules.stop_at_m if stop_at is None else min(stop_at, rules.stop_at_m)
        backing = self._back_to is not None and self._place_m > self._back_to + 0.5
        if backing:  # held at rest by its plans: back to there, then on again (`_back_off`)
            stop_at = self._back_to if stop_at is None else min(stop_at, self._back_to)
            said = f"{BACKING_OFF} {self._place_m - self._back_to:.0f} m: held at rest"
            rules = replace(rules, reason=f"{rules.reason}; {said}" if rules.reason else said)
        else:
            self._back_to = None
        ref_speed = speed if rules.speed_mps is None else min(speed, rules.speed_mps)
        ref_speed, blind, slow_to = self._blind_speed(float(s[0]), x[:2], segs, ref_speed,
                                                      float(x[3]))
        if blind:
            rules = replace(rules, reason=f"{rules.reason}; {blind}" if rules.reason else blind)
        # waiting for a blocked way, the boat keeps to the rules' line: the gap the sweep
        # leads to is shut (led to it, a boat waiting at a side canal's mouth was steered
        # about the mouth, its thrust for the rudder driving it on to 1 m of a kayak
        # stopped across the canal: fuzz seed 1 case 3)
        offset = (rules.offset_m if backing or stop is not None and stop.blocked_at_m
                  is not None else self._line(rules.offset_m))
        reference = reference_trajectory(self._path, x[:2], x[2], ref_speed, c.horizon,
                                         c.step_s, self._back_to if backing else
                                         self._progress_m, self.search_ahead_m,
                                         stop_at, c.stop_decel_mps2, inputs.current, offset,
                                         slow_to, back_to_stop=backing or stop is not None
                                         and stop.blocked_at_m is not None
                                         and stop_at == stop.at_m,
                                         heading_along_line=c.heading_along_line)
        planned = reference.states[:, :2] if guess is None else guess[self._xy_at]
        selection = select_checked(segs, x[:2], c.segment_slots, c.segment_range_m, planned)
        slots = self._keep_slots(selection.slots)
        vessel_sel = predict_vessels(vessels, c.vessel_slots, c.horizon, c.step_s, planned,
                                     x[:2], max_lateral_inflation_m=c.vessel_lateral_inflation_m,
                                     path=self._path, path_window=(self._progress_m - 80.0,
                                                                   self._progress_m + 150.0),
                                     lanes=frozenset(e.track_id for e in rules.encounters
                                                     if e.kind == "meeting" and e.lane))
        p, lay = buffers.p, self._layout  # filled in place: every part is written each step
        p[lay.vessels] = vessel_sel.slots.reshape(-1)
        p[lay.current] = inputs.current
        p[lay.bias] = inputs.bias
        p[lay.segments] = slots.reshape(-1)
        slack_ref = self._slack_reference(reference, speed, guess, x[:2], slots, offset)
        w_ref = buffers.w_ref
        w_ref[self._ref_at] = reference.states
        if guess is not None and c.heading_full_speed_mps:
            self._loosen_heading(reference.states, guess, w_ref)
        w_ref[self._slack_ref_at] = slack_ref
        self._surge_cap(reference.states[:, 3], float(x[3]), elapsed, buffers.surge_cap)
        return _Setup(reference, selection, stop, rules, vessel_sel, slack_ref, p, w_ref,
                      buffers.lbw, buffers.ubw, buffers.surge_cap)

    def _loosen_heading(self, reference: np.ndarray, guess: np.ndarray,
                        w_ref: np.ndarray) -> None:
        """The heading weight of stages slower than `heading_full_speed_mps` in proportion
        to their reference speed, by the reference: moved from the plan's heading (the
        guess's) a fraction a = |u_ref| / full of the way to its own. The QP's gradient in
        the heading is then a times the full weight's, so at its fixed point the weight is
        a Q_psi, while the Hessian keeps Q_psi and damps the heading's change from step to
        step. At rest the position alone holds the boat, at whatever heading stems the
        current."""
        speed = np.abs(reference[:, 3])
        share = speed / self.config.heading_full_speed_mps
        slow = share < 1.0
        if not slow.any():
            return
        at = self._psi_at[slow]
        planned = guess[at]
        wanted = reference[slow, 2]
        w_ref[at] = planned + share[slow] * wrap_angle(wanted - planned)

    def _surge_cap(self, reference_u: np.ndarray, surge_mps: float, elapsed_s: float,
                   out: np.ndarray) -> None:
        """The plan's soft surge ceiling per stage into `out` (`problem.surge_cap`). A boat
        above its reference brakes along a line that goes down at surge_decel_mps2 in real
        time from when it went above: drawn from each step's surge afresh, the line let
        every plan put its braking off by a step, and a boat asked for 0.6 m/s at a blind
        opening held 1.4 m/s to it (fuzz seed 1 case 48). Within the margin of the
        reference, the line starts again from the boat's surge."""
        c = self.config
        if c.surge_margin_mps is None:
            out[:] = np.inf
            return
        line = self._surge_line
        if line is None or surge_mps <= reference_u[0] + c.surge_margin_mps:
            line = surge_mps
        else:
            line = min(surge_mps, line - c.surge_decel_mps2 * elapsed_s)
        self._surge_line = line
        surge_cap(reference_u, line, c.step_s, c.surge_margin_mps, c.surge_decel_mps2, out)

    def _memory(self) -> tuple:
        """What `_setup` moves on, to be put back when a prepared setup goes unused."""
        return (self._way.memory(), self._rules_stop, self._rules_clear_s, self._slots_prev,
                self._giving_way, self._overtaking, self._place_m, self._back_to,
                self._surge_line)

    def _restore(self, memory: tuple) -> None:
        (way, self._rules_stop, self._rules_clear_s, self._slots_prev,
         self._giving_way, self._overtaking, self._place_m, self._back_to,
         self._surge_line) = memory
        self._way.restore(way)

    def _rules(self, s: float, d: float, vessels, segments, speed_mps: float,
               elapsed_s: float) -> Shaping:
        """What the rules of the road ask of the reference for these vessels (`seamanship`).
        A stop to give way is held `resume_after_s` after the rules stop asking for it, so a
        track's jitter (a kayak's wandering heading) cannot start and stop the boat."""
        c = self.config
        rules = Shaping()
        if c.colreg and vessels:
            rules = assess(vessels, self._path, s, d, speed_mps, segments,
                           hull_radius_m=c.hull_radius_m,
                           separation_m=c.separation_m,
                           vessel_separation_m=c.vessel_separation_m, bow_m=c.bow_m,
                           follow_gap_m=c.follow_gap_m, give_way_to=self._giving_way,
                           sight_m=c.sight_m, oncoming_mps=c.oncoming_mps,
                           oncoming_room_m=c.oncoming_room_m, overtaking=self._overtaking)
        self._giving_way = frozenset(e.track_id for e in rules.encounters
                                     if e.kind in ("give_way", "stand_on_acts"))
        self._overtaking = {e.track_id: e.side for e in rules.encounters if e.side}
        if rules.stop_at_m is not None:
            self._rules_stop, self._rules_clear_s = rules, 0.0
        elif self._rules_stop is not None:
            self._rules_clear_s += elapsed_s
            if self._rules_clear_s < c.resume_after_s - 1e-9:
                held = self._rules_stop
                return Shaping(rules.offset_m, held.speed_mps, held.stop_at_m,
                               held.reason + " (holding)", rules.encounters)
            self._rules_stop = None
        return rules

    def _blind_speed(self, s: float, xy: np.ndarray, segments, speed: float,
                     surge_mps: float):
        """The reference speed capped for the first blind opening ahead (`blind_openings`)
        for a boat going at `surge_mps`, what to say of it ("" when nothing is capped), and
        where the reference must be down to the blind speed ((arc length, speed), or None)."""
        c = self.config
        if not c.blind_speed_mps or speed <= c.blind_speed_mps:  # 0 or None: no rule
            return speed, "", None
        at = blind_opening_ahead(self._path, s, xy, segments, c.segment_range_m,
                                 c.blind_depth_m)
        if at is None:
            return speed, "", None
        cap = blind_speed_cap(at - c.blind_margin_m - s, c.blind_speed_mps, c.stop_decel_mps2)
        slow_to = (at - c.blind_margin_m, c.blind_speed_mps)
        if cap >= speed:  # not braking yet: the reference brakes where the horizon reaches
            return speed, "", slow_to
        cap = ask_below_cap(cap, surge_mps)
        return cap, f"blind opening {at - s:.0f} m ahead: {cap:.1f} m/s", slow_to

    def _stop(self, s: float, d: float, x: np.ndarray, segments, elapsed_s: float,
              blind: bool):
        """The stop the reference must make this period (`passage.WayAhead`), or None."""
        c = self.config
        lookahead = c.segment_range_m + c.stop_short_m
        return self._way.update(self._path, s, d, float(x[3]), segments, blind, elapsed_s,
                                lookahead)

    def _set_path(self, waypoints) -> None:
        """A new waypoint list restarts the progress along the path; the same one keeps it."""
        known = self._waypoints_given
        if type(waypoints) is np.ndarray and known is not None and waypoints.dtype == float \
                and waypoints.shape == known.shape and waypoints.tobytes() == known.tobytes():
            return  # the same array (the common case, without a copy)
        try:
            given = np.array(waypoints, float)
        except (TypeError, ValueError):
            given = None  # waypoint_path says what is wrong
        if given is not None and self._waypoints_given is not None \
                and given.shape == self._waypoints_given.shape \
                and np.array_equal(given, self._waypoints_given):
            return
        self._path = waypoint_path(waypoints)
        self._waypoints_given = given
        self._progress_m = self._place_m = None  # located at the next step

    def _solve(self, w, p, w_ref, lbw, ubw) -> SqpResult:
        if self.method == "ipopt":
            return self._ipopt.solve(w, p, w_ref, lbw, ubw)
        max_iter = 1 if self.method == "rti" else self.sqp_max_iter
        result = sqp(self._qp, w, p, w_ref, lbw, ubw, max_iter, self.sqp_tol)
        if result.ok and not self._plausible(result.w, lbw, ubw):
            return SqpResult(w, False, False, "implausible solution (bounds violated)",
                             result.sqp_iterations, result.qp_iterations, result.step_norm,
                             result.time_linearisation_s, result.time_qp_s)
        return result

    def _keep_slots(self, slots: np.ndarray) -> np.ndarray:
        """The selected segments with each one still selected in the slot it had last step
        (`segment_slots.kept_in_place`)."""
        prev = self._slots_prev
        if prev is not None and (slots == prev).all():
            return prev  # the same segments in the same slots (a static map, a still scene)
        out = slots if prev is None else kept_in_place(slots, prev)
        self._slots_prev = out
        return out

    def _feed_back(self, w, p, w_ref) -> SqpResult:
        """The RTI step on the prepared QP: what `_solve` gives for RTI, but for the
        linearisation done in `prepare` (the bounds are the OCP's, x_0's those of w)."""
        r = self._qp.feedback(w, p, w_ref)
        if not r.ok:
            return SqpResult(w, False, False, f"QP failed ({r.status})", 1,
                             max(r.qp_iterations, 0), np.inf, r.time_linearisation_s,
                             r.time_qp_s)
        new = w + r.dw
        norm = float(np.abs(r.dw).max()) if r.step_norm is None else r.step_norm  # NaN or
        # infinite when an entry of dw is
        if not (math.isfinite(norm) and (new >= self._plausible_lo).all()
                and (new <= self._plausible_hi).all()):  # `_plausible` (w, dw finite)
            return SqpResult(w, False, False, "implausible solution (bounds violated)", 1,
                             max(r.qp_iterations, 0), norm, r.time_linearisation_s,
                             r.time_qp_s)
        return SqpResult(new, True, norm < self.sqp_tol, r.status, 1, max(r.qp_iterations, 0),
                         norm, r.time_linearisation_s, r.time_qp_s)

    @staticmethod
    def _plausible(w, lbw, ubw, tol: float = PLAUSIBLE_TOL) -> bool:
        """A QP that claims success can still return garbage: check it is finite and bounded."""
        return bool(np.isfinite(w).all() and (w >= lbw - tol).all() and (w <= ubw + tol).all())

    @staticmethod
    def _merge(first: SqpResult, retry: SqpResult) -> SqpResult:
        """The retry's outcome, with both attempts' iterations and times."""
        return SqpResult(retry.w, retry.ok, retry.converged,
                         retry.status if retry.ok else f"{first.status}; retry: {retry.status}",
                         first.sqp_iterations + retry.sqp_iterations,
                         first.qp_iterations + retry.qp_iterations, retry.step_norm,
                         first.time_linearisation_s + retry.time_linearisation_s,
                         first.time_qp_s + retry.time_qp_s)

    def _shifted_plan(self, elapsed_s: float) -> np.ndarray | None:
        """The previous plan moved forward by `elapsed_s` (linear interpolation between
        stages, extrapolated past the last one)."""
        if self._plan is None:
            return None
        at = self._shift_cache.get(elapsed_s)
        if at is None:
            if len(self._shift_cache) > 8:  # elapsed times measured by a caller: keep a few
                self._shift_cache.clear()
            at = self._shift_cache[elapsed_s] = self._shift_indices(elapsed_s)
        lo, hi, f = at
        w = self._plan
        a = w[lo]
        return a + f * (w[hi] - a)

    def _shift_indices(self, elapsed_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Where in w each entry of the shifted plan interpolates from (lo, hi) and how far
        (f): states between stages i and i + 1 at i + elapsed / Ts (extrapolated past the
        last), inputs the same but clamped to their last interval."""
        N, Ts = self.config.horizon, self.config.step_s
        S, U = self.ocp.states_at, self.ocp.inputs_at
        pos = np.arange(N + 1) + elapsed_s / Ts
        i = np.minimum(pos.astype(int), N - 1)
        f = np.broadcast_to((pos - i)[:, None], S.shape)
        j = np.minimum(pos[:N].astype(int), N - 2)
        g = np.broadcast_to(np.clip(pos[:N] - j, 0.0, 1.0)[:, None], U.shape)
        lo, hi, weight = np.empty(self.ocp.nw, int), np.empty(self.ocp.nw, int), np.empty(self.ocp.nw)
        lo[S], hi[S], weight[S] = S[i], S[i + 1], f
        lo[U], hi[U], weight[U] = U[j], U[j + 1], g
        return lo, hi, weight

    def _hold(self, guess: np.ndarray, x_init: np.ndarray) -> np.ndarray:
        """An unsolved guess with the actuators held where they are (all rates 0): what a
        controller with no solved plan yet may send while it retries."""
        states, inputs = self.ocp.unpack(self._start_at(guess, x_init))
        states[:, 6:8] = x_init[6:8]
        inputs[:, :2] = 0.0
        return self.ocp.pack(states, inputs)

    def _start_at(self, w: np.ndarray, x_init: np.ndarray) -> np.ndarray:
        w = w.copy()
        w[:NX_BOAT] = x_init  # x_0 leads w (hpipm's stage order), its slack 0
        w[NX_BOAT] = 0.0
        return w

    def _line(self, rules_offset_m: float):
        """The line the reference follows across the path: where the way ahead lies off the
        path (`WayAhead.channel`: a gap beside an obstruction), into it, faded in and out
        over `channel_ramp_m`; elsewhere the rules' offset."""
        channel = self._way.channel
        if not channel:
            return rules_offset_m
        ramp = self.config.channel_ramp_m

        def line(s):
            d = channel.at(s, ramp)
            return np.where(d != 0.0, d, rules_offset_m)

        return line

    def _slack_reference(self, reference: Reference, speed_mps: float, guess, position,
                         slots: np.ndarray, offset=None) -> np.ndarray:
        """s_1..s_Np's reference: the clearance the canal forces each stage to give up
        (`slack_reference`), over the path between the stage's reference point and its place in
        the warm start, widened by the hull circles' offsets and half a stage's travel."""
        c = self.config
        step_m = speed_mps * c.step_s
        lo = hi = reference.progress_m + step_m * self._stages
        if guess is not None:
            xy = self._xy_buffer  # the boat, then stages 1..Np of the warm start
            xy[0] = position
            xy[1:] = guess[self._x1_xy_at]
            d = xy[1:] - xy[:-1]  # (np.diff with prepend costs ten times as much)
            travelled = reference.progress_m + np.cumsum(np.hypot(d[:, 0], d[:, 1]))
            lo, hi = np.minimum(lo, travelled), np.maximum(hi, travelled)
        widen = self._widen_m + 0.5 * step_m
        segments = slots[slots[:, -1] > 0, :4]
        return forced_slack(self._path, lo - widen, hi + widen, segments,
                            c.hull_radius_m + c.separation_m, c.slack_min_m,
                            offset=offset if callable(offset) else None)

    def _safe_guess(self, x_init: np.ndarray, reference: Reference,
                    slack_ref: np.ndarray | None = None) -> np.ndarray:
        """The reference itself, the slack at its reference (what the canal forces), steering
        centred, and the throttle moving at its rate limit toward the steady throttle of each
        stage's reference speed.

        The ramp matters: thrust goes with nT |nT|, so a guess at nT = 0 (a boat at rest)
        linearises to a boat that can neither speed up nor steer, and its QP fails.
        """
        c = self.config
        N, Ts = c.horizon, c.step_s
        states = np.zeros((N + 1, NX))
        states[:, :4] = reference.states[:, :4]
        target = steady_throttle(reference.states[:, 3], c.boat)
        nT = np.empty(N + 1)
        nT[0] = x_init[6]
        for k in range(N):
            nT[k + 1] = nT[k] + np.clip(target[k + 1] - nT[k], -c.dnT_max * Ts, c.dnT_max * Ts)
        states[:, 6] = np.clip(nT, -c.nT_max, c.nT_max)
        states[0, :NX_BOAT] = x_init
        if slack_ref is not None:
            states[1:, NX - 1] = slack_ref
        inputs = np.zeros((N, NU))
        inputs[:, 0] = np.diff(states[:, 6]) / Ts
        inputs[:, 2] = states[1:, NX - 1]
        return self.ocp.pack(states, inputs)

    def _command(self, plan: np.ndarray, act: np.ndarray) -> tuple:
        """The plan's first move as a command: (command, rates, clipped). (Two numbers each:
        in floats, a tenth of the time of numpy's calls.)"""
        dt = self.config.control_period_s
        rates, command, clipped = [], [], False
        for r, a, top, bound in zip(plan[self._u0_rates].tolist(), act.tolist(),
                                    self._rate_max_f, self._act_hi_f):
            rate = min(max(r, -top), top)
            wanted = a + rate * dt
            out = min(max(wanted, -bound), bound)
            clipped = clipped or abs(rate - r) > 1e-6 or abs(out - wanted) > 1e-6
            rates.append(rate)
            command.append(out)
        command, rates = np.array(command), np.array(rates)
        return command, rates, clipped

    def _output(self, plan, command, reference, result: SqpResult, fallback: str,
                times: tuple[float, float], selection, stop, vessel_sel, rules,
                fed_back: bool, set_up: bool, prepared: bool, restarted: bool,
                preparation_s: float) -> NmpcStep:
        """The step as the caller gets it: `times` are the feedback's (wall, CPU), the
        preparation's seconds (the one before this feedback, or with `split` the one after)
        count in the step's total."""
        command, rates, clipped = command
        qp = getattr(self, "_qp", None)  # (IPOPT has none)
        elastic = self._elastic or (qp.elastic() if qp is not None else (0.0, 0.0))
        stats = SolverStats(
            method=self.method, ok=result.ok, converged=result.converged, status=result.status,
            fallback=fallback, sqp_iterations=result.sqp_iterations,
            qp_iterations=result.qp_iterations,
            consecutive_failures=self.consecutive_failures,
            time_total_s=times[0] + preparation_s, cpu_time_s=times[1],
            time_linearisation_s=result.time_linearisation_s, time_qp_s=result.time_qp_s,
            segments_dropped=selection.dropped, dropped_nearest_m=selection.dropped_nearest_m,
            command_clipped=clipped, waiting="" if stop is None else stop.reason,
            blocked_at_m=None if stop is None else stop.blocked_at_m,
            vessels=vessel_sel.ids, vessels_dropped=vessel_sel.dropped,
            rules=rules.reason, fed_back=fed_back, set_up_in_preparation=set_up,
            time_feedback_s=times[0],
            time_preparation_s=preparation_s, elastic_segments=elastic[0],
            elastic_vessels=elastic[1], surge_over_mps=self._surge_over, restarted=restarted,
            backing_off=BACKING_OFF in rules.reason)
        return NmpcStep(command, rates, plan[self._states_boat_at], plan[self._inputs_rates_at],
                        plan[self._slack_ref_at], reference, stats)
