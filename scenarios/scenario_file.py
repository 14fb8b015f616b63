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
from controller.geometry import Polyline
from controller.params import IDENTIFIED, BoatParams

from .sensors.lidar import LidarNoise
from .sensors.gps_ahrs import AhrsConfig, GpsConfig
from .world.canal import OBSTACLE_KINDS, CanalWorld, Obstacle, Wall, WorldError, walls_crossing

CONTROLLERS = ("nmpc", "los-pid", "lexicographic")
WATER_MODES = ("estimated", "still", "true")
"""What the NMPC knows of the water: the on-line estimate (default), nothing (still water),
or the scenario's true current (as from a current meter)."""
PERCEPTIONS = ("lidar", "known-walls")


@dataclass(frozen=True)
class Criteria:
    """Pass criteria checked by the scenario tests (None: not checked)."""

    reach_goal: bool = True
    reach_goal_within_s: float | None = None
    min_clearance_m: float | None = None
    max_time_below_desired_s: float | None = None
    max_mean_cross_track_m: float | None = None
    min_clearance_where_wide_m: float | None = None  # where the canal is >= 2 (R_b + d_p) wide
    max_mean_centre_offset_narrow_m: float | None = None  # where it is narrower than that
    max_fallback_steps: int | None = None  # steps on a fallback plan (a failed solve)
    min_first_detected_m: float | None = None  # each obstacle first seen at least this far off
    min_time_held_s: float | None = None  # held at rest before a blocked way at least this long
    max_speed_while_held_mps: float | None = None  # and no faster than this while held
    max_swing_while_waiting_m: float | None = None  # to and fro over the ground while waiting
    min_vessel_distance_m: float | None = None  # hull to hull, to every other vessel
    vessels_passed_on: str | None = None  # each vessel on this side of the boat when closest
    min_starboard_half_while_meeting: float | None = None  # share of the meeting time


