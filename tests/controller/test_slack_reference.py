"""The slack's reference: the clearance a stretch narrower than 2 (R_b + d_p) forces the boat to
give up is not paid for, so a finite horizon has no reason to slow down before such a stretch."""

import numpy as np
import pytest

from controller.geometry import Segment
from controller.nmpc.problem import NmpcConfig
from controller.nmpc.bench import Canal, bend_canal, closed_loop
from controller.nmpc.controller import NmpcController
from controller.nmpc.reference import waypoint_path
from controller.nmpc.slack_reference import forced_slack, forced_slack_at, free_width, \
    separation_allowed

MARGIN = 5.0  # R_b + d_p
SLACK_MIN = -4.9


def narrowing_canal(narrow_m=9.0, taper_m=10.0):
    """North along y = 0: 16 m wide, narrow_m wide for x in [50 + taper, 100 + taper], tapers."""
    xs = np.array([0, 15, 30, 50, 50 + taper_m, 65 + taper_m, 80 + taper_m, 100 + taper_m,
                   100 + 2 * taper_m, 115 + 2 * taper_m, 130 + 2 * taper_m])
    half = np.array([8, 8, 8, 8, 1, 1, 1, 1, 8, 8, 8]) * 1.0
    half[4:8] = narrow_m / 2
    port, stbd = np.column_stack([xs, -half]), np.column_stack([xs, half])
    return Canal((port, stbd), np.array([[0.0, 0.0], [xs[-1], 0.0]]))


def least_separation(point, segments):
    """Bisection: the largest m' with the point outside every super-ellipse (the constraint)."""
    best = np.inf
    for xc, yc, th, length in segments:
        dx, dy = point[0] - xc, point[1] - yc
        a = abs(dx * np.cos(th) + dy * np.sin(th))
        b = abs(-dx * np.sin(th) + dy * np.cos(th))
        lo, hi = 0.0, 50.0
        for _ in range(60):
            m = 0.5 * (lo + hi)
            lo, hi = (m, hi) if (a / (length / 2 + m)) ** 4 + (b / m) ** 4 >= 1 else (lo, m)
        best = min(best, lo)
    return best


def test_free_width_counts_walls_abeam_only():
    walls = np.array([Segment.from_endpoints([0, -4.5], [40, -4.5]).as_array(),
                      Segment.from_endpoints([0, 4.5], [40, 4.5]).as_array(),
                      # a wall across the way 5 m ahead of the first point: no side wall
                      Segment.from_endpoints([15, -3], [15, 3]).as_array()])
    points = np.array([[10.0, 0.0], [20.0, 2.0], [60.0, 0.0]])
    width = free_width(points, np.zeros(3), walls)
    assert width[0] == pytest.approx(9.0)
    assert width[1] == pytest.approx(9.0)  # off the middle, the same width
    assert np.isinf(width[2])  # past the walls' ends they are not abeam: open
    assert np.isinf(free_width(points, np.zeros(3), walls[:1])).all()  # one side open


def test_separation_allowed_is_the_constraints_own_and_never_more():
    rng = np.random.default_rng(3)
    segments = np.column_stack([rng.uniform(-10, 10, (6, 2)), rng.uniform(-np.pi, np.pi, 6),
                                rng.uniform(0.5, 20, 6)])
    points = rng.uniform(-15, 15, (200, 2))
    c, s = np.cos(segments[:, 2]), np.sin(segments[:, 2])
    dx, dy = points[:, :1] - segments[:, 0], points[:, 1:] - segments[:, 1]
    got = separation_allowed(dx * c + dy * s, dy * c - dx * s, segments[:, 3] / 2, MARGIN)
    want = np.array([min(least_separation(p, segments), MARGIN) for p in points])
    assert np.all(got <= want + 1e-9)  # never lets the boat closer than the constraint does
    assert np.abs(got - want).max() < 0.01
    assert (got < MARGIN).sum() > 20  # the test reaches inside the ellipses


def test_forced_slack_is_what_a_narrow_stretch_forces_and_zero_elsewhere():
    canal = narrowing_canal(narrow_m=9.0, taper_m=10.0)
    path = waypoint_path(canal.waypoints)
    arcs = np.array([20.0, 45.0, 80.0, 100.0, 135.0])
    points, headings = path.at(arcs)
    forced = forced_slack_at(points, headings, canal.segments(), MARGIN, SLACK_MIN)
    assert forced[[0, 1, 4]] == pytest.approx(0.0)  # 16 m wide: nothing forced
    # 9 m wide: 0.5 m; the super-ellipses let a little more at the joints of wall pieces
    assert forced[2] == pytest.approx(-0.5, abs=0.01)
    assert -0.5 - 0.01 <= forced[3] <= -0.45
    # an abrupt step (a quay corner): the power-4 ellipse's corners reach further than the
    # distance, and the forced slack follows the constraint, not the distance
    steep = narrowing_canal(narrow_m=9.0, taper_m=1.0)
    arcs = np.arange(45.0, 56.0, 0.25)
    points, headings = waypoint_path(steep.waypoints).at(arcs)
    forced = forced_slack_at(points, headings, steep.segments(), MARGIN, SLACK_MIN)
    by_distance = np.clip(free_width(points, headings, steep.segments()) / 2 - MARGIN,
                          SLACK_MIN, 0)
    assert forced.min() < by_distance.min() - 0.2
    # per stage, the most negative over its interval
    lo = np.array([0.0, 40.0, 58.0, 60.0])
    per_stage = forced_slack(path, lo, lo + 6.0, canal.segments(), MARGIN, SLACK_MIN)
    assert per_stage[0] == 0.0 and per_stage[1] == 0.0
    assert per_stage[2] == pytest.approx(-0.5, abs=0.06) and per_stage[3] < -0.45
    assert np.all(per_stage >= SLACK_MIN)
    assert not forced_slack(path, lo, lo + 6.0, np.zeros((0, 4)), MARGIN, SLACK_MIN).any()


def test_the_speed_is_held_into_a_stretch_narrower_than_the_margin():
    """The bench's canal (a bend, then 9 m wide): with rho = 1e4 paid for the unavoidable 0.5 m
    the boat slowed from 2.0 to 1.1 m/s before the stretch; now it holds 2 m/s through it, on
    the middle, the slack taking the 0.5 m."""
    cfg = NmpcConfig()
    assert cfg.slack_weight == 1e4
    run = closed_loop(NmpcController(cfg, method="rti"), bend_canal(narrow_m=9.0),
                      np.array([0.0, 0.0, 0.0, 2.0, 0.0, 0.0]), np.array([47.0, 0.0]), 760)
    assert not run.failure and all(s.stats.ok for s in run.steps)
    x, y, u = run.states[:, 0], run.states[:, 1], run.states[:, 3]
    approach, inside = (y > 40) & (y <= 70), (y > 72) & (y < 98)
    print(f"\napproach {u[approach].min():.3f}..{u[approach].max():.3f} m/s, inside "
          f"{u[inside].min():.3f}..{u[inside].max():.3f} m/s, offset "
          f"{np.abs(x[inside] - 70).max():.3f} m")
    assert inside.sum() > 100
    assert np.all(np.abs(u[approach | inside] - 2.0) < 0.1)
    assert np.abs(x[inside] - 70.0).max() < 0.5
    slack = np.array([s.slack_m[0] for s, i in zip(run.steps, inside[:-1]) if i])
    assert np.all(slack < -0.45)  # the next stage gives up the 0.5 m: the slack takes it
