"""Tracking of other vessels in the LiDAR cloud (issue 17), in the style of SORT.

Each scan: the points no wall explains are clustered (`clusters`); each track predicts with
a constant-velocity Kalman filter (filterpy), state [x, y, vx, vy] in the inertial NED frame;
clusters are assigned to tracks by the Hungarian method (`scipy.optimize.
linear_sum_assignment`) on the Mahalanobis distance, gated; a matched track is updated, an
unmatched cluster starts a tentative track, confirmed after `confirm_hits` hits within its
first `confirm_window` scans once it shows a hull (below); a track dies after `max_misses`
scans or `max_coast_s` unseen, or when it leaves the view; one confirmed where a confirmed
track died lately takes that one's id (`_reacquire`). Two vessels passing close make one
cluster: one that two moving tracks' predicted outlines claim is split between them
(`clusters.split_by_outlines`). A moving track whose vessel turned (a route's corner) has
its anchored measure fall outside the gate: a cluster that fits inside its outline is taken
all the same, with the covariance grown (`_manoeuvres`).

What a cluster measures. The points lie on the faces turned to the sensor, so the box around
them is partial: an L, a line, a bow alone. The tracker keeps the vessel's extent along and
across its axis as the largest seen (at least a small boat's, `prior_length_m` x
`prior_width_m`; under way, at least `prior_aspect` times as long as wide) and measures the
centre axis by axis from the ends that are the vessel's own: where the crop did not cut it,
the scan saw through the water just beyond it (`clusters.free_space`) and no detected
segment runs on past it. An end hidden behind something nearer, or where the face goes on
out of the height band or between the beams' rings, moves with the own boat, not with the
vessel, and is not used. From both ends where the whole extent is seen, else from the one
nearest the sensor, half the extent away; along an axis with no end of its own the filter
predicts. So until a vessel has shown its whole length its centre lies nearer the sensor
than the truth, by half the part not yet seen (a boat seen bow-on is placed half its
assumed length behind its bow): the near end, the one a collision is about, is right. When
more of it appears the extent grows and the centre moves with it, away from the end it is
measured from, and the velocity does not change (the hidden part was always there).

Static things (a piece of quay, a pier, a moored boat) are clusters too. They are tracked,
and `moving` turns on only after `moving_hits` updates in a row in which the speed, along
the directions the update measured, is above `moving_mps` and significant given the
covariance (chi-square), and off after as many without; a track that is not moving is an
obstacle like a wall, and its segments stay in `static_segments`. Along an axis whose ends
it has not shown for `unseen_hold_s`, a track at rest is held at rest (a velocity prior of
0): a piece of quay seen without its ends would otherwise keep for good a speed one glitch
gave it, its position drifting along the quay until it took some other cluster as itself.

Hull evidence. A piece of quay seen through a side canal's mouth or at a corner makes a
cluster as well, and the way its visible part grows with the own boat's motion can even look
like motion. What a hull has and a piece of wall has not is an outline of its own: along
some axis, water seen beyond both ends (or beyond the far one only in the object's own
shadow), where a wall goes on into the next wall or behind the corner that hides it. A track
is confirmed when moving, or after `confirm_hits` such clusters; one at rest is handed on
only while such a cluster came within the last `hull_hold_s`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from functools import lru_cache

import numpy as np

from ..errors import InputError
from ..geometry import wrap_angle
from . import wall_cells
from .clusters import Clusters, find_clusters, free_space, half_turn as _half_turn, remember_walls
from ..kernels import pointer
from .cloud_crop import crop_kernel
from .detection import DEFAULT, DetectionConfig, crop_rows


@dataclass(frozen=True)
class TrackerConfig:
    """Thresholds of the tracker, SI units. The crop and the view's range are detection's."""

    detection: DetectionConfig = DEFAULT
    # Clusters (see clusters.py).
    max_vessel_length_m: float = 40.0  # longer segments, chains and clusters are walls
    wall_margin_m: float = 0.3  # points this close to a wall are the wall's
    wall_cell_m: float = 0.1  # grid the walls are drawn into
    wall_extend_m: float = 3.0  # a wall's line claims its points this far beyond its ends
    chain_gap_m: float = 1.0  # segment ends this close, ...
    chain_angle_deg: float = 20.0  # ... at most this angle apart, make one wall
    cell_m: float = 0.5  # clustering grid
    min_points: int = 5  # fewest points of a cluster
    edge_m: float = 1.0  # hull corners this close to the crop's edges are cut off there
    collinear_deg: float = 3.0  # a segment this parallel on a wall's line is the wall
    occluder_top_m: float = 3.0  # returns up to this height hide what lies behind them
    free_step_m: float = 1.0  # an end is the object's if the scan saw through this far beyond
    free_margin_m: float = 0.5  # ... it (the nearest return there this much farther, or none)
    hull_spread_bins: int = 1  # ... for hull evidence, in its bearing bin and this many aside
    # Where the LiDARs sit, (x_m, y_m, height_m above the water) in the body frame: free
    # space is judged from each, the own hull's returns (in detection's hull box) cutting the
    # sight lines they stand in (a bow unit does not see the water behind the cabin). ()
    # when not known: judged from the boat's origin with the hull's box cropped out, where a
    # bearing the hull shadows looks like open water.
    viewpoints: tuple = ()
    # Filter.
    accel_sigma_mps2: float = 0.3  # white acceleration (small boats, erratic kayaks)
    meas_sigma_m: float = 0.1  # a seen end or side of a vessel
    anchor_sigma_m: float = 0.2  # more, where the centre is half an extent from one end
    init_speed_sigma_mps: float = 2.0  # a new track's velocity (0 +- this)
    gate_chi2: float = 13.8  # Mahalanobis gate (99.9 % of chi-square, 2 dof)
    # A moving track that the gate left without a cluster takes one that fits inside its
    # predicted outline up to this far out (a turn: `VesselTracker._manoeuvres`).
    manoeuvre_chi2: float = 69.0
    full_view_m: float = 0.5  # seen within this of the extent: both ends are in view
    extent_growth_m: float = 1.0  # the extent grows by at most this per scan (merges)
    prior_length_m: float = 3.0  # a small boat's extent until more is seen
    prior_width_m: float = 1.0
    prior_aspect: float = 3.0  # a moving hull is at least this many times as long as wide
    align_gain: float = 0.3  # how fast the axis follows the hull's sides
    realign_deg: float = 10.0  # a side this far off the axis replaces it (a wrong first guess)
    course_sigma_deg: float = 10.0  # a course known this well picks which side is the length
    # Life.
    confirm_hits: int = 3
    confirm_window: int = 5  # scans from birth in which to gather confirm_hits
    tentative_misses: int = 2  # a tentative track dies after this many misses in a row
    max_misses: int = 10  # a confirmed track after this many scans unseen ...
    max_coast_s: float = 1.5  # ... or this long without a hit (scans missing or not)
    # Motion.
    moving_mps: float = 0.3
    # A track at rest whose ends along one of its axes were last seen `unseen_hold_s` ago
    # is held at rest along that axis: a velocity of 0 +- `unseen_speed_sigma_mps` measured
    # at each hit (None: no such prior). A piece of wall seen without its ends shows no
    # motion along the wall, so a velocity one glitch gave it stayed for good: one drifted
    # 18 s at 0.3-0.4 m/s along a quay, its position spreading along the quay with it, till
    # it took a cluster 12.7 m on and became a vessel moving at 0.9 m/s for 27 s. (A boat
    # alongside, its ends cut off by the own hull's box, keeps what it showed that long.)
    unseen_speed_sigma_mps: float | None = 0.3
    unseen_hold_s: float = 3.0
    moving_chi2: float = 13.8  # v' P_vv^-1 v: speed significant given the covariance
    moving_hits: int = 5  # updates in a row passing (failing) the test to turn on (off)
    # Hull evidence: a track is confirmed when moving, or after confirm_hits clusters that
    # closed an outline of their own (both ends seen through beyond, along an axis); one at
    # rest is handed on only while such a cluster came within the last hull_hold_s.
    hull_hold_s: float = 1.0
    # Reacquiring: a track confirmed where a confirmed one died within reacquire_s takes its
    # id (the vessel went out of sight and came back), its prediction's reach grown by
    # reacquire_m beyond the covariance's (the centre of a part seen is a guess).
    reacquire_s: float = 6.0
    reacquire_m: float = 2.0
    segment_margin_m: float = 0.5  # a segment this close inside a moving vessel's box is its
    # Wall memory: lines of segments longer than any vessel seen in the last wall_memory_s
    # claim the pieces on them up to wall_reach_m beyond their ends (the quay between and
    # beyond moored boats; a wall's far end broken up at grazing angles).
    wall_memory_s: float = 30.0
    wall_reach_m: float = 120.0
    # Wall cells (`wall_cells`): where confident walls' returns fell, remembered this long,
    # taken every wall_cells_every_s; a cluster with this share of its points in them (or
    # next to them) is wall, whatever the wall's shape (a curved quay seen from afar);
    # a share above 1 turns the check off.
    wall_cells_m: float = 0.5
    wall_cells_memory_s: float = 300.0
    wall_cells_every_s: float = 1.0
    wall_cells_share: float = 0.6

    def __post_init__(self) -> None:
        if not isinstance(self.detection, DetectionConfig):
            raise InputError(f"tracker config: detection must be a DetectionConfig, got "
                             f"{type(self.detection).__name__}")
        counts = ("min_points", "confirm_hits", "confirm_window", "tentative_misses",
                  "max_misses", "moving_hits")
        self._check_viewpoints()
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in ("detection", "viewpoints") or (
                    f.name == "unseen_speed_sigma_mps" and v is None):
                continue
            if f.name in counts:
                if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                    raise InputError(f"tracker config: {f.name} must be a whole number >= 1, "
                                     f"got {v!r}")
            elif isinstance(v, bool) or not isinstance(v, (int, float)) \
                    or not math.isfinite(v) or v <= 0:
                raise InputError(f"tracker config: {f.name} must be a positive number, got {v!r}")
        if self.confirm_hits > self.confirm_window:
            raise InputError("tracker config: confirm_hits must not exceed confirm_window")

    def _check_viewpoints(self) -> None:
        try:
            points = np.asarray(self.viewpoints, float)
        except (TypeError, ValueError):
            points = None
        if points is None or not np.isfinite(points).all() or (
                points.size and (points.ndim != 2 or points.shape[1] != 3)):
            raise InputError(f"tracker config: viewpoints must be (x_m, y_m, height_m) rows "
                             f"of finite numbers (the LiDARs in the body frame, height above "
                             f"the water), got {self.viewpoints!r}")
        unique = dict.fromkeys(map(tuple, points.reshape(-1, 3).tolist()))  # in order, once
        object.__setattr__(self, "viewpoints", tuple(unique))


@dataclass(frozen=True, eq=False)
class Track:
    """One vessel as the tracker sees it (inertial NED frame, SI units)."""

    id: int
    position: np.ndarray  # (2,) m, the centre of the vessel's outline
    velocity: np.ndarray  # (2,) m/s
    heading_rad: float  # of the long axis; along the velocity when moving
    length_m: float  # extent along the heading
    width_m: float  # extent across it
    covariance: np.ndarray  # (4, 4) of [x, y, vx, vy]
    moving: bool  # speed above TrackerConfig.moving_mps with confidence
    hits: int
    misses: int  # scans in a row without a detection
    age_s: float
    first_seen_s: float
    confirmed_s: float  # NaN while tentative
    # known for a vessel: seen under way once (the tracker), or handed on as one (known
    # walls); at rest (a kayak stopped, a boat waiting) it is still passed as a vessel,
    # where a thing never seen moving (a moored boat, a pier) is an obstacle like a wall
    vessel: bool = False

    @property
    def confirmed(self) -> bool:
        return not math.isnan(self.confirmed_s)

    @property
    def speed_mps(self) -> float:
        return float(math.hypot(*self.velocity))

    @classmethod
    def from_truth(cls, id: int, position, velocity, heading_rad: float, length_m: float,
                   width_m: float, time_s: float = 0.0, moving_mps: float = 0.3,
                   sigma_m: float = 0.05, sigma_mps: float = 0.02,
                   under_way: bool = False) -> "Track":
        """A track from a true vessel state (the known-walls perception): exact, with a small
        covariance, confirmed; `moving` when the speed is above `moving_mps`, a `vessel`
        when moving or `under_way` before."""
        p = np.array(position, float).reshape(2)
        v = np.array(velocity, float).reshape(2)
        p.setflags(write=False)
        v.setflags(write=False)
        cov = np.diag([sigma_m ** 2, sigma_m ** 2, sigma_mps ** 2, sigma_mps ** 2])
        cov.setflags(write=False)
        moving = bool(math.hypot(*v) > moving_mps)
        return cls(int(id), p, v, float(heading_rad), float(length_m), float(width_m), cov,
                   moving, 1, 0, 0.0, float(time_s), float(time_s), moving or under_way)

    def as_record(self) -> dict:
        """Plain numbers for a log row (JSON-ready)."""
        return {"id": self.id, "x": float(self.position[0]), "y": float(self.position[1]),
                "vx": float(self.velocity[0]), "vy": float(self.velocity[1]),
                "heading_rad": self.heading_rad, "length_m": self.length_m,
                "width_m": self.width_m,
                "sigma_pos_m": float(math.sqrt(max(np.trace(self.covariance[:2, :2]), 0.0))),
                "sigma_vel_mps": float(math.sqrt(max(np.trace(self.covariance[2:, 2:]), 0.0))),
                "moving": self.moving, "vessel": self.vessel, "hits": self.hits,
                "misses": self.misses,
                "age_s": self.age_s, "first_seen_s": self.first_seen_s,
                "confirmed_s": None if math.isnan(self.confirmed_s) else self.confirmed_s}


@dataclass(frozen=True, eq=False)
class TrackerOutput:
    """One update's result. `status`: "ok", or why the scan was not used ("no_scan",
    "bad_points", "bad_pose", "bad_time"); the tracks are then predicted only."""

    time_s: float
    tracks: tuple  # confirmed tracks (Track)
    static_segments: np.ndarray  # (K, 4) the input segments not on a confirmed moving track
    tentative: int  # unconfirmed tracks
    clusters: int  # detections this scan
    status: str = "ok"


STATUSES = ("no_scan", "bad_points", "bad_pose", "bad_time", "dropped_points")


@lru_cache(maxsize=64)
def _transition(dt: float, accel_sigma: float):
    """F and Q of the constant-velocity model over dt (white acceleration), [x, y, vx, vy];
    cached: scans come at a steady rate."""
    from filterpy.common import Q_discrete_white_noise

    f = np.eye(4)
    f[0, 2] = f[1, 3] = dt
    q = Q_discrete_white_noise(2, dt, accel_sigma ** 2, block_size=2, order_by_dim=False)
    f.setflags(write=False)
    q.setflags(write=False)
    return f, q


def _mahalanobis2(y: np.ndarray, s: np.ndarray) -> float:
    """y' S^-1 y for a 2-vector and a 2x2 covariance (closed form; 0 if S is singular)."""
    a, b, c, d = float(s[0, 0]), float(s[0, 1]), float(s[1, 0]), float(s[1, 1])
    det = a * d - b * c
    if not det > 0:
        return 0.0
    y0, y1 = float(y[0]), float(y[1])
    return (d * y0 * y0 - (b + c) * y0 * y1 + a * y1 * y1) / det


