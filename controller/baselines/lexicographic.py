"""Baseline 2: the paper's Appendix version of Shan et al. 2020, a lexicographic planner.

A two-point boundary value problem on the kinematic model

    x' = u cos psi,  y' = u sin psi,  psi' = r,     x_b = [x, y, psi], u_b = [u, r]

over N_b = 50 steps of 0.5 s from the current pose to the point 50 m ahead on the reference
path (its position and the path's heading there), with |u| <= 4 m/s, |r| <= 0.1 rad/s and
hard obstacle constraints (the super-ellipse of eq. mpc:pnorm for both hull circles, every
stage and segment slot). Solved lexicographically with IPOPT:

    1. J1* = min sum r_i^2                           (heading variation first)
    2.       min sum u_i^2  s.t. sum r_i^2 <= J1* (1 + 1e-3) + 1e-9   (then distance)

Choices the paper leaves open, said here: the relative tolerance 1e-3 is the paper's; the
absolute 1e-9 keeps stage 2 feasible in the strict interior when J1* = 0 (a straight path),
where an exact bound would break IPOPT's constraint qualification. The kinematic model is
discretised with one RK4 step per stage. Segments fill the same 16 slots as the NMPC's.
Where IPOPT finds no feasible plan (a canal too narrow for the hard constraints), the last
feasible plan is kept; before the first one, the waypoint path itself is followed.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..errors import InputError
from ..geometry import Polyline, unwrap_near
from ..model import rk4
from ..nmpc.obstacle import hull_circle_centres, super_ellipse_margin
from ..nmpc.segment_slots import SLOT_FIELDS, fill_segment_slots


@dataclass(frozen=True)
class LexicographicConfig:
    steps: int = 50  # N_b
    step_s: float = 0.5
    end_ahead_m: float = 50.0  # the end point, along the reference path
    u_max_mps: float = 4.0
    r_max_radps: float = 0.1
    hull_radius_m: float = 3.0  # R_b
    separation_m: float = 2.0  # d_p
    hull_offsets_m: tuple[float, float] = (2.0, -2.0)
    heading_tolerance: float = 1e-3  # stage 2 keeps sum r^2 <= J1* (1 + this)
    segment_slots: int = 16
    segment_range_m: float = 50.0
    max_iter: int = 300
    ipopt_print_level: int = 0


@dataclass(frozen=True)
class Plan:
    path: np.ndarray  # (N_b + 1, 2) planned positions
    states: np.ndarray  # (N_b + 1, 3) x, y, psi
    inputs: np.ndarray  # (N_b, 2) u, r
    feasible: bool  # False: this is the previous plan (or the waypoints) kept
    status: str
    j1: float  # heading cost of stage 1
    iterations: int


class LexicographicPlanner:
    """Builds the two NLPs once; `plan(pose, segments)` solves them for the current situation."""

    STAGE2_OPTIONS: dict = {}  # extra IPOPT options of the distance stage

    def __init__(self, waypoints, config: LexicographicConfig = LexicographicConfig()):
        pts = np.asarray(waypoints, float).reshape(-1, 2)
        if len(pts) < 2 or not np.all(np.isfinite(pts)):
            raise InputError("lexicographic planner: needs at least two finite waypoints")
        self.config = config
        self.path = Polyline(pts)
        self._progress = 0.0
        self._last: Plan | None = None
        self._build()

    # -- the NLPs --------------------------------------------------------------------------
    def _build(self) -> None:
        cfg = self.config
        N, nslot = cfg.steps, cfg.segment_slots
        X = ca.SX.sym("X", 3, N + 1)
        U = ca.SX.sym("U", 2, N)
        x_init = ca.SX.sym("x_init", 3)
        x_end = ca.SX.sym("x_end", 3)
        slots = ca.SX.sym("slots", len(SLOT_FIELDS), nslot)
        j1_bound = ca.SX.sym("j1_bound")

        def kinematics(z, v):
            return ca.vertcat(v[0] * ca.cos(z[2]), v[0] * ca.sin(z[2]), v[1])

        g, lbg, ubg = [X[:, 0] - x_init, X[:, N] - x_end], [0] * 6, [0] * 6
        margin = cfg.hull_radius_m + cfg.separation_m
        for i in range(N):
            g.append(X[:, i + 1] - rk4(lambda z: kinematics(z, U[:, i]), X[:, i], cfg.step_s))
            lbg += [0, 0, 0]
            ubg += [0, 0, 0]
        for i in range(1, N + 1):  # x_0 is given: a constraint there could only be violated
            for px, py in hull_circle_centres(X[0, i], X[1, i], X[2, i], cfg.hull_offsets_m):
                for j in range(nslot):
                    xc, yc, th, ln, active = (slots[k, j] for k in range(len(SLOT_FIELDS)))
                    h = super_ellipse_margin(px, py, xc, yc, th, ln, margin, margin)
                    g.append(active * h + (1 - active))
                    lbg.append(0)
                    ubg.append(ca.inf)
        heading_cost = ca.sumsqr(U[1, :])
        distance_cost = ca.sumsqr(U[0, :])
        w = ca.vertcat(ca.vec(X), ca.vec(U))
        p = ca.vertcat(x_init, x_end, ca.vec(slots))
        opts = {"ipopt.print_level": cfg.ipopt_print_level, "print_time": False, "ipopt.sb": "yes",
                "ipopt.max_iter": cfg.max_iter, "ipopt.tol": 1e-6}
        self._heading = ca.nlpsol("lexi_heading", "ipopt",
                                  {"x": w, "p": p, "f": heading_cost, "g": ca.vertcat(*g)}, opts)
        # Stage 2 starts from stage 1's solution, with IPOPT's default barrier start: a warm
        # start of the barrier (warm_start_init_point) hit the iteration limit in trials here.
        opts = {**opts, **self.STAGE2_OPTIONS}
        self._distance = ca.nlpsol(
            "lexi_distance", "ipopt",
            {"x": w, "p": ca.vertcat(p, j1_bound), "f": distance_cost,
             "g": ca.vertcat(*g, heading_cost / j1_bound - 1)}, opts)  # scaled: J1* ~ 1e-3
        self._lbg = np.array(lbg, float)
        self._ubg = np.array(ubg, float)
        lbx = np.concatenate([np.full(3 * (N + 1), -np.inf),
                              np.tile([-cfg.u_max_mps, -cfg.r_max_radps], N)])
        self._lbx, self._ubx = lbx, -lbx
        self._ubx[: 3 * (N + 1)] = np.inf
        self._nx = 3 * (N + 1)

    # -- planning --------------------------------------------------------------------------
    def end_point(self, pose) -> np.ndarray:
        """The pose 50 m ahead on the reference path (searched forward from the last progress)."""
        s, _, _, _ = self.path.project(np.asarray(pose)[:2], s_min=self._progress)
        self._progress = s
        xy, heading = self.path.at(s + self.config.end_ahead_m)
        return np.array([xy[0, 0], xy[0, 1], float(unwrap_near(heading[0], pose[2]))])

    def _guess(self, pose, end) -> np.ndarray:
        """Positions along the reference path from the boat to the end point, evenly timed."""
        N = self.config.steps
        s_end = min(self._progress + self.config.end_ahead_m, self.path.length)
        s = np.linspace(self._progress, s_end, N + 1)
        xy, heading = self.path.at(s)
        xy[0] = pose[:2]
        psi = np.array([unwrap_near(h, pose[2]) for h in heading])
        psi[0], psi[-1] = pose[2], end[2]
        X = np.column_stack([xy, psi]).T
        speed = np.full(N, (s_end - self._progress) / (N * self.config.step_s))
        U = np.vstack([speed, np.diff(psi) / self.config.step_s])
        return np.concatenate([X.ravel(order="F"), U.ravel(order="F")])

    def _shifted(self, pose, end) -> np.ndarray | None:
        """The last feasible plan advanced to the boat's progress, its tail run on to the new
        end point: a warm start that is usually a few iterations from the new solution."""
        last = self._last
        if last is None or not last.feasible:
            return None
        N, dt = self.config.steps, self.config.step_s
        d = np.hypot(*(last.states[:, :2] - pose[:2]).T)
        k = int(np.argmin(d))
        if d[k] > 5.0:
            return None
        X = last.states[k:].copy()
        U = last.inputs[k:].copy()
        if len(X) < 2:
            return None
        # extend with a straight run from the old end to the new end point
        tail = N + 1 - len(X)
        if tail > 0:
            t = np.linspace(0, 1, tail + 1)[1:, None]
            ext = X[-1] + t * (end - X[-1])
            X = np.vstack([X, ext])
            u_ext = np.hypot(*np.diff(np.vstack([X[-tail - 1:, :2]]), axis=0).T) / dt
            U = np.vstack([U, np.column_stack([u_ext, np.diff(X[-tail - 1:, 2]) / dt])])
        X[0] = pose
        return np.concatenate([X.ravel(), U.ravel()])

    def plan(self, pose, segments) -> Plan:
        pose = np.asarray(pose, float).reshape(-1)[:3]
        if not np.all(np.isfinite(pose)):
            raise InputError(f"lexicographic planner: pose must be finite, got {pose.tolist()}")
        cfg = self.config
        end = self.end_point(pose)
        slots = fill_segment_slots(segments, pose[:2], cfg.segment_slots, cfg.segment_range_m)
        p = np.concatenate([pose, end, np.asarray(slots, float).T.ravel(order="F")])
        guess = self._shifted(pose, end)
        if guess is None:
            guess = self._guess(pose, end)
        first = self._heading(x0=guess, p=p, lbx=self._lbx, ubx=self._ubx,
                              lbg=self._lbg, ubg=self._ubg)
        st1 = self._heading.stats()
        if not st1["success"]:
            return self._keep(f"heading stage: {st1['return_status']}", st1["iter_count"])
        j1 = float(first["f"])
        bound = j1 * (1 + cfg.heading_tolerance) + 1e-9
        second = self._distance(x0=first["x"], p=np.append(p, bound), lbx=self._lbx,
                                ubx=self._ubx, lbg=np.append(self._lbg, -np.inf),
                                ubg=np.append(self._ubg, 0.0))
        st2 = self._distance.stats()
        iters = st1["iter_count"] + st2["iter_count"]
        if not st2["success"]:
            return self._keep(f"distance stage: {st2['return_status']}", iters)
        w = np.asarray(second["x"]).ravel()
        states = w[: self._nx].reshape(-1, 3)
        inputs = w[self._nx:].reshape(-1, 2)
        self._last = Plan(states[:, :2], states, inputs, True, "ok", j1, iters)
        return self._last

    def _keep(self, status: str, iterations: int) -> Plan:
        if self._last is not None:
            last = self._last
            return Plan(last.path, last.states, last.inputs, False, status, last.j1, iterations)
        pts = self.path.points
        return Plan(pts, np.column_stack([pts, np.zeros(len(pts))]), np.zeros((0, 2)), False,
                    status + "; following the waypoints", float("nan"), iterations)
