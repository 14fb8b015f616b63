"""How well one scan's detected segments match the true canal: the wall the sensors can see
and how much of it a segment covers, and detected length far from any true surface.

Used by `canalnav bench detection` (sums over many scans) and `canalnav detect` (one scan).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

COVER_PERP_M = 0.3
COVER_ANGLE_DEG = 3.0
FALSE_FAR_M = 1.0
SAMPLED_POINTS = 3
SAMPLED_RADIUS_M = 2.0


@dataclass(frozen=True)
class ScanScore:
    """Lengths in metres for one scan (sums over scans give the benchmark's ratios)."""

    visible_m: float  # true surface the sensors can see within the radius
    covered_m: float  # of that, covered by a detected segment (perpendicular and angle)
    sampled_m: float  # of the visible, where the scan has >= SAMPLED_POINTS returns in the
    # detection's height band within SAMPLED_RADIUS_M (what a detector can work with)
    sampled_covered_m: float
    detected_m: float  # total detected segment length
    false_m: float  # detected length farther than FALSE_FAR_M from any true surface


def score_scan(world, simulator, pose, segments, detection_config, radius_m: float = 50.0,
               spacing_m: float = 0.25, cloud=None) -> ScanScore:
    """Compare detected segments (M, 4) with the true canal around one pose.

    Visible: sampled along the surfaces that stand in the detection's height band, a point
    counts when some sensor has it in range and field of view at the band's mid-height, the
    own hull does not hide it, and no other surface is in the way (2-D line of sight). With
    the scan's cloud given, also how much of that has returns near it (`sampled_m`).
    """
    import numpy as np
    from scipy.spatial import cKDTree

    from controller.perception.detection import crop_mask
    from controller.geometry import point_segment_distance, segments_to_endpoints

    pose = np.asarray(pose, float)
    band_top = detection_config.max_height_m
    mid = 0.5 * (detection_config.min_height_m + detection_config.max_height_m)
    pts, theta, edge = world.surface_samples(pose[:2], radius_m, spacing_m, air_draft_m=band_top)
    los = world.line_of_sight(simulator.sensor_positions(pose), pts, edge, air_draft_m=band_top)
    visible = (los & simulator.in_view(pose, pts, mid)).any(axis=1)
    pts, theta = pts[visible], theta[visible]
    sampled = np.zeros(len(pts), bool)
    if cloud is not None and len(pts):
        kept = np.asarray(cloud, float)[crop_mask(cloud, detection_config)]
        c, s = math.cos(pose[2]), math.sin(pose[2])
        xy = np.column_stack([pose[0] + c * kept[:, 0] - s * kept[:, 1],
                              pose[1] + s * kept[:, 0] + c * kept[:, 1]])
        if len(xy):
            counts = cKDTree(xy).query_ball_point(pts, SAMPLED_RADIUS_M, return_length=True)
            sampled = counts >= SAMPLED_POINTS
    segs = np.asarray(segments, float).reshape(-1, 4)
    covered = np.zeros(len(pts), bool)
    detected = false = 0.0
    if len(segs):
        a, b = segments_to_endpoints(segs)
        if len(pts):
            dist = point_segment_distance(pts, a, b)
            dang = np.abs((theta[:, None] - segs[None, :, 2] + np.pi / 2) % np.pi - np.pi / 2)
            covered = ((dist <= COVER_PERP_M) & (dang <= math.radians(COVER_ANGLE_DEG))).any(axis=1)
        step = 0.1
        n = np.maximum(np.ceil(segs[:, 3] / step).astype(int), 1)
        which = np.repeat(np.arange(len(segs)), n)
        frac = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n) + 0.5) / n[which]
        samples = a[which] + frac[:, None] * (b - a)[which]
        far = world.clearance(samples) > FALSE_FAR_M
        piece = segs[which, 3] / n[which]
        detected, false = float(segs[:, 3].sum()), float(piece[far].sum())
    return ScanScore(visible_m=len(pts) * spacing_m, covered_m=int(covered.sum()) * spacing_m,
                     sampled_m=int(sampled.sum()) * spacing_m,
                     sampled_covered_m=int((sampled & covered).sum()) * spacing_m,
                     detected_m=detected, false_m=false)