@dataclass(frozen=True)
class Scenario:
    name: str
    path: Path | None
    description: str
    world: CanalWorld
    waypoints: np.ndarray  # (K, 2)
    target_speed_mps: float
    initial_state: np.ndarray  # [x, y, psi, u, v, r]
    current_ne: tuple[float, float]  # the current at the start (everywhere, if no profile)
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
    gps: GpsConfig = GpsConfig()
    ahrs: AhrsConfig = AhrsConfig()
    lidar_noise: LidarNoise = LidarNoise()
    lidar_outages_s: tuple = ()  # (start, end) spans with no scan (a sensor fault, for tests)
    max_scan_age_s: float = 1.0  # the last segments stand in this long, then "blind"
    current_profile: tuple | None = None  # ((s_m, north, east), ...) along the centre line
    lidar_table: dict | None = None  # [lidar]: the bridge's sensors (read by bridge.lidar.config)

    @property
    def current_field(self):
        """The water current over the canal (`scenarios.world.current.CurrentField`)."""
        from .world.current import CurrentField

        if self.current_profile is None:
            return CurrentField(tuple(self.current_ne))
        return CurrentField(tuple(self.current_ne), np.array(self.current_profile),
                            self.world.centre_line)


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

    def number(self, key: str, default=None, low=None, strict=False, required=False, high=None):
        if key not in self.data:
            if required:
                raise self.err(key, "is required")
            return default
        v = self.raw(key)
        if not _is_number(v):
            raise self.err(key, f"expected a number, got {v!r}")
        v = float(v)
        if not math.isfinite(v):
            raise self.err(key, f"must be finite, got {v!r}")
        if low is not None and (v <= low if strict else v < low):
            raise self.err(key, f"must be {'>' if strict else '>='} {low}, got {v!r}")
        if high is not None and v > high:
            raise self.err(key, f"must be <= {high}, got {v!r}")
        return v

    def integer(self, key: str, default=None, low=None):
        if key not in self.data:
            return default
        v = self.raw(key)
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.err(key, f"expected a whole number, got {v!r}")
        if low is not None and v < low:
            raise self.err(key, f"must be >= {low}, got {v!r}")
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

    def numbers(self, key: str, default=(), low=None):
        """A list of finite numbers (booleans are not numbers)."""
        if key not in self.data:
            return default
        v = self.raw(key)
        if not isinstance(v, list) or not all(_is_number(x) and math.isfinite(x) for x in v):
            raise self.err(key, f"expected a list of numbers, got {v!r}")
        if low is not None and any(x < low for x in v):
            raise self.err(key, f"must all be >= {low}, got {v!r}")
        return tuple(float(x) for x in v)

    def side_pair(self, key: str, default: float, low: float, strict: bool):
        """A number for both banks, or a [left, right] pair."""
        v = self.data.get(key, default)
        self.used.add(key)
        pair = v if isinstance(v, list) else [v]
        if len(pair) not in (1, 2) or not all(_is_number(x) and math.isfinite(x) for x in pair):
            raise self.err(key, f"expected a number or a [left, right] pair, got {v!r}")
        if any(x <= low if strict else x < low for x in pair):
            raise self.err(key, f"must be {'>' if strict else '>='} {low}, got {v!r}")
        return tuple(float(x) for x in pair) if len(pair) == 2 else float(pair[0])

    def points(self, key: str, required=False, min_points=2, pair="[north_m, east_m]"):
        if key not in self.data:
            if required:
                raise self.err(key, "is required")
            return None
        v = self.raw(key)
        if not isinstance(v, list) or not all(
                isinstance(q, list) and len(q) == 2 and all(map(_is_number, q)) for q in v):
            raise self.err(key, f"expected a list of {pair} pairs of numbers")
        arr = np.array(v, dtype=float).reshape(-1, 2)
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


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


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
    if t.has("wall"):
        return _load_walls(t, obstacles, name)
    centre = t.points("centre_line", required=True)
    step = np.hypot(*np.diff(centre, axis=0).T)
    if np.any(step <= 0.0):
        i = int(np.argmin(step)) + 1
        raise t.err("centre_line", f"point {i} ({centre[i, 0]:g}, {centre[i, 1]:g}) repeats the "
                    "one before it")
    radius = t.number("corner_radius_m", 0.0, low=0)
    spacing = t.number("resample_m", 2.0, low=0, strict=True)
    centre = round_corners(centre, radius, spacing)
    step = np.hypot(*np.diff(centre, axis=0).T)
    if np.any(step <= 1e-9):  # resampled onto itself: the line turned straight back
        s = float(np.cumsum(step)[int(np.argmin(step))])
        raise t.err("centre_line", f"turns straight back on itself near s = {s:.0f} m along it; "
                    "a U-turn needs two corners, each rounded wider (corner_radius_m) than half "
                    "the width")
    if t.has("width_profile"):
        if t.has("width_m"):
            raise t.err("width_m", "give width_m or width_profile, not both")
        width_key = "width_profile"
        width = t.points("width_profile", min_points=1, pair="[s_m, width_m]")
        if np.any(width[:, 1] <= 0):
            raise t.err("width_profile", f"widths must be > 0, got {width[:, 1].min():g}")
        if np.any(np.diff(width[:, 0]) <= 0):
            raise t.err("width_profile", "the s_m values must increase")
    else:
        width_key = "width_m"
        width = t.number("width_m", required=True, low=0, strict=True)
    try:
        world = CanalWorld.from_centre_line(
            centre, width, wall_height_m=t.side_pair("wall_height_m", 1.5, 0.0, strict=True),
            setback_m=t.side_pair("setback_m", 5.0, 0.0, strict=True),
            backdrop_height_m=t.side_pair("backdrop_height_m", 8.0, 0.0, strict=False),
            obstacles=obstacles, name=name)
    except WorldError as exc:
        key = width_key if exc.key == "width_m" else exc.key
        raise t.err(key, exc.detail) from None
    t.done()
    return world


def _load_walls(t: _Table, obstacles: tuple, name: str) -> CanalWorld:
    """Explicit [[canal.wall]] tables; a crossing names the walls' fields."""
    for key in ("width_m", "width_profile", "corner_radius_m", "resample_m"):
        if t.has(key):
            raise t.err(key, "belongs to a canal given by its centre line, not by explicit walls")
    walls, tables = [], t.tables("wall")
    for i, w in enumerate(tables):
        wall_name = w.string("name", f"wall {i}")
        points = w.points("points", required=True)
        try:
            walls.append(Wall(
                points, height_m=w.number("height_m", 1.5, low=0, strict=True),
                land_side=w.string("land_side", "left", choices=("left", "right")),
                setback_m=w.number("setback_m", 5.0, low=0, strict=True),
                backdrop_height_m=w.number("backdrop_height_m", 8.0, low=0), name=wall_name))
        except WorldError as exc:
            raise w.err(exc.key, f"wall {wall_name!r}: {exc.detail}") from None
        w.done()
    crossing = walls_crossing(walls)
    if crossing is not None:
        i, j, leg_i, leg_j = crossing
        raise tables[i].err("points", f"walls {walls[i].name!r} and {walls[j].name!r} "
                            f"({tables[j].where}) cross each other (their legs {leg_i} and {leg_j})")
    centre = t.points("centre_line")
    t.done()
    try:
        return CanalWorld.from_walls(walls, obstacles, centre, name)
    except WorldError as exc:
        raise t.err(exc.key, exc.detail) from None


