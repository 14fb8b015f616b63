"""Three simulated LiDARs on the boat (paper, Table "Boat specifications"): point clouds per scan.

A front 64-beam unit on the bow and port/starboard 32-beam units tilted down, 0.5-120 m.
One call renders one 10 Hz scan of all three and returns one merged (N, 3) cloud in the
body frame (x forward, y starboard, z down, origin at the boat's origin on the waterline).

Speed comes from the world being vertical prisms (DESIGN.md, LiDAR): each sensor casts its
azimuth columns once in 2-D against the wall, backdrop and obstacle outlines, and every beam
of a column then finds its elevation's hit in closed form (water in front, the wall face,
the quay top, the backdrop behind, an obstacle's face, top or underside). The beams are
stored by column and elevation, so the beams of a column meeting one surface are one run:
four binary searches per column classify them, and classes and distances are runs repeated
from per-column tables. Beams blocked by the boat's own hull and cabin return the hull
(detection crops them). Range noise, dropouts, speckle off the water and spray in the wake
are drawn from one seeded generator. No Python loop runs over beams or edges: a scan is a
few dozen array operations (~4-5 ms for the ~116k beams of the default suite on the 2-core
development machine, `canalnav bench detection`). The cloud is float32 and comes as the
(N, 3) view of a (3, N) buffer, so each coordinate is contiguous.

Simplifications, on purpose: per column only the first wall and the land behind it are
rendered (nothing beyond the backdrop), one obstacle per column (the nearest), and the boat
does not roll or pitch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from controller.errors import InputError

from ..world.canal import CanalWorld

# What each returned point hit (see LidarScan.labels).
WATER, FACE, GROUND, BACKDROP, OBSTACLE, HULL, SPRAY = range(7)
LABEL_NAMES = ("water", "wall face", "quay top", "backdrop", "obstacle", "own hull", "spray")
# The renderer's classes: 0-3 as the labels above (in elevation order), 4 sky (no return),
# 5 obstacle.


def sensor_rotation(roll_rad: float, pitch_rad: float, yaw_rad: float) -> np.ndarray:
    """Sensor to body frame (both x forward, y right, z down): Rz(yaw) Ry(pitch) Rx(roll)."""
    cy, sy = np.cos(yaw_rad), np.sin(yaw_rad)
    cp, sp = np.cos(pitch_rad), np.sin(pitch_rad)
    cr, sr = np.cos(roll_rad), np.sin(roll_rad)
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


@dataclass(frozen=True)
class LidarMount:
    """One sensor: where it sits on the boat, how it points, and its beam pattern.

    Position in the body frame (x forward, y starboard) and height above the waterline
    (positive up). Orientation: yaw (to starboard positive), then pitch (nose up positive;
    a unit tilted down has negative pitch), then roll. Elevations of the beams are spread
    evenly over [elevation_min_rad, elevation_max_rad] in the sensor's own frame.
    """

    name: str
    x_m: float
    y_m: float
    height_m: float
    channels: int
    yaw_rad: float = 0.0
    pitch_rad: float = 0.0
    roll_rad: float = 0.0
    elevation_min_rad: float = np.radians(-16.6)
    elevation_max_rad: float = np.radians(16.6)
    columns: int = 1024  # azimuth samples per revolution
    min_range_m: float = 0.5
    max_range_m: float = 120.0

    def __post_init__(self) -> None:
        if self.channels < 1 or self.columns < 8:
            raise InputError(f"lidar {self.name!r}: channels >= 1 and columns >= 8 needed")
        if not 0.0 < self.min_range_m < self.max_range_m:
            raise InputError(f"lidar {self.name!r}: need 0 < min_range_m < max_range_m")
        if not self.elevation_min_rad <= self.elevation_max_rad:
            raise InputError(f"lidar {self.name!r}: elevation_min_rad above elevation_max_rad")

    def rotation(self) -> np.ndarray:
        """Sensor to body frame (both x forward, y right, z down)."""
        return sensor_rotation(self.roll_rad, self.pitch_rad, self.yaw_rad)

    def beam_directions(self) -> np.ndarray:
        """Unit beam directions in the body frame (z down): (channels * columns, 3)."""
        el = np.linspace(self.elevation_min_rad, self.elevation_max_rad, self.channels)
        az = np.arange(self.columns) * (2.0 * np.pi / self.columns)
        el, az = np.meshgrid(el, az, indexing="ij")
        d = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)], -1)
        return d.reshape(-1, 3) @ self.rotation().T


def default_mounts() -> tuple[LidarMount, ...]:
    """The paper's layout: 64-beam on the bow; 32-beam units on brackets just outboard of the
    cabin roof, turned outboard and tilted 15 deg down to see the side walls close by."""
    tilt = np.radians(-15.0)
    return (
        LidarMount("front", 3.5, 0.0, 1.3, 64),
        LidarMount("port", 0.0, -1.35, 2.4, 32, yaw_rad=-np.pi / 2, pitch_rad=tilt),
        LidarMount("starboard", 0.0, 1.35, 2.4, 32, yaw_rad=np.pi / 2, pitch_rad=tilt),
    )


@dataclass(frozen=True)
class HullShape:
    """The boat's own structure as boxes in the body frame: (x0, x1, y0, y1, h0, h1), metres,
    heights above the waterline. Default: 7.9 m x 2.6 m hull with 0.7 m freeboard and a
    cabin roof 2.2 m above the water."""

    boxes: tuple[tuple[float, float, float, float, float, float], ...] = (
        (-3.95, 3.95, -1.3, 1.3, 0.0, 0.7),
        (-2.6, 1.6, -1.2, 1.2, 0.7, 2.2),
    )

    @property
    def stern_x_m(self) -> float:
        return min(b[0] for b in self.boxes)

    @property
    def half_breadth_m(self) -> float:
        return max(max(abs(b[2]), abs(b[3])) for b in self.boxes)


@dataclass(frozen=True)
class LidarNoise:
    """Imperfections, all drawn from the simulator's seeded generator.

    range_sigma_m: Gaussian range noise. dropout: chance a return is lost. water_speckle:
    chance a beam that reaches the water returns from it (ripples, floating debris).
    spray_points: points of wake spray per scan at 2 m/s (scaled by speed, none at rest),
    in a wedge `spray_length_m` behind the stern up to `spray_height_m` above the water.
    """

    range_sigma_m: float = 0.02
    dropout: float = 0.03
    water_speckle: float = 0.01
    water_ripple_m: float = 0.05
    spray_points: int = 300
    spray_length_m: float = 12.0
    spray_height_m: float = 1.0


@dataclass(frozen=True)
class LidarConfig:
    """The sensor suite: mounts, the hull that blocks them, noise, and the scan rate."""

    mounts: tuple[LidarMount, ...] = field(default_factory=default_mounts)
    hull: HullShape = HullShape()
    noise: LidarNoise = LidarNoise()
    rate_hz: float = 10.0


@dataclass(frozen=True, eq=False)
class LidarScan:
    """One merged scan: points (N, 3) body frame z down, what each hit, and which sensor."""

    points: np.ndarray
    labels: np.ndarray  # (N,) int, index into LABEL_NAMES
    sensor: np.ndarray  # (N,) int, index into the config's mounts; -1 for spray


def _ordered(x: np.ndarray) -> np.ndarray:
    """float32 values as int64 in the same order (-0.0 as 0.0; no NaN expected): sorting
    and binary search on these are exact comparisons of the floats."""
    i = (np.asarray(x, np.float32) + np.float32(0.0)).view(np.int32).astype(np.int64)
    return np.where(i < 0, -(i & 0x7FFFFFFF), i)


def _level16(p: float) -> int:
    """The 16-bit level below which a uniform 16-bit draw falls with probability p."""
    return int(round(min(max(p, 0.0), 1.0) * 65536))


def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


def _hull_range(origin, dirs, boxes) -> np.ndarray:
    """Slant range from `origin` along each direction to the first hull box (inf: clear).
    Coordinates (x, y, height up)."""
    best = np.full(len(dirs), np.inf)
    d = np.where(np.abs(dirs) < 1e-12, 1e-12, dirs)
    for box in boxes:
        lo, hi = np.array(box[0::2]), np.array(box[1::2])
        t1, t2 = (lo - origin) / d, (hi - origin) / d
        t_near = np.minimum(t1, t2).max(axis=1)
        t_far = np.maximum(t1, t2).min(axis=1)
        hit = (t_far >= t_near) & (t_near > 0)
        best = np.where(hit, np.minimum(best, t_near), best)
    return best


class _Sensor:
    """Per-mount tables computed once: beams grouped by azimuth bin, hull blocking.

    Each beam keeps its own elevation but takes the azimuth of its bin (the nearest of
    `columns` per revolution, like an encoder), so every return lies exactly on the surface
    its column's 2-D cast found. For an untilted unit the two are the same; for a tilted
    one the azimuth moves by at most half a bin.
    """

    def __init__(self, mount: LidarMount, hull: HullShape) -> None:
        self.mount = mount
        d = mount.beam_directions()
        dirs_up = d * np.array([1.0, 1.0, -1.0])  # (x, y, height up)
        origin = np.array([mount.x_m, mount.y_m, mount.height_m])
        hull_r = _hull_range(origin, dirs_up, hull.boxes)
        self.origin_body = np.array([mount.x_m, mount.y_m, -mount.height_m], np.float32)
        self.height = np.float32(mount.height_m)
        horiz = np.hypot(d[:, 0], d[:, 1])
        self.bins = mount.columns
        self.step = 2.0 * np.pi / self.bins
        bin_of = np.round(np.arctan2(d[:, 1], d[:, 0]) / self.step).astype(np.intp) % self.bins
        blocked = np.isfinite(hull_r)
        keep = ~blocked
        f32 = np.float32
        self.bin = bin_of[keep]
        self.tan_el = (dirs_up[keep, 2] / horiz[keep]).astype(f32)
        self.cos_el = horiz[keep].astype(f32)  # horizontal metres per metre of range
        az = self.bin * self.step
        # Body-frame displacement per metre of horizontal distance, z down.
        self.vec = np.column_stack([np.cos(az), np.sin(az), -self.tan_el]).astype(f32)
        # Beams that see the hull: fixed points, only noise changes between scans.
        hull_ok = blocked & (hull_r >= mount.min_range_m)
        self.hull_dir = d[hull_ok].astype(f32)
        self.hull_r = hull_r[hull_ok].astype(f32)
        self.min_h = f32(mount.min_range_m) * self.cos_el
        self.max_h = f32(mount.max_range_m) * self.cos_el


@dataclass(frozen=True, eq=False)
class _Beams:
    """All sensors' world-facing beams in one batch (bins numbered across sensors)."""

    bin: np.ndarray
    height: np.ndarray
    tan_el: np.ndarray
    cos_el: np.ndarray
    inv_drop: np.ndarray  # 1 / -tan(elevation) for beams going down, else 0
    vec: np.ndarray  # (3, n) body displacement per metre of horizontal distance
    origin: tuple  # x, y, z arrays: the beam's sensor position in the body frame
    min_h: np.ndarray
    max_h: np.ndarray
    sensor: np.ndarray
    hull_points: np.ndarray  # (3, m) noiseless own-hull returns (x, y, z down)
    hull_unit: np.ndarray  # (3, m) their beam directions, for range noise
    hull_sensor: np.ndarray

    @classmethod
    def join(cls, sensors) -> "_Beams":
        """All sensors' beams, ordered by bin (so by sensor) and within a bin by elevation:
        the beams of one column that meet one surface are then one contiguous run."""
        offsets = np.cumsum([0] + [s.bins for s in sensors[:-1]])
        cat = np.concatenate
        bin_ = cat([s.bin + off for s, off in zip(sensors, offsets)])
        tan_el = cat([s.tan_el for s in sensors])
        order = np.lexsort((tan_el, bin_))
        sort = lambda a: a[order]  # noqa: E731
        return cls(
            bin=sort(bin_),
            height=sort(cat([np.full(len(s.bin), s.height, np.float32) for s in sensors])),
            tan_el=sort(tan_el),
            cos_el=sort(cat([s.cos_el for s in sensors])),
            inv_drop=sort(cat([np.where(s.tan_el < 0, -1.0 / np.minimum(s.tan_el, -1e-9), 0.0)
                               .astype(np.float32) for s in sensors])),
            vec=np.ascontiguousarray(sort(cat([s.vec for s in sensors])).T),
            origin=tuple(sort(cat([np.full(len(s.bin), s.origin_body[i]) for s in sensors]))
                         for i in range(3)),
            min_h=sort(cat([s.min_h for s in sensors])),
            max_h=sort(cat([s.max_h for s in sensors])),
            sensor=sort(cat([np.full(len(s.bin), k, np.int8) for k, s in enumerate(sensors)])),
            hull_points=np.ascontiguousarray(
                cat([s.origin_body + s.hull_r[:, None] * s.hull_dir for s in sensors]).T),
            hull_unit=np.ascontiguousarray(cat([s.hull_dir for s in sensors]).T),
            hull_sensor=cat([np.full(len(s.hull_r), k, np.int8) for k, s in enumerate(sensors)]),
        )


