"""Scenario files (TOML): schema, validation with errors that name the file and field, loading.

A scenario says everything a closed-loop run needs: the canal (a centre line with a width
profile, or explicit walls), obstacles, the route (waypoints, possibly wrong), the initial
state, the current, sensors and seeds, the plant's parameters (which may differ from the
controller's), the controller and its parameters, the goal, the duration and pass criteria.
The format is documented in `scenarios/README.md`; every table and key is checked, and an
unknown key is an error (a typo must not silently fall back to a default).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from controller.errors import InputError
from controller.geometry import Polyline, segments_cross
from controller.params import IDENTIFIED, BoatParams

from .world import OBSTACLE_KINDS, CanalWorld, Obstacle, Wall

CONTROLLERS = ("nmpc", "los-pid", "lexicographic")
PERCEPTIONS = ("lidar", "known-walls")


@dataclass(frozen=True)
class Criteria:
    """Pass criteria checked by the scenario tests (None: not checked)."""

    reach_goal: bool = True
    reach_goal_within_s: float | None = None
    min_clearance_m: float | None = None
    max_time_below_desired_s: float | None = None
    max_mean_cross_track_m: float | None = None


@dataclass(frozen=True)
class Scenario:
    name: str
    path: Path | None
    description: str
    world: CanalWorld
    waypoints: np.ndarray  # (K, 2)
    target_speed_mps: float
    initial_state: np.ndarray  # [x, y, psi, u, v, r]
    current_ne: tuple[float, float]
    duration_s: float
    goal_radius_m: float
    seed: int
    perception: str
    known_walls_range_m: float
    plant_params: BoatParams
    actuator_rates: tuple[float, float]  # dnT_max, dnS_max (%/s), 0 = off
    controller: str
    controller_params: BoatParams
    d_p_m: float
    controller_options: dict = field(default_factory=dict)
    criteria: Criteria = Criteria()
    default_test: bool = True  # short enough for the default test command
    snapshot_times_s: tuple = ()
    geodetic_origin: tuple | None = None  # (lat_deg, lon_deg, alt_m) of the local frame's origin
    replay_mount: tuple = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # x, y, z m (body, z down), roll, pitch, yaw rad


# -- small typed readers that name the field -------------------------------------------------
class _Table:
    """A TOML table being read: every access names `file: table.key`; leftovers are errors."""

    def __init__(self, data, where: str, source: str):
        if not isinstance(data, dict):
            raise InputError(f"{source}: field {where!r} must be a table")
        self.data, self.where, self.source = data, where, source
        self.used: set[str] = set()

    def _name(self, key: str) -> str:
        return f"{self.where}.{key}" if self.where else key

    def err(self, key: str, msg: str) -> InputError:
        return InputError(f"{self.source}: field {self._name(key)!r}: {msg}")

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default=None):
        self.used.add(key)
        return self.data.get(key, default)

    def number(self, key: str, default=None, low=None, strict=False, required=False):
        if key not in self.data:
            if required:
                raise self.err(key, "is required")
            return default
        v = self.raw(key)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.err(key, f"expected a number, got {v!r}")
        v = float(v)
        if not math.isfinite(v):
            raise self.err(key, f"must be finite, got {v!r}")
        if low is not None and (v <= low if strict else v < low):
            raise self.err(key, f"must be {'>' if strict else '>='} {low}, got {v!r}")
        return v

    def string(self, key: str, default=None, choices=None):
        if key not in self.data:
            return default
        v = self.raw(key)
        if not isinstance(v, str):
            raise self.err(key, f"expected a string, got {v!r}")
        if choices is not None and v not in choices:
            raise self.err(key, f"must be one of {', '.join(choices)}, got {v!r}")
        return v

    def boolean(self, key: str, default=None):
        if key not in self.data:
            return default
        v = self.raw(key)
        if not isinstance(v, bool):
            raise self.err(key, f"expected true or false, got {v!r}")
        return v

    def points(self, key: str, required=False, min_points=2):
        if key not in self.data:
            if required:
                raise self.err(key, "is required")
            return None
        v = self.raw(key)
        try:
            arr = np.array(v, dtype=float)
        except (TypeError, ValueError):
            raise self.err(key, "expected a list of [north_m, east_m] pairs") from None
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise self.err(key, "expected a list of [north_m, east_m] pairs")
        if len(arr) < min_points:
            raise self.err(key, f"needs at least {min_points} points, got {len(arr)}")
        if not np.all(np.isfinite(arr)):
            raise self.err(key, "contains a non-finite coordinate")
        return arr

    def table(self, key: str, required=False) -> "_Table | None":
        if key not in self.data:
            if required:
                raise self.err(key, "is required")
            return None
        return _Table(self.raw(key), self._name(key), self.source)

    def tables(self, key: str) -> list["_Table"]:
        if key not in self.data:
            return []
        v = self.raw(key)
        if not isinstance(v, list) or not all(isinstance(t, dict) for t in v):
            raise self.err(key, "expected an array of tables ([[...]])")
        return [_Table(t, f"{self._name(key)}[{i}]", self.source) for i, t in enumerate(v)]

    def done(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            raise self.err(unknown[0], "unknown field (check the spelling; see scenarios/README.md)")


# -- canal geometry helpers -----------------------------------------------------------------
def round_corners(points: np.ndarray, radius_m: float, spacing_m: float = 2.0) -> np.ndarray:
    """Replace each interior corner of a polyline by a circular arc of `radius_m`, then
    resample every `spacing_m`: bends become smooth and a width profile has vertices to act on."""
    pts = np.asarray(points, float)
    out = [pts[0]]
    for i in range(1, len(pts) - 1):
        a, b, c = pts[i - 1], pts[i], pts[i + 1]
        d1, d2 = (b - a) / np.linalg.norm(b - a), (c - b) / np.linalg.norm(c - b)
        turn = math.atan2(d1[0] * d2[1] - d1[1] * d2[0], float(d1 @ d2))
        if radius_m <= 0 or abs(turn) < 1e-6:
            out.append(b)
            continue
        cut = radius_m * math.tan(abs(turn) / 2)
        cut = min(cut, 0.5 * np.linalg.norm(b - a), 0.5 * np.linalg.norm(c - b))
        r = cut / math.tan(abs(turn) / 2)
        p1, p2 = b - d1 * cut, b + d2 * cut
        normal = np.array([-d1[1], d1[0]]) * (1 if turn > 0 else -1)  # starboard turn: centre to starboard
        centre = p1 + normal * r
        a1 = math.atan2(*(p1 - centre)[::-1])
        a2 = math.atan2(*(p2 - centre)[::-1])
        da = (a2 - a1 + math.pi) % (2 * math.pi) - math.pi
        n = max(2, int(abs(da) * r / 1.0))
        for k in range(n + 1):
            ang = a1 + da * k / n
            out.append(centre + r * np.array([math.cos(ang), math.sin(ang)]))
    out.append(pts[-1])
    line = Polyline(np.array(out))
    s = np.linspace(0.0, line.length, max(2, int(math.ceil(line.length / spacing_m)) + 1))
    return line.at(s)[0]


def _load_canal(t: _Table, obstacles: tuple, name: str) -> CanalWorld:
    source = t.source
    try:
        if t.has("wall"):
            if t.has("width_m") or t.has("width_profile"):
                raise t.err("wall", "give either explicit walls or a centre line with a width, not both")
            walls = []
            for w in t.tables("wall"):
                walls.append(Wall(
                    w.points("points", required=True),
                    height_m=w.number("height_m", 1.5, low=0, strict=True),
                    land_side=w.string("land_side", "left", choices=("left", "right")),
                    setback_m=w.number("setback_m", 5.0, low=0, strict=True),
                    backdrop_height_m=w.number("backdrop_height_m", 8.0, low=0),
                    name=w.string("name", f"wall {len(walls)}"),
                ))
                w.done()
            centre = t.points("centre_line")
            t.done()
            return CanalWorld.from_walls(walls, obstacles, centre, name)
        centre = t.points("centre_line", required=True)
        radius = t.number("corner_radius_m", 0.0, low=0)
        spacing = t.number("resample_m", 2.0, low=0, strict=True)
        centre = round_corners(centre, radius, spacing)
        if t.has("width_profile"):
            width = t.raw("width_profile")
            if t.has("width_m"):
                raise t.err("width_m", "give width_m or width_profile, not both")
        else:
            width = t.number("width_m", required=True, low=0, strict=True)

        def side(key, default):
            v = t.raw(key, default)
            if isinstance(v, list):
                if len(v) != 2:
                    raise t.err(key, "expected a number or a [left, right] pair")
                return tuple(v)
            return v

        world = CanalWorld.from_centre_line(
            centre, width, wall_height_m=side("wall_height_m", 1.5), setback_m=side("setback_m", 5.0),
            backdrop_height_m=side("backdrop_height_m", 8.0), obstacles=obstacles, name=name)
        t.done()
        return world
    except InputError as exc:
        msg = str(exc)
        raise InputError(msg if msg.startswith(source) else f"{source}: canal: {msg}") from None


def _load_obstacles(doc: _Table) -> tuple:
    out = []
    for o in doc.tables("obstacle"):
        try:
            out.append(Obstacle(
                o.points("outline", required=True, min_points=3),
                z_top_m=o.number("z_top_m", 1.0),
                z_bottom_m=o.number("z_bottom_m", 0.0, low=0),
                kind=o.string("kind", "pier", choices=OBSTACLE_KINDS),
                name=o.string("name", f"obstacle {len(out)}"),
            ))
        except InputError as exc:
            msg = str(exc)
            raise InputError(msg if msg.startswith(o.source) else f"{o.source}: {o.where}: {msg}") from None
        o.done()
    return tuple(out)


def _route(t: _Table, world: CanalWorld) -> np.ndarray:
    """Waypoints: explicit, or along the centre line every `spacing_m` with lateral offsets."""
    if t.has("waypoints"):
        return t.points("waypoints", required=True)
    if world.centre_line is None:
        raise t.err("waypoints", "is required when the canal has no centre line")
    spacing = t.number("spacing_m", 25.0, low=0, strict=True)
    line = Polyline(world.centre_line)
    s = np.append(np.arange(0.0, line.length, spacing), line.length)
    offset = np.full(len(s), t.number("offset_m", 0.0))
    for i, o in enumerate(t.tables("offsets")):
        s0 = o.number("from_s_m", required=True, low=0)
        s1 = o.number("to_s_m", required=True, low=0)
        off = o.number("offset_m", required=True)
        if s1 <= s0:
            raise o.err("to_s_m", f"must be greater than from_s_m ({s0}), got {s1}")
        offset[(s >= s0) & (s <= s1)] = off
        o.done()
    xy, heading = line.at(s)
    normal = np.column_stack([-np.sin(heading), np.cos(heading)])  # starboard of the centre line
    return xy + offset[:, None] * normal


def check_waypoints_inside(world: CanalWorld, waypoints: np.ndarray, source: str, field_name: str) -> None:
    """Every waypoint must lie on the water: reachable from the centre line without crossing a
    wall, and not inside an obstacle."""
    if world.centre_line is None:
        return
    line = Polyline(world.centre_line)
    walls = world.wall_polylines()
    a = np.vstack([w[:-1] for w in walls])
    b = np.vstack([w[1:] for w in walls])
    for i, p in enumerate(np.asarray(waypoints)):
        where = f"{source}: field {field_name!r}: waypoint {i} ({p[0]:.1f}, {p[1]:.1f})"
        for o in world.obstacles:
            if o.z_bottom_m == 0 and o.contains(p)[0]:
                raise InputError(f"{where} lies inside obstacle {o.name!r}")
        foot = line.project(p)[1]
        if np.hypot(*(p - foot)) > 1e-9 and segments_cross(foot[None, :], p[None, :], a, b).any():
            raise InputError(f"{where} lies outside the canal")


def _params(t: _Table | None, base: BoatParams, source: str) -> BoatParams:
    """A [plant.boat] / [controller.boat] table: a parameter file and/or overrides, or a
    common relative change (`scale_all`)."""
    if t is None:
        return base
    params = base
    if t.has("file"):
        rel = t.string("file")
        path = (Path(source).parent / rel) if source != "<string>" else Path(rel)
        params = BoatParams.from_toml(path)
    overrides = {k: v for k, v in t.data.items() if k not in ("file",)}
    for k in overrides:
        t.used.add(k)
    if overrides:
        params = BoatParams.from_mapping(
            {**{k: (math.degrees(v) if k == "delta_max" else v) for k, v in params.as_dict().items()},
             **overrides}, source=f"{source}: [{t.where}]")
    return params


def load_scenario(path: str | Path) -> Scenario:
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise InputError(f"{path}: no such scenario file") from None
    return parse_scenario(text, str(path), path)


def parse_scenario(text: str, source: str = "<string>", path: Path | None = None) -> Scenario:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{source}: not valid TOML: {exc}") from None
    doc = _Table(data, "", source)

    meta = doc.table("scenario", required=True)
    name = meta.string("name", Path(source).stem)
    description = meta.string("description", "")
    duration = meta.number("duration_s", required=True, low=0, strict=True)
    goal_radius = meta.number("goal_radius_m", 5.0, low=0, strict=True)
    seed = meta.number("seed", 0.0, low=0)
    if seed != int(seed):
        raise meta.err("seed", f"must be a whole number, got {seed}")
    default_test = meta.boolean("default_test", True)
    snaps = meta.raw("snapshot_times_s", [])
    if not isinstance(snaps, list) or not all(isinstance(v, (int, float)) for v in snaps):
        raise meta.err("snapshot_times_s", "expected a list of times in seconds")
    meta.done()

    obstacles = _load_obstacles(doc)
    world = _load_canal(doc.table("canal", required=True), obstacles, name)

    route = doc.table("route", required=True)
    waypoints = _route(route, world)
    target_speed = route.number("target_speed_mps", 2.0, low=0, strict=True)
    route.done()
    check_waypoints_inside(world, waypoints, source, "route.waypoints")

    init = doc.table("initial") or _Table({}, "initial", source)
    if init.has("x_m") or init.has("y_m"):
        x0 = np.array([init.number("x_m", required=True), init.number("y_m", required=True),
                       math.radians(init.number("psi_deg", required=True)), 0, 0, 0], float)
    else:
        start = waypoints[0]
        d = waypoints[1] - waypoints[0]
        psi = math.atan2(d[1], d[0])
        if init.has("psi_deg"):
            psi = math.radians(init.number("psi_deg"))
        x0 = np.array([start[0], start[1], psi, 0, 0, 0], float)
    x0[3] = init.number("u_mps", 0.0)
    x0[4] = init.number("v_mps", 0.0)
    x0[5] = math.radians(init.number("r_degps", 0.0))
    init.done()
    check_waypoints_inside(world, x0[None, :2], source, "initial")

    cur = doc.table("current") or _Table({}, "current", source)
    current = (cur.number("north_mps", 0.0), cur.number("east_mps", 0.0))
    cur.done()

    origin = None
    org = doc.table("origin")
    if org is not None:
        origin = (org.number("lat_deg", required=True, low=-90), org.number("lon_deg", required=True, low=-180),
                  org.number("alt_m", 0.0))
        if origin[0] > 90 or origin[1] > 180:
            raise org.err("lat_deg" if origin[0] > 90 else "lon_deg", "out of range")
        org.done()

    sens = doc.table("sensors") or _Table({}, "sensors", source)
    perception = sens.string("perception", "lidar", choices=PERCEPTIONS)
    known_range = sens.number("known_walls_range_m", 50.0, low=0, strict=True)
    mount = sens.table("replay_mount") or _Table({}, "sensors.replay_mount", source)
    replay_mount = (mount.number("x_m", 0.0), mount.number("y_m", 0.0), mount.number("z_m", 0.0),
                    math.radians(mount.number("roll_deg", 0.0)),
                    math.radians(mount.number("pitch_deg", 0.0)),
                    math.radians(mount.number("yaw_deg", 0.0)))
    mount.done()
    sens.done()

    plant = doc.table("plant") or _Table({}, "plant", source)
    plant_params = _params(plant.table("boat"), IDENTIFIED, source)
    rates = (plant.number("dnT_max_pctps", 10.0, low=0), plant.number("dnS_max_pctps", 40.0, low=0))
    plant.done()

    ctrl = doc.table("controller") or _Table({}, "controller", source)
    controller = ctrl.string("type", "nmpc", choices=CONTROLLERS)
    d_p = ctrl.number("d_p_m", 2.0, low=0)
    ctrl_params = _params(ctrl.table("boat"), IDENTIFIED, source)
    options = ctrl.raw("options", {})
    if not isinstance(options, dict):
        raise ctrl.err("options", "must be a table")
    ctrl.done()

    crit = doc.table("criteria") or _Table({}, "criteria", source)
    criteria = Criteria(
        reach_goal=crit.boolean("reach_goal", True),
        reach_goal_within_s=crit.number("reach_goal_within_s", None, low=0, strict=True),
        min_clearance_m=crit.number("min_clearance_m", None, low=0),
        max_time_below_desired_s=crit.number("max_time_below_desired_s", None, low=0),
        max_mean_cross_track_m=crit.number("max_mean_cross_track_m", None, low=0),
    )
    crit.done()
    doc.done()

    return Scenario(
        name=name, path=path, description=description, world=world, waypoints=waypoints,
        target_speed_mps=target_speed, initial_state=x0, current_ne=current,
        duration_s=duration, goal_radius_m=goal_radius, seed=int(seed), perception=perception,
        known_walls_range_m=known_range, plant_params=plant_params, actuator_rates=rates,
        controller=controller, controller_params=ctrl_params, d_p_m=d_p,
        controller_options=dict(options), criteria=criteria, default_test=default_test,
        snapshot_times_s=tuple(float(v) for v in snaps),
        geodetic_origin=origin, replay_mount=replay_mount,
    )
