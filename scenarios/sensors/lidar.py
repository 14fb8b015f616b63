"""Three simulated LiDARs on the boat (paper, Table "Boat specifications"): point clouds per scan.

A front 64-beam unit on the bow and port/starboard 32-beam units tilted down, 0.5-120 m.
One call renders one 10 Hz scan of all three and returns one merged (N, 3) cloud in the
body frame (x forward, y starboard, z down, origin at the boat's origin on the waterline).

Every beam returns the nearest surface at its own height along its azimuth, among all
walls and obstacles: the water, wall faces and quay tops, the backdrops behind them (and
what stands behind a low quay), piers and moored boats, and what floats above the water
(bridge decks, quay overhangs: their faces, tops and undersides, with piers and boats
below them). Speed comes from the world being vertical prisms (DESIGN.md, LiDAR): each
sensor casts its azimuth columns once in 2-D against every outline, keeping every crossing
and which way it goes (into a wall's land, an obstacle, or out of it). Along a column the
land and the obstacles standing on the water make a height profile, whose first hit moves
away as the elevation rises; so each visible piece of it (a face, a top, the water) is one
interval of tan(elevation), and with the beams stored by column and elevation, one run of
beams: one binary search over all columns' thresholds classifies every beam, and
distances are runs of a + b / -tan(elevation) from per-piece tables. Floating prisms are
then tested beam by beam in the columns they cover, each stretch inside a footprint (a
sensor under a deck starts inside one), the nearer hit winning. Beams blocked by the
boat's own hull and cabin return the hull (detection crops them). Range noise, dropouts,
speckle off the water and spray in the wake are drawn from one seeded generator. No
Python loop runs over beams, edges or columns: a scan is a few dozen array operations
(~4-6 ms for the ~116k beams of the default suite on the shared 2-core development
machine, `canalnav bench detection`). The cloud is float32 and comes as the (N, 3) view of a
(3, N) buffer, so each coordinate is contiguous.

A scan can be taken at a simulation time (obstacles removed by then are not rendered) and
with extra prisms for that scan only (other vessels where they are now).

Simplifications, on purpose: the boat does not roll or pitch (the sensors' mounting tilt
is kept); each beam takes the azimuth of its column (for the tilted units up to half a
column off); surfaces are vertical prisms, so a sloped bank or a rounded hull is a step;
every surface returns (no reflectivity, no mixed returns at edges, no beam divergence);
behind the end of a wall the land is not defined: a ray that enters a wall's land keeps
it past the wall's end, one that goes round the end meets the water, and a wall's face
and a backdrop's front stand as thin surfaces where a ray meets them from behind; a ray
that meets a polygon's vertex exactly passes it (the vertical line there is not hit).
"""

from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from controller.errors import InputError
from controller.kernels import Kernel, pointer

from ..world.canal import CanalWorld, Obstacle, obstacle_edges

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