class _Tracked:
    """One track: the Kalman filter, the vessel's axis and extent, and its life."""

    def __init__(self, id_, time_s, centre, cov, axis_rad, extent, cfg: TrackerConfig):
        from filterpy.kalman import KalmanFilter

        self.id = id_
        self.kf = KalmanFilter(dim_x=4, dim_z=2)
        self.kf.x = np.array([centre[0], centre[1], 0.0, 0.0])
        p = np.zeros((4, 4))
        p[:2, :2] = cov
        p[2, 2] = p[3, 3] = cfg.init_speed_sigma_mps ** 2
        self.kf.P = p
        self.kf.H = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])
        self.axis = float(axis_rad)  # direction of the long axis, mod pi
        self.extent = np.array(extent, float)  # along, across the axis
        self.hits, self.misses, self.scans = 1, 0, 1
        self.first_seen_s = self.last_hit_s = float(time_s)
        self.confirmed_s = math.nan
        self.moving, self._votes = False, 0
        self.vessel = False  # moving once (`Track.vessel`)
        # Clusters that closed its outline along an axis (both ends its own, `_real_ends`):
        # a hull; a piece of wall seen through a gap or at a corner goes on into the wall.
        self.hull_hits, self.hull_s = 0, -math.inf  # how many, the last one's time
        self.seen_box = None  # (u, v, lo, hi) of this scan's cluster, for static_segments
        self.seen_s = [float(time_s)] * 2  # an end last seen along the axis, across it

    def predict(self, dt: float, cfg: TrackerConfig) -> None:
        f, q = _transition(round(dt, 6), cfg.accel_sigma_mps2)
        self.kf.predict(F=f, Q=q)

    def align(self, angle: float, from_side: bool, cfg: TrackerConfig) -> bool:
        """Turn the long axis toward the hull side a cluster shows (of its two directions,
        the one nearer the course when moving, else the axis); True when the side was so
        far off that it replaced the axis (the extents then start again)."""
        if not from_side:
            return False
        course = self._course(cfg) if self.moving else None
        ref = self.axis if course is None else course
        cand = angle if abs(_half_turn(angle - ref)) <= math.pi / 4 else angle + math.pi / 2
        d = _half_turn(cand - self.axis)
        if abs(d) > math.radians(cfg.realign_deg):
            if abs(d) > math.pi / 4:
                self.extent = self.extent[::-1].copy()
            self.axis = float(_half_turn(cand))
            return True
        self.axis = float(_half_turn(self.axis + cfg.align_gain * d))
        return False

    def _course(self, cfg: TrackerConfig) -> float | None:
        """The course over ground, if the velocity gives it within `course_sigma_deg`."""
        vx, vy = self.kf.x[2:]
        speed = math.hypot(vx, vy)
        if speed <= 0:
            return None
        across = np.array([-vy, vx]) / speed
        sigma = math.sqrt(max(float(across @ self.kf.P[2:, 2:] @ across), 0.0)) / speed
        return math.atan2(vy, vx) if sigma <= math.radians(cfg.course_sigma_deg) else None

    def update(self, time_s, z, r, extent, shift, observed, cfg: TrackerConfig) -> None:
        """A detection: centre z with covariance r, the extent, the shift of the centre its
        growth implies, and the directions (rows) along which an end was seen."""
        self.kf.x[:2] += shift  # the extent grew: the centre moves, the velocity does not
        self.extent = extent
        self.kf.update(z, R=r)
        self._note_seen(time_s, observed)
        if not self.moving and cfg.unseen_speed_sigma_mps is not None:
            self._hold_unseen(time_s, cfg)
        self.hits += 1
        self.misses = 0
        self.last_hit_s = float(time_s)
        self._update_motion(observed, cfg)
        if not self.moving and self.extent[1] > self.extent[0]:  # the long axis is along
            self.axis = float(_half_turn(self.axis + math.pi / 2))
            self.extent = self.extent[::-1].copy()

    def _note_seen(self, time_s: float, observed) -> None:
        """When an end was last seen along the track's axis and across it (`observed`: the
        directions this detection measured)."""
        c, s = math.cos(self.axis), math.sin(self.axis)
        for row in np.asarray(observed, float).reshape(-1, 2):
            self.seen_s[0 if abs(row[0] * c + row[1] * s) >= math.sqrt(0.5) else 1] = time_s

    def _hold_unseen(self, time_s: float, cfg: TrackerConfig) -> None:
        """A velocity of 0 +- `unseen_speed_sigma_mps` measured along each axis of the track
        not seen for `unseen_hold_s`: what is at rest stays so where it is not seen."""
        stale = [i for i in (0, 1) if time_s - self.seen_s[i] > cfg.unseen_hold_s]
        if not stale:
            return
        from filterpy.kalman import update  # (the functional update: any measure's size)

        c, s = math.cos(self.axis), math.sin(self.axis)
        h = np.zeros((len(stale), 4))
        h[:, 2:] = np.array([[c, s], [-s, c]])[stale]
        self.kf.x, self.kf.P = update(self.kf.x, self.kf.P, np.zeros(len(stale)),
                                      np.eye(len(stale)) * cfg.unseen_speed_sigma_mps ** 2, h)

    def _update_motion(self, observed: np.ndarray, cfg: TrackerConfig) -> None:
        """The moving test, on the velocity along the directions this detection measured;
        no vote when they miss the course (a cluster whose ends along it are cut off or
        hidden says nothing of that motion)."""
        speed = math.hypot(*self.kf.x[2:])
        if not len(observed) or (speed > 0 and np.abs(observed @ self.kf.x[2:]).max()
                                 < math.cos(math.pi / 4) * speed):
            return  # (its course lies along no direction measured now)
        v = observed @ self.kf.x[2:]
        pv = observed @ self.kf.P[2:, 2:] @ observed.T
        if len(v) == 2:
            m2 = _mahalanobis2(v, pv)
        else:
            m2 = float(v[0] ** 2 / pv[0, 0]) if pv[0, 0] > 0 else 0.0
        passes = (self.hits >= cfg.confirm_hits and float(np.hypot.reduce(v)) >= cfg.moving_mps
                  and m2 >= cfg.moving_chi2)
        if passes != self.moving:
            self._votes += 1
            if self._votes >= cfg.moving_hits:
                self.moving, self._votes = passes, 0
                self.vessel = self.vessel or passes
                course = self._course(cfg)
                if passes and course is not None \
                        and abs(_half_turn(course - self.axis)) > math.pi / 3:
                    # A hull is longer than wide: seen bow-on at first, it turns its axis.
                    self.extent = self.extent[::-1].copy()
                    self.axis = float(_half_turn(self.axis + math.pi / 2))
        else:
            self._votes = 0

    def snapshot(self, time_s: float) -> Track:
        x = self.kf.x.copy()
        p = self.kf.P.copy()
        heading = float(_half_turn(self.axis))
        if self.moving and math.cos(heading) * x[2] + math.sin(heading) * x[3] < 0:
            heading = float(wrap_angle(heading + math.pi))
        pos, vel = x[:2], x[2:]
        for a in (pos, vel, p):
            a.setflags(write=False)
        return Track(self.id, pos, vel, heading, float(self.extent[0]), float(self.extent[1]),
                     p, self.moving, self.hits, self.misses, float(time_s - self.first_seen_s),
                     self.first_seen_s, self.confirmed_s, self.vessel)


