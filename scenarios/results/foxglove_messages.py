"""Foxglove messages from the run's plain data: frames, clouds, walls, segments, plans, fixes.

Pure functions from numpy arrays to `foxglove.messages` objects, shared by the closed loop's
log (`scenarios.results.mcap_log`) and the bridge's. Frames: `map` is the root the viewer
shows (ENU, z up, as ROS's REP 103 wants it); `world` is our NED frame under it (x north,
y east, z down), `boat` the body frame (x forward, y starboard, z down) under `world`, and
each LiDAR under `boat`. Everything is logged in `world` or `boat`, so no NED value is ever
converted by hand: the one static transform map <- world turns the picture right side up.
"""

from __future__ import annotations

import math

import numpy as np

VIZ_EXTRA = "pip install 'canalnav[viz]'"

MAP, WORLD, BOAT, BOAT_ESTIMATE = "map", "world", "boat", "boat_estimate"

# NED -> ENU: x_enu = y_ned, y_enu = x_ned, z_enu = -z_ned, a half turn about (1, 1, 0)/sqrt 2
_NED_TO_ENU = (math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0)  # quaternion x, y, z, w


def require_viz():
    """The Foxglove SDK, or an InputError naming the extra that brings it."""
    try:
        import foxglove  # noqa: F401
        import foxglove.messages  # noqa: F401
    except ImportError:
        from controller.errors import InputError

        raise InputError(f"MCAP logs and the live view need the Foxglove SDK: {VIZ_EXTRA}") \
            from None
    return foxglove


def viz_available() -> bool:
    try:
        require_viz()
    except Exception:  # noqa: BLE001 - any failure to import means "not installed"
        return False
    return True


def ns(time_s: float) -> int:
    """Seconds of the run's clock -> integer nanoseconds (MCAP's log time)."""
    return int(round(float(time_s) * 1e9))


def _stamp(time_s: float):
    from foxglove.messages import Timestamp

    t = ns(time_s)
    return Timestamp(t // 1_000_000_000, t % 1_000_000_000)


def _yaw_quaternion(psi_rad: float):
    from foxglove.messages import Quaternion

    return Quaternion(x=0.0, y=0.0, z=math.sin(0.5 * psi_rad), w=math.cos(0.5 * psi_rad))


def _rotation_quaternion(r: np.ndarray):
    """A rotation matrix -> foxglove Quaternion (Shepperd's method, the larger diagonal)."""
    from foxglove.messages import Quaternion

    r = np.asarray(r, float)
    tr = np.trace(r)
    if tr > 0:
        s = 2.0 * math.sqrt(1.0 + tr)
        q = (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, 0.25 * s
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k])
        v = [0.0, 0.0, 0.0]
        v[i] = 0.25 * s
        v[j] = (r[j, i] + r[i, j]) / s
        v[k] = (r[k, i] + r[i, k]) / s
        q = (*v, (r[k, j] - r[j, k]) / s)
    return Quaternion(x=q[0], y=q[1], z=q[2], w=q[3])


def _transform(time_s, parent, child, xyz, rotation):
    from foxglove.messages import FrameTransform, Vector3

    return FrameTransform(timestamp=_stamp(time_s), parent_frame_id=parent, child_frame_id=child,
                          translation=Vector3(x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2])),
                          rotation=rotation)