def _load_obstacles(doc: _Table) -> tuple:
    out = []
    for o in doc.tables("obstacle"):
        name = o.string("name", f"obstacle {len(out)}")
        outline = o.points("outline", required=True, min_points=3)
        z_bottom = o.number("z_bottom_m", 0.0, low=0)
        z_top = o.number("z_top_m", 1.0)
        if z_top <= z_bottom:
            raise o.err("z_top_m", f"must be above z_bottom_m ({z_bottom:g}), got {z_top:g}")
        remove_at = o.number("remove_at_s", None, low=0)
        try:
            out.append(Obstacle(outline, z_top_m=z_top, z_bottom_m=z_bottom,
                                kind=o.string("kind", "pier", choices=OBSTACLE_KINDS), name=name,
                                remove_at_s=remove_at))
        except WorldError as exc:
            raise o.err(exc.key, f"obstacle {name!r}: {exc.detail}") from None
        o.done()
    return tuple(out)


def _load_vessels(doc: _Table, world: CanalWorld, duration_s: float, seed: int) -> tuple:
    """[[vessel]]: name, [vessel.hull] and a motion, [vessel.route] or [vessel.course]; each
    must start on open water, keep off the walls and not start inside another object."""
    out = []
    for k, v in enumerate(doc.tables("vessel")):
        vessel, where, key, line = _read_vessel(v, k, duration_s, seed)
        _check_vessel(world, vessel, where, key, line, out)
        out.append(vessel)
    return tuple(out)


def vessel_from_table(table: dict, index: int, duration_s: float, seed: int,
                      source: str = "vessel") -> "Vessel":
    """One [[vessel]] table's vessel as a scenario file with `seed` makes it, the `index`-th
    of the file (its wander's seed), read and checked as a table but not placed in a world
    (no check against walls or other vessels): for a generator that moves a vessel in time."""
    return _read_vessel(_Table(table, f"vessel[{index}]", source), index, duration_s, seed)[0]


def _read_vessel(v: _Table, k: int, duration_s: float, seed: int):
    """The k-th [[vessel]] table read: (vessel, the motion's table, the key that places it,
    the line it follows), for `_check_vessel`."""
    from .world.vessels import HULL_SHAPES, Hull, Vessel

    name = v.string("name", f"vessel {k}")
    h = v.table("hull", required=True)
    hull_args = dict(length_m=h.number("length_m", required=True, low=0, strict=True),
                     beam_m=h.number("beam_m", required=True, low=0, strict=True),
                     height_m=h.number("height_m", 1.5, low=0, strict=True),
                     shape=h.string("shape", "pointed", choices=HULL_SHAPES))
    h.done()
    hull = Hull(**hull_args)
    route, course = v.table("route"), v.table("course")
    if (route is None) == (course is None):
        raise v.err("route", "give the vessel a [vessel.route] (waypoints and a speed) or "
                    "a [vessel.course] (start, course and speed), one of the two")
    if route is not None:
        waypoints = route.points("waypoints", required=True, min_points=2)
        if np.any(np.hypot(*np.diff(waypoints, axis=0).T) <= 0):
            raise route.err("waypoints", "repeats a point")
        speed = route.number("speed_mps", required=True, low=0)
        start = route.number("start_s", 0.0, low=0)
        waits = [(int(a), float(b)) for a, b in _waits(
            route, lambda a: isinstance(a, int) and not isinstance(a, bool)
            and 0 < a < len(waypoints), f"waypoint index (1..{len(waypoints) - 1})")]
        route.done()
        vessel = Vessel.on_route(name, hull, waypoints, speed, duration_s, start, waits)
        where, line = route, waypoints
    else:
        start_xy = (course.number("x_m", required=True), course.number("y_m", required=True))
        heading = math.radians(course.number("course_deg", required=True))
        speed = course.number("speed_mps", required=True, low=0)
        start = course.number("start_s", 0.0, low=0)
        wander = course.number("wander_degps", 0.0, low=0)
        distance = course.number("distance_m", None, low=0, strict=True)
        rests = [(float(a), float(b)) for a, b in _waits(
            course, lambda a: _is_number(a) and a >= 0, "metres along the course >= 0")]
        if rests and speed <= 0:
            raise course.err("waits", "a vessel with speed_mps = 0 never reaches a wait")
        course.done()
        vessel = Vessel.on_course(name, hull, start_xy, heading, speed, duration_s, start,
                                  wander, seed=seed * 7919 + 11 + k, distance_m=distance,
                                  waits=rests)
        where, line = course, vessel.poses[:, :2]
    v.done()
    return vessel, where, "waypoints" if route is not None else "x_m", line