class VesselTracker:
    """Tracks of the vessels in a sequence of scans; `update` once per scan (~10 Hz).

    Nothing a scan delivers makes it raise: no cloud, an empty one, NaN points, a NaN pose or
    a time that does not advance are counted in `counts` and the tracks are predicted only.
    Deterministic: the same inputs give the same tracks.
    """

    def __init__(self, config: TrackerConfig | None = None):
        self.config = config or TrackerConfig()
        det = self.config.detection
        self._occluder_crop = _tracker_crop(self.config)
        self._tracks: list[_Tracked] = []
        self._lost: list[_Tracked] = []  # confirmed tracks that died lately (`_reacquire`)
        self._next_id = 1
        self._time_s: float | None = None
        self.counts = dict.fromkeys(STATUSES, 0)  # over the run
        self._walls = np.zeros((0, 5))  # wall lines seen lately (clusters.remember_walls)
        self._cells = wall_cells.WallCells.empty()  # where walls were seen (wall_cells)
        # Imported now, not on the first scan with a cluster or the first birth (filterpy's
        # import takes a second or two): a perception worker builds its tracker while the
        # loop sets up, instead of stalling a scan in the run.
        from filterpy.common import Q_discrete_white_noise  # noqa: F401
        from filterpy.kalman import KalmanFilter  # noqa: F401
        from scipy.optimize import linear_sum_assignment  # noqa: F401

    @property
    def tracks(self) -> tuple:
        """All tracks, tentative ones included (confirmed_s NaN), for debugging and logs."""
        t = math.nan if self._time_s is None else self._time_s
        return tuple(k.snapshot(t) for k in self._tracks)

    def update(self, time_s, points, pose, segments=None, cropped: bool = False) -> TrackerOutput:
        """One scan: `points` (N, 3) body frame (x fwd, y stbd, z down) or None, `pose`
        (x, y, psi) of the boat in NED placing the cloud, `segments` (M, 4) the walls
        `detect_segments` found in the same cloud (x_c, y_c, theta, length). `cropped`:
        `points` is `crop_for_tracker` of a scan's cloud (empty: the scan had nothing in the crop, not
        no scan); the same tracks as from the whole cloud."""
        cfg = self.config
        segs = _clean_segments(segments)
        t = _finite_float(time_s)
        if t is None or (self._time_s is not None and t < self._time_s):
            self.counts["bad_time"] += 1
            return self._output(self._time_s, segs, 0, "bad_time")
        dt = 0.0 if self._time_s is None else t - self._time_s
        self._time_s = t
        if dt > 0:
            for k in self._tracks:
                k.predict(dt, cfg)
        status, cloud = _clean_cloud(points, allow_empty=cropped)
        p = _finite_pose(pose)
        if status == "dropped_points":  # some rows had NaN: counted, the rest used
            self.counts["dropped_points"] += 1
            status = "ok"
        if status == "ok" and p is None:
            status = "bad_pose"
        if status != "ok":
            self.counts[status] += 1
            self._end_of_life(t, p, scanned=False)
            return self._output(t, segs, 0, status)
        # The crop with a taller band: all of it can hide things (free_space), the
        # detection band of it is what the clusters are made of. (Columns one by one:
        # fast for the column-major clouds LiDAR drivers and the simulator deliver.) A
        # cropped cloud is that crop already (cropping it again keeps every point).
        if not cropped:
            cloud = crop_rows(cloud, self._occluder_crop)
        occluders, xy, hull = split_crop(cloud, cfg)
        collect = wall_cells.due(self._cells, t, cfg.wall_cells_every_s)
        found = find_clusters(xy, p, segs, cfg, self._walls, occluders, hull, self._cells,
                              collect, self._outlines())
        if collect:
            self._cells = wall_cells.remember(self._cells, found.wall_points, t,
                                              cfg.wall_cells_m, cfg.wall_cells_memory_s)
        self._walls = remember_walls(self._walls, segs[segs[:, 3] > cfg.max_vessel_length_m],
                                     t, cfg)
        self._associate(t, found, p)
        self._end_of_life(t, p, scanned=True)
        return self._output(t, segs, len(found), "ok")

    def _outlines(self) -> np.ndarray:
        """(T, 5) x, y, axis, length, width of the confirmed moving tracks, predicted to
        this scan: a cluster two of them claim is split between them (`find_clusters`),
        not taken for one vessel the size of both."""
        return np.array([(*k.kf.x[:2], k.axis, *k.extent) for k in self._tracks
                         if k.moving and not math.isnan(k.confirmed_s)]).reshape(-1, 5)

    # -- one scan ---------------------------------------------------------------------
    def _associate(self, t: float, found: Clusters, pose) -> None:
        from scipy.optimize import linear_sum_assignment

        cfg = self.config
        sensor = np.array(pose[:2], float)
        for k in self._tracks:
            k.seen_box = None
        n_t, n_c = len(self._tracks), len(found)
        cost = np.full((n_t, n_c), np.inf)
        meas = {}
        for a, k in enumerate(self._tracks):
            x = k.kf.x[:2]
            reach = 0.5 * (k.extent.max() + 0.0) + 3.0 * math.sqrt(max(np.trace(k.kf.P[:2, :2]), 0.0)) + 2.0
            near = np.flatnonzero(np.hypot(*(found.centre - x).T) <= reach + 0.5 * found.size[:, 0])
            for b in near.tolist():
                m = _measure(k, found, b, sensor, cfg)
                y = m[0] - (x + m[3])
                s = k.kf.P[:2, :2] + m[1]
                d2 = _mahalanobis2(y, s)
                if d2 <= cfg.gate_chi2:
                    cost[a, b] = d2
                    meas[a, b] = m
        used = np.zeros(n_c, bool)
        if meas:
            rows, cols = linear_sum_assignment(np.where(np.isfinite(cost), cost, 1e9))
            for a, b in zip(rows.tolist(), cols.tolist()):
                if (a, b) in meas:
                    self._hit(t, self._tracks[a], found, b, meas[a, b], sensor)
                    used[b] = True
        self._manoeuvres(t, found, used, sensor)
        for k in self._tracks:
            if k.seen_box is None:
                k.misses += 1
            k.scans += 1
            if math.isnan(k.confirmed_s) and k.hits >= cfg.confirm_hits \
                    and (k.hull_hits >= cfg.confirm_hits or k.moving) \
                    and not any(o is not k and not math.isnan(o.confirmed_s)
                                and _inside(o, k.kf.x[:2], cfg) for o in self._tracks):
                k.confirmed_s = t  # (not a second track inside a confirmed one's outline)
                self._reacquire(t, k)
        for b in np.flatnonzero(~used).tolist():
            if not any(_inside(k, found.centre[b], cfg) for k in self._tracks):
                self._birth(t, found, b, sensor)

    def _hit(self, t: float, k: _Tracked, found: Clusters, b: int, m, sensor) -> None:
        """Update track k with cluster b, measured `m` (`_measure`)."""
        cfg = self.config
        realigned = k.align(float(found.angle[b]), bool(found.from_side[b]), cfg)
        if realigned:
            k.extent = np.array([cfg.prior_length_m, cfg.prior_width_m])
            k.extent = np.maximum(k.extent, _seen(k.axis, found.hulls[b]))
        z, r, extent, shift, box = _measure(k, found, b, sensor, cfg) if realigned else m
        if realigned:  # new axes, new extents: the centre is where they put it
            shift = z - k.kf.x[:2]
        k.update(t, z, r, extent, shift, box[2], cfg)
        if box[3]:
            k.hull_hits, k.hull_s = k.hull_hits + 1, t
        k.seen_box = box

    def _manoeuvres(self, t: float, found: Clusters, used: np.ndarray, sensor) -> None:
        """A confirmed moving track the gate left without a cluster, with one left over
        inside its predicted outline, no bigger than the vessel (a part of it) and not cut
        off by the crop (the own hull's box, the range: its ends say less than they seem): the
        vessel turned (at a bend, the axis and velocity went stale) and the anchored measure
        missed the gate; that cluster could start no track (`_birth`), so the track coasted
        to its death. It takes the nearest such cluster within `manoeuvre_chi2`, its
        covariance first scaled so that the residual lies on the gate (fading memory: the
        velocity follows the turn)."""
        cfg = self.config
        for k in self._tracks:
            if k.seen_box is not None or not k.moving or math.isnan(k.confirmed_s):
                continue
            best, best_d2 = None, cfg.manoeuvre_chi2
            fits = np.sort(k.extent)[::-1] + cfg.extent_growth_m  # long side, short side
            for b in np.flatnonzero(~used).tolist():
                if not _inside(k, found.centre[b], cfg) or (found.size[b] > fits).any() \
                        or found.cut[b].any() or any(
                        o is not k and _inside(o, found.centre[b], cfg) for o in self._tracks):
                    continue
                m = _measure(k, found, b, sensor, cfg)
                d2 = _mahalanobis2(m[0] - (k.kf.x[:2] + m[3]), k.kf.P[:2, :2] + m[1])
                if d2 <= best_d2:
                    best, best_d2 = (b, m), d2
            if best is None:
                continue
            k.kf.P = k.kf.P * max(best_d2 / cfg.gate_chi2, 1.0)
            self._hit(t, k, found, best[0], best[1], sensor)
            used[best[0]] = True

    def _birth(self, t: float, found: Clusters, b: int, sensor) -> None:
        cfg = self.config
        extent = np.maximum(found.size[b], (cfg.prior_length_m, cfg.prior_width_m))
        k = _Tracked(self._next_id, t, found.centre[b], np.eye(2), found.angle[b], extent, cfg)
        z, r, extent, _, box = _measure(k, found, b, sensor, cfg)
        k.kf.x[:2] = z
        # An axis with no end in view: the centre is somewhere along the extent.
        w, vecs = np.linalg.eigh(r)
        k.kf.P[:2, :2] = (vecs * np.minimum(w, (0.5 * extent.max()) ** 2)) @ vecs.T
        k.extent = extent
        k.seen_box = box
        k.hull_hits, k.hull_s = (1, t) if box[3] else (0, -math.inf)
        self._next_id += 1
        self._tracks.append(k)

    def _reacquire(self, t: float, k: _Tracked) -> None:
        """A track just confirmed where a confirmed track was lost lately (out of sight
        behind a corner, another boat, the own cabin) takes its id: the nearest whose
        constant-velocity prediction, with a reach growing with the time unseen, holds the
        new centre, with a velocity within reach of the new one's; of several, the one seen
        last (the id the vessel had last, not an older one lost at the same place)."""
        cfg = self.config
        best, best_d = None, -math.inf
        for lost in self._lost:
            dt = t - lost.last_hit_s
            x = lost.kf.x
            sp = math.sqrt(max(np.trace(lost.kf.P[:2, :2]), 0.0))
            sl = math.sqrt(max(np.trace(lost.kf.P[2:, 2:]), 0.0))
            sv = math.sqrt(sl * sl + max(np.trace(k.kf.P[2:, 2:]), 0.0))
            reach = (0.5 * max(float(lost.extent.max()), float(k.extent.max())) + 3.0 * sp
                     + 3.0 * sl * dt + 1.5 * cfg.accel_sigma_mps2 * dt * dt + cfg.reacquire_m)
            d = float(np.hypot(*(k.kf.x[:2] - x[:2] - dt * x[2:])))
            dv = float(np.hypot(*(k.kf.x[2:] - x[2:])))
            if d <= reach and dv <= 3.0 * sv + cfg.moving_mps and lost.last_hit_s > best_d:
                best, best_d = lost, lost.last_hit_s
        if best is not None:
            k.id, k.vessel = best.id, k.vessel or best.vessel
            self._lost.remove(best)

    def _end_of_life(self, t: float, pose, scanned: bool) -> None:
        cfg = self.config
        self._lost = [k for k in self._lost if t - k.last_hit_s <= cfg.reacquire_s]
        keep = []
        for k in self._tracks:
            if math.isnan(k.confirmed_s):
                dead = k.misses >= cfg.tentative_misses or (
                    scanned and k.scans > cfg.confirm_window and k.hits < cfg.confirm_hits)
            else:
                dead = k.misses >= cfg.max_misses or t - k.last_hit_s > cfg.max_coast_s
            if not dead and pose is not None:
                dead = not _in_view(k, pose, cfg)
            if not dead:
                keep.append(k)
            elif not math.isnan(k.confirmed_s):
                self._lost.append(k)
        self._tracks = keep

    def _output(self, t, segs: np.ndarray, n_clusters: int, status: str) -> TrackerOutput:
        t = math.nan if t is None else t
        confirmed = [k for k in self._tracks if not math.isnan(k.confirmed_s)]
        on_vessel = np.zeros(len(segs), bool)
        for k in confirmed:
            if k.moving:
                on_vessel |= _segments_on(k, segs, self.config)
        # A track at rest is handed on while it shows a hull of its own now and then: a
        # piece of wall that once looked closed (a glitch) does not stay a boat.
        shown = [k for k in confirmed
                 if k.moving or not t - k.hull_s > self.config.hull_hold_s]
        return TrackerOutput(t, tuple(k.snapshot(t) for k in shown), segs[~on_vessel],
                             len(self._tracks) - len(confirmed), n_clusters, status)


