"""Seeded random encounters (`canalnav fuzz`): scenario files nobody wrote by hand, run on
the study engine and judged by what must never happen.

Each case is drawn from one seed and written as an ordinary scenario file: a canal 12-40 m
wide, either with a bend of up to 45 degrees or straight with a side canal on one side;
moored boats along a quay and piers now and then; a current of up to 0.5 m/s; one to three
vessels, each met, overtaken, followed, crossing (from the side canal, from either side) or
drifting (a kayak, resting a while on its way across, and ending its drift clear of the way:
`_kayaks_end_clear`). Every vessel is timed to reach its encounter when the own boat does, at
the place where it is hardest: in the bend, at the side canal's mouth, beside a moored boat.
Scripted vessels give way to nobody, so they are kept apart by construction (`_kept_apart`),
and one whose hull would come within `VESSEL_GAP_M` of another's sets off later, as a skipper
waits for a vessel to clear (a launch crossing out of a side canal through a barge, a kayak
drifting into a barge's way; `_give_way`).
The judgement comes from the true poses in each run's summary: no exception, collision or
controller failure, at least `min_hull_m` hull to hull from every vessel; the goal, fallback
steps, tracks on walls and what the rules of the road asked are reported beside.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field

import numpy as np

from scenarios.studies.overrides import toml_value

KINDS = ("meeting", "overtaken", "followed", "crossing", "drifting")
SPEED_MPS = 2.0  # the own boat's target speed (the scenario default)
BARGE_HALF_BEAM_M = 3.0  # the widest followed barge's (30 m long, beam a fifth of that)
VESSEL_GAP_M = 1.0  # scripted vessels keep this far apart, and from the quays
GIVE_WAY_STEP_S, GIVE_WAY_MAX_S = 5.0, 60.0  # a vessel in another's way waits in such steps
KAYAK_REST_S = (15.0, 60.0)  # a drifting kayak rests mid-canal this long, then goes on
KAYAK_CLEAR_GAP_M = 8.0  # and ends its drift leaving a gap this wide (the boat passes, in time)
MOORED_ALLOWANCE_M = 3.5  # a moored boat's beam (up to 3.2 m) and its fenders off the quay


@dataclass(frozen=True)
class Case:
    """One generated encounter: its scenario file's text and what it was drawn to test."""

    name: str
    text: str
    kinds: tuple  # the encounter kind of each vessel
    place: str  # "bend", "junction", "moored boat" or "open"
    width_m: float
    perception: str
    vessels: tuple = field(default_factory=tuple)  # vessel names, in the kinds' order
    waited_s: float = 0.0  # the longest a vessel was held back from another's way


def generate(seed: int, index: int, perception: str = "mixed") -> Case:
    """Case `index` of the fuzz with `seed`: the same pair always gives the same file. A draw
    the scenario checker refuses (a vessel starting on a moored boat, say) is drawn again,
    from the same generator, so the case stays a function of the pair."""
    from controller.errors import InputError
    from scenarios.scenario_file import parse_scenario

    rng = np.random.default_rng([seed, index])
    for _ in range(50):
        case = _draw(rng, seed, index, perception)
        if case is None:  # a kayak that would end its drift across the way
            continue
        try:
            parse_scenario(case.text, f"{case.name}.toml")
        except InputError:
            continue
        return case
    raise RuntimeError(f"fuzz: no valid case {index} of seed {seed} in 50 draws")


