"""The NMPC of the paper's §III-B: the optimal control problem, written once.

    min  sum_{i<Np} (x_i - r_i)' Q (x_i - r_i) + u_i' R u_i + rho (s_i - sbar_i)^2
         + (x_Np - r_Np)' Q_T (x_Np - r_Np) + rho (s_Np - sbar_Np)^2
    s.t. x_0 = x_init,   x_{i+1} = f_d(x_i, u_i, P*)               (multiple shooting)
         |nT|, |nS| <= 100 %,  |dnT| <= 10 %/s,  |dnS| <= 40 %/s
         h(p_circle(x_i), L_j, s_i) >= 0   per hull circle, segment slot and stage (eq. mpc:pnorm)
         u_i <= ubar_i, soft (an exact penalty)   the surge ceiling (not the paper's, below)

with x = [x, y, psi, u, v, r, nT, nS] and u = [dnT, dnS] (DESIGN.md, NMPC). Choices the paper
leaves open, and why:
- The slack may shrink the separation R_b + d_p, -(R_b + d_p) + 0.1 <= s_i <= 0: printed with
  s_i >= 0 it could only make the constraint harder and an optimiser keeps it at 0. It shrinks
  both half axes (DESIGN.md: the minor one only): otherwise a segment's ends keep a hard margin
  R_b + d_p, and a short segment across the way (a wall's step where the canal narrows, a pier
  end) made the QP infeasible wherever the canal is narrower than twice that margin.
- The slack is paid for from the clearance the canal forces the boat to give up, sbar_i <= 0
  (`slack_reference`; 0 wherever the canal is at least 2 (R_b + d_p) wide, so there the cost
  is the paper's rho s_i^2). Paid from 0, the unavoidable violation of a stretch narrower than
  that cost rho s^2 for every 1 s stage inside it: the finite horizon planned to slow down
  before the stretch and sprint through it (fewer stages inside), and in closed loop only the
  slowing down was carried out (2.0 -> 0.9 m/s before the bench's 9 m stretch; a boat stopped
  before an 8.5 m one). sbar_i enters as the slack's reference in w_ref: a runtime input.
- The slack is carried as a ninth state, s_{i+1} = sigma_i with sigma_i a third input. Each
  stage's constraints then involve only that stage's variables, as structure-exploiting QP
  solvers (hpipm) need, and the terminal stage has its slack too.
- Obstacle constraints act on stages 1..Np: x_0 is fixed, so at stage 0 a constraint could
  only make the problem infeasible when the boat is already too close.
- h is the 4th root of the paper's super-ellipse, (X^4 + Y^4)^(1/4) - 1 >= 0: the same set,
  but it grows like a distance, so its linearisation far from a wall stays accurate and the
  QP is well scaled (the paper's X^4 + Y^4 - 1 reaches 1e4 for a wall 50 m away).
- The plan's surge has a soft ceiling ubar_i (`surge_cap`): the reference's speed, or a
  braking line from a boat above it, plus a margin, paid for per m/s above at a price between
  the obstacle rows' and the tracking terms' (HPIPM's soft bound, set per step with the QP's
  bounds). A cost on the speed error alone let a plan trade speed for steering, or sprint,
  where a rule had slowed the reference. None (`surge_margin_mps`) is the paper's problem.
- Segments come in a fixed number of slots (16, see `segment_slots`), each with an `active`
  flag that multiplies its constraint: the problem is built (and compiled) once.

Everything that changes at run time is a parameter of the problem: the boat parameters, the
current and the model-error bias (as `water_estimator` estimates them), the reference, the
segments, R_b and d_p. Structure (Np, Ts, RK4 sub-steps, number of
slots) is fixed when the problem is built.
"""

from __future__ import annotations

import functools
import math
import numbers
from dataclasses import dataclass, field, fields

import casadi as ca
import numpy as np

from ..errors import InputError
from ..model import SMOOTH, Variant, augmented_ode, rk4
from .obstacle import hull_circle_centres, super_ellipse_margin
from ..params import IDENTIFIED, PARAM_NAMES, BoatParams
from .segment_slots import SLOT_FIELDS
from .vessel_slots import VESSEL_FIELDS

NX_BOAT = 8  # [x, y, psi, u, v, r, nT, nS]
NX = 9  # plus the slack of the stage
NU = 3  # [dnT, dnS, sigma]: sigma is the next stage's slack
STATE_NAMES = ("x", "y", "psi", "u", "v", "r", "nT", "nS", "slack")
INPUT_NAMES = ("dnT", "dnS", "next_slack")
_NP = len(PARAM_NAMES)  # boat parameters
OBSTACLE_ROWS = ("exact-penalty", "hard")