def crop_for_tracker(points, config: TrackerConfig) -> np.ndarray:
    """The returns of a clean (N, 3) cloud that the tracker reads (detection's crop with a
    taller height band: all of it can hide things), in the cloud's order: what a process
    that scans and detects sends to the one that tracks (`update(..., cropped=True)`)
    instead of the whole cloud. Cropping twice gives the same points."""
    return crop_rows(points, _tracker_crop(config))


def split_crop(cloud: np.ndarray, cfg: TrackerConfig):
    """The tracker's crop of a scan, (N, 3), split: (occluders (x, y, the cloud's dtype:
    all of it can hide things), the detection band's points (x, y, float64: what clusters
    are made of), the own hull's returns (x, y, height up, float64; None: none, or the
    LiDARs not placed)). The compiled pass of `cloud_crop.c`, or `split_crop_numpy`."""
    lib = crop_kernel()
    if lib is None or cloud.dtype not in (np.float32, np.float64):
        return split_crop_numpy(cloud, cfg)
    n, det = len(cloud), cfg.detection
    occluders = np.empty((n, 2), cloud.dtype)
    xy, hull = np.empty((n, 2)), np.empty((n, 3))
    counts = np.zeros(3, np.int64)
    size = cloud.itemsize
    split = lib.split_f32 if cloud.dtype == np.float32 else lib.split_f64
    split(n, cloud.__array_interface__["data"][0] if n else 0, cloud.strides[0] // size,
          cloud.strides[1] // size, det.min_height_m, det.max_height_m, bool(cfg.viewpoints),
          *det.hull_x_m, det.hull_half_width_m, pointer(occluders), pointer(xy), pointer(hull),
          pointer(counts))
    n_occ, n_band, n_hull = counts.tolist()
    return occluders[:n_occ], xy[:n_band], (hull[:n_hull] if n_hull else None)