def _draw(rng, seed: int, index: int, perception: str) -> Case | None:
    """Case `index` from `rng`, or None where a drifting kayak would end its drift across
    the way (the case is drawn again)."""
    width = float(np.round(rng.uniform(12.0, 40.0), 1))
    junction = bool(rng.uniform() < 0.4)
    bend_deg = 0.0 if junction else float(np.round(rng.uniform(-45.0, 45.0), 1))
    leg = float(np.round(rng.uniform(90.0, 140.0)))  # the first leg: where the bend or mouth is
    length = leg + 170.0
    side = int(rng.choice([-1, 1]))  # the side canal's (or the moored boats') side: +1 east
    moored = bool(rng.uniform() < 0.35)
    current = float(np.round(rng.uniform(0.0, 0.5), 2)) if rng.uniform() < 0.5 else 0.0
    current_dir = float(rng.uniform(-np.pi, np.pi))
    n_vessels = int(rng.choice([1, 2, 3], p=[0.5, 0.35, 0.15]))
    kinds = []
    for _ in range(n_vessels):
        pool = [k for k in KINDS if (k != "crossing" or junction) and k not in kinds]
        kinds.append(str(rng.choice(pool)))
    if perception == "mixed":
        perception = str(rng.choice(["lidar", "known-walls"]))
    canal = _Canal(width, leg, length, bend_deg, junction, side)
    place = "junction" if junction else ("bend" if abs(bend_deg) >= 10 else "open")
    lines = ["[scenario]", f"name = {toml_value(f'fuzz-{seed}-{index:04d}')}"]
    body, obstacles = canal.toml(), []
    if moored:
        obstacles = canal.moored_boats(rng)
        if place == "open":
            place = "moored boat"
    # scripted vessels do not avoid each other: one met or overtaken keeps beside a barge
    # followed in mid-channel by construction (and the two on their own sides of the centre
    # line), or is left out where the canal has no room
    beside = BARGE_HALF_BEAM_M + VESSEL_GAP_M if "followed" in kinds else (
        0.5 * VESSEL_GAP_M if {"meeting", "overtaken"} <= set(kinds) else 0.0)
    vessels, names, duration, kept = [], [], 0.0, []
    for k, kind in enumerate(kinds):
        drawn = _vessel(kind, k, canal, rng, place, beside)
        if drawn is None:
            continue
        text, end_s = drawn
        vessels.append(text)
        names.append(f"{kind}-{k}")
        kept.append(kind)
        duration = max(duration, end_s)
    duration = max(duration, (canal.route_length + 20.0) / SPEED_MPS * 1.6 + 30.0)
    vessels, names, kinds, waited = _give_way(vessels, names, kept, duration, index)
    duration += waited
    if not _kayaks_end_clear(vessels, kinds, canal, moored, duration, index):
        return None
    lines.insert(0, f"# canalnav fuzz case {index} of seed {seed}: {', '.join(kinds)} at the "
                    f"{place}")
    lines += [f"duration_s = {math.ceil(duration)}", f"seed = {index}", ""]
    lines += body + obstacles
    if current > 0:
        lines += ["[current]", f"north_mps = {current * math.cos(current_dir):.3f}",
                  f"east_mps = {current * math.sin(current_dir):.3f}", ""]
    lines += vessels
    lines += ["[sensors]", f"perception = {toml_value(perception)}", "",
              "[controller]", 'type = "nmpc"', "d_p_m = 2.0", ""]
    return Case(f"case-{index:04d}", "\n".join(lines), tuple(kinds), place, width, perception,
                tuple(names), waited)


