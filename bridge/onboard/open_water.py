"""Where the manoeuvre session may take the boat: the scenario's water, a margin off its walls
and obstacles, and an optional radius around the start; which way has the most of it; and
how far each identification run goes, so that the runs are planned inside it.

The scenario's walls come at a vertex a metre or two apart (a 2 km canal is two walls of a
thousand legs each), and the session asks about hundreds of points at every heading it
weighs: the walls are simplified first (within `TOLERANCE_M`, added to the margin), which
makes a look round the boat take milliseconds instead of seconds of a 10 Hz loop.

A boat may start at the water's edge (a scenario's start is often the end of its canal, and
an EKF's position puts it a few decimetres beyond): a heading is then judged by how soon its
ray reaches open water (`entry_m`) as well as by how much of it follows (`free_m`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from controller.geometry import simplify_polyline, wrap_angle

HULL_MARGIN_M = 5.0  # a hull circle (R_b = 3 m) 2 m ahead of the reference point
TOLERANCE_M = 0.25  # the simplified walls stay this close to the true ones
RAY_STEP_M = 5.0
RAY_MAX_M = 2000.0
HEADING_STEP_DEG = 10.0
_COMPASS = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))
ENTRY_COST = 2.0  # metres of open water a metre to reach it is worth


@dataclass(frozen=True)
class Ray:
    """The water along one heading from a point: where open water starts (0: here; inf:
    nowhere within RAY_MAX_M) and how much of it follows without a break."""

    heading: float
    entry_m: float
    free_m: float

    @property
    def score(self) -> float:
        return -math.inf if not math.isfinite(self.entry_m) else self.free_m - ENTRY_COST * self.entry_m


class OpenWater:
    """The water the boat may use: `ok` points, `ray` and `best_heading` (see the module
    docstring). `start_xy` is the centre of `radius_m` (None: no radius)."""

    def __init__(self, world, start_xy, radius_m: float | None = None,
                 margin_m: float = HULL_MARGIN_M, tolerance_m: float = TOLERANCE_M):
        from scenarios.world.canal import CanalWorld

        walls = tuple(dataclasses.replace(w, points=simplify_polyline(w.points, tolerance_m))
                      for w in world.walls)
        centre = (None if world.centre_line is None
                  else simplify_polyline(world.centre_line, tolerance_m))
        self.world = CanalWorld(walls, world.obstacles, centre, world.name)
        self.margin_m = float(margin_m) + float(tolerance_m)
        self.start_xy = np.asarray(start_xy, float).reshape(2)
        self.radius_m = radius_m

    def ok(self, points) -> np.ndarray:
        """(N,) mask: the boat may be at each point (on the water, `margin_m` clear of walls
        and obstacles, within the radius)."""
        pts = np.asarray(points, float).reshape(-1, 2)
        # on the water and margin_m from its edge in the four directions: an open end of the
        # canal is no surface that clearance measures
        probes = np.vstack([pts] + [pts + self.margin_m * np.array(d) for d in _COMPASS])
        on = np.array([r is None for r in self.world.off_water(probes)], bool)
        ok = on.reshape(len(_COMPASS) + 1, len(pts)).all(axis=0)
        ok &= self.world.clearance(pts) >= self.margin_m
        if self.radius_m is not None:
            ok &= np.hypot(*(pts - self.start_xy).T) <= self.radius_m
        return ok

    def why_not(self, point) -> str:
        """Why the boat may not be at `point` ('' if it may)."""
        p = np.asarray(point, float).reshape(1, 2)
        off = self.world.off_water(p)[0]
        if off is not None:
            return off
        if not self.ok(p)[0] and self.world.clearance(p)[0] >= self.margin_m and (
                self.radius_m is None or np.hypot(*(p[0] - self.start_xy)) <= self.radius_m):
            return f"within {self.margin_m:.1f} m of the water's edge"
        if self.radius_m is not None and np.hypot(*(p[0] - self.start_xy)) > self.radius_m:
            return f"beyond the {self.radius_m:g} m radius"
        clearance = float(self.world.clearance(p)[0])
        if clearance < self.margin_m:
            return f"{clearance:.1f} m from a wall or obstacle (at least {self.margin_m:.1f} m)"
        return ""

    def rays(self, xy, headings) -> list[Ray]:
        """The water along each heading from `xy` (one query for all of them)."""
        xy = np.asarray(xy, float).reshape(2)
        headings = np.atleast_1d(np.asarray(headings, float))
        d = np.arange(0.0, RAY_MAX_M + 1e-9, RAY_STEP_M)
        dirs = np.column_stack([np.cos(headings), np.sin(headings)])
        pts = xy + d[None, :, None] * dirs[:, None, :]
        ok = self.ok(pts.reshape(-1, 2)).reshape(len(headings), len(d))
        out = []
        for h, row in zip(headings, ok):
            if not row.any():
                out.append(Ray(float(h), math.inf, 0.0))
                continue
            i = int(np.argmax(row))
            rest = row[i:]
            j = i + (int(np.argmin(rest)) if not rest.all() else len(rest))
            out.append(Ray(float(h), float(d[i]), float(d[j - 1] - d[i])))
        return out

    def best_heading(self, xy, psi: float) -> Ray:
        """The heading (HEADING_STEP_DEG steps from `psi`) with the most open water for the
        least way to it; the smaller turn on a tie (within a ray step)."""
        turns = np.radians(np.arange(0.0, 360.0, HEADING_STEP_DEG))
        rays = self.rays(xy, psi + turns)
        best, best_turn = None, math.inf
        for ray, turn in zip(rays, turns):
            turn = abs(float(wrap_angle(turn)))
            if (best is None or ray.score > best.score + RAY_STEP_M
                    or (abs(ray.score - best.score) <= RAY_STEP_M and turn < best_turn)):
                best, best_turn = ray, turn
        return dataclasses.replace(best, heading=float(wrap_angle(best.heading)))


def coast_distance_m(params, speed_mps: float, to_mps: float = 0.2) -> float:
    """How far the boat coasts (no thrust, straight) from `speed_mps` to `to_mps`, from the
    surge equation m11 u' = Xu u + Xuu u|u| (closed form)."""
    u0, u1 = abs(float(speed_mps)), float(to_mps)
    if u0 <= u1:
        return 0.0
    a, b = max(-params.Xu, 1e-6), max(-params.Xuu, 1e-6)
    return params.m11 / b * math.log((a + b * u0) / (a + b * u1))


def run_length_m(run, params, hold_s: float, stop_factor: float = 1.5) -> float:
    """About how far a run of `controller.identification.maneuvers` takes the boat on the
    water, from the model with `params`: its straight running before the log (a level held
    `hold_s`), the logged run with each throttle level held `hold_s`, and the coasting
    after it (`stop_factor` on the model's distance). The length of the way, not the
    distance from the start: a zigzag's swing counts in full."""
    from controller.identification.maneuvers import NOISE, Steady, SurgeRun, simulate_run

    surge = isinstance(run, SurgeRun)
    if surge:
        run = dataclasses.replace(run, steady=Steady(window_s=hold_s, speed_tol_mps=0.0,
                                                     min_hold_s=hold_s, max_hold_s=hold_s))
    log = simulate_run(run, params, NOISE["none"], noise_name="none")
    path = float(np.sum(np.hypot(*np.diff(log.states[:, :2], axis=0).T)))
    before = 0.0 if surge and not run.start_pct else hold_s * abs(float(log.states[0, 3]))
    return before + path + stop_factor * coast_distance_m(params, log.states[-1, 3])