def split_crop_numpy(cloud: np.ndarray, cfg: TrackerConfig):
    """`split_crop`'s numpy twin."""
    x, y, z = cloud[:, 0], cloud[:, 1], cloud[:, 2]
    occluders = np.empty((len(x), 2), cloud.dtype)
    occluders[:, 0] = x
    occluders[:, 1] = y
    band = (z <= -cfg.detection.min_height_m) & (z >= -cfg.detection.max_height_m)
    hull = None
    if cfg.viewpoints:  # the own hull's returns cut sight lines, but are no cluster
        inside = _in_hull_box(x, y, cfg.detection)
        if inside.any():
            hull = np.column_stack([x[inside], y[inside], -z[inside]]).astype(float)
            occluders, band = occluders[~inside], band[~inside]
    return occluders, occluders[band].astype(float), hull


@lru_cache(maxsize=8)
def _tracker_crop(config: TrackerConfig) -> DetectionConfig:
    """Detection's crop up to `occluder_top_m`; with the LiDARs placed (`viewpoints`), the
    own hull's box kept (its returns shadow what lies behind the hull)."""
    det = config.detection
    crop = replace(det, max_height_m=max(det.max_height_m, config.occluder_top_m))
    if config.viewpoints:  # (the box along x stays: the wake's box starts at its end)
        crop = replace(crop, hull_half_width_m=0.0)
    return crop