class _Canal:
    """The canal of a case: a first leg along north from (0, 0), then a second leg turned by
    the bend (or, with a side canal, straight on, the side canal opening at the leg's end)."""

    def __init__(self, width, leg, length, bend_deg, junction, side):
        self.width, self.leg, self.length = width, leg, length
        self.bend = math.radians(bend_deg)
        self.junction, self.side = junction, side
        self.mouth_m = min(max(0.8 * width, 12.0), 20.0)  # the side canal's width

    @property
    def corner(self) -> np.ndarray:
        return np.array([self.leg, 0.0])

    def at(self, s: float, offset: float = 0.0) -> np.ndarray:
        """The point `s` metres along the centre line, `offset` to the east of it (to the
        right of the way north)."""
        if s <= self.leg or self.junction:
            return np.array([s, offset])
        d = np.array([math.cos(self.bend), math.sin(self.bend)])
        n = np.array([-d[1], d[0]])
        return self.corner + (s - self.leg) * d + offset * n

    def turn(self, offset: float) -> list:
        """Where a line `offset` east of the centre line turns at the first leg's end: the
        two offset legs' meeting point (the centre line's points a metre either side of
        the corner, offset, would step back on the inside of the bend)."""
        if self.junction:
            return [self.at(self.leg - 1.0, offset), self.at(self.leg + 1.0, offset)]
        n0 = np.array([0.0, 1.0])
        n1 = np.array([-math.sin(self.bend), math.cos(self.bend)])
        return [self.corner + offset * (n0 + n1) / (1.0 + float(n0 @ n1))]

    def offset(self, xy) -> float:
        """How far east of the centre line (to the right of the way north) `xy` lies: from
        the second leg past the bend, else from the first."""
        p = np.asarray(xy, float)
        if not self.junction and self.bend:
            d = np.array([math.cos(self.bend), math.sin(self.bend)])
            if float((p - self.corner) @ d) > 0.0:
                return float((p - self.corner) @ np.array([-d[1], d[0]]))
        return float(p[1])

    def heading(self, s: float) -> float:
        return 0.0 if s <= self.leg or self.junction else self.bend

    @property
    def route_length(self) -> float:
        return self.length - 15.0

    def toml(self) -> list[str]:
        end = self.at(self.length)
        if not self.junction:
            return ["[canal]", f"centre_line = {_points([[0, 0], self.corner, end])}",
                    f"width_m = {self.width}", f"corner_radius_m = {max(self.width, 20.0)}", "",
                    "[route]",  # along the centre line, round the bend
                    f"waypoints = {_points([[0, 0], self.corner, self.at(self.route_length)])}",
                    ""]
        h, a, b = self.width / 2, self.leg - self.mouth_m / 2, self.leg + self.mouth_m / 2
        far = 60.0 * self.side
        walls = [("west", [[0, -h], [self.length, -h]], "left"),
                 ("east", [[0, h], [self.length, h]], "right")]
        near = "east" if self.side > 0 else "west"
        land = "right" if self.side > 0 else "left"
        walls = [w for w in walls if w[0] != near]
        y = h * self.side
        walls += [(f"{near} before the side canal", [[0, y], [a, y], [a, far]], land),
                  (f"{near} after the side canal", [[b, far], [b, y], [self.length, y]], land)]
        out = ["[canal]", f"centre_line = {_points([[0, 0], [self.length, 0]])}", ""]
        for name, pts, side in walls:
            out += ["[[canal.wall]]", f"name = {toml_value(name)}", f"points = {_points(pts)}",
                    f"land_side = {toml_value(side)}", ""]
        out += ["[route]", f"waypoints = {_points([[0, 0], [self.route_length, 0]])}", ""]
        return out

    def moored_boats(self, rng) -> list[str]:
        """Two or three boats moored along the quay of the far side from the side canal,
        ahead of the first leg's end (where encounters are timed)."""
        out, s = [], self.leg - float(rng.uniform(5.0, 30.0))
        side = -self.side
        for k in range(int(rng.integers(2, 4))):
            length, beam = float(rng.uniform(8.0, 16.0)), float(rng.uniform(2.2, 3.2))
            inner = self.width / 2 - 0.3
            if inner - beam < 5.0:  # too narrow a canal to moor and pass: none
                break
            a, b = self.at(s, side * inner), self.at(s + length, side * inner)
            c, d = self.at(s + length, side * (inner - beam)), self.at(s, side * (inner - beam))
            out += ["[[obstacle]]", f"name = {toml_value(f'moored boat {k + 1}')}",
                    'kind = "boat"', f"outline = {_points([a, b, c, d])}",
                    f"z_top_m = {float(rng.uniform(0.9, 1.8)):.2f}", ""]
            s += length + float(rng.uniform(2.0, 10.0))
        return out