def _waits(t: "_Table", place_ok, place: str) -> list:
    """A vessel's `waits` ([] when not given): [place, seconds >= 0] pairs, each place
    checked by `place_ok` and named `place` in the error."""
    if not t.has("waits"):
        return []
    raw = t.raw("waits")
    if not (isinstance(raw, list) and all(
            isinstance(w, list) and len(w) == 2 and place_ok(w[0]) and _is_number(w[1])
            and w[1] >= 0 for w in raw)):
        raise t.err("waits", f"expected [{place}, seconds >= 0] pairs, got {raw!r}")
    return raw


def _check_vessel(world: CanalWorld, vessel, t: _Table, key: str, line, others) -> None:
    """The vessel starts on open water, its track crosses no wall, and it does not start
    inside an obstacle or another vessel."""
    from controller.geometry import polyline_legs, segments_cross

    outline = vessel.outline_at(0.0)
    why = [r for r in world.off_water(np.vstack([vessel.pose_at(0.0)[:2], outline])) if r]
    if why:
        raise t.err(key, f"vessel {vessel.name!r} starts off the water: its hull lies {why[0]}")
    a, b = polyline_legs(world.wall_polylines())
    track = np.asarray(line, float)
    hits = segments_cross(track[:-1], track[1:], a, b)
    if hits.any():
        leg = int(np.argwhere(hits)[0][0])
        raise t.err(key, f"vessel {vessel.name!r}: its track crosses a wall near "
                    f"({track[leg, 0]:.1f}, {track[leg, 1]:.1f}); keep it on the water over the "
                    f"whole run (shorten the route, or the course's speed or start)")
    for o in list(world.obstacles) + [w.obstacle_at(0.0) for w in others]:
        if o.z_bottom_m == 0 and (o.contains(outline).any()
                                  or Obstacle(outline).contains(o.outline).any()):
            raise t.err(key, f"vessel {vessel.name!r} starts inside {o.name!r}")


@dataclass(frozen=True)
class _Route:
    """Waypoints and, for each, the field to blame if it is wrong."""

    waypoints: np.ndarray  # (K, 2)
    fields: tuple[str, ...]


def _route(t: _Table, world: CanalWorld) -> _Route:
    """Waypoints: explicit, or along the centre line every `spacing_m` with lateral offsets."""
    generated = [k for k in ("spacing_m", "offset_m", "offsets") if t.has(k)]
    if t.has("waypoints"):
        if generated:
            raise t.err(generated[0], "give waypoints, or spacing_m / offset_m / offsets to "
                        "place them along the centre line, not both")
        waypoints = t.points("waypoints", required=True)
        return _Route(waypoints, ("route.waypoints",) * len(waypoints))
    if world.centre_line is None:
        raise t.err("waypoints", "is required when the canal has no centre line")
    spacing = t.number("spacing_m", 25.0, low=0, strict=True)
    line = Polyline(world.centre_line)
    s = np.append(np.arange(0.0, line.length, spacing), line.length)
    offset = np.full(len(s), t.number("offset_m", 0.0))
    blame = np.full(len(s), "route.offset_m" if offset[0] else "canal.centre_line", dtype=object)
    for o in t.tables("offsets"):
        s0 = o.number("from_s_m", required=True, low=0)
        s1 = o.number("to_s_m", required=True, low=0)
        off = o.number("offset_m", required=True)
        if s1 <= s0:
            raise o.err("to_s_m", f"must be greater than from_s_m ({s0}), got {s1}")
        span = (s >= s0) & (s <= s1)
        offset[span] = off
        blame[span] = f"{o.where}.offset_m"
        o.done()
    xy, heading = line.at(s)
    normal = np.column_stack([-np.sin(heading), np.cos(heading)])  # starboard of the centre line
    return _Route(xy + offset[:, None] * normal, tuple(blame))


def check_on_water(world: CanalWorld, route: _Route, source: str) -> None:
    """Every waypoint must lie on the water: inside the canal (not on or across a wall, not
    past its open ends) and not inside an obstacle. The error names the field to fix."""
    for i, (p, why) in enumerate(zip(route.waypoints, world.off_water(route.waypoints))):
        if why is not None:
            raise InputError(f"{source}: field {route.fields[i]!r}: waypoint {i} "
                             f"({p[0]:.1f}, {p[1]:.1f}) lies {why}")