def lidar_frames(mounts) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(frame name, translation in the body frame, rotation sensor -> body) per LiDAR mount
    (`scenarios.sensors.lidar.LidarMount`: heights above the waterline, so z = -height)."""
    return [(f"lidar_{m.name}", np.array([m.x_m, m.y_m, -m.height_m]), m.rotation())
            for m in mounts]


def frame_transforms(time_s: float, pose, estimate=None, lidars=()):
    """The frame tree at a time: map <- world (static), world <- boat at `pose` (x, y, psi),
    world <- boat_estimate at `estimate` if given, boat <- each LiDAR (`lidar_frames`)."""
    from foxglove.messages import FrameTransforms, Quaternion

    out = [_transform(time_s, MAP, WORLD, (0, 0, 0), Quaternion(
        x=_NED_TO_ENU[0], y=_NED_TO_ENU[1], z=_NED_TO_ENU[2], w=_NED_TO_ENU[3]))]
    out.append(_transform(time_s, WORLD, BOAT, (pose[0], pose[1], 0.0), _yaw_quaternion(pose[2])))
    if estimate is not None:
        out.append(_transform(time_s, WORLD, BOAT_ESTIMATE, (estimate[0], estimate[1], 0.0),
                              _yaw_quaternion(estimate[2])))
    for name, xyz, rot in lidars:
        out.append(_transform(time_s, BOAT, name, xyz, _rotation_quaternion(rot)))
    return FrameTransforms(transforms=out)


def decimate(points, max_points: int) -> np.ndarray:
    """At most `max_points` of an (N, 3) cloud, every k-th (deterministic, spread over all
    sensors and azimuths), as row-major float32."""
    p = np.asarray(points)
    if max_points <= 0 or not len(p):
        return np.zeros((0, 3), np.float32)
    step = max(1, math.ceil(len(p) / max_points))
    return np.ascontiguousarray(p[::step, :3], dtype=np.float32)


def point_cloud(time_s: float, points, frame_id: str = BOAT):
    """A foxglove PointCloud of (N, 3) float32 points x, y, z in `frame_id` (the body frame)."""
    from foxglove.messages import PackedElementField, PackedElementFieldNumericType, PointCloud

    f32 = PackedElementFieldNumericType.Float32
    data = np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 3)
    return PointCloud(timestamp=_stamp(time_s), frame_id=frame_id, point_stride=12,
                      fields=[PackedElementField(name=n, offset=4 * k, type=f32)
                              for k, n in enumerate("xyz")],
                      data=data.tobytes())


def _color(rgba):
    from foxglove.messages import Color

    return Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])


def _points(xy, z: float = 0.0):
    from foxglove.messages import Point3

    return [Point3(x=float(p[0]), y=float(p[1]), z=z) for p in np.asarray(xy, float).reshape(-1, 2)]


WALL_RGBA = (0.55, 0.55, 0.6, 1.0)
OBSTACLE_RGBA = (0.9, 0.5, 0.1, 1.0)
SEGMENT_RGBA = (0.1, 0.9, 0.3, 1.0)
HORIZON_RGBA = (0.2, 0.6, 1.0, 1.0)
HULL_RGBA = (0.2, 0.6, 1.0, 0.35)
TRACK_RGBA = (1.0, 0.2, 0.6, 0.5)
VESSEL_RGBA = (0.9, 0.9, 0.2, 1.0)


def _entity(time_s, entity_id, frame_id=WORLD, **primitives):
    from foxglove.messages import SceneEntity

    return SceneEntity(timestamp=_stamp(time_s), frame_id=frame_id, id=entity_id, **primitives)


def polylines_update(time_s: float, groups, thickness_m: float = 0.3):
    """Polylines in the world frame (true walls, obstacle outlines): one entity per group
    (entity id, polylines, rgba)."""
    from foxglove.messages import LinePrimitive, LinePrimitiveLineType, SceneUpdate

    entities = []
    for entity_id, polylines, rgba in groups:
        lines = [LinePrimitive(type=LinePrimitiveLineType.LineStrip, thickness=thickness_m,
                               points=_points(p), color=_color(rgba))
                 for p in polylines if len(np.asarray(p).reshape(-1, 2)) >= 2]
        entities.append(_entity(time_s, entity_id, lines=lines))
    return SceneUpdate(entities=entities)


def segments_update(time_s: float, segments, entity_id: str = "segments",
                    rgba=SEGMENT_RGBA, z_m: float = -0.5):
    """Segments (x_c, y_c, theta, length) in the world frame as one line list, drawn half a
    metre above the water (NED z = -0.5) so they sit over the true walls."""
    from controller.geometry import segments_to_endpoints
    from foxglove.messages import LinePrimitive, LinePrimitiveLineType, SceneUpdate

    a, b = segments_to_endpoints(segments)
    ends = np.empty((2 * len(a), 2))
    ends[0::2], ends[1::2] = a, b
    line = LinePrimitive(type=LinePrimitiveLineType.LineList, thickness=0.4,
                         points=_points(ends, z_m), color=_color(rgba))
    return SceneUpdate(entities=[_entity(time_s, entity_id, lines=[line] if len(a) else [])])


def plan_update(time_s: float, predicted, hull_offsets_m=(-2.0, 2.0), hull_radius_m: float = 3.0):
    """The predicted horizon (x, y, psi per stage) as a line strip, and the hull circles at
    every predicted stage as flat discs (radius R_b at the body x offsets), in the world
    frame; an empty entity when there is no plan."""
    from foxglove.messages import (LinePrimitive, LinePrimitiveLineType, Pose, SceneUpdate,
                                   SpherePrimitive, Vector3)

    pred = None if predicted is None else np.asarray(predicted, float)
    lines, discs = [], []
    if pred is not None and pred.ndim == 2 and len(pred) and pred.shape[1] >= 3:
        lines.append(LinePrimitive(type=LinePrimitiveLineType.LineStrip, thickness=0.25,
                                   points=_points(pred[:, :2], -0.2), color=_color(HORIZON_RGBA)))
        size = Vector3(x=2 * hull_radius_m, y=2 * hull_radius_m, z=0.05)
        color = _color(HULL_RGBA)
        for x, y, psi in pred[:, :3]:
            c, s = math.cos(psi), math.sin(psi)
            for d in hull_offsets_m:
                discs.append(SpherePrimitive(pose=Pose(position=Vector3(
                    x=x + d * c, y=y + d * s, z=-0.1)), size=size, color=color))
    return SceneUpdate(entities=[_entity(time_s, "horizon", lines=lines),
                                 _entity(time_s, "hull_circles", spheres=discs)])


def hull_update(time_s: float, hull_offsets_m=(-2.0, 2.0), hull_radius_m: float = 3.0,
                separation_m: float | None = None):
    """The hull circles of the boat now (frame-locked to `boat`) and, if given, the desired
    separation R_b + d_p around each as a ring."""
    from foxglove.messages import (LinePrimitive, LinePrimitiveLineType, Pose, SceneUpdate,
                                   SpherePrimitive, Vector3)

    discs = [SpherePrimitive(pose=Pose(position=Vector3(x=d, y=0.0, z=-0.15)),
                             size=Vector3(x=2 * hull_radius_m, y=2 * hull_radius_m, z=0.05),
                             color=_color((0.1, 0.4, 1.0, 0.6))) for d in hull_offsets_m]
    rings = []
    if separation_m:
        a = np.linspace(0, 2 * np.pi, 48, endpoint=False)
        for d in hull_offsets_m:
            rings.append(LinePrimitive(
                type=LinePrimitiveLineType.LineLoop, thickness=0.1,
                points=_points(np.column_stack([d + separation_m * np.cos(a),
                                                separation_m * np.sin(a)]), -0.15),
                color=_color((1.0, 0.3, 0.3, 0.8))))
    from foxglove.messages import SceneEntity

    return SceneUpdate(entities=[SceneEntity(timestamp=_stamp(time_s), frame_id=BOAT, id="hull",
                                             frame_locked=True, spheres=discs, lines=rings)])


def tracks_update(time_s: float, tracks, vessels=()):
    """The vessel tracks (boxes of their length and width, labelled with the id) and the true
    vessels' outlines (name, outline (K, 2)) in the world frame."""
    from foxglove.messages import (CubePrimitive, LinePrimitive, LinePrimitiveLineType, Pose,
                                   SceneUpdate, TextPrimitive, Vector3)

    cubes, texts = [], []
    for tr in tracks:
        x, y = (float(v) for v in tr.position)
        pose = Pose(position=Vector3(x=x, y=y, z=-0.5), orientation=_yaw_quaternion(
            float(tr.heading_rad)))
        cubes.append(CubePrimitive(pose=pose, size=Vector3(
            x=float(tr.length_m), y=float(tr.width_m), z=1.0), color=_color(TRACK_RGBA)))
        texts.append(TextPrimitive(pose=Pose(position=Vector3(x=x, y=y, z=-2.0)), billboard=True,
                                   font_size=14.0, scale_invariant=True,
                                   color=_color((1, 1, 1, 1)), text=f"track {tr.id}"))
    lines = [LinePrimitive(type=LinePrimitiveLineType.LineLoop, thickness=0.2,
                           points=_points(outline, -0.3), color=_color(VESSEL_RGBA))
             for _, outline in vessels]
    return SceneUpdate(entities=[_entity(time_s, "tracks", cubes=cubes, texts=texts),
                                 _entity(time_s, "vessels", lines=lines)])