def _vessel(kind: str, k: int, canal: _Canal, rng, place: str,
            beside_m: float = 0.0) -> tuple[str, float] | None:
    """A vessel's [[vessel]] table, timed to meet the own boat at the first leg's end (the
    bend, the mouth, the moored boats), and when its run ends. `beside_m` > 0: a barge is
    followed in mid-channel, and a vessel met or overtaken keeps its side this far (plus its
    half beam) off the centre line, or is not drawn (None) where the canal leaves no room."""
    s_meet = canal.leg + float(rng.uniform(-15.0, 10.0))
    t_meet = s_meet / SPEED_MPS + 5.0  # the own boat's arrival (it starts from rest)
    w = canal.width
    name = f"{kind}-{k}"
    if kind == "meeting":  # the other way, on its own starboard side (our port)
        v = float(rng.uniform(1.0, 2.5))
        off = -float(rng.uniform(0.1, 0.3)) * w
        hull, beam = _hull(rng, 6.0, 14.0)
        off = _kept_apart(off, beam, w, beside_m)
        if off is None:
            return None
        s0 = min(s_meet + v * t_meet, canal.length - 5.0)
        pts = [canal.at(s0, off), *canal.turn(off)[::-1], canal.at(5.0, off)]
        if s0 <= canal.leg + 1.0:
            pts = [canal.at(s0, off), canal.at(5.0, off)]
        return _route(name, hull, pts, v, max(0.0, t_meet - (s0 - s_meet) / v)), \
            t_meet + 120.0
    if kind in ("overtaken", "followed"):  # the same way, slower, reached at the place
        v = float(rng.uniform(0.6, 1.2)) if kind == "overtaken" else float(rng.uniform(0.5, 0.9))
        off = float(rng.uniform(0.1, 0.25)) * w if kind == "overtaken" else 0.0
        s0 = max(s_meet - v * t_meet, 30.0)
        hull, beam = _hull(rng, 6.0, 12.0) if kind == "overtaken" else _hull(rng, 20.0, 30.0,
                                                                             barge=True)
        if kind == "overtaken":
            off = _kept_apart(off, beam, w, beside_m)
            if off is None:
                return None
        pts = [canal.at(s0, off), *canal.turn(off),
               canal.at(canal.length + 60.0, off)]  # on past the canal's end: the goal clears
        if s0 >= canal.leg - 1.0:
            pts = [canal.at(s0, off), canal.at(canal.length + 60.0, off)]
        end_s = (canal.route_length + 45.0 - s0) / v + 30.0  # it clears the goal, with a gap
        return _route(name, hull, pts, v, 0.0), end_s
    if kind == "crossing":  # out of the side canal, across our course, then up the canal
        v = float(rng.uniform(1.0, 2.0))
        x = canal.leg + float(rng.uniform(-0.25, 0.25)) * canal.mouth_m
        y0, y1 = 55.0 * canal.side, -0.25 * canal.width * canal.side
        path = abs(y0)
        pts = [[x, y0], [x, y1], [x + 0.5 * canal.width, y1], [canal.length + 60.0, y1]]
        return _route(name, _hull(rng, 5.0, 10.0)[0], pts, v, max(0.0, t_meet - path / v)), \
            t_meet + 90.0
    # drifting: a kayak wandering near the place, from a quay
    y = canal.side * (w / 2 - 2.0)  # (the moored boats are on the other side)
    p = canal.at(s_meet + float(rng.uniform(0.0, 20.0)), y)
    course = math.degrees(canal.heading(s_meet)) + (90.0 if y < 0 else -90.0) + float(
        rng.uniform(-30.0, 30.0))
    v = float(rng.uniform(0.3, 0.7))
    distance = max(4.0, w - 6.0)
    rest_at, rest_s = float(rng.uniform(0.3, 0.7)) * distance, float(rng.uniform(*KAYAK_REST_S))
    lines = ["[[vessel]]", f"name = {toml_value(name)}", "[vessel.hull]", "length_m = 3.5",
             "beam_m = 0.8", "height_m = 0.6", 'shape = "pointed"', "[vessel.course]",
             f"x_m = {p[0]:.2f}", f"y_m = {p[1]:.2f}", f"course_deg = {course:.1f}",
             f"speed_mps = {v:.2f}", f"start_s = {max(0.0, t_meet - 20.0):.1f}",
             f"wander_degps = {float(rng.uniform(0.0, 15.0)):.1f}",
             f"distance_m = {distance:.1f}", f"waits = [[{rest_at:.1f}, {rest_s:.1f}]]", ""]
    return "\n".join(lines), t_meet + 90.0 + rest_s