def parameter_file_path(source: str, rel: str) -> Path:
    """Where a parameter file named in a scenario (`[plant.boat] file = ...`) lives: beside
    the scenario file (or as given, for a scenario from a string)."""
    return (Path(source).parent / rel) if source != "<string>" else Path(rel)


def _distinct(waypoints: np.ndarray) -> np.ndarray:
    """The waypoints without consecutive repeats (as the reference path sees them)."""
    keep = np.concatenate([[True], np.hypot(*np.diff(waypoints, axis=0).T) > 1e-9])
    return waypoints[keep]


def _params(t: _Table | None, base: BoatParams, source: str,
            files: dict | None = None) -> BoatParams:
    """A [plant.boat] / [controller.boat] table: a parameter file and/or overrides, or a
    common relative change (`scale_all`). The file's text comes from `files` if it is there
    (a study sends it with the run), else from the disk beside the scenario file."""
    if t is None:
        return base
    params = base
    if t.has("file"):
        rel = t.string("file")
        path = parameter_file_path(source, rel)
        if files is not None and rel in files:
            params = BoatParams.from_toml_text(files[rel], str(path))
        else:
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
    """Read and check a scenario file; every problem is an InputError naming the file."""
    path = Path(path)
    try:
        text = path.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise InputError(f"{path}: no such scenario file") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a folder, not a scenario file (give a .toml file)") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not UTF-8 text (byte {exc.start}: "
                         f"{exc.object[exc.start:exc.start + 1]!r}); a scenario is a TOML file") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read the scenario file: {exc.strerror}") from None
    return parse_scenario(text, str(path), path)


DEMO_NAMES = ("demo",)


def load_world(scenario: str | Path | None) -> CanalWorld:
    """The canal of a scenario file, or the built-in demo canal (None or "demo")."""
    if scenario is None or str(scenario) in DEMO_NAMES:
        from .world.demo import demo_canal

        return demo_canal()
    return load_scenario(scenario).world


def parse_scenario(text: str, source: str = "<string>", path: Path | None = None,
                   files: dict | None = None) -> Scenario:
    """A scenario from the text of its file; `source` names it in errors, `files` holds the
    texts of the parameter files it names (by the name it gives them; else read from disk)."""
    return scenario_from_table(parse_toml(text, source), source, path, files)