@dataclass(frozen=True)
class NmpcConfig:
    """The paper's Table "NMPC parameters" (weights in percent units, DESIGN.md) and our knobs."""

    horizon: int = 25  # Np, stages
    step_s: float = 1.0  # Ts, s
    control_period_s: float = 0.1  # the controller runs at 10 Hz
    rk4_substeps: int = 4  # sway and yaw settle in ~0.5 s: one RK4 step per 1 s is too coarse
    q_diag: tuple[float, ...] = (1.0, 1.0, 500.0, 10.0, 0.0, 1000.0, 0.0, 0.0)
    r_diag: tuple[float, float] = (1.0, 1.0)  # on [dnT, dnS] in (%/s)^2
    terminal_factor: float | None = None  # Q_T = factor * Q; None means Np, as in the paper
    # Below this reference speed a stage's heading weight counts in proportion to the speed,
    # down to 0 at rest (`NmpcController._loosen_heading`); 0 or None: the paper's constant
    # weight.
    # At speed the heading keeps the boat's line; at a stop the position is what matters,
    # and the heading weight, 500 times the position's, held a boat waiting in a cross
    # current to a heading that cannot stem it, so it surged to and fro past its stop
    # (fuzz seed 1 case 69, 183 m swung in 280 s of waiting; 1.0 gives 22 m). Not the
    # default yet: in the fuzz (seed 1, 100 cases, the tuned HPIPM) it took the failures from
    # 3 to 2 and the swing over all cases from 267 to 93 m, but with casadi's HPIPM the LiDAR
    # rerun of case 90 (`test_a_plan_running_past_its_stop_...`) held the crab's heading at
    # rest and drifted into the side canal's corner (a collision at 91.9 s; none without).
    heading_full_speed_mps: float | None = None
    # Where the reference moves across the path along the way (over to a gap beside an
    # obstruction, over `channel_ramp_m`), its heading is the line's, not the leg's
    # (`reference_trajectory`): against the leg's heading a slow boat behind a kayak stopped
    # in its way stayed at rest beside the gap (`test_encounters.py`). False: the leg's, as
    # before.
    heading_along_line: bool = True
    slack_weight: float = 1e4  # rho, per m^2
    nT_max: float = 100.0  # %
    nS_max: float = 100.0  # %
    dnT_max: float = 10.0  # %/s
    dnS_max: float = 40.0  # %/s
    hull_radius_m: float = 3.0  # R_b
    hull_offsets_m: tuple[float, float] = (2.0, -2.0)  # circle centres along body x (l_b, -l_s)
    separation_m: float = 2.0  # d_p: 2 m in simulation, 4 m in the field
    # The slack may shrink R_b + d_p down to this (None: R_b, the hull circle touching):
    # the room the passage rule (`min_passage_m`, 2 R_b) gives the hull is the room the OCP
    # lets it take, so a gap the rule calls open is passed with the circles clear of its
    # sides, and one it calls blocked is waited for. (The paper's 0.1 m let the plan push
    # the circles 2.9 m into a barge's end rather than leave the path for the gap.)
    min_half_axis_m: float | None = None
    # How the QP treats the obstacle rows: "exact-penalty" (each row may be violated at a
    # cost of obstacle_l1 per unit of h, plus obstacle_l2 / 2 per unit squared: the QP is
    # feasible whatever a crowded canal or a mistaken track asks, and equals the hard one
    # whenever that is feasible, as obstacle_l1 is above its multipliers) or "hard" (the
    # paper's: a QP with no feasible point fails). Input bounds and rate limits stay hard.
    obstacle_rows: str = "exact-penalty"
    obstacle_l1: float = 1e5  # per unit of h: the SQP merit's weight, above the multipliers
    obstacle_l2: float = 1e2  # per unit of h squared: keeps the elastic QP well conditioned
    restart_elastic_h: float = 1.0  # a QP whose rows broke by more than this (units of
    # h) is solved again from the reference, the one breaking less kept (0: never)
    # ... and so is one whose rows have broken by more than restart_broken_h at every step
    # for restart_broken_s (0: never): a plan that stays broken is one the real-time
    # iteration follows into the bank (fuzz seed 1 case 252: 0.5 units for 14 s), while a
    # single step's break past 0.3 is no reason to leave a plan (restarted at once there,
    # a meeting at a junction with the LiDAR ended in a collision: case 98); at 0.3 a plan
    # whose tail ran past a stop through a gap beside a kayak, breaking its rows by 0.2-0.3
    # for 25 s, drew the boat into a side canal's corner at full throttle (case 90)
    restart_broken_h: float = 0.15
    restart_broken_s: float = 1.0
    restart_stuck_s: float = 5.0  # a boat held at rest this long by a plan that stays while
    # the reference goes on, nothing asking it to wait, is planned again from the reference
    # by SQP to convergence (0: never)
    back_off_m: float = 8.0  # still held so after as long again, the boat backs off this far
    # along its path (twice, three times as far if held again) and comes on once more: the
    # swing round an obstruction that no plan from rest beside it finds (0: never)
    vessel_l1_share: float = 0.75  # the vessel rows' share of those penalties: where a
    # crowded canal leaves no plan clear of everything, another boat's predicted, inflated
    # hull gives before a wall does (a meeting in a bend steered the boat into the quay),
    # but not by half (at 0.5 a launch met in a 12 m canal was passed 1.05 m off)
    segment_slots: int = 16
    segment_range_m: float = 50.0  # segments farther than this are left out
    vessel_slots: int = 4  # other vessels avoided over the horizon (`vessel_slots`)
    vessel_separation_m: float = 2.0  # d_v: kept beyond R_b from a vessel's (inflated) hull
    # a vessel at rest (`Track.vessel`, not moving) is a wall grown by this: its d_p may go
    # to the slack like a wall's, and the hull circles reach 0.6 m past the hull's corners,
    # so the hulls keep 2 m (0: its sides are walls like any others')
    rest_keep_m: float = 1.5
    # how much a vessel's predicted hull may widen with its track's uncertainty over the
    # horizon (its length may grow up to 6 m): in a canal a vessel keeps its side
    vessel_lateral_inflation_m: float = 1.0
    colreg: bool = True  # shape the reference by the rules of the road (`seamanship`)
    follow_gap_m: float = 20.0  # behind a vessel there is no room to overtake: bow to its stern
    # Overtaking in the lane of vessels coming the other way (`seamanship`): only where the
    # channel leaves them room too, or the way is seen clear this far ahead (the perception's
    # reach; inf: no such rule) for one coming unseen at oncoming_mps
    sight_m: float = 50.0
    oncoming_mps: float = 2.5
    oncoming_room_m: float = 5.0  # its beam and its way off the wall
    bow_m: float = 3.95  # from the boat's origin to its bow (the 7.9 m hull)
    smooth_eps: float = SMOOTH.eps  # of the smooth |z| in the prediction model
    hessian_regularisation: float = 1e-6  # on zero diagonal weights (v, nT, nS, sigma)
    # A blocked way or blind perception (`passage`): the reference stops the boat.
    min_passage_m: float = 6.0  # narrowest way for the hull: the two hull circles, 2 R_b
    stop_margin_m: float = 1.0  # stop this far beyond R_b + d_p from the obstruction
    stop_decel_mps2: float = 0.06  # the reference's braking: gentle, as the throttle reverses at 10 %/s
    resume_after_s: float = 1.0  # the way must stay clear this long before going on
    channel_ramp_m: float = 20.0  # where the way lies off the path (a gap beside a barge),
    # the reference moves over to it along this many metres before, and back after
    # A side canal opening behind a corner the boat cannot see past (`blind_openings`): come
    # to it at this speed (0 or None: no such rule, as in the paper), braking at stop_decel_mps2
    # to be at it `blind_margin_m` before the opening (about where a vessel coming out of it
    # is first seen past the corner); an opening is a side free this deep. With the
    # throttle reversing at dnT_max the identified boat stops from 0.5 m/s in 2.7 m, from
    # 0.7 in 4.2 m and from 1.0 in 6.8 m, and the room left when a vessel coming out is
    # first seen (its lane some 10 m ahead, less the bow, its half beam and d_v) is about
    # 3 m: fuzz seed 1 case 48, a boat out of a blind side canal at 1.3 m/s, was met at 0 m
    # with 1.0 and 0.7 and passed 2.7 m off with 0.5. 0.5 is not the default yet: with
    # casadi's HPIPM it made case 69's boat, waiting in a cross current, swing 182 m (the
    # slow tests of `test_encounters.py`; the stall it once caused short of the opening in
    # `drifting_kayak_at_a_junction_while_overtaking` went with `heading_along_line`).
    blind_speed_mps: float | None = 1.0
    blind_margin_m: float = 15.0
    blind_depth_m: float = 25.0
    # The reference's speed as a soft ceiling on the plan's surge (`surge_cap`): every rule
    # that slows the boat (a stop, a blind opening, a vessel followed) shapes the reference,
    # but a cost on the error alone lets a plan trade speed for steering or sprint past an
    # obstruction (fuzz seed 1 case 48: 1.5 m/s at a blind opening capped at 0.6; case 15:
    # 3.05 m/s past a kayak for a target of 2). At stage k the plan's surge above
    # max(u_ref_k, u_0 - surge_decel_mps2 t_k, 0) + surge_margin_mps costs surge_l1 per m/s
    # plus surge_l2 / 2 per (m/s)^2: below the obstacle rows' price (1e5), above the
    # tracking terms' (at 1e3 a boat steering to starboard for a vessel met kept 0.2 m/s
    # over its ceiling for the rudder's thrust). The line is kept from step to step
    # (`NmpcController._surge_cap`). None (the default): no ceiling, as in the paper; 0.2
    # is what was tried, and it is not the default yet: the soft bound takes HPIPM about
    # three times the iterations, and where the reference stops short (the goal) the plan
    # sprints to the ceiling before braking (controller/README.md). (Direct HPIPM only: a
    # soft bound of its QP.)
    surge_margin_mps: float | None = None
    surge_decel_mps2: float = 0.1
    surge_l1: float = 1e4
    surge_l2: float = 1e4
    boat: BoatParams = field(default=IDENTIFIED)

    def __post_init__(self) -> None:
        def bad(name, why):
            raise InputError(f"NMPC config {name!r}: {why}, got {getattr(self, name)!r}")

        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, (list, np.ndarray)):
                if not isinstance(f.default, tuple):
                    bad(f.name, "expected a number")
                value = tuple(np.asarray(value).reshape(-1).tolist())  # weights as a list
                object.__setattr__(self, f.name, value)
            values = value if isinstance(value, tuple) else (value,)
            if f.name in ("boat", "terminal_factor", "colreg", "obstacle_rows",
                          "heading_along_line") or value is None:
                continue
            if any(not isinstance(v, numbers.Real) or isinstance(v, (bool, np.bool_))
                   for v in values):
                bad(f.name, "expected numbers")
            if any(not math.isfinite(v) for v in values):
                bad(f.name, "must be finite")
        for name in ("colreg", "heading_along_line"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                bad(name, "expected true or false")
        if len(self.q_diag) != NX_BOAT:
            bad("q_diag", f"needs {NX_BOAT} weights for [x, y, psi, u, v, r, nT, nS]")
        if len(self.r_diag) != 2:
            bad("r_diag", "needs 2 weights for [dnT, dnS]")
        for name in ("q_diag", "r_diag"):
            if any(v < 0 for v in getattr(self, name)):
                bad(name, "weights must not be negative")
        if self.terminal_factor is not None and not (
            math.isfinite(self.terminal_factor) and self.terminal_factor >= 0
        ):
            bad("terminal_factor", "must be a non-negative number or None")
        for name in ("slack_weight", "separation_m", "hessian_regularisation",
                     "vessel_separation_m", "vessel_lateral_inflation_m", "rest_keep_m"):
            if getattr(self, name) < 0:
                bad(name, "must not be negative")
        if self.heading_full_speed_mps is not None and self.heading_full_speed_mps < 0:
            bad("heading_full_speed_mps", "must be a speed >= 0 (0 or None: a constant weight)")
        if self.surge_margin_mps is not None and self.surge_margin_mps < 0:
            bad("surge_margin_mps", "must be a speed >= 0 (None: no surge ceiling)")
        for name in ("surge_l1", "surge_l2"):
            if getattr(self, name) < 0:
                bad(name, "must not be negative")
        if not self.surge_decel_mps2 > 0:
            bad("surge_decel_mps2", "must be positive")
        if self.blind_speed_mps is not None and self.blind_speed_mps < 0:
            bad("blind_speed_mps", "must be a speed >= 0 (0 or None: no blind-opening rule)")
        for name in ("stop_margin_m", "resume_after_s", "blind_margin_m", "sight_m",
                     "oncoming_mps", "oncoming_room_m"):
            if getattr(self, name) < 0:
                bad(name, "must not be negative")
        for name in ("step_s", "control_period_s", "nT_max", "nS_max", "dnT_max", "dnS_max",
                     "hull_radius_m", "segment_range_m", "smooth_eps",
                     "min_passage_m", "stop_decel_mps2", "channel_ramp_m", "blind_depth_m"):
            if getattr(self, name) <= 0:
                bad(name, "must be positive")
        for name in ("horizon", "rk4_substeps", "segment_slots"):
            if int(getattr(self, name)) != getattr(self, name) or getattr(self, name) < 1:
                bad(name, "must be a positive integer")
        if int(self.vessel_slots) != self.vessel_slots or self.vessel_slots < 0:
            bad("vessel_slots", "must be a whole number >= 0")
        if self.control_period_s > self.step_s:
            bad("control_period_s", "must not exceed step_s")
        if self.min_half_axis_m is not None and not (
                0 < self.min_half_axis_m <= self.hull_radius_m + self.separation_m):
            bad("min_half_axis_m", "must be positive and at most R_b + d_p")
        if len(self.hull_offsets_m) != 2:
            bad("hull_offsets_m", "needs the two circle centres")
        if self.obstacle_rows not in OBSTACLE_ROWS:
            bad("obstacle_rows", f"choose one of {', '.join(OBSTACLE_ROWS)}")
        for name in ("obstacle_l1", "obstacle_l2", "vessel_l1_share", "restart_elastic_h",
                     "restart_broken_h", "restart_broken_s",
                     "restart_stuck_s", "back_off_m"):
            if getattr(self, name) < 0:
                bad(name, "must not be negative")
        if self.obstacle_rows == "exact-penalty" and not self.obstacle_l1 > 0:
            bad("obstacle_l1", "must be positive for exact-penalty obstacle rows")
        if not isinstance(self.boat, BoatParams):
            bad("boat", "expected a BoatParams")

    # -- derived --------------------------------------------------------------------------
    @property
    def stop_short_m(self) -> float:
        """From an obstruction to where the boat's origin stops: the bow circle's offset,
        then R_b + d_p, then the margin."""
        return (max(self.hull_offsets_m) + self.hull_radius_m + self.separation_m
                + self.stop_margin_m)

    @property
    def Q(self) -> np.ndarray:
        return np.diag(self.q_diag)

    @property
    def Q_T(self) -> np.ndarray:
        factor = self.horizon if self.terminal_factor is None else self.terminal_factor
        return factor * self.Q

    @property
    def R(self) -> np.ndarray:
        return np.diag(self.r_diag)

    @property
    def slack_min_m(self) -> float:
        """Lower bound of s_i: the minor half axis R_b + d_p + s_i stays >= min_half_axis_m
        (R_b when not given)."""
        floor = self.hull_radius_m if self.min_half_axis_m is None else self.min_half_axis_m
        return min(-(self.hull_radius_m + self.separation_m) + floor, 0.0)


def surge_cap(reference_u: np.ndarray, surge_mps: float, step_s: float, margin_mps: float,
              decel_mps2: float, out: np.ndarray | None = None) -> np.ndarray:
    """The plan's soft surge ceiling at stages 0..Np (`NmpcConfig.surge_margin_mps`): the
    reference's surge, or the boat's own braking at `decel_mps2` from `surge_mps` where that
    is higher (a boat above its reference is asked to slow down, not to stop at once), never
    below 0 (nothing is asked to go astern), plus the margin."""
    ref = np.asarray(reference_u, float)
    braking = surge_mps - decel_mps2 * step_s * np.arange(len(ref))
    cap = np.maximum(np.maximum(ref, braking, out=out), 0.0, out=out)
    cap += margin_mps
    return cap


# -- the runtime parameters of the problem: one flat vector --------------------------------
@dataclass(frozen=True)
class ParamLayout:
    """Where each runtime parameter sits in the problem's parameter vector."""

    n_slots: int
    n_vessels: int = 0  # vessel slots
    horizon: int = 25  # stages 1..horizon each have their own vessel slots

    @classmethod
    def of(cls, config: "NmpcConfig") -> "ParamLayout":
        return cls(config.segment_slots, config.vessel_slots, config.horizon)

    @property
    def boat(self) -> slice:  # model parameters, PARAM_NAMES order
        return slice(0, _NP)

    @property
    def current(self) -> slice:  # [north, east] m/s
        return slice(_NP, _NP + 2)

    @property
    def geometry(self) -> slice:  # [R_b, d_p, offset_front, offset_back, d_v]
        return slice(_NP + 2, _NP + 7)

    @property
    def bias(self) -> slice:  # [b_u, b_v, b_r]: the model error's body-frame acceleration
        return slice(_NP + 7, _NP + 10)

    @property
    def segments(self) -> slice:  # n_slots x SLOT_FIELDS, row-major
        start = _NP + 10
        return slice(start, start + self.n_slots * len(SLOT_FIELDS))

    @property
    def vessels(self) -> slice:  # stage 1..N: n_vessels x VESSEL_FIELDS each, row-major
        start = self.segments.stop
        return slice(start, start + self.horizon * self.n_vessels * len(VESSEL_FIELDS))

    @property
    def size(self) -> int:
        return self.vessels.stop


def pack_params(config: NmpcConfig, segment_slots: np.ndarray, current=(0.0, 0.0),
                boat: BoatParams | None = None, bias=(0.0, 0.0, 0.0),
                vessel_slots: np.ndarray | None = None) -> np.ndarray:
    """The problem's parameter vector from its parts (segment slots as (n_slots, 5), vessel
    slots as (horizon, n_vessels, 6); none: all inactive)."""
    layout = ParamLayout.of(config)
    p = np.zeros(layout.size)
    p[layout.boat] = (boat or config.boat).as_vector()
    p[layout.current] = current
    p[layout.geometry] = (config.hull_radius_m, config.separation_m, *config.hull_offsets_m,
                          config.vessel_separation_m)
    p[layout.bias] = bias
    p[layout.segments] = np.asarray(segment_slots, float).reshape(-1)
    if vessel_slots is not None:
        p[layout.vessels] = np.asarray(vessel_slots, float).reshape(-1)
    return p


# -- the OCP -------------------------------------------------------------------------------
def dynamics_function(config: NmpcConfig) -> ca.Function:
    """f_d: one shooting interval of Ts, RK4 in sub-steps on the smooth model; the slack
    state takes the value of the input sigma (so stage i+1's slack is chosen at stage i)."""
    x = ca.SX.sym("x", NX)
    u = ca.SX.sym("u", NU)
    p = ca.SX.sym("p", _NP)
    current = ca.SX.sym("current", 2)
    bias = ca.SX.sym("bias", 3)
    variant = Variant(smooth=True, eps=config.smooth_eps)
    boat = rk4(lambda z: augmented_ode(z, u[:2], p, current, variant, bias), x[:NX_BOAT],
               config.step_s, config.rk4_substeps)
    return ca.Function("f_d", [x, u, p, current, bias], [ca.vertcat(boat, u[2])],
                       ["x", "u", "p", "current", "bias"], ["x_next"])


def clearance_function(config: NmpcConfig) -> ca.Function:
    """h >= 0 for each hull circle and segment slot, then each vessel slot, at one stage
    (eq. mpc:pnorm, 4th root).

    Slot = (x_c, y_c, theta, length, active); an inactive slot gives h = 1: strictly satisfied, so
    an interior-point QP solver never sees a degenerate active row. A vessel slot is the
    vessel as predicted for this stage, (x, y, theta, length, width, active), its hull
    inflated by its uncertainty; the super-ellipse around it has half axes
    length/2 + R_b + d_v + s and width/2 + R_b + d_v + s: the same slack s softens it.
    """
    x = ca.SX.sym("x", NX)
    slots = ca.SX.sym("slots", len(SLOT_FIELDS), config.segment_slots)  # a column per slot
    geometry = ca.SX.sym("geometry", 5)  # R_b, d_p, offsets, d_v
    vessels = ca.SX.sym("vessels", len(VESSEL_FIELDS), config.vessel_slots)
    Rb, dp, dv = geometry[0], geometry[1], geometry[4]
    s = x[NX - 1]
    h = []
    circles = hull_circle_centres(x[0], x[1], x[2], [geometry[2], geometry[3]])
    for px, py in circles:
        for j in range(config.segment_slots):
            xc, yc, th, length, active = (slots[k, j] for k in range(len(SLOT_FIELDS)))
            margin = Rb + dp + s  # the slack softens the separation all round, ends included
            h.append(active * super_ellipse_margin(px, py, xc, yc, th, length, margin, margin)
                     + (1 - active))
    for px, py in circles:
        for j in range(config.vessel_slots):
            xv, yv, th, length, width, active = (vessels[k, j] for k in range(len(VESSEL_FIELDS)))
            margin = Rb + dv + s
            h.append(active * super_ellipse_margin(px, py, xv, yv, th, length, margin,
                                                   width / 2 + margin) + (1 - active))
    return ca.Function("clearance", [x, slots, geometry, vessels], [ca.vertcat(*h)],
                       ["x", "slots", "geometry", "vessels"], ["h"])


@dataclass(frozen=True)
class Ocp:
    """The NLP of the OCP over w = [x_0, u_0, x_1, u_1, ..., x_Np] (hpipm's stage order).

    `constraints(w, p) -> g` is ordered [gap_0, gap_1, h_1, gap_2, h_2, ..., h_Np] with
    gap_i = f_d(x_i, u_i) - x_{i+1}; equality rows are gaps, inequality rows h >= 0.
    The cost is quadratic in w: 1/2 w' H w + g_r' w + const, with H constant.
    """

    config: NmpcConfig
    nw: int
    ng: int
    n_gap: int  # rows per gap
    n_h: int  # rows per stage of obstacle constraints
    constraints: ca.Function  # (w, p) -> g
    linearisation: ca.Function  # (w, p) -> (gaps, dgap_nz, h, dh_nz), stage by stage
    dyn_sparsity: ca.Sparsity  # of d gap_k / d [x_k; u_k], NX x (NX + NU)
    h_sparsity: ca.Sparsity  # of d h_k / d x_k, n_h x NX
    jac_sparsity: ca.Sparsity  # of dg/dw
    jac_gather: np.ndarray  # dg/dw nonzeros = [dgap_nz, dh_nz, -1][jac_gather]
    dynamics: ca.Function
    states_at: np.ndarray  # (Np+1, NX) indices of x_k in w
    hpipm_linearisation: ca.Function  # (w, p) -> (b, A, B, lg, C): the QP's blocks as hpipm
    # takes them, dense, column-major, a stage after another (see `HpipmOcpQp`)
    first_stage: ca.Function  # (x_0, u_0, x_1, p) -> (b_0, A_0, B_0): stage 0 alone
    hpipm_clearance: ca.Function  # (w, p) -> (lg, C): the obstacle rows alone
    dynamics_params: np.ndarray  # where in p the dynamics' parameters are (boat, current, bias)
    inputs_at: np.ndarray  # (Np, NU) indices of u_k in w

    @property
    def N(self) -> int:
        return self.config.horizon

    # -- indices ----------------------------------------------------------------------------
    def state_index(self, k: int) -> slice:
        return slice(k * (NX + NU), k * (NX + NU) + NX)

    def input_index(self, k: int) -> slice:
        start = k * (NX + NU) + NX
        return slice(start, start + NU)

    def unpack(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """w -> states (Np+1, 9), inputs (Np, 3)."""
        w = np.asarray(w)
        return w[self.states_at], w[self.inputs_at]

    def pack(self, states: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        w = np.empty(self.nw)
        w[self.states_at] = states
        w[self.inputs_at] = inputs
        return w

    def assemble(self, gaps, dgap_nz, h, dh_nz) -> tuple[np.ndarray, np.ndarray]:
        """g and the nonzeros of dg/dw (jac_sparsity's order) from the linearisation's outputs,
        each flattened column by column (a column per stage), as a Function buffer gives them."""
        N = self.N
        gaps, h = np.reshape(gaps, (N, NX)).T, np.reshape(h, (N, self.n_h)).T
        g = np.concatenate([gaps[:, 0], np.vstack([gaps[:, 1:], h[:, : N - 1]]).T.ravel(),
                            h[:, N - 1]])
        sources = np.concatenate([np.ravel(dgap_nz), np.ravel(dh_nz), [-1.0]])
        return g, sources[self.jac_gather]

    def gap_rows(self) -> np.ndarray:
        """Boolean mask of equality (gap) rows in g."""
        rows = np.zeros(self.ng, bool)
        rows[: self.n_gap] = True
        per = self.n_gap + self.n_h
        for k in range(1, self.N):
            start = self.n_gap + (k - 1) * per
            rows[start:start + self.n_gap] = True
        return rows

    # -- cost -------------------------------------------------------------------------------
    def hessian(self) -> np.ndarray:
        """Diagonal of H (the cost is a sum of weighted squares: Gauss-Newton is exact)."""
        c, eps = self.config, self.config.hessian_regularisation
        d = np.zeros(self.nw)
        for k in range(self.N + 1):
            q = np.diag(c.Q_T if k == self.N else c.Q)
            d[self.state_index(k)] = 2 * np.concatenate([q, [c.slack_weight if k else 0.0]])
            if k < self.N:
                d[self.input_index(k)] = 2 * np.array([*c.r_diag, 0.0])
        return np.maximum(d, eps)

    # -- bounds -----------------------------------------------------------------------------
    def bounds(self, x_init: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """lbw, ubw: x_0 fixed (with slack 0), actuator, rate and slack bounds."""
        c = self.config
        lbx = np.array([-np.inf] * 6 + [-c.nT_max, -c.nS_max, c.slack_min_m])
        ubx = np.array([np.inf] * 6 + [c.nT_max, c.nS_max, 0.0])
        lbu = np.array([-c.dnT_max, -c.dnS_max, c.slack_min_m])
        ubu = np.array([c.dnT_max, c.dnS_max, 0.0])
        lbw = np.concatenate([np.tile(np.concatenate([lbx, lbu]), self.N), lbx])
        ubw = np.concatenate([np.tile(np.concatenate([ubx, ubu]), self.N), ubx])
        x0 = np.concatenate([x_init, [0.0]])
        lbw[self.state_index(0)] = x0
        ubw[self.state_index(0)] = x0
        return lbw, ubw

    def constraint_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        gaps = self.gap_rows()
        return np.zeros(self.ng), np.where(gaps, 0.0, np.inf)

    def hpipm_structure(self) -> dict:
        """The stage sizes hpipm needs (N, nx, nu, ng), nu ending with 0."""
        return {"N": self.N, "nx": [NX] * (self.N + 1), "nu": [NU] * self.N + [0],
                "ng": [0] + [self.n_h] * self.N}


def _with_jacobian(f: ca.Function, wrt: list[int]) -> tuple[ca.Function, ca.Sparsity]:
    """f's first output and the nonzeros of its Jacobian with respect to inputs `wrt`, stacked.

    Per-stage Jacobians stay small SX expressions; the OCP maps them over the horizon and
    gathers the nonzeros into the big Jacobian's order, which keeps the generated C small.
    """
    args = f.sx_in()
    out = f.call(args)[0]
    jac = ca.jacobian(out, ca.vertcat(*[args[i] for i in wrt]))
    name = f.name() + "_jac"
    return ca.Function(name, args, [out, ca.vertcat(*jac.nonzeros())]), jac.sparsity()


def _with_dense_jacobians(f: ca.Function, wrt: list[int]) -> ca.Function:
    """f's first output and its dense Jacobians with respect to each input in `wrt`."""
    args = f.sx_in()
    out = f.call(args)[0]
    jacs = [ca.densify(ca.jacobian(out, args[i])) for i in wrt]
    return ca.Function(f.name() + "_dense_jac", args, [out, *jacs])


def _stage_blocks(sparsity: ca.Sparsity, row0: int, col0: int, src0: int):
    """(rows, cols, source index) of a stage block's nonzeros in the big Jacobian."""
    rows, cols = sparsity.get_triplet()
    n = len(rows)
    return np.asarray(rows) + row0, np.asarray(cols) + col0, np.arange(n) + src0


def build_ocp(config: NmpcConfig) -> Ocp:
    """Variables, dynamics, constraints and their Jacobian, as CasADi Functions of (w, p).

    Built once per config in a process (its CasADi graphs take about 0.1 s, a tenth of a
    minute's run; a study or the tests run many): the Ocp is immutable (its index arrays are
    read-only), so controllers share it."""
    try:
        hash(config)
    except TypeError:  # a config holding something unhashable: build it afresh
        return _build_ocp(config)
    return _shared_ocp(config)


@functools.lru_cache(maxsize=8)
def _shared_ocp(config: NmpcConfig) -> Ocp:
    built = _build_ocp(config)
    for value in vars(built).values():
        if isinstance(value, np.ndarray):
            value.setflags(write=False)
    return built


def _build_ocp(config: NmpcConfig) -> Ocp:
    N = config.horizon
    layout = ParamLayout.of(config)
    nz = NX + NU  # variables per stage
    nw = N * nz + NX
    w = ca.MX.sym("w", nw)
    p = ca.MX.sym("p", layout.size)

    # variables, stage by stage: [x_k, u_k] for k < N, then x_N
    main = ca.reshape(w[: N * nz], nz, N)
    X = ca.horzcat(main[:NX, :], w[N * nz:])  # NX x (N+1)
    U = main[NX:, :]  # NU x N

    # dynamics, and its Jacobian with respect to [x_k; u_k]
    f_d = dynamics_function(config)
    f_d_jac, sp_dyn = _with_jacobian(f_d, [0, 1])
    boat, current, bias = p[layout.boat], p[layout.current], p[layout.bias]
    X_next, AB = f_d_jac.map(N)(X[:, :N], U, ca.repmat(boat, 1, N), ca.repmat(current, 1, N),
                                ca.repmat(bias, 1, N))
    gaps = X_next - X[:, 1:]  # NX x N: x_{k+1} = f_d(x_k, u_k) as gap_k = 0

    # obstacle constraints at stages 1..N, and their Jacobian with respect to x_k
    clearance = clearance_function(config)
    clearance_jac, sp_h = _with_jacobian(clearance, [0])
    slots = ca.reshape(p[layout.segments], len(SLOT_FIELDS), config.segment_slots)
    vessels = ca.reshape(p[layout.vessels], len(VESSEL_FIELDS), config.vessel_slots * N)
    H, C = clearance_jac.map(N)(X[:, 1:], ca.repmat(slots, 1, N),
                                ca.repmat(p[layout.geometry], 1, N), vessels)  # n_h x N

    # rows in hpipm's stage order: gap_0, then (gap_k, h_k) for k = 1..N-1, then h_N
    n_h = 2 * (config.segment_slots + config.vessel_slots)
    g = ca.vertcat(gaps[:, 0], ca.vec(ca.vertcat(gaps[:, 1:], H[:, : N - 1])), H[:, N - 1])

    # where each nonzero of dg/dw comes from: [A_k B_k] and -I per gap, C_k per stage
    def gap_row(k):
        return 0 if k == 0 else NX + (k - 1) * (NX + n_h)

    def h_row(k):  # k = 1..N
        return gap_row(k) + NX if k < N else gap_row(N - 1) + NX + n_h

    n_ab, n_c = sp_dyn.nnz(), sp_h.nnz()
    minus_one = N * n_ab + N * n_c  # source index of the constant -1
    parts = []
    for k in range(N):
        parts.append(_stage_blocks(sp_dyn, gap_row(k), k * nz, k * n_ab))
        idx = np.arange(NX)
        parts.append((gap_row(k) + idx, (k + 1) * nz + idx, np.full(NX, minus_one)))
        parts.append(_stage_blocks(sp_h, h_row(k + 1), (k + 1) * nz, N * n_ab + k * n_c))
    rows, cols, src = (np.concatenate(a) for a in zip(*parts))
    order = np.lexsort((rows, cols))  # column-major, as CasADi stores sparse matrices
    jac_sparsity = ca.Sparsity.triplet(g.numel(), nw, rows[order].tolist(), cols[order].tolist())

    # the same blocks dense, in the layout hpipm takes (stage after stage, column-major), so
    # that a Function buffer writes them straight into the QP's arrays
    f_d_dense = _with_dense_jacobians(f_d, [0, 1])
    X_next_d, A_d, B_d = f_d_dense.map(N)(X[:, :N], U, ca.repmat(boat, 1, N),
                                          ca.repmat(current, 1, N), ca.repmat(bias, 1, N))
    clearance_dense = _with_dense_jacobians(clearance, [0])
    H_d, C_d = clearance_dense.map(N)(X[:, 1:], ca.repmat(slots, 1, N),
                                      ca.repmat(p[layout.geometry], 1, N), vessels)
    hpipm_linearisation = ca.Function(
        "nmpc_hpipm_linearisation", [w, p], [X_next_d - X[:, 1:], A_d, B_d, -H_d, C_d],
        ["w", "p"], ["b", "A", "B", "lg", "C"])
    hpipm_clearance = ca.Function("nmpc_hpipm_clearance", [w, p], [-H_d, C_d], ["w", "p"],
                                  ["lg", "C"])
    x0, u0, x1 = ca.MX.sym("x0", NX), ca.MX.sym("u0", NU), ca.MX.sym("x1", NX)
    x_next0, A0, B0 = f_d_dense(x0, u0, boat, current, bias)
    first_stage = ca.Function("nmpc_first_stage", [x0, u0, x1, p], [x_next0 - x1, A0, B0],
                              ["x0", "u0", "x1", "p"], ["b0", "A0", "B0"])

    return Ocp(
        config=config, hpipm_linearisation=hpipm_linearisation, first_stage=first_stage,
        hpipm_clearance=hpipm_clearance, dynamics_params=np.r_[np.arange(layout.boat.start,
        layout.current.stop), np.arange(layout.bias.start, layout.bias.stop)], nw=nw, ng=g.numel(), n_gap=NX, n_h=n_h,
        constraints=ca.Function("constraints", [w, p], [g], ["w", "p"], ["g"]),
        linearisation=ca.Function("nmpc_linearisation", [w, p], [gaps, AB, H, C],
                                  ["w", "p"], ["gaps", "dgap_nz", "h", "dh_nz"]),
        dyn_sparsity=sp_dyn, h_sparsity=sp_h,
        jac_sparsity=jac_sparsity, jac_gather=src[order],
        dynamics=f_d,
        states_at=np.array([np.arange(k * nz, k * nz + NX) for k in range(N + 1)]),
        inputs_at=np.array([np.arange(k * nz + NX, (k + 1) * nz) for k in range(N)]),
    )