def _kayaks_end_clear(vessels: list, kinds: list, canal: "_Canal", moored: bool,
                      duration: float, seed: int) -> bool:
    """Every drifting kayak ends its drift (its wandering course run out) leaving a gap of
    at least `KAYAK_CLEAR_GAP_M` on one side, its hull turned any way and the moored boats
    counted: a kayak may rest across the way, but one that stopped there for good would
    block the canal, an obstruction rather than an encounter, and no goal could be reached."""
    half = canal.width / 2
    for k, (text, kind) in enumerate(zip(vessels, kinds)):
        if kind != "drifting":
            continue
        table = tomllib.loads(text)["vessel"][0]
        end = _moved(table, 0.0, duration, seed, k).poses[-1, :2]
        off = canal.offset(end)
        reach = 0.5 * math.hypot(table["hull"]["length_m"], table["hull"]["beam_m"])
        moored_side = -canal.side if moored else 0  # +1: the moored boats are to the east
        east = half - off - reach - (MOORED_ALLOWANCE_M if moored_side > 0 else 0.0)
        west = half + off - reach - (MOORED_ALLOWANCE_M if moored_side < 0 else 0.0)
        if abs(off) < half and max(east, west) < KAYAK_CLEAR_GAP_M:
            return False
    return True


def _give_way(vessels: list, names: list, kinds: list, duration: float, seed: int):
    """The vessels with each, in turn, started later (by `GIVE_WAY_STEP_S` at a time, up to
    `GIVE_WAY_MAX_S`) until its hull keeps `VESSEL_GAP_M` from those before it all the run,
    sampled every half second; one that cannot is left out. (tables, names, kinds, and the
    longest wait: the run is made that much longer)"""
    run_s = duration + GIVE_WAY_MAX_S
    times = np.arange(0.0, run_s, 0.5)
    kept: list = []  # (text, name, kind, vessel, centres, radius)
    waited = 0.0
    for text, name, kind in zip(vessels, names, kinds):
        table = tomllib.loads(text)["vessel"][0]
        for delay in np.arange(0.0, GIVE_WAY_MAX_S + 1e-9, GIVE_WAY_STEP_S):
            mine = _moved(table, float(delay), run_s, seed, len(kept))
            centres = np.column_stack([np.interp(times, mine.times, mine.poses[:, i])
                                       for i in (0, 1)])
            radius = 0.5 * math.hypot(mine.hull.length_m, mine.hull.beam_m)
            if all(_apart(mine, centres, radius, k[3], k[4], k[5], times) for k in kept):
                later = re.sub(r"start_s = ([0-9.]+)",
                               lambda m: f"start_s = {float(m.group(1)) + delay:.1f}", text,
                               count=1) if delay else text
                kept.append((later, name, kind, mine, centres, radius))
                waited = max(waited, float(delay))
                break
    return [k[0] for k in kept], [k[1] for k in kept], [k[2] for k in kept], waited


def _moved(table: dict, delay: float, duration_s: float, seed: int, index: int):
    """The `index`-th [[vessel]] table's vessel, started `delay` later, as the scenario file
    with `seed` makes it."""
    from scenarios.scenario_file import vessel_from_table

    motion = "route" if "route" in table else "course"
    start = table[motion].get("start_s", 0.0) + delay
    later = {**table, motion: {**table[motion], "start_s": start}}
    return vessel_from_table(later, index, duration_s, seed)


def _apart(a, centres_a, radius_a, b, centres_b, radius_b, times) -> bool:
    """Vessels a and b keep more than `VESSEL_GAP_M` hull to hull at every one of `times`
    (outlines compared only where their centres come near)."""
    from scenarios.results.encounters import polygon_distance

    near = np.hypot(*(centres_a - centres_b).T) <= radius_a + radius_b + VESSEL_GAP_M
    return all(polygon_distance(a.outline_at(t), b.outline_at(t)) > VESSEL_GAP_M
               for t in times[near])