def _pcg64_bytes16(bitgen: np.random.PCG64, n: int) -> np.ndarray:
    """What `Generator.bytes(2 n)` gives as n uint16 (n >= 1), about four times faster.

    `bytes` draws ceil(2 n / 4) full-range uint32 and keeps their little-endian bytes; a PCG64
    serves uint32 as the low then the high half of each 64-bit output, holding a spare high
    half in its state (`has_uint32`, `uinteger`). Here the halves come from `random_raw`
    (which leaves that spare alone) and the spare is set as the uint32 draws would leave it.
    """
    m = (2 * n - 1) // 4 + 1
    state = bitgen.state
    out = np.empty(m, np.uint32)
    k = 0
    if state["has_uint32"]:
        out[0] = state["uinteger"]
        k = 1
    rest = m - k
    halves = bitgen.random_raw((rest + 1) // 2).astype("<u8", copy=False).view("<u4")
    out[k:] = halves[:rest]
    state = bitgen.state
    state["has_uint32"], state["uinteger"] = (1, int(halves[-1])) if rest % 2 else (0, 0)
    bitgen.state = state
    return out.astype("<u4", copy=False).view("<u2")[:n]


def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


def _by_solid(group, t, enter, order):
    """Crossings in `order` (by column and solid, then distance) less the pairs where a ray
    only touches a solid: entering and leaving it at one point (a vertex met exactly,
    whose two legs then come in either order). Returns that order and where each (column,
    solid) group starts."""
    g = group[order]
    same = g[1:] == g[:-1]
    touch = same & (enter[order[1:]] != enter[order[:-1]])
    touch &= np.abs(t[order[1:]] - t[order[:-1]]) <= 1e-7
    if touch.any():
        keep = np.ones(len(g), bool)
        keep[:-1] &= ~touch
        keep[1:] &= ~touch
        order, g = order[keep], g[keep]
    return order, np.r_[True, g[1:] != g[:-1]]


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

    _made: dict = {}  # (mount, hull) -> _Sensor, this process's (`of`)

    @classmethod
    def of(cls, mount: LidarMount, hull: HullShape) -> "_Sensor":
        """The tables of a mount on a hull, computed once per process (~25 ms a mount; a
        study or the tests build many simulators): read-only, so simulators share them."""
        key = (mount, hull)
        try:
            made = cls._made.get(key)
        except TypeError:  # unhashable fields: compute afresh
            return cls(mount, hull)
        if made is None:
            if len(cls._made) >= 32:
                cls._made.clear()
            made = cls._made[key] = cls(mount, hull)
            for value in vars(made).values():
                if isinstance(value, np.ndarray):
                    value.setflags(write=False)
        return made

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


# The renderer's kinds of solid along a column: a wall's land (its quay top), the backdrop
# behind it, an obstacle standing on the water (a pier, a moored boat) and one floating
# above it (a bridge deck, an overhang).
_LAND, _BACK, _STANDING, _FLOATING = range(4)
# The label of a face and of a top by kind; index 4 is no solid: the water.
_FACE_LABEL = np.array([FACE, BACKDROP, OBSTACLE, OBSTACLE, WATER], np.int8)
_TOP_LABEL = np.array([GROUND, BACKDROP, OBSTACLE, OBSTACLE, WATER], np.int8)
_NEG_INF_KEY = int(_ordered(np.float32([-np.inf]))[0])
_SOLID_BITS = 24  # a profile key: float32 height as ordered int << 24 | (solid + 1)
_i64, _ptr, _f64 = ctypes.c_int64, ctypes.c_void_p, ctypes.c_double
_profile_kernel = Kernel(Path(__file__).with_name("lidar_profile.c"), {
    "lidar_profile": (ctypes.c_int, [_i64] + [_ptr] * 13 + [ctypes.c_int8] + [_ptr] * 2),
    "lidar_edge_rows": (_i64, [_i64, _ptr, _ptr, _ptr, _f64, _f64, _i64, _ptr, _i64, _ptr,
                               _ptr]),
    "lidar_cast": (_i64, [_i64, _i64, _ptr, _ptr, _ptr, _f64] + [_ptr] * 10
                   + [_f64] * 3 + [_i64] + [_ptr] * 4),
    "lidar_columns": (ctypes.c_int, [_i64] + [_ptr] * 4 + [_i64, _f64] + [_ptr] * 4),
    "lidar_in_range": (_i64, [_i64] + [_ptr] * 4),
    "lidar_keep": (_i64, [_i64, _ptr, _ptr, _ptr, ctypes.c_int, ctypes.c_int, ctypes.c_int8,
                          _ptr, _ptr]),
    "lidar_points": (None, [_i64, _ptr, _ptr, _ptr, _ptr, ctypes.c_float, _ptr, _ptr, _i64,
                            _i64, _ptr, _ptr, _ptr, ctypes.c_int8, _ptr, _i64]),
    "lidar_hull": (None, [_i64, _ptr, _ptr, _ptr, _i64, _ptr, ctypes.c_float, _ptr, _i64])})
"""The renderer's compiled passes (call it: the library, or None to render with numpy)."""


@dataclass(frozen=True, eq=False)
class _Scene:
    """What one scan renders: every leg a -> b of every outline with the solid it bounds and
    the side of the leg that solid lies on (+1 right, -1 left), and per solid its kind and
    heights (top; bottom for obstacles, 0 otherwise)."""

    a: np.ndarray
    b: np.ndarray
    owner: np.ndarray
    side: np.ndarray
    kind: np.ndarray
    top: np.ndarray
    bottom: np.ndarray

    @classmethod
    def of_walls(cls, world: CanalWorld) -> "_Scene":
        """The walls' faces (solid w: the land of wall w) and backdrops (solid W + w)."""
        fa, fb, _, fo, fside = world.edges["face"]
        ba, bb, _, _, bo, bside = world.edges["backdrop"]
        n = len(world.walls)
        return cls(np.concatenate([fa, ba]), np.concatenate([fb, bb]),
                   np.concatenate([fo, n + bo]).astype(np.intp), np.concatenate([fside, bside]),
                   np.repeat(np.int8([_LAND, _BACK]), n),
                   np.array([w.height_m for w in world.walls]
                            + [w.backdrop_height_m for w in world.walls], float),
                   np.zeros(2 * n))

    @cached_property
    def a_c(self) -> np.ndarray:  # (the kernels' views: contiguous, of their C types)
        return np.ascontiguousarray(self.a, np.float64)

    @cached_property
    def b_c(self) -> np.ndarray:
        return np.ascontiguousarray(self.b, np.float64)

    @cached_property
    def owner_c(self) -> np.ndarray:
        return np.ascontiguousarray(self.owner, np.int64)

    @cached_property
    def side_c(self) -> np.ndarray:
        return np.ascontiguousarray(self.side, np.float64)

    @cached_property
    def kind_c(self) -> np.ndarray:
        return np.ascontiguousarray(self.kind, np.int8)

    @cached_property
    def top_c(self) -> np.ndarray:
        return np.ascontiguousarray(self.top, np.float64)

    @cached_property
    def at(self) -> dict:
        """The addresses of the kernels' views (they live as long as the scene)."""
        return {name: pointer(getattr(self, name)) for name in (
            "a_c", "b_c", "owner_c", "side_c", "kind_c", "top_c", "profile_key")}

    def reach_len(self, reach: float) -> np.ndarray:
        """Per edge: `reach` plus its length (`LidarSimulator._cast`'s test of which edges
        are near), kept for the last `reach` asked."""
        cached = self.__dict__.get("_reach_len")
        if cached is None or cached[0] != reach:
            cached = (reach, np.ascontiguousarray(reach + np.hypot(*(self.b - self.a).T)))
            self.__dict__["_reach_len"] = cached
        return cached[1]

    @cached_property
    def profile_key(self) -> np.ndarray:
        """Per solid: a key that orders by top height, ties by index; its low bits hold
        the solid's index + 1 (0 is the water)."""
        return (_ordered(self.top) << _SOLID_BITS) + np.arange(1, len(self.kind) + 1)

    def with_obstacles(self, obstacles) -> "_Scene":
        """This scene and the obstacles (solids numbered after this scene's)."""
        a, b, owner, zb, zt, side = obstacle_edges(obstacles)
        kind = np.where(zb > 0.0, _FLOATING, _STANDING).astype(np.int8)
        cat = np.concatenate
        return _Scene(cat([self.a, a]), cat([self.b, b]), cat([self.owner, owner + len(self.kind)]),
                      cat([self.side, side]), cat([self.kind, kind]), cat([self.top, zt]),
                      cat([self.bottom, zb]))

    def without(self, absent: np.ndarray) -> "_Scene":
        """The scene without the edges of the solids marked `absent` (their tables stay)."""
        keep = np.flatnonzero(~absent[self.owner])
        return _Scene(self.a[keep], self.b[keep], self.owner[keep], self.side[keep], self.kind,
                      self.top, self.bottom)


class LidarSimulator:
    """Renders scans of a canal world from a boat pose; one seeded generator for all noise."""

    def __init__(self, world: CanalWorld, config: LidarConfig | None = None,
                 seed: int | np.random.Generator | None = 0, compiled: bool = True) -> None:
        self.world = world
        self.compiled = compiled  # False: the numpy version of every step (the reference)
        self.config = config or LidarConfig()
        self.rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        self.sensors = [_Sensor.of(m, self.config.hull) for m in self.config.mounts]
        self._beams = _Beams.join(self.sensors)
        self._bin_height = np.concatenate([np.full(s.bins, s.mount.height_m) for s in self.sensors])
        self._beam_start = np.concatenate([[0], np.cumsum([len(s.bin) for s in self.sensors])[:-1]])
        self._normals = self.rng.standard_normal(1 << 20, dtype=np.float32)
        # Exact per-bin thresholding on tan(elevation) by binary search: each beam's key is
        # bin * 2**32 + its float32 tan as an order-preserving integer (sorted, exact).
        beams = self._beams
        self._keys = (beams.bin.astype(np.int64) << 32) + _ordered(beams.tan_el)
        self._n_bins = n_bins = int(sum(s.bins for s in self.sensors))
        self._bin_first = np.searchsorted(beams.bin, np.arange(n_bins + 1))  # beam range per bin
        self._bin_first64 = self._bin_first.astype(np.int64)
        self._bin_index = np.arange(n_bins)
        self._bin_key = self._bin_index.astype(np.int64) << 32
        # Each bin's lowest and highest beam key (an empty bin: nothing is inside its range).
        filled = self._bin_first[1:] > self._bin_first[:-1]
        self._bin_lo_key = np.where(filled, self._keys[np.minimum(self._bin_first[:-1],
                                                                  len(self._keys) - 1)],
                                    self._bin_key + (1 << 32) - 1)
        self._bin_hi_key = np.where(filled, self._keys[self._bin_first[1:] - 1], 0)
        self.max_range_m = max(m.max_range_m for m in self.config.mounts)
        self._reach = self.max_range_m + 10.0
        self._t_scale = 2.0 ** math.ceil(math.log2(self._reach + 1.0))  # sort key bin * scale + t
        # The world's own scene, and the same without obstacles gone at some time (cached).
        self._scene = _Scene.of_walls(world).with_obstacles(world.obstacles)
        self._first_obstacle = 2 * len(world.walls)
        self._scene_present: dict[bytes, _Scene] = {}
        counts = np.array([s.bins for s in self.sensors])
        self._bin_count = counts
        self._bin_offset = np.concatenate([[0], np.cumsum(counts)[:-1]])
        self._bin_step = 2.0 * np.pi / counts
        self._bin_offset64 = self._bin_offset.astype(np.int64)
        self._bin_count64 = counts.astype(np.int64)
        self._beam_start64 = self._beam_start.astype(np.int64)
        self._origins32 = np.ascontiguousarray([s.origin_body for s in self.sensors], np.float32)
        local = np.arange(counts.sum()) - np.repeat(self._bin_offset, counts)
        self._bin_cos = np.cos(local * np.repeat(self._bin_step, counts))
        self._bin_sin = np.sin(local * np.repeat(self._bin_step, counts))
        self._rows_buf = np.empty(0, np.int64)  # the compiled cast's scratch, grown as needed
        self._offsets_buf = np.empty((2, 0))
        self._cast_room = 1 << 14  # its room for crossings, grown as needed
        b = self._beams  # addresses of the fixed tables the kernels read (they live as long)
        self._at = {name: arr.ctypes.data for name, arr in (
            ("bin_offset", self._bin_offset64), ("bin_count", self._bin_count64),
            ("bin_step", self._bin_step),
            ("bin_cos", self._bin_cos), ("bin_sin", self._bin_sin),
            ("bin_height", self._bin_height), ("bin_first", self._bin_first64),
            ("tan_el", b.tan_el), ("inv_drop", b.inv_drop), ("min_h", b.min_h),
            ("max_h", b.max_h), ("cos_el", b.cos_el), ("vec", b.vec),
            ("hull_points", b.hull_points), ("hull_unit", b.hull_unit),
            ("beam_start", self._beam_start64), ("origins", self._origins32),
            ("face_label", _FACE_LABEL), ("top_label", _TOP_LABEL))}

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

    def scan(self, pose, speed_mps: float = 0.0, time_s: float | None = None,
             extra_obstacles=()) -> np.ndarray:
        """One merged scan at pose (x, y, psi): (N, 3) float32 (as LiDAR drivers deliver),
        body frame, z down, origin at the boat's origin on the waterline. (Column-major:
        `np.ascontiguousarray` gives row-major points if a consumer needs them.)

        `time_s`: the simulation time; only the obstacles in the water then are rendered
        (None: all of them). `extra_obstacles`: more prisms for this scan only (outlines in
        the inertial frame, e.g. other vessels at their pose now), rendered like the world's
        and as given (their `remove_at_s` is not consulted).
        """
        return self._scan(pose, speed_mps, time_s, extra_obstacles, labelled=False).points

    def scan_labelled(self, pose, speed_mps: float = 0.0, time_s: float | None = None,
                      extra_obstacles=()) -> LidarScan:
        """One merged scan with what each point hit (for tests, figures and benchmarks)."""
        return self._scan(pose, speed_mps, time_s, extra_obstacles, labelled=True)

    def _scan(self, pose, speed_mps, time_s, extra_obstacles, labelled: bool) -> LidarScan:
        """The scan; the labels and sensors only if `labelled` (the points are the same
        either way, and so is every draw of the generator)."""
        pose = np.asarray(pose, float).reshape(-1)
        if pose.shape != (3,) or not np.all(np.isfinite(pose)):
            raise InputError(f"lidar: pose must be three finite numbers (x, y, psi), got {pose}")
        scene = self._scene_at(time_s, extra_obstacles)
        origins = self.sensor_positions(pose)
        spray = self._spray(speed_mps)
        n_spray = len(spray[1])
        t_all, label = self._distances(scene, *self._cast(scene, origins, pose[2]))
        columns, labels, sensor = self._render(t_all, label, n_spray=n_spray, labelled=labelled)
        if n_spray:
            columns[:, -n_spray:] = spray[0].T
        # (N, 3) view of the (3, N) buffer: no copy, and each coordinate is contiguous.
        if not labelled:
            return LidarScan(columns.T, None, None)
        return LidarScan(columns.T, np.concatenate([labels, spray[1]]),
                         np.concatenate([sensor, spray[2]]))

    # -- rendering ----------------------------------------------------------------------
    def _scene_at(self, time_s, extra_obstacles) -> _Scene:
        """The world's scene at `time_s` (obstacles removed by then left out), plus extras."""
        scene = self._scene
        if time_s is not None:
            if isinstance(time_s, bool) or not isinstance(time_s, (int, float, np.number)) \
                    or not math.isfinite(time_s):
                raise InputError(f"lidar: time_s must be a finite number of seconds or None, "
                                 f"got {time_s!r}")
            if self.world.changes:
                present = self.world.obstacles_present(float(time_s))
                key = present.tobytes()
                if key not in self._scene_present:
                    absent = np.zeros(len(scene.kind), bool)
                    absent[self._first_obstacle:] = ~present
                    self._scene_present[key] = scene.without(absent)
                scene = self._scene_present[key]
        extra = tuple(extra_obstacles)
        if extra:
            bad = [o for o in extra if not isinstance(o, Obstacle)]
            if bad:
                raise InputError(f"lidar: extra_obstacles must be Obstacle objects, got "
                                 f"{type(bad[0]).__name__}")
            scene = scene.with_obstacles(extra)
        return scene

    def _cast(self, scene: _Scene, origins, psi):
        """The 2-D cast of every azimuth bin of every sensor (bins numbered across sensors):
        every crossing of a bin's ray with an edge within reach, as (bin, horizontal
        distance, solid, whether the ray enters the solid there).

        Each edge is paired only with the bins inside its angular span as a sensor sees it,
        so the work grows with bins times surfaces crossed, not bins times all edges. Which
        way a ray crosses is the sign of its cross product with the edge, against the side
        the solid lies on.
        """
        lib = _profile_kernel() if self.compiled else None
        if lib is not None:
            return self._cast_compiled(lib, scene, origins, psi)
        a, b = scene.a, scene.b
        reach = self._reach
        centre = origins.mean(axis=0)
        near = np.minimum(np.hypot(*(a - centre).T), np.hypot(*(b - centre).T))
        keep = np.flatnonzero(near < reach + np.hypot(*(b - a).T))
        if not len(keep):
            return np.zeros(0, np.intp), np.zeros(0), np.zeros(0, np.intp), np.zeros(0, bool)
        # One row per (sensor, edge).
        n_s, n_e = len(origins), len(keep)
        edge = np.tile(keep.astype(np.int64), n_s)
        sensor = np.repeat(np.arange(n_s), n_e)
        o = origins[sensor]
        step = self._bin_step[sensor]
        ea, eb = a[edge], b[edge]
        ang_a = np.arctan2(ea[:, 1] - o[:, 1], ea[:, 0] - o[:, 0]) - psi
        ang_b = np.arctan2(eb[:, 1] - o[:, 1], eb[:, 0] - o[:, 0]) - psi
        span = (ang_b - ang_a + np.pi) % (2 * np.pi) - np.pi
        lo = np.where(span < 0, ang_b, ang_a)
        hi = np.where(span < 0, ang_a, ang_b)
        # Bins from each end's own angle (and whole turns), so two legs meeting at a vertex
        # agree on whether a bin's ray passes there (both take it, or neither).
        k0 = np.ceil(lo / step).astype(np.int64)
        turns = np.rint((lo + np.abs(span) - hi) / (2 * np.pi)).astype(np.int64)
        k1 = np.floor(hi / step).astype(np.int64) + turns * self._bin_count[sensor]
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
        den = _cross(cp * cb - sp * sb, sp * cb + cp * sb, ex, ey)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = _cross(ea[row, 0] - o[row, 0], ea[row, 1] - o[row, 1], ex, ey) / den
        ok = np.flatnonzero((t > 1e-6) & (t <= reach))  # (inf and nan fail both)
        gbin, t, den, e = gbin[ok], t[ok], den[ok], edge[row[ok]]
        # The solid lies on side +1 (right of a -> b) or -1: the ray enters it where the
        # ray's cross product with the edge (den) has the opposite sign.
        return gbin, t, scene.owner[e], scene.side[e] * den < 0.0

    def _cast_compiled(self, lib, scene: _Scene, origins, psi):
        """`_cast` by the kernels of `lidar_profile.c`, bit for bit the same: the near edges'
        rows (and their ends' offsets), numpy's arctan2 of those, then the crossings."""
        centre = origins.mean(axis=0)
        origins = np.ascontiguousarray(origins, float)
        n_e, n_s = len(scene.a), len(origins)
        room = n_e * n_s
        if len(self._rows_buf) < room:
            self._rows_buf = np.empty(room, np.int64)
            self._offsets_buf = np.empty((2, 2 * room))
        rows, d, p = self._rows_buf, self._offsets_buf, pointer
        sat = scene.at
        n_rows = lib.lidar_edge_rows(n_e, sat["a_c"], sat["b_c"],
                                     p(scene.reach_len(self._reach)), float(centre[0]),
                                     float(centre[1]), n_s, p(origins), d.shape[1] // 2,
                                     p(rows), p(d))
        if n_rows <= 0:
            return np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64), np.zeros(0, bool)
        ang = np.arctan2(d[0, :2 * n_rows], d[1, :2 * n_rows])
        at, cp, sp = self._at, math.cos(psi), math.sin(psi)
        while True:
            room = self._cast_room
            gbin, t = np.empty(room, np.int64), np.empty(room)
            owner, enter = np.empty(room, np.int64), np.empty(room, np.uint8)
            n = lib.lidar_cast(n_rows, n_rows // n_s, p(rows), p(ang), p(ang) + 8 * n_rows,
                               float(psi), sat["a_c"], sat["b_c"], sat["owner_c"],
                               sat["side_c"], p(origins), at["bin_offset"], at["bin_count"],
                               at["bin_step"], at["bin_cos"], at["bin_sin"], cp, sp,
                               float(self._reach), room, p(gbin), p(t), p(owner), p(enter))
            if n >= 0:
                return gbin[:n], t[:n], owner[:n], enter[:n].view(bool)
            self._cast_room = 2 * (-n - 1)

    def _distances(self, scene: _Scene, gbin, t, owner, enter):
        """Every world-facing beam's horizontal distance to the first surface it meets
        (inf: none) and that surface's label, from the crossings of `_cast`.

        Along a column the walls' land, the backdrops and the obstacles standing on the
        water make a height profile (`_profile`); what floats above the water is then
        tested beam by beam in the columns it covers (`_floating`), the nearer hit winning.
        """
        floating = scene.kind[owner] == _FLOATING
        if floating.any():
            ground = np.flatnonzero(~floating)
            t_all, label = self._profile(scene, gbin[ground], t[ground], owner[ground],
                                         enter[ground])
            fl = np.flatnonzero(floating)
            self._floating(scene, gbin[fl], t[fl], owner[fl], enter[fl], t_all, label)
            return t_all, label
        return self._profile(scene, gbin, t, owner, enter)

    def _profile(self, scene: _Scene, gbin, t, owner, enter):
        """First hits against the height profile of every column (`_profile_numpy`'s
        method) by the compiled kernel `lidar_profile.c`, bit for bit the same; the numpy
        version where no kernel can be built."""
        lib = _profile_kernel() if self.compiled else None
        if lib is None:
            return self._profile_numpy(scene, gbin, t, owner, enter)
        m = len(t)
        gbin = np.ascontiguousarray(gbin, np.int64)
        t_in = np.ascontiguousarray(t, np.float64)
        owner_in = np.ascontiguousarray(owner, np.int64)
        enter_in = np.ascontiguousarray(enter).view(np.uint8)
        t, owner, enter = np.empty(m), np.empty(m, np.int64), np.empty(m, np.uint8)
        first = np.empty(self._n_bins + 1, np.int64)
        p = pointer
        if lib.lidar_columns(m, p(gbin), p(t_in), p(owner_in), p(enter_in), self._n_bins,
                             float(self._t_scale), p(first), p(t), p(owner), p(enter)):
            raise MemoryError("lidar: the column sort ran out of memory")
        n = len(self._keys)
        t_all = np.empty(n, np.float32)
        label = np.empty(n, np.int8)
        at = self._at
        sat = scene.at
        rc = lib.lidar_profile(
            self._n_bins, p(first), p(t), p(owner), p(enter), sat["kind_c"], sat["top_c"],
            sat["profile_key"], at["bin_height"], at["bin_first"], at["tan_el"], at["inv_drop"],
            at["face_label"], at["top_label"], WATER, p(t_all), p(label))
        if rc != 0:
            raise MemoryError("lidar: the profile kernel ran out of memory")
        return t_all, label

    def _profile_numpy(self, scene: _Scene, gbin, t, owner, enter):
        """First hits against the height profile of every column, for all beams at once.

        The crossings of a column, sorted by distance, cut it into segments; on each the
        profile's height is the highest solid there (water: 0). A solid is there after a
        crossing that enters it until its next crossing; an obstacle is there from the
        sensor on if the column's first crossing of it leaves it (the sensor is inside).
        Wall faces and backdrop fronts also stand where a ray meets them from the land
        side (a wall's back, seen past the end of a bank).

        For a profile the first hit moves away as the elevation rises (a higher beam passes
        over where a lower one hit), so with C_i the least tan(elevation) that clears
        segments 0..i-1 and F_i the tan to the top of segment i's face, a beam of segment
        i's column meets that face for tan in (C_i, F_i] and its top in (max(C_i, F_i),
        C_i+1]; above the last C: sky. As beams are stored by column and elevation, every
        piece is one run of beams, found by one binary search of all (bin, tan) keys, and
        its distance is a + b / -tan(elevation): the face's distance, or (h - height) for a
        top. No Python loop runs over beams, crossings or columns.
        """
        n_cols = self._n_bins
        order = np.argsort(gbin * self._t_scale + t, kind="stable")  # (runs of bins: fast)
        gbin, t, owner, enter = gbin[order], t[order], owner[order], enter[order]
        n_ev = len(t)
        count = np.bincount(gbin, minlength=n_cols)
        first = np.zeros(n_cols + 1, np.intp)  # column c's crossings: first[c]:first[c + 1]
        np.cumsum(count, out=first[1:])
        n_seg = n_ev + n_cols  # segment 0 of each column, then one after each crossing
        seg_col = np.repeat(self._bin_index, count + 1)
        seg0 = first[:-1] + np.arange(n_cols)  # each column's first segment
        ev_seg = np.arange(n_ev) + gbin + 1  # the segment each crossing starts
        kind = scene.kind[owner]

        # Which solid is highest on each segment: each solid's stretches are segment ranges,
        # expanded into (segment, solid) pairs and reduced by a maximum of keys that order
        # by height (ties: the later solid).
        group = gbin * len(scene.kind) + owner
        # (Stable: distance order within a group. 16-bit keys sort by radix, several times
        # faster.)
        by_solid, new = _by_solid(group, t, enter, np.argsort(
            group.astype(np.uint16) if n_cols * len(scene.kind) <= 1 << 16 else group,
            kind="stable"))
        nxt = np.empty(len(by_solid), np.intp)
        nxt[:-1] = by_solid[1:]
        col = gbin[by_solid]
        last = np.r_[new[1:], True]
        nxt = np.where(last, first[col + 1], nxt)  # the solid's next crossing, or column end
        ent = enter[by_solid]
        inside = new & ~ent & (kind[by_solid] == _STANDING)
        use = np.flatnonzero(ent | inside)
        p, c = by_solid[use], col[use]
        start = np.where(ent[use], p + c + 1, seg0[c])
        stop = np.where(ent[use], nxt[use] + c + 1, p + c + 1)
        length = stop - start
        pair = np.repeat(start - np.cumsum(length) + length, length) + np.arange(int(length.sum()))
        key = np.zeros(n_seg, np.int64)  # 0: the water, height 0
        np.maximum.at(key, pair, np.repeat(scene.profile_key[owner[p]], length))
        top_of = (key & ((1 << _SOLID_BITS) - 1)) - 1
        solid = top_of >= 0
        height = np.where(solid, scene.top[top_of], 0.0)
        seg_kind = np.where(solid, scene.kind[top_of], 4)
        # Wall faces and backdrop fronts stand at every crossing, from either side.
        fin = np.zeros(n_seg)
        fin_kind = np.full(n_seg, 4)
        wallish = np.flatnonzero(kind <= _BACK)
        fin[ev_seg[wallish]] = scene.top[owner[wallish]]
        fin_kind[ev_seg[wallish]] = kind[wallish]
        face_height = np.maximum(height, fin)
        face_kind = np.where(fin > height, fin_kind, seg_kind)

        start_m = np.zeros(n_seg)
        start_m[ev_seg] = t
        end_m = np.full(n_seg, np.inf)
        end_m[ev_seg - 1] = t
        h = self._bin_height[seg_col]
        with np.errstate(divide="ignore", invalid="ignore"):
            f = (face_height - h) / start_m  # +-inf at a column's start
            clear = np.where(height < h, (height - h) / end_m, (height - h) / start_m)
        f[np.isnan(f)] = -np.inf
        clear[np.isnan(clear)] = np.inf
        colkey = self._bin_key[seg_col]
        key_f = colkey + _ordered(f)
        c_next = np.maximum.accumulate(np.maximum(key_f, colkey + _ordered(clear)))
        c_here = np.empty(n_seg, np.int64)
        c_here[1:] = c_next[:-1]
        c_here[seg0] = self._bin_key + _NEG_INF_KEY
        # Per column the pieces face_0, top_0, face_1, ..., top_last, sky start at the beams
        # past C_0, F_0', C_1, ..., F_last', C_end (F' = max(C, F)).
        found = self._beams_at_or_below(np.column_stack([np.maximum(c_here, key_f), c_next])
                                        .ravel(), np.repeat(seg_col, 2)).reshape(-1, 2)
        q = 2 * np.arange(n_seg) + seg_col
        q_sky = 2 * (first[1:] + np.arange(n_cols)) + np.arange(n_cols) + 2
        q1, q2 = q + 1, q + 2
        bound = np.empty(n_seg * 2 + n_cols, np.int64)
        bound[q[seg0]] = self._bin_first[:-1]
        bound[q1] = found[:, 0]
        bound[q2] = found[:, 1]
        runs = np.diff(bound, append=len(self._keys))
        f32 = np.float32
        a = np.zeros(len(bound), f32)
        b = np.zeros(len(bound), f32)
        lab = np.empty(len(bound), np.int8)
        a[q], lab[q] = start_m, _FACE_LABEL[face_kind]
        b[q1], lab[q1] = h - height, _TOP_LABEL[seg_kind]
        a[q_sky], lab[q_sky] = np.inf, WATER
        t_all = np.repeat(a, runs)
        t_all += np.repeat(b, runs) * self._beams.inv_drop
        return t_all, np.repeat(lab, runs)

    def _beams_at_or_below(self, key, col):
        """For sorted (bin, tan) keys, each in the bin `col`: how many beams have a key at
        or below it (`searchsorted` right). Keys outside their bin's range of beams and
        repeated keys, most of them, are answered without a search."""
        above = key >= self._bin_lo_key[col]
        out = self._bin_first[col + above]
        inside = np.flatnonzero(above & (key < self._bin_hi_key[col]))
        if len(inside):
            v = key[inside]
            new = np.empty(len(v), bool)
            new[0] = True
            np.not_equal(v[1:], v[:-1], out=new[1:])
            out[inside] = np.searchsorted(self._keys, v[new], "right")[np.cumsum(new) - 1]
        return out

    def _floating(self, scene: _Scene, gbin, t, owner, enter, t_all, label) -> None:
        """Solids above the water (bridge decks, overhangs): where a beam meets one (face,
        top or underside) before its profile hit, set its distance and label. Each stretch
        of a column inside a footprint (a concave outline gives several; a sensor under
        it starts inside) is tested against the beams of that column only."""
        order, new = _by_solid(gbin * len(scene.kind) + owner, t, enter,
                               np.lexsort((t, owner, gbin)))
        gbin, t, owner, enter = gbin[order], t[order], owner[order], enter[order]
        t_next = np.r_[t[1:], np.inf]
        t_next[np.r_[new[1:], True]] = np.inf
        lead = np.flatnonzero(new & ~enter)  # first crossing leaves: inside from the sensor on
        ent = np.flatnonzero(enter)
        cols = np.concatenate([gbin[ent], gbin[lead]])
        t_in = np.concatenate([t[ent], np.zeros(len(lead))])
        t_out = np.concatenate([t_next[ent], t[lead]])
        who = np.concatenate([owner[ent], owner[lead]])
        by_col = np.argsort(cols, kind="stable")
        cols, t_in, t_out, who = cols[by_col], t_in[by_col], t_out[by_col], who[by_col]
        # A column crossing several footprints: one layer of stretches at a time, so each
        # beam is written at most once per layer and the nearest hit wins.
        layer = np.arange(len(cols)) - np.searchsorted(cols, cols)
        beams = self._beams
        first = self._bin_first
        f32 = np.float32
        for k in range(int(layer.max()) + 1 if len(layer) else 0):
            sel = np.flatnonzero(layer == k)
            cb = cols[sel]
            runs = first[cb + 1] - first[cb]
            idx = np.repeat(first[cb] - np.cumsum(runs) + runs, runs) + np.arange(int(runs.sum()))
            rep = np.repeat(sel, runs)
            tan = beams.tan_el[idx]
            h = beams.height[idx]
            tin, tout = t_in.astype(f32)[rep], t_out.astype(f32)[rep]
            zlo, zhi = scene.bottom.astype(f32)[who[rep]], scene.top.astype(f32)[who[rep]]
            zi = h + tin * tan
            inv = beams.inv_drop[idx]  # 1 / -tan going down, 0 going up
            t_top = np.where(inv > 0, (h - zhi) * inv, np.inf)
            with np.errstate(divide="ignore", invalid="ignore"):
                t_under = np.where(tan > 0, (zlo - h) / tan, np.inf)
            hit = np.where((tin > 0) & (zi >= zlo) & (zi <= zhi), tin, np.inf)
            hit = np.where((zi > zhi) & (t_top > tin) & (t_top < tout), t_top, hit)
            hit = np.where((zi < zlo) & (t_under > tin) & (t_under < tout), t_under, hit)
            nearer = np.flatnonzero(hit < t_all[idx])  # sky is at infinity
            t_all[idx[nearer]] = hit[nearer]
            label[idx[nearer]] = OBSTACLE

    def _render(self, t_all, label, n_spray=0, labelled=True):
        """The scan from every beam's first-hit distance and label: beams within range,
        dropouts and speckle off the water, range noise, the points, the own hull's returns
        (with room for the spray after them); their labels and sensors if `labelled`."""
        lib = _profile_kernel() if self.compiled else None
        if lib is not None:
            return self._render_compiled(lib, t_all, label, n_spray, labelled)
        beams = self._beams
        noise = self.config.noise
        rng = self.rng
        f32 = np.float32
        # Beams within range (sky is infinitely far), then dropouts and speckle.
        returns = t_all >= beams.min_h
        returns &= t_all <= beams.max_h
        idx = np.flatnonzero(returns)
        lab = label[idx]
        u = self._uniform16(len(idx))
        drop, speckle = _level16(noise.dropout), _level16(noise.dropout + noise.water_speckle)
        keep = (u >= drop) & ((lab != WATER) | (u < speckle))
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
        water = np.flatnonzero(lab == WATER)
        if len(water):
            pts[2, water] -= rng.uniform(-1.0, 1.0, len(water)).astype(f32) * f32(
                noise.water_ripple_m)

        # Own hull: fixed returns, with dropouts and range noise.
        hull = out[:, n:n + m]
        beams.hull_points.take(hull_keep, axis=1, out=hull)
        hull += beams.hull_unit.take(hull_keep, axis=1) * (
            self._normal(m) * f32(noise.range_sigma_m))
        if not labelled:
            return out, None, None
        return (out,
                np.concatenate([lab, np.full(m, HULL, np.int8)]),
                np.concatenate([beams.sensor[idx], beams.hull_sensor[hull_keep]]))

    def _render_compiled(self, lib, t_all, label, n_spray, labelled):
        """`_render` with its per-beam passes compiled: the same draws of the generator in
        the same order, the same float32 arithmetic, the same scan bit for bit."""
        beams = self._beams
        noise = self.config.noise
        f32 = np.float32
        p = pointer
        t_all = np.ascontiguousarray(t_all, f32)
        label = np.ascontiguousarray(label, np.int8)
        idx = np.empty(len(t_all), np.int64)
        at = self._at
        n_ret = lib.lidar_in_range(len(t_all), p(t_all), at["min_h"], at["max_h"], p(idx))
        u = np.ascontiguousarray(self._uniform16(n_ret))
        drop, speckle = _level16(noise.dropout), _level16(noise.dropout + noise.water_speckle)
        lab = np.empty(n_ret, np.int8)
        n_water = ctypes.c_int64(0)
        n = lib.lidar_keep(n_ret, p(idx), p(label), p(u), drop, speckle, WATER, p(lab),
                           ctypes.byref(n_water))
        idx, lab = idx[:n], lab[:n]
        normal = np.ascontiguousarray(self._normal(n), f32)
        hull_keep = np.flatnonzero(self._uniform16(beams.hull_points.shape[1]) >= drop)
        m = len(hull_keep)
        out = np.empty((3, n + m + n_spray), f32)
        ripple = (self.rng.uniform(-1.0, 1.0, n_water.value).astype(f32) * f32(
            noise.water_ripple_m)) if n_water.value else np.zeros(1, f32)
        lib.lidar_points(n, p(idx), p(lab), p(t_all), p(normal), f32(noise.range_sigma_m),
                         at["cos_el"], at["vec"], len(t_all), len(self.sensors),
                         at["beam_start"], at["origins"], p(ripple), WATER, p(out),
                         out.shape[1])
        hull_keep = np.ascontiguousarray(hull_keep, np.int64)
        normal = np.ascontiguousarray(self._normal(m), f32)
        lib.lidar_hull(m, p(hull_keep), at["hull_points"], at["hull_unit"],
                       beams.hull_points.shape[1], p(normal), f32(noise.range_sigma_m),
                       p(out) + 4 * n, out.shape[1])
        if not labelled:
            return out, None, None
        return (out,
                np.concatenate([lab, np.full(m, HULL, np.int8)]),
                np.concatenate([beams.sensor[idx], beams.hull_sensor[hull_keep]]))

    def _uniform16(self, n: int) -> np.ndarray:
        """n uniform 16-bit draws (compare with `_level16`): cheaper than float draws, and
        probabilities resolved to 1/65536. The bytes of `rng.bytes(2 n)`, bit for bit, and
        the generator left as that leaves it (`_pcg64_bytes16`)."""
        if n > 0 and type(self.rng.bit_generator) is np.random.PCG64:
            return _pcg64_bytes16(self.rng.bit_generator, n)
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