def parse_toml(text: str, source: str = "<string>") -> dict:
    """The TOML document of a scenario file, or an InputError naming the file."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{source}: not valid TOML: {exc}") from None


def scenario_from_table(data: dict, source: str = "<string>", path: Path | None = None,
                        files: dict | None = None) -> Scenario:
    """A scenario from a parsed TOML document (e.g. one a study changed key by key): every
    check of `parse_scenario` applies, and errors name `source` and the field."""
    doc = _Table(data, "", source)

    meta = doc.table("scenario", required=True)
    name = meta.string("name", Path(source).stem)
    description = meta.string("description", "")
    duration = meta.number("duration_s", required=True, low=0, strict=True)
    goal_radius = meta.number("goal_radius_m", 5.0, low=0, strict=True)
    seed = meta.integer("seed", 0, low=0)
    default_test = meta.boolean("default_test", True)
    snaps = meta.numbers("snapshot_times_s", (), low=0)
    meta.done()

    obstacles = _load_obstacles(doc)
    world = _load_canal(doc.table("canal", required=True), obstacles, name)
    vessels = _load_vessels(doc, world, duration, seed)
    if vessels:
        from dataclasses import replace as _replace

        world = _replace(world, vessels=vessels)

    route = doc.table("route", required=True)
    planned = _route(route, world)
    target_speed = route.number("target_speed_mps", 2.0, low=0, strict=True)
    route.done()
    waypoints = planned.waypoints
    distinct = _distinct(waypoints)
    if len(distinct) < 2:
        raise InputError(f"{source}: field {planned.fields[0]!r}: needs at least two distinct "
                         f"waypoints, got {len(distinct)} (a point repeating the one before it "
                         "does not count)")
    check_on_water(world, planned, source)

    x0 = _initial_state(doc.table("initial") or _Table({}, "initial", source), distinct, world)

    cur = doc.table("current") or _Table({}, "current", source)
    current = (cur.number("north_mps", 0.0), cur.number("east_mps", 0.0))
    profile = _current_profile(cur, world, x0)
    if profile is not None:
        if cur.has("north_mps") or cur.has("east_mps"):
            raise cur.err("profile", "give north_mps / east_mps (one current everywhere) or a "
                          "profile along the canal, not both")
        from .world.current import CurrentField

        current = tuple(float(v) for v in CurrentField(
            (0.0, 0.0), np.array(profile), world.centre_line).at(x0[:2]))
    cur.done()

    origin = None
    org = doc.table("origin")
    if org is not None:
        origin = (org.number("lat_deg", required=True, low=-90, high=90),
                  org.number("lon_deg", required=True, low=-180, high=180),
                  org.number("alt_m", 0.0))
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
    gps, ahrs = _gps(sens.table("gps")), _ahrs(sens.table("ahrs"))
    lidar_noise, outages, max_scan_age = _lidar(sens.table("lidar"))
    sens.done()

    plant = doc.table("plant") or _Table({}, "plant", source)
    plant_params = _params(plant.table("boat"), IDENTIFIED, source, files)
    rates = (plant.number("dnT_max_pctps", 10.0, low=0), plant.number("dnS_max_pctps", 40.0, low=0))
    plant.done()

    ctrl = doc.table("controller") or _Table({}, "controller", source)
    controller = ctrl.string("type", "nmpc", choices=CONTROLLERS)
    d_p = ctrl.number("d_p_m", 2.0, low=0)
    ctrl_params = _params(ctrl.table("boat"), IDENTIFIED, source, files)
    options = _controller_options(ctrl.table("options") or _Table({}, "controller.options", source),
                                  controller, d_p, ctrl_params)
    ctrl.done()
    from controller.nmpc.controller import top_speed_mps

    throttle = options.get("nT_max", 100.0)
    if target_speed > top_speed_mps(ctrl_params, throttle):
        raise InputError(f"{source}: field 'route.target_speed_mps': {target_speed:g} m/s is "
                         f"above the controller's boat's top speed, "
                         f"{top_speed_mps(ctrl_params, throttle):.2f} m/s at {throttle:g} % "
                         f"throttle")

    crit = doc.table("criteria") or _Table({}, "criteria", source)
    criteria = Criteria(
        reach_goal=crit.boolean("reach_goal", True),
        reach_goal_within_s=crit.number("reach_goal_within_s", None, low=0, strict=True),
        min_clearance_m=crit.number("min_clearance_m", None, low=0),
        max_time_below_desired_s=crit.number("max_time_below_desired_s", None, low=0),
        max_mean_cross_track_m=crit.number("max_mean_cross_track_m", None, low=0),
        min_clearance_where_wide_m=crit.number("min_clearance_where_wide_m", None, low=0),
        max_mean_centre_offset_narrow_m=crit.number("max_mean_centre_offset_narrow_m", None, low=0),
        max_fallback_steps=crit.integer("max_fallback_steps", None, low=0),
        min_first_detected_m=crit.number("min_first_detected_m", None, low=0),
        min_time_held_s=crit.number("min_time_held_s", None, low=0),
        max_speed_while_held_mps=crit.number("max_speed_while_held_mps", None, low=0),
        max_swing_while_waiting_m=crit.number("max_swing_while_waiting_m", None, low=0),
        min_vessel_distance_m=crit.number("min_vessel_distance_m", None, low=0),
        vessels_passed_on=crit.string("vessels_passed_on", None, choices=("port", "starboard")),
        min_starboard_half_while_meeting=crit.number("min_starboard_half_while_meeting", None,
                                                     low=0, high=1),
    )
    crit.done()
    lidar_table = doc.raw("lidar") if doc.has("lidar") else None
    doc.done()

    return Scenario(
        name=name, path=path, description=description, world=world, waypoints=waypoints,
        target_speed_mps=target_speed, initial_state=x0, current_ne=current,
        duration_s=duration, goal_radius_m=goal_radius, seed=seed, perception=perception,
        known_walls_range_m=known_range, plant_params=plant_params, actuator_rates=rates,
        controller=controller, controller_params=ctrl_params, d_p_m=d_p,
        controller_options=options, criteria=criteria, default_test=default_test,
        snapshot_times_s=snaps, geodetic_origin=origin, replay_mount=replay_mount,
        gps=gps, ahrs=ahrs, lidar_noise=lidar_noise, lidar_outages_s=outages,
        max_scan_age_s=max_scan_age, current_profile=profile, lidar_table=lidar_table,
    )


def _current_profile(cur: _Table, world: CanalWorld, x0) -> tuple | None:
    """[current] profile: [s_m, north_mps, east_mps] rows along the centre line."""
    if not cur.has("profile"):
        return None
    rows = cur.raw("profile")
    ok = isinstance(rows, list) and rows and all(
        isinstance(r, list) and len(r) == 3 and all(_is_number(v) and math.isfinite(v) for v in r)
        for r in rows)
    if not ok:
        raise cur.err("profile", f"expected a list of [s_m, north_mps, east_mps] rows, got {rows!r}")
    s = [float(r[0]) for r in rows]
    if any(b <= a for a, b in zip(s, s[1:])):
        raise cur.err("profile", f"the s_m values must increase, got {s}")
    if world.centre_line is None:
        raise cur.err("profile", "a current profile runs along the canal's centre line; give "
                      "[canal] centre_line")
    return tuple(tuple(float(v) for v in r) for r in rows)


def _initial_state(init: _Table, waypoints: np.ndarray, world: CanalWorld) -> np.ndarray:
    """[x, y, psi, u, v, r]: given, or at the first waypoint heading along the first leg."""
    if init.has("x_m") or init.has("y_m"):
        x0 = np.array([init.number("x_m", required=True), init.number("y_m", required=True),
                       math.radians(init.number("psi_deg", required=True)), 0, 0, 0], float)
        why = world.off_water(x0[None, :2])[0]
        if why is not None:
            raise InputError(f"{init.source}: fields 'initial.x_m', 'initial.y_m': the start "
                             f"({x0[0]:.1f}, {x0[1]:.1f}) lies {why}")
    else:
        d = waypoints[1] - waypoints[0]
        psi = math.atan2(d[1], d[0])
        if init.has("psi_deg"):
            psi = math.radians(init.number("psi_deg"))
        x0 = np.array([waypoints[0, 0], waypoints[0, 1], psi, 0, 0, 0], float)
    x0[3] = init.number("u_mps", 0.0)
    x0[4] = init.number("v_mps", 0.0)
    x0[5] = math.radians(init.number("r_degps", 0.0))
    init.done()
    return x0


# -- sensors: only what the file gives, so the defaults stay the sensors' own ---------------
def _gps(t: _Table | None) -> GpsConfig:
    """[sensors.gps]: rate and 1-sigma noise of the RTK fix."""
    if t is None:
        return GpsConfig()
    ahrs_hz = AhrsConfig().rate_hz
    given = {
        "rate_hz": t.number("rate_hz", None, low=0, strict=True, high=ahrs_hz),
        "pos_sigma_m": t.number("pos_sigma_m", None, low=0),
        "vel_sigma_mps": t.number("vel_sigma_mps", None, low=0),
    }
    rate = given["rate_hz"]
    if rate is not None and abs(ahrs_hz / rate - round(ahrs_hz / rate)) > 1e-9:
        raise t.err("rate_hz", f"the fix comes every n-th AHRS sample ({ahrs_hz:g} Hz): the rate "
                    f"must divide {ahrs_hz:g} Hz (e.g. 1, 2, 5, 10, 20), got {rate:g}")
    t.done()
    return GpsConfig(**{k: v for k, v in given.items() if v is not None})


def _ahrs(t: _Table | None) -> AhrsConfig:
    """[sensors.ahrs]: 1-sigma noise, degrees in the file, radians inside."""
    if t is None:
        return AhrsConfig()
    heading = t.number("heading_sigma_deg", None, low=0)
    yaw_rate = t.number("yaw_rate_sigma_degps", None, low=0)
    given = {
        "heading_sigma_rad": None if heading is None else math.radians(heading),
        "yaw_rate_sigma_radps": None if yaw_rate is None else math.radians(yaw_rate),
        "accel_sigma_mps2": t.number("accel_sigma_mps2", None, low=0),
    }
    t.done()
    return AhrsConfig(**{k: v for k, v in given.items() if v is not None})


def _lidar(t: _Table | None) -> tuple[LidarNoise, tuple, float]:
    """[sensors.lidar]: the simulated LiDAR's imperfections (named as in LidarNoise), its
    outages (`outages_s`: [start, end] spans with no scan) and how long the last segments
    bridge missing scans (`max_scan_age_s`)."""
    if t is None:
        return LidarNoise(), (), 1.0
    outages = []
    if t.has("outages_s"):
        spans = t.raw("outages_s")
        ok = isinstance(spans, list) and all(
            isinstance(s, list) and len(s) == 2 and all(_is_number(v) and math.isfinite(v)
                                                        for v in s) and 0 <= s[0] < s[1]
            for s in spans)
        if not ok:
            raise t.err("outages_s", f"expected a list of [start_s, end_s] pairs with "
                        f"0 <= start < end, got {spans!r}")
        outages = [(float(a), float(b)) for a, b in spans]
    max_age = t.number("max_scan_age_s", 1.0, low=0)
    given = {
        "range_sigma_m": t.number("range_sigma_m", None, low=0),
        "dropout": t.number("dropout", None, low=0, high=1),
        "water_speckle": t.number("water_speckle", None, low=0, high=1),
        "water_ripple_m": t.number("water_ripple_m", None, low=0),
        "spray_points": t.integer("spray_points", None, low=0),
        "spray_length_m": t.number("spray_length_m", None, low=0),
        "spray_height_m": t.number("spray_height_m", None, low=0),
    }
    t.done()
    noise = LidarNoise(**{k: v for k, v in given.items() if v is not None})
    if noise.dropout + noise.water_speckle > 1.0:
        raise t.err("water_speckle", f"dropout + water_speckle must be <= 1 (both are chances "
                    f"per return), got {noise.dropout:g} + {noise.water_speckle:g}")
    return noise, tuple(outages), max_age


# -- controller options ----------------------------------------------------------------------
FIXED_BY_THE_LOOP = {
    "control_period_s": "the closed loop runs every controller at 10 Hz (0.1 s)",
    "hull_radius_m": "the hull circles (R_b = 3 m at +-2 m) are fixed: the clearance metrics "
                     "and the desired separation R_b + d_p use them too",
    "hull_offsets_m": "the hull circles (R_b = 3 m at +-2 m) are fixed: the clearance metrics "
                      "and the desired separation R_b + d_p use them too",
}
"""NmpcConfig fields a scenario may not change, because the loop and its metrics assume them."""


def _controller_options(t: _Table, controller: str, d_p_m: float, params: BoatParams) -> dict:
    """[controller.options], checked now so a bad value never reaches a run: the NMPC takes
    NmpcConfig's fields by name plus `method`, `water` (and its older form `knows_current`);
    the baselines take none."""
    if controller != "nmpc":
        if t.data:
            raise t.err(sorted(t.data)[0], f"the {controller} controller takes no options "
                        "(its planner and tracker are set as in the paper)")
        return {}
    import typing

    from controller.nmpc.problem import NmpcConfig
    from controller.nmpc.controller import METHODS

    hints = typing.get_type_hints(NmpcConfig)
    settable = sorted(set(hints) - {"boat", "separation_m"})
    config = {}
    for key in sorted(t.data):
        if key == "method":
            t.string("method", choices=METHODS)
        elif key == "knows_current":
            t.boolean("knows_current")
        elif key == "water":
            t.string("water", choices=WATER_MODES)
        elif key == "separation_m":
            raise t.err(key, "d_p is set by controller.d_p_m")
        elif key == "boat":
            raise t.err(key, "the controller's model is set in [controller.boat]")
        elif key in FIXED_BY_THE_LOOP:
            raise t.err(key, FIXED_BY_THE_LOOP[key])
        elif key in settable:
            config[key] = _option_value(t, key, hints[key])
        else:
            raise t.err(key, "unknown NMPC option (known: method, water, knows_current, "
                        f"{', '.join(settable)})")
    if "knows_current" in t.data and "water" in t.data:
        raise t.err("knows_current", "give water = \"true\" (or \"estimated\", \"still\"), "
                    "not both water and knows_current")
    try:
        NmpcConfig(separation_m=d_p_m, boat=params, **config)
    except (InputError, TypeError, ValueError) as exc:
        named = [k for k in config if f"'{k}'" in str(exc)]
        where = f"controller.options.{named[0]}" if named else "controller.options"
        raise InputError(f"{t.source}: field {where!r}: {exc}") from None
    t.done()
    return dict(t.data)


def _option_value(t: _Table, key: str, hint):
    """An option's value checked against its NmpcConfig type: a whole number, a number, or a
    list of numbers (of a fixed length where the type says so)."""
    import types
    import typing

    v = t.raw(key)
    args = [a for a in typing.get_args(hint) if a is not type(None)]
    if typing.get_origin(hint) in (typing.Union, types.UnionType) and len(args) == 1:
        hint = args[0]  # "or None": TOML has no null, so a number
    if hint is int:
        if isinstance(v, bool) or not isinstance(v, int):
            raise t.err(key, f"expected a whole number, got {v!r}")
    elif hint is float:
        if not _is_number(v):
            raise t.err(key, f"expected a number, got {v!r}")
    elif typing.get_origin(hint) is tuple:
        size = None if (len(typing.get_args(hint)) == 2 and typing.get_args(hint)[1] is Ellipsis) \
            else len(typing.get_args(hint))
        if not isinstance(v, list) or not all(map(_is_number, v)):
            raise t.err(key, f"expected a list of numbers, got {v!r}")
        if size is not None and len(v) != size:
            raise t.err(key, f"expected {size} numbers, got {len(v)}")
        return tuple(v)
    return v