def _hull(rng, lo: float, hi: float, barge: bool = False) -> tuple[list[str], float]:
    """A hull's [vessel.hull] lines and its beam."""
    length = float(rng.uniform(lo, hi))
    beam = round(length / (5.0 if barge else 3.2), 1)
    return ["[vessel.hull]", f"length_m = {length:.1f}", f"beam_m = {beam:.1f}",
            f"height_m = {1.8 if barge else 1.4}",
            f"shape = {toml_value('rectangle' if barge else 'pointed')}"], beam


def _kept_apart(off: float, beam: float, width: float, beside_m: float) -> float | None:
    """The offset `off` (its sign kept) moved out to `beside_m` plus half the `beam` from the
    centre line (clear of a barge there, or of a vessel on the other side), and no nearer the
    quay than VESSEL_GAP_M; None where both do not fit."""
    if beside_m <= 0.0:
        return off
    least, most = beside_m + 0.5 * beam, 0.5 * width - 0.5 * beam - VESSEL_GAP_M
    if least > most:
        return None
    return math.copysign(min(max(abs(off), least), most), off)


def _route(name: str, hull: list[str], pts, speed: float, start_s: float) -> str:
    return "\n".join(["[[vessel]]", f"name = {toml_value(name)}", *hull, "[vessel.route]",
                      f"waypoints = {_points(pts)}", f"speed_mps = {speed:.2f}",
                      f"start_s = {start_s:.1f}", ""])


def _points(pts) -> str:
    return "[" + ", ".join(f"[{float(p[0]):.2f}, {float(p[1]):.2f}]" for p in pts) + "]"


# -- judging -------------------------------------------------------------------------------
@dataclass(frozen=True)
class Verdict:
    """What one run of a case showed, from its summary (true poses)."""

    case: str
    passed: bool
    why: str  # "" or the worst thing that happened
    severity: int  # 0 passed; larger is worse
    reached_goal: bool
    min_hull_m: float | None  # least hull-to-hull distance to any vessel
    min_clearance_m: float | None
    fallback_steps: int
    wall_tracks: int
    elastic_steps: int
    longest_wall_track_s: float = 0.0  # the LiDAR's tracks on a true wall (0: none)
    most_id_switches: int = 0  # the most track id changes of any one vessel
    swing_while_waiting_m: float = 0.0  # way made to and fro over the ground while waiting


def judge(case: str, row: dict, summary: dict | None, min_hull_m: float = 2.0) -> Verdict:
    """The fuzz's rule for one run: no exception, controller failure or collision, and at
    least `min_hull_m` from every vessel's hull."""
    s = summary or {}
    hulls = [v.get("min_hull_distance_m") for v in s.get("vessels", [])
             if v.get("min_hull_distance_m") is not None]
    least = min(hulls) if hulls else None
    why, severity = "", 0
    if row.get("status") != "ok":
        why, severity = f"exception: {row.get('error', '')}"[:200], 5
    elif row.get("controller_failed"):
        why, severity = f"controller failed: {s.get('status', '')}"[:200], 4
    elif row.get("collision"):
        why, severity = s.get("status", "collision"), 3
    elif least is not None and least < min_hull_m:
        why, severity = f"{least:.2f} m hull to hull (< {min_hull_m} m)", 2
    tracking = s.get("tracking") or {}
    return Verdict(case, severity == 0, why, severity, bool(s.get("reached_goal")), least,
                   s.get("min_clearance_m"), int(s.get("fallback_steps") or 0),
                   int(tracking.get("wall_tracks") or 0),
                   int((s.get("elastic") or {}).get("steps") or 0),
                   float(tracking.get("longest_wall_track_s") or 0.0),
                   max((int(n) for n in (tracking.get("id_switches") or {}).values()),
                       default=0),
                   float(s.get("swing_while_waiting_m") or 0.0))