def location_fix(time_s: float, north_m: float, east_m: float, origin, sigma_m: float = 0.0):
    """A LocationFix for a position in the local frame around a geodetic `origin`."""
    from controller.geodetic import ned_to_geodetic
    from foxglove.messages import LocationFix, LocationFixPositionCovarianceType

    lat, lon = ned_to_geodetic(north_m, east_m, origin)
    alt = float(origin[2]) if len(origin) > 2 else 0.0
    var = float(sigma_m) ** 2
    return LocationFix(timestamp=_stamp(time_s), frame_id=BOAT, latitude=float(lat),
                       longitude=float(lon), altitude=alt,
                       position_covariance=[var, 0, 0, 0, var, 0, 0, 0, var],
                       position_covariance_type=(
                           LocationFixPositionCovarianceType.DiagonalKnown if var > 0
                           else LocationFixPositionCovarianceType.Unknown))


def figures_schema(title: str, numbers, texts=()) -> dict:
    """A JSON schema for the per-step figures (numbers that plot, texts for state panels)."""
    props = {n: {"type": ["number", "null"]} for n in numbers}
    props.update({n: {"type": "string"} for n in texts})
    return {"title": title, "type": "object", "properties": props}


def finite(v) -> float | None:
    """A float for JSON (None for NaN and inf, which JSON has not)."""
    v = float(v)
    return v if math.isfinite(v) else None