def _in_hull_box(x: np.ndarray, y: np.ndarray, det: DetectionConfig) -> np.ndarray:
    """Body-frame points inside detection's own-hull box."""
    x0, x1 = det.hull_x_m
    return (x >= x0) & (x <= x1) & (np.abs(y) <= det.hull_half_width_m)


# -- what a cluster measures -----------------------------------------------------------
_CUT_COS = math.cos(math.radians(50.0))  # a cut this close to an axis' direction cuts its end
_END_M = 0.3  # hull corners this close to an end are that end's


def _seen(axis_rad: float, hull: np.ndarray) -> np.ndarray:
    """(2,) the extent of a hull along and across an axis."""
    c, s = math.cos(axis_rad), math.sin(axis_rad)
    p = hull @ np.array([[c, -s], [s, c]])
    return p.max(axis=0) - p.min(axis=0)


def _measure(k: _Tracked, found: Clusters, b: int, sensor, cfg: TrackerConfig):
    """The centre a cluster (its hull and which corners are cut off) measures for track k:
    (z (2,), R (2, 2), new extent (2,), shift of the track's centre (2,), (the axes, the
    seen box on them, the axes along which an end was seen: the directions it measures)).

    Axis by axis: where both ends are in view and the whole extent is seen, the middle;
    else the end nearest the sensor (or, cut off, the other), half the extent away. When
    the extent grows, the centre shifts by half the growth away from that end.
    """
    hull = found.hulls[b]
    c, s = math.cos(k.axis), math.sin(k.axis)
    axes = np.array([[c, s], [-s, c]])  # rows: along, across
    proj = hull @ axes.T  # (h, 2)
    centre = axes @ k.kf.x[:2]
    eye = axes @ sensor
    lo_hi = np.column_stack([proj.min(axis=0), proj.max(axis=0)])
    # The extent seen: the cluster's own box (on its own sides, so a lagging axis, a
    # weaving kayak, does not stretch it), its long side on the axis nearer the track's.
    seen = found.size[b].copy()
    if abs(_half_turn(float(found.angle[b]) - k.axis)) > math.pi / 4:
        seen = seen[::-1]
    old = k.extent
    extent = np.minimum(np.maximum(old, np.minimum(seen, old + cfg.extent_growth_m)),
                        cfg.max_vessel_length_m)
    if k.moving:  # a boat under way is longer than wide
        extent[0] = min(max(extent[0], cfg.prior_aspect * extent[1]), cfg.max_vessel_length_m)
    real, own = _real_ends(found, b, axes, proj, lo_hi, cfg)
    z = np.empty(2)
    sigma = np.empty(2)
    shift = np.zeros(2)
    informative = np.ones(2, bool)
    for i in range(2):
        lo, hi = lo_hi[i]
        lo_real, hi_real = real[i]
        near_lo = abs(lo - eye[i]) <= abs(hi - eye[i])
        anchor_lo = near_lo if (lo_real if near_lo else hi_real) else not near_lo
        if not (lo_real if anchor_lo else hi_real):  # both ends cut off: no information,
            z[i], sigma[i] = centre[i], 1e3  # and no telling which way it grew
            extent[i] = old[i]
            informative[i] = False
            continue
        shift[i] = 0.5 * (extent[i] - old[i]) * (1.0 if anchor_lo else -1.0)
        if lo_real and hi_real and seen[i] >= extent[i] - cfg.full_view_m:
            z[i], sigma[i] = 0.5 * (lo + hi), cfg.meas_sigma_m
        else:
            z[i] = lo + 0.5 * extent[i] if anchor_lo else hi - 0.5 * extent[i]
            sigma[i] = math.hypot(cfg.meas_sigma_m, cfg.anchor_sigma_m)
    r = (axes.T * sigma ** 2) @ axes
    closed = bool((own[:, 0] & own[:, 1]).any())  # an outline of its own along an axis
    return axes.T @ z, r, extent, axes.T @ shift, (axes, lo_hi, axes[informative], closed)