def tracking_bar(verdicts: list[Verdict]) -> dict:
    """Issue 34's tracking bar over the cases: how many have a track on a wall for more than
    1 s or a vessel whose track id changed more than once, and the worst of each."""
    return {
        "cases_with_a_wall_track_over_1_s": sum(v.longest_wall_track_s > 1.0 for v in verdicts),
        "longest_wall_track_s": max((v.longest_wall_track_s for v in verdicts), default=0.0),
        "cases_with_a_vessel_over_1_id_switch": sum(v.most_id_switches > 1 for v in verdicts),
        "most_id_switches": max((v.most_id_switches for v in verdicts), default=0)}


def verdict_record(v: Verdict) -> dict:
    """What fuzz.json keeps of a verdict, for a later run to compare against (`--against`)."""
    return {"case": v.case, "passed": v.passed, "why": v.why, "reached_goal": v.reached_goal,
            "min_hull_m": v.min_hull_m}


def changes_against(before: list[dict], verdicts: list[Verdict]) -> dict:
    """The cases run both times whose outcome changed, from `before` (`verdict_record`s of an
    earlier run of the same seed) to `verdicts`: failing now and not before, the other way
    round, and the goal lost or reached; each entry "case: before -> now"."""
    old = {r["case"]: r for r in before}
    out = {"common_cases": 0, "newly_failing": [], "no_longer_failing": [], "goal_lost": [],
           "goal_reached": []}

    for v in sorted(verdicts, key=lambda v: v.case):
        r = old.get(v.case)
        if r is None:
            continue
        out["common_cases"] += 1
        if r["passed"] != v.passed:
            key = "no_longer_failing" if v.passed else "newly_failing"
            out[key].append(f"{v.case}: {r['why'] or 'passed'} -> {v.why or 'passed'}")
        if r["reached_goal"] != v.reached_goal:
            out["goal_reached" if v.reached_goal else "goal_lost"].append(
                f"{v.case}: {'goal' if r['reached_goal'] else 'no goal'} -> "
                f"{'goal' if v.reached_goal else 'no goal'}")
    return out


def conformance(cases: list[Case], summaries: dict) -> dict:
    """Per encounter kind: how the vessels were passed (the side, from the true poses) and,
    for meetings, the share of the meeting spent in the starboard half."""
    out: dict = {}
    for case in cases:
        s = summaries.get(case.name) or {}
        by_name = {v.get("name"): v for v in s.get("vessels", [])}
        for kind, name in zip(case.kinds, case.vessels):
            v = by_name.get(name)
            if v is None:
                continue
            k = out.setdefault(kind, {"encounters": 0, "passed_on": {}, "starboard_half": []})
            k["encounters"] += 1
            side = str(v.get("passed_on"))
            k["passed_on"][side] = k["passed_on"].get(side, 0) + 1
            if v.get("starboard_half_while_meeting") is not None:
                k["starboard_half"].append(float(v["starboard_half_while_meeting"]))
    for k in out.values():
        share = k.pop("starboard_half")
        k["mean_starboard_half_while_meeting"] = round(float(np.mean(share)), 3) if share else None
    return out