class LidarSimulator:
    """Renders scans of a canal world from a boat pose; one seeded generator for all noise."""

    def __init__(self, world: CanalWorld, config: LidarConfig | None = None,
                 seed: int | np.random.Generator | None = 0) -> None:
        self.world = world
        self.config = config or LidarConfig()
        self.rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        self.sensors = [_Sensor(m, self.config.hull) for m in self.config.mounts]
        self._beams = _Beams.join(self.sensors)
        self._bin_height = np.concatenate([np.full(s.bins, s.mount.height_m) for s in self.sensors])
        self._beam_start = np.concatenate([[0], np.cumsum([len(s.bin) for s in self.sensors])[:-1]])
        self._normals = self.rng.standard_normal(1 << 20, dtype=np.float32)
        # Exact per-bin thresholding on tan(elevation) by binary search: each beam's key is
        # bin * 2**32 + its float32 tan as an order-preserving integer (sorted, exact).
        beams = self._beams
        self._keys = (beams.bin.astype(np.int64) << 32) + _ordered(beams.tan_el)
        n_bins = int(sum(s.bins for s in self.sensors))
        self._bin_first = np.searchsorted(beams.bin, np.arange(n_bins + 1))  # beam range per bin
        self._class_of_run = np.tile(np.arange(5, dtype=np.int8), n_bins)
        self.max_range_m = max(m.max_range_m for m in self.config.mounts)
        e = world.edges
        self._obst = e["obstacle"]
        self._obstacles = world.obstacles
        fa, fb, fh = e["face"]
        ba, bb, bh, _ = e["backdrop"]
        oa, ob, oo, _, _ = e["obstacle"]
        self._edges = (  # a, b, category (0 face, 1 backdrop, 2 obstacle), height, obstacle
            np.concatenate([fa, ba, oa]), np.concatenate([fb, bb, ob]),
            np.concatenate([np.zeros(len(fa), int), np.ones(len(ba), int), np.full(len(oa), 2)]),
            np.concatenate([fh, bh, np.zeros(len(oa))]),
            np.concatenate([np.full(len(fa) + len(ba), -1), oo]).astype(int))
        counts = np.array([s.bins for s in self.sensors])
        self._bin_count = counts
        self._bin_offset = np.concatenate([[0], np.cumsum(counts)[:-1]])
        self._bin_step = 2.0 * np.pi / counts
        self._bin_sensor = np.repeat(np.arange(len(counts)), counts)
        local = np.arange(counts.sum()) - np.repeat(self._bin_offset, counts)
        self._bin_cos = np.cos(local * np.repeat(self._bin_step, counts))
        self._bin_sin = np.sin(local * np.repeat(self._bin_step, counts))

    @property
    def mount_positions_body(self) -> np.ndarray:
        """(S, 2) sensor positions (x, y) in the body frame."""
        return np.array([[m.x_m, m.y_m] for m in self.config.mounts])

    def sensor_positions(self, pose) -> np.ndarray:
        """(S, 2) sensor positions in the inertial frame for a boat pose (x, y, psi)."""
        x, y, psi = np.asarray(pose, float)
        c, s = np.cos(psi), np.sin(psi)
        b = self.mount_positions_body
        return np.column_stack([x + c * b[:, 0] - s * b[:, 1], y + s * b[:, 0] + c * b[:, 1]])

    def in_view(self, pose, xy, height_m: float) -> np.ndarray:
        """(N, S) mask: sensor s could see the point (x, y) at `height_m` above the water if
        nothing in the world were in the way: within its range and vertical field of view,
        and not behind the boat's own hull or cabin. With `CanalWorld.line_of_sight` this is
        what 'the sensors can see' means in the detection benchmark."""
        x, y, psi = np.asarray(pose, float)
        c, s = np.cos(psi), np.sin(psi)
        rel = np.asarray(xy, float).reshape(-1, 2) - (x, y)
        body = np.column_stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1],
                                np.full(len(rel), float(height_m))])
        out = np.zeros((len(rel), len(self.sensors)), bool)
        for k, sensor in enumerate(self.sensors):
            m = sensor.mount
            d = body - (m.x_m, m.y_m, m.height_m)
            rng_ = np.linalg.norm(d, axis=1)
            u = d / np.maximum(rng_, 1e-9)[:, None]
            down = u * (1.0, 1.0, -1.0)  # body frame, z down
            elev = np.arcsin(np.clip(-(down @ m.rotation())[:, 2], -1.0, 1.0))
            hull = _hull_range(np.array([m.x_m, m.y_m, m.height_m]), u, self.config.hull.boxes)
            out[:, k] = ((rng_ >= m.min_range_m) & (rng_ <= m.max_range_m)
                         & (elev >= m.elevation_min_rad) & (elev <= m.elevation_max_rad)
                         & ~(hull < rng_))
        return out

    def scan(self, pose, speed_mps: float = 0.0) -> np.ndarray:
        """One merged scan at pose (x, y, psi): (N, 3) float32 (as LiDAR drivers deliver),
        body frame, z down, origin at the boat's origin on the waterline. (Column-major:
        `np.ascontiguousarray` gives row-major points if a consumer needs them.)"""
        return self.scan_labelled(pose, speed_mps).points

    def scan_labelled(self, pose, speed_mps: float = 0.0) -> LidarScan:
        """One merged scan with what each point hit (for tests, figures and benchmarks)."""
        pose = np.asarray(pose, float).reshape(-1)
        if pose.shape != (3,) or not np.all(np.isfinite(pose)):
            raise InputError(f"lidar: pose must be three finite numbers (x, y, psi), got {pose}")
        psi = pose[2]
        reach = self.max_range_m + 10.0
        origins = self.sensor_positions(pose)
        spray = self._spray(speed_mps)
        n_spray = len(spray[1])
        columns, labels, sensor = self._render(*self._cast(origins, psi, reach), n_spray=n_spray)
        if n_spray:
            columns[:, -n_spray:] = spray[0].T
        # (N, 3) view of the (3, N) buffer: no copy, and each coordinate is contiguous.
        return LidarScan(columns.T, np.concatenate([labels, spray[1]]),
                         np.concatenate([sensor, spray[2]]))

    # -- rendering ----------------------------------------------------------------------
    def _cast(self, origins, psi, reach):
        """The 2-D cast of every azimuth bin of every sensor (bins numbered across sensors).

        Returns per bin: distance to the nearest wall face and its height, to the backdrop
        behind it and its height, and to the nearest obstacle's entry and exit with that
        obstacle's index (-1: none). Each edge is paired only with the bins inside its
        angular span as a sensor sees it, so the work grows with bins times surfaces crossed,
        not bins times all edges.
        """
        a, b, cat, value, owner = self._edges
        centre = origins.mean(axis=0)
        near = np.minimum(np.hypot(*(a - centre).T), np.hypot(*(b - centre).T))
        keep = np.flatnonzero(near < reach + np.hypot(*(b - a).T))
        n_total = self._bin_offset[-1] + self.sensors[-1].bins
        none = np.full(n_total, np.inf)
        if not len(keep):
            return none, np.zeros(n_total), none, np.zeros(n_total), none, none, np.full(n_total, -1)
        # One row per (sensor, edge).
        n_s, n_e = len(origins), len(keep)
        edge = np.tile(keep, n_s)
        sensor = np.repeat(np.arange(n_s), n_e)
        o = origins[sensor]
        step = self._bin_step[sensor]
        ea, eb = a[edge], b[edge]
        ang_a = np.arctan2(ea[:, 1] - o[:, 1], ea[:, 0] - o[:, 0]) - psi
        ang_b = np.arctan2(eb[:, 1] - o[:, 1], eb[:, 0] - o[:, 0]) - psi
        span = (ang_b - ang_a + np.pi) % (2 * np.pi) - np.pi
        lo = np.where(span < 0, ang_b, ang_a)
        k0 = np.ceil(lo / step).astype(np.int64)
        k1 = np.floor((lo + np.abs(span)) / step).astype(np.int64)
        count = np.maximum(k1 - k0 + 1, 0)
        row = np.repeat(np.arange(len(edge)), count)
        k = np.repeat(k0 - (np.cumsum(count) - count), count) + np.arange(int(count.sum()))
        s = sensor[row]
        gbin = self._bin_offset[s] + k % self._bin_count[s]
        # The ray of bin k at heading psi, from the bins' cos and sin (no trigonometry here).
        cb, sb = self._bin_cos[gbin], self._bin_sin[gbin]
        cp, sp = math.cos(psi), math.sin(psi)
        d = eb - ea
        ex, ey = d[row, 0], d[row, 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = _cross(ea[row, 0] - o[row, 0], ea[row, 1] - o[row, 1], ex, ey) / _cross(
                cp * cb - sp * sb, sp * cb + cp * sb, ex, ey)
        ok = np.flatnonzero(np.isfinite(t) & (t > 1e-6))
        row, t, gbin = row[ok], t[ok], gbin[ok]
        e = edge[row]
        c = cat[e]

        def nearest(mask, floor=None):
            gb, tt, ee = gbin[mask], t[mask], e[mask]
            if floor is not None:
                beyond = tt > floor[gb] + 1e-6
                gb, tt, ee = gb[beyond], tt[beyond], ee[beyond]
            best = np.full(n_total, np.inf)
            np.minimum.at(best, gb, tt)
            which = np.full(n_total, -1)
            hit = tt == best[gb]
            which[gb[hit]] = ee[hit]
            return best, which

        t_face, e_face = nearest(c == 0)
        wall_h = np.where(e_face >= 0, value[e_face], 0.0)
        t_back, e_back = nearest(c == 1, floor=t_face)
        back_h = np.where(e_back >= 0, value[e_back], 0.0)
        t_in, e_in = nearest(c == 2)
        obst = np.where(e_in >= 0, owner[e_in], -1)
        t_out, _ = nearest((c == 2) & (owner[e] == obst[gbin]), floor=t_in)
        if self._obstacles:
            inside = np.array([ob.contains(origins) for ob in self._obstacles])  # (O, S)
            in_bin = (obst >= 0) & inside[np.maximum(obst, 0), self._bin_sensor]
            t_in, t_out = np.where(in_bin, 0.0, t_in), np.where(in_bin, t_in, t_out)
        return t_face, wall_h, t_back, back_h, t_in, t_out, obst

    def _render(self, t_face, wall_h, t_back, back_h, t_in, t_out, owner, n_spray=0):
        """Every beam of every sensor at once: which surface its elevation meets first.

        Along one column the surfaces are met in a fixed order of elevation: water below
        the wall's foot, the wall face up to its top, the quay top behind it (if the sensor
        is above it), the backdrop, then sky. So per column four thresholds on tan(elevation)
        classify all its beams; as the beams are stored by column and elevation, each class
        is one run of beams per column, found by binary search, and the classes and
        distances of all beams are runs repeated from per-column tables (no per-beam
        gathers). The horizontal distance of every class is a + b / -tan(elevation).
        """
        beams = self._beams
        noise = self.config.noise
        rng = self.rng
        f32 = np.float32
        h = self._bin_height
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = -h / t_face  # wall foot
            t2 = np.maximum(t1, (wall_h - h) / t_face)  # wall top
            t3 = np.maximum(t2, np.where(h > wall_h, -(h - wall_h) / t_back, -np.inf))
            t4 = np.maximum(t3, (back_h - h) / t_back)  # backdrop top
        # cls: 0 water, 1 face, 2 quay top, 3 backdrop, 4 sky (LABELS below), 5 obstacle.
        cls, runs = self._classes(t1, t2, t3, t4)
        zero = np.zeros(len(h))
        a = np.column_stack([zero, t_face, zero, t_back, np.full(len(h), np.inf)])
        b = np.column_stack([h, zero, h - wall_h, zero, zero])
        t_all = np.repeat(a.astype(f32).ravel(), runs)
        t_all += np.repeat(b.astype(f32).ravel(), runs) * beams.inv_drop
        self._render_obstacles(t_in, t_out, owner, cls, t_all)

        # Beams within range (sky is infinitely far), then dropouts and speckle.
        returns = t_all >= beams.min_h
        returns &= t_all <= beams.max_h
        idx = np.flatnonzero(returns)
        lab = cls[idx]
        u = self._uniform16(len(idx))
        drop, speckle = _level16(noise.dropout), _level16(noise.dropout + noise.water_speckle)
        keep = (u >= drop) & ((lab != 0) | (u < speckle))
        # (Indexing through flatnonzero is several times faster than with a boolean mask.)
        keep = np.flatnonzero(keep)
        idx, lab = idx[keep], lab[keep]
        t = t_all[idx]
        t += self._normal(len(idx)) * (f32(noise.range_sigma_m) * beams.cos_el[idx])
        # Points as rows x, y, z of one buffer (long contiguous rows: fast arithmetic), with
        # room for the hull returns and the spray after them; scan_labelled transposes.
        hull_keep = np.flatnonzero(self._uniform16(beams.hull_points.shape[1]) >= drop)
        n, m = len(idx), len(hull_keep)
        out = np.empty((3, n + m + n_spray), f32)
        pts = out[:, :n]
        for i in range(3):
            beams.vec[i].take(idx, out=pts[i])
        pts *= t
        # Beams are ordered by sensor, so each sensor's origin is added to one slice.
        cuts = np.searchsorted(idx, self._beam_start)
        for k, (lo, hi) in enumerate(zip(cuts, np.r_[cuts[1:], n])):
            pts[:, lo:hi] += self.sensors[k].origin_body[:, None]
        label = np.where(lab == 5, np.int8(OBSTACLE), lab)  # classes 0-3 are the labels
        water = np.flatnonzero(label == WATER)
        if len(water):
            pts[2, water] -= rng.uniform(-1.0, 1.0, len(water)).astype(f32) * f32(
                noise.water_ripple_m)

        # Own hull: fixed returns, with dropouts and range noise.
        hull = out[:, n:n + m]
        beams.hull_points.take(hull_keep, axis=1, out=hull)
        hull += beams.hull_unit.take(hull_keep, axis=1) * (
            self._normal(m) * f32(noise.range_sigma_m))
        return (out,
                np.concatenate([label, np.full(m, HULL, np.int8)]),
                np.concatenate([beams.sensor[idx], beams.hull_sensor[hull_keep]]))

    def _classes(self, t1, t2, t3, t4):
        """Class of every beam, 0-4: how many of tan >= t1, tan > t2, tan >= t3, tan > t4
        hold for its tan(elevation) and its bin's thresholds (float32 comparisons), and the
        (bins * 5) run lengths of the classes (beams are sorted by bin, then tan).

        In each bin the beams meeting one condition are a tail of the bin's run; where it
        starts is a binary search of the (bin, tan) keys, exact as the keys are integers."""
        base = np.arange(len(t1), dtype=np.int64) << 32
        bounds = np.empty((len(t1), 6), np.int64)
        bounds[:, 0], bounds[:, 5] = self._bin_first[:-1], self._bin_first[1:]
        for q, (t, side) in enumerate(((t1, "left"), (t2, "right"), (t3, "left"),
                                       (t4, "right"))):
            key = base + _ordered(np.asarray(t).astype(np.float32))
            bounds[:, q + 1] = np.searchsorted(self._keys, key, side)
        bounds[:, 1:5].sort(axis=1)  # a count of conditions, whatever their order
        runs = np.diff(bounds, axis=1).ravel()
        return np.repeat(self._class_of_run, runs), runs

    def _render_obstacles(self, t_in, t_out, owner, cls, t_all):
        """Where a beam meets an obstacle (face, top or underside) before its surface, mark
        it (class 5) and set its distance in `t_all`; only beams of columns that cross one."""
        beams = self._beams
        cols = np.flatnonzero(owner >= 0)
        if not len(cols):
            return
        first = self._bin_first
        runs = first[cols + 1] - first[cols]
        # The beams of those columns (contiguous per column), without a per-beam search.
        idx = np.repeat(first[cols] - np.cumsum(runs) + runs, runs) + np.arange(int(runs.sum()))
        _, _, _, zb_all, zt_all = self._obst
        f32 = np.float32
        b = beams.bin[idx]
        tan = beams.tan_el[idx]
        h = beams.height[idx]
        tin, tout = t_in.astype(f32)[b], t_out.astype(f32)[b]
        zlo, zhi = zb_all.astype(f32)[owner[b]], zt_all.astype(f32)[owner[b]]
        zi = h + tin * tan
        inv = beams.inv_drop[idx]  # 1 / -tan going down, 0 going up
        t_top = np.where(inv > 0, (h - zhi) * inv, np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            t_under = np.where(tan > 0, (zlo - h) / tan, np.inf)
        t = np.where((tin > 0) & (zi >= zlo) & (zi <= zhi), tin, np.inf)
        t = np.where((zi > zhi) & (t_top > tin) & (t_top < tout), t_top, t)
        t = np.where((zi < zlo) & (t_under > tin) & (t_under < tout), t_under, t)
        nearer = t < t_all[idx]  # sky is at infinity
        t_all[idx[nearer]] = t[nearer]
        cls[idx[nearer]] = 5

    def _uniform16(self, n: int) -> np.ndarray:
        """n uniform 16-bit draws (compare with `_level16`): cheaper than float draws, and
        probabilities resolved to 1/65536."""
        return np.frombuffer(self.rng.bytes(2 * n), np.uint16)

    def _normal(self, n: int) -> np.ndarray:
        """n standard normal draws (float32): a window at a random offset into a table
        drawn once from the seed; drawing fresh Gaussians would cost more than the
        rendering. Draws within a scan are independent; windows of different scans start
        at independent offsets."""
        size = len(self._normals)
        if n > size:
            return self.rng.standard_normal(n, dtype=np.float32)
        start = int(self.rng.integers(0, size))
        if start + n <= size:
            return self._normals[start:start + n]
        return np.concatenate([self._normals[start:], self._normals[:start + n - size]])

    def _spray(self, speed_mps: float):
        """Droplets in a wedge behind the stern; more at speed, none at rest."""
        noise, hull = self.config.noise, self.config.hull
        n = self.rng.poisson(noise.spray_points * min(max(speed_mps, 0.0) / 2.0, 2.0))
        back = self.rng.uniform(0.0, noise.spray_length_m, n)
        half = hull.half_breadth_m + 0.15 * back
        pts = np.column_stack([
            hull.stern_x_m - back,
            self.rng.uniform(-1.0, 1.0, n) * half,
            -self.rng.uniform(0.0, noise.spray_height_m, n),
        ])
        return pts.astype(np.float32), np.full(n, SPRAY, np.int8), np.full(n, -1, np.int8)
