"""Baseline 2, the lexicographic planner: bound on the heading cost, hard constraints, fallback."""

import numpy as np
import pytest

from controller.baselines.lexicographic import LexicographicConfig, LexicographicPlanner
from controller.geometry import Segment, point_segment_distance

# a canal running north, 16 m wide, with a pier sticking 4 m out of the east wall at x = 40
WALLS = np.array([
    Segment.from_endpoints([-20, -8], [120, -8]).as_array(),
    Segment.from_endpoints([-20, 8], [120, 8]).as_array(),
    Segment.from_endpoints([38, 8], [38, 4]).as_array(),
    Segment.from_endpoints([38, 4], [42, 4]).as_array(),
    Segment.from_endpoints([42, 4], [42, 8]).as_array(),
])


@pytest.fixture(scope="module")
def planner():
    return LexicographicPlanner([[0, 2], [200, 2]])


def test_plan_respects_kinematics_bounds_and_end_point(planner):
    plan = planner.plan([0, 2, 0], WALLS)
    assert plan.feasible, plan.status
    cfg = planner.config
    assert plan.states[0] == pytest.approx([0, 2, 0], abs=1e-6)
    assert plan.states[-1][:2] == pytest.approx([50, 2], abs=1e-4)  # 50 m ahead on the path
    assert np.all(np.abs(plan.inputs[:, 0]) <= cfg.u_max_mps + 1e-6)
    assert np.all(np.abs(plan.inputs[:, 1]) <= cfg.r_max_radps + 1e-6)


def test_heading_cost_stays_within_its_bound_and_hard_constraints_hold(planner):
    planner._progress = 0.0
    plan = planner.plan([0, 2, 0], WALLS)
    heading_cost = float(np.sum(plan.inputs[:, 1] ** 2))
    assert heading_cost <= plan.j1 * (1 + 1e-3) + 1e-9 + 1e-7
    # the pier forces a detour: J1* > 0, and the plan keeps both hull circles 5 m clear
    assert plan.j1 > 1e-6
    c, s = np.cos(plan.states[:, 2]), np.sin(plan.states[:, 2])
    a = np.array([Segment(*w).endpoints[0] for w in WALLS])
    b = np.array([Segment(*w).endpoints[1] for w in WALLS])
    for off in (2.0, -2.0):
        centres = plan.states[1:, :2] + off * np.column_stack([c, s])[1:]
        # the super-ellipse lets the centre in ~0.6 m near a segment end (DESIGN.md)
        assert point_segment_distance(centres, a, b).min() > 5.0 - 0.7


def test_infeasible_keeps_the_last_plan():
    p = LexicographicPlanner([[0, 0], [200, 0]], LexicographicConfig(separation_m=2.0))
    first = p.plan([0, 0, 0], WALLS[:2])
    assert first.feasible
    # a canal 8 m wide cannot keep 5 m from both walls: hard constraints have no solution
    narrow = np.array([Segment.from_endpoints([-20, -4], [120, -4]).as_array(),
                       Segment.from_endpoints([-20, 4], [120, 4]).as_array()])
    second = p.plan([1, 0, 0], narrow)
    assert not second.feasible and "heading stage" in second.status
    assert np.array_equal(second.path, first.path)