def report_markdown(verdicts: list[Verdict], cases: dict, out_dir: str, seed: int,
                    conform: dict, wall_s: float, against: tuple[str, dict] | None = None,
                    overrides=()) -> str:
    """report.md: the failures worst first, each with the command that reproduces it, then
    the figures; with `against` (an earlier run's folder and `changes_against`), the cases
    whose outcome changed since; `overrides` ((path, value) pairs) are named at the top."""
    failed = sorted((v for v in verdicts if not v.passed), key=lambda v: (-v.severity, v.case))
    n = len(verdicts)
    goal = sum(v.reached_goal for v in verdicts)
    hulls = [v.min_hull_m for v in verdicts if v.min_hull_m is not None]
    lines = [f"# canalnav fuzz, seed {seed}: {n} cases, {len(failed)} failed", "",
             f"- wall time {wall_s:.0f} s; goal reached {goal} of {n}"
             f" ({100.0 * goal / max(n, 1):.1f} %)",
             f"- least hull to hull over all cases: "
             f"{min(hulls):.2f} m" if hulls else "- no vessel came near", ""]
    if overrides:
        lines[-1:-1] = ["- every case run with " + ", ".join(
            f"`--set {p}={toml_value(v)}`" for p, v in overrides)]
    if against is not None:
        where, ch = against
        lines += [f"## Against {where} ({ch['common_cases']} cases run both times)", ""]
        for key, title in (("newly_failing", "failing now"), ("no_longer_failing",
                                                             "no longer failing"),
                           ("goal_lost", "goal lost"), ("goal_reached", "goal reached")):
            lines.append(f"- {title}: " + ("; ".join(ch[key]) if ch[key] else "none"))
        lines.append("")
    if failed:
        lines += ["## Failures, worst first", "", "| case | what | kinds | place | command |",
                  "| --- | --- | --- | --- | --- |"]
        for v in failed:
            c = cases[v.case]
            lines.append(f"| {v.case} | {v.why} | {', '.join(c.kinds)} | {c.place} | "
                         f"`canalnav run {out_dir}/cases/{v.case}.toml` |")
        lines.append("")
    lines += ["## Rules of the road, per encounter kind", "", "| kind | encounters | passed on |"
              " mean starboard half while meeting |", "| --- | --- | --- | --- |"]
    for kind, k in sorted(conform.items()):
        sides = ", ".join(f"{s}: {c}" for s, c in sorted(k["passed_on"].items()))
        lines.append(f"| {kind} | {k['encounters']} | {sides} | "
                     f"{k['mean_starboard_half_while_meeting']} |")
    lidar = [v for v in verdicts if cases[v.case].perception == "lidar"]
    if lidar:
        bar = tracking_bar(lidar)
        longest = max(lidar, key=lambda v: v.longest_wall_track_s)
        switches = max(lidar, key=lambda v: v.most_id_switches)
        lines += ["", "## Tracks that mean boats (LiDAR cases)", "",
                  f"- {len(lidar)} cases; a track on a wall for more than 1 s in "
                  f"{bar['cases_with_a_wall_track_over_1_s']}, the longest "
                  f"{bar['longest_wall_track_s']:.1f} s ({longest.case})",
                  f"- a vessel's track id changed more than once in "
                  f"{bar['cases_with_a_vessel_over_1_id_switch']}, at most "
                  f"{bar['most_id_switches']} times ({switches.case})"]
    waited = [v for v in verdicts if v.swing_while_waiting_m > 0.0]
    if waited:
        most = max(waited, key=lambda v: v.swing_while_waiting_m)
        lines += ["", "## Waiting", "",
                  f"- swung to and fro more than 10 m while waiting in "
                  f"{sum(v.swing_while_waiting_m > 10.0 for v in verdicts)} cases, the most "
                  f"{most.swing_while_waiting_m:.1f} m ({most.case}); over all cases "
                  f"{sum(v.swing_while_waiting_m for v in verdicts):.1f} m"]
    lines += ["", "## Every case", "", "| case | passed | goal | least hull m | clearance m |"
              " fallback steps | wall tracks | longest wall track s | most id switches |"
              " elastic steps | swing while waiting m | kinds | place | perception |",
              "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
              " --- |"]
    for v in sorted(verdicts, key=lambda v: v.case):
        c = cases[v.case]
        hull = "" if v.min_hull_m is None else f"{v.min_hull_m:.2f}"
        clear = "" if v.min_clearance_m is None else f"{v.min_clearance_m:.2f}"
        lines.append(f"| {v.case} | {'yes' if v.passed else 'NO'} | "
                     f"{'yes' if v.reached_goal else 'no'} | {hull} | {clear} | "
                     f"{v.fallback_steps} | {v.wall_tracks} | {v.longest_wall_track_s:.1f} | "
                     f"{v.most_id_switches} | {v.elastic_steps} | "
                     f"{v.swing_while_waiting_m:.1f} | "
                     f"{', '.join(c.kinds)} | {c.place} | {c.perception} |")
    return "\n".join(lines) + "\n"