def _real_ends(found: Clusters, b: int, axes, proj, lo_hi, cfg: TrackerConfig):
    """(2, 2) bool [axis, low/high end], twice. First: the end is the object's, not cut off
    by the crop (no corner within `edge_m` of it cut in its direction) and not hidden: the
    scan saw through the water `free_step_m` beyond its corners (those at the end itself: a
    point beyond a corner of the side next to it would lie on the end's own face), and no
    segment through the cluster reaches on beyond it. Second, for the hull evidence
    (`_Tracked.hull_hits`): the same, but water beyond a corner in the cluster's own
    shadow (the far end of a hull seen from its quarter) counts as seen through: nothing
    else hides it, where a piece of wall goes on into the wall or behind a corner; and
    water is seen through only with no return in the `hull_spread_bins` either side of its
    bin too (a wall at a glancing angle has its returns farther apart than the bins)."""
    hull, cut = found.hulls[b], found.cut[b]
    sign = np.array([-1.0, 1.0])
    inward = (proj.T[:, None, :] - lo_hi[:, :, None]) * sign[None, :, None]  # (2, 2, h)
    cut_out = (axes @ cut.T)[:, None, :] * sign[None, :, None] > _CUT_COS
    real = ~((inward >= -cfg.edge_m) & cut_out).any(axis=2)
    i, j, h = np.nonzero(inward >= -_END_M)
    beyond = hull[h] + (sign[j] * cfg.free_step_m)[:, None] * axes[i]
    free = free_space(found, beyond, cfg.free_margin_m)
    hidden = (np.bincount(2 * i + j, ~free, minlength=4) > 0).reshape(2, 2)
    # A hull's own end, seen without a return in the bins either side of the water beyond
    # it: a bin between two beams is empty on a wall seen at a glancing angle too.
    clear = free.copy()
    if free.any():
        clear[free] = free_space(found, beyond[free], cfg.free_margin_m, cfg.hull_spread_bins)
    own = ~(np.bincount(2 * i + j, ~(clear | _in_shadow(hull, beyond, found.pose)),
                        minlength=4) > 0).reshape(2, 2) if not clear.all() else ~hidden
    faces = found.faces[b] if found.faces else ()
    if len(faces):  # a face the line detector followed on beyond an end: it goes on there
        f = faces.reshape(-1, 2) @ axes.T  # (2f, 2)
        goes_on = np.column_stack([f.min(axis=0) < lo_hi[:, 0] - cfg.free_step_m,
                                   f.max(axis=0) > lo_hi[:, 1] + cfg.free_step_m])
        hidden |= goes_on
        own &= ~goes_on
    return real & ~hidden, real & own


def _in_shadow(hull: np.ndarray, points: np.ndarray, pose) -> np.ndarray:
    """(K,) bool: inertial points that lie in the shadow a convex hull (h, 2) casts seen
    from the pose's position: strictly between its outer bearings, farther than its
    nearest corner."""
    d = hull - np.asarray(pose[:2], float)
    mid = d.mean(axis=0)
    ref = math.atan2(mid[1], mid[0])
    ang = wrap_angle(np.arctan2(d[:, 1], d[:, 0]) - ref)
    e = points - np.asarray(pose[:2], float)
    be = wrap_angle(np.arctan2(e[:, 1], e[:, 0]) - ref)
    return (be > ang.min()) & (be < ang.max()) & (np.hypot(*e.T) > np.hypot(*d.T).min())


def _inside(k: _Tracked, xy, cfg: TrackerConfig) -> bool:
    """Whether a point lies inside track k's predicted outline (plus the cluster cell)."""
    c, s = math.cos(k.axis), math.sin(k.axis)
    d = np.asarray(xy) - k.kf.x[:2]
    return (abs(c * d[0] + s * d[1]) <= 0.5 * k.extent[0] + cfg.cell_m
            and abs(-s * d[0] + c * d[1]) <= 0.5 * k.extent[1] + cfg.cell_m)


def _in_view(k: _Tracked, pose, cfg: TrackerConfig) -> bool:
    """Whether some of track k's predicted outline lies inside the crop's range square."""
    x, y, psi = pose
    c, s = math.cos(psi), math.sin(psi)
    dx, dy = k.kf.x[0] - x, k.kf.x[1] - y
    reach = cfg.detection.range_m + 0.5 * float(k.extent.max())
    return abs(c * dx + s * dy) <= reach and abs(-s * dx + c * dy) <= reach


def _segments_on(k: _Tracked, segs: np.ndarray, cfg: TrackerConfig) -> np.ndarray:
    """(M,) bool: segments with both ends inside track k's outline (its centre and extent
    now) or the box of this scan's cluster on its axes (the line detector bridges a little
    past the returns the cluster kept), grown by segment_margin_m, and by twice the
    position's sigma where the track was not seen this scan."""
    if not len(segs):
        return np.zeros(0, bool)
    c, s = math.cos(k.axis), math.sin(k.axis)
    axes = np.array([[c, s], [-s, c]])
    mid = axes @ k.kf.x[:2]
    lo_hi = np.column_stack([mid - 0.5 * k.extent, mid + 0.5 * k.extent])
    if k.seen_box is not None:
        seen_axes, seen = k.seen_box[:2]
        if np.allclose(seen_axes, axes):
            lo_hi = np.column_stack([np.minimum(lo_hi[:, 0], seen[:, 0]),
                                     np.maximum(lo_hi[:, 1], seen[:, 1])])
        margin = cfg.segment_margin_m
    else:
        margin = cfg.segment_margin_m + 2.0 * math.sqrt(max(np.trace(k.kf.P[:2, :2]), 0.0))
    half = 0.5 * segs[:, 3:4] * np.column_stack([np.cos(segs[:, 2]), np.sin(segs[:, 2])])
    ok = np.ones(len(segs), bool)
    for end in (segs[:, :2] - half, segs[:, :2] + half):
        p = end @ axes.T
        ok &= ((p >= lo_hi[:, 0] - margin) & (p <= lo_hi[:, 1] + margin)).all(axis=1)
    return ok


# -- run-time input: cleaned, never raised on -------------------------------------------
def _finite_float(v) -> float | None:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _finite_pose(pose):
    try:
        p = np.asarray(pose, float).reshape(-1)
    except (TypeError, ValueError):
        return None
    if p.shape != (3,) or not np.isfinite(p).all():
        return None
    return float(p[0]), float(p[1]), float(p[2])


def _clean_cloud(points, allow_empty: bool = False):
    """("ok" | "dropped_points" | "no_scan" | "bad_points", cloud); an empty cloud is "ok"
    if `allow_empty` (a cropped one)."""
    if points is None:
        return "no_scan", None
    try:
        arr = np.asarray(points)
    except (TypeError, ValueError):
        return "bad_points", None
    if arr.dtype.kind not in "fiu" or (arr.size and (arr.ndim != 2 or arr.shape[1] != 3)):
        return "bad_points", None
    if arr.size == 0:
        return ("ok", arr.reshape(0, 3).astype(float)) if allow_empty else ("no_scan", None)
    if arr.dtype.kind != "f":
        arr = arr.astype(float)
    if np.isfinite(arr.sum()):
        return "ok", arr
    finite = np.isfinite(arr).all(axis=1)
    if not finite.any():
        return "bad_points", None
    return "dropped_points", arr[finite]


def _clean_segments(segments) -> np.ndarray:
    """The finite rows of an (M, 4) array; anything else is no segments."""
    if segments is None:
        return np.zeros((0, 4))
    try:
        s = np.asarray(segments, float)
    except (TypeError, ValueError):
        return np.zeros((0, 4))
    if s.ndim != 2 or s.shape[1] != 4:
        return np.zeros((0, 4))
    return s[np.isfinite(s).all(axis=1)]
