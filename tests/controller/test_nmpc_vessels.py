"""Other vessels in the NMPC (issue 17): vessel slots predicted over the horizon, and the
rules of the road shaping the reference: meet port to port in the starboard half, overtake
with room or follow, give way to a vessel crossing from starboard, stand on otherwise."""

import math
from dataclasses import dataclass, field

import numpy as np
import pytest

from controller.model import SMOOTH, plant_step_function
from controller.nmpc import NmpcConfig, NmpcController
from controller.nmpc.bench import hull_centres, visible_segments
from controller.nmpc.problem import clearance_function
from controller.nmpc.vessel_slots import predict_vessels


@dataclass(frozen=True)
class Vessel:
    """A track as perception gives it (the fields the NMPC reads)."""

    id: int
    position: np.ndarray
    velocity: np.ndarray
    heading_rad: float
    length_m: float
    width_m: float
    covariance: np.ndarray = field(default_factory=lambda: np.diag([0.01, 0.01, 0.001, 0.001]))


def vessel_at(t, start, velocity, length=12.0, width=3.5, vid=1):
    v = np.asarray(velocity, float)
    heading = math.atan2(v[1], v[0]) if np.hypot(*v) > 0 else 0.0
    return Vessel(vid, np.asarray(start, float) + t * v, v, heading, length, width)


def test_vessel_slots_predict_at_constant_velocity_and_grow_with_uncertainty():
    tr = vessel_at(0.0, (50.0, 0.0), (-1.0, 0.0))
    sel = predict_vessels([tr], 2, 25, 1.0, position=(0.0, 0.0))
    slots = sel.slots
    assert slots.shape == (25, 2, 6) and sel.ids == (1,)
    assert np.allclose(slots[:, 0, 0], 50.0 - np.arange(1, 26)) and np.all(slots[:, 0, 5] == 1)
    assert np.all(np.diff(slots[:, 0, 3]) >= 0) and slots[0, 0, 3] > 12.0  # inflated, growing
    assert np.all(slots[:, 1, 5] == 0)  # the second slot is empty
    far = vessel_at(0.0, (500.0, 0.0), (0.0, 0.0), vid=2)
    sel = predict_vessels([far, tr], 1, 25, 1.0, position=(0.0, 0.0))
    assert sel.ids == (1,) and sel.dropped == 0  # the far one is out of range, not dropped
    near2 = vessel_at(0.0, (30.0, 5.0), (0.0, 0.0), vid=3)
    sel = predict_vessels([tr, near2], 1, 25, 1.0, position=(0.0, 0.0))
    assert sel.ids == (1,) and sel.dropped == 1  # the one that comes closest gets the slot


def test_a_lane_is_taken_from_where_the_vessel_will_be():
    """A vessel met head-on in its lane (-4 m across a straight route) is placed where it is
    predicted while that is ahead of the boat's plan, abeam of the plan once they would
    have met, never beyond where it is now: a boat in the lane when the vessel is 60 m off
    has the time to move over."""
    from controller.nmpc.reference import waypoint_path

    path = waypoint_path(np.array([[0.0, 0.0], [200.0, 0.0]]))
    tr = vessel_at(0.0, (60.0, -4.0), (-2.0, 0.0))
    plan = np.column_stack([2.0 * np.arange(26), np.zeros(26)])  # 2 m/s up the route
    sel = predict_vessels([tr], 1, 25, 1.0, plan=plan, path=path, path_window=(0.0, 200.0),
                          lanes=frozenset({1}))
    x = sel.slots[:, 0, 0]
    t = np.arange(1, 26)
    ahead = 60.0 - 2.0 * t > 2.0 * t  # before they would have met (t < 15 s)
    assert np.allclose(x[ahead], 60.0 - 2.0 * t[ahead])  # where it will be
    assert np.allclose(x[~ahead], np.minimum(2.0 * t[~ahead], 60.0))  # then abeam of the plan
    assert np.allclose(sel.slots[:, 0, 1], -4.0)  # in its lane throughout


def test_the_vessel_constraint_is_the_super_ellipse_around_the_inflated_hull():
    cfg = NmpcConfig(segment_slots=1, vessel_slots=1)
    h = clearance_function(cfg)
    Rb, dv = cfg.hull_radius_m, cfg.vessel_separation_m
    vessel = np.array([[10.0, 0.0, 0.0, 12.0, 4.0, 1.0]]).T
    slots = np.zeros((5, 1))
    x = np.zeros(9)
    for px, inside in ((10.0 + 6.0 + Rb + dv - 0.1 - 2.0, True), (10.0 + 6.0 + Rb + dv + 0.1 - 2.0, False)):
        x[0] = px  # the bow circle sits 2 m ahead of the origin, on the vessel's axis
        vals = np.array(h(x, slots, [Rb, 2.0, 2.0, -2.0, dv], vessel)).ravel()
        bow_vessel = vals[2]  # rows: 2 circles x 1 segment slot, then 2 circles x 1 vessel slot
        assert (bow_vessel < 0) == inside
    x[0], x[1] = 10.0, 2.0 + Rb + dv + 0.1  # abeam of it, just outside the half-width margin
    vals = np.array(h(x, slots, [Rb, 2.0, 2.0, -2.0, dv], vessel)).ravel()
    assert vals[2] > 0 and vals[3] > 0


def loop(vessel_fn, width=20.0, steps=700, speed=2.0, config=NmpcConfig()):
    """The NMPC on the smooth model in a straight canal with one other vessel."""
    ctl = NmpcController(config)
    plant = plant_step_function(SMOOTH)
    p = config.boat.as_vector()
    walls = np.array([[250.0, -width / 2, 0.0, 600.0], [250.0, width / 2, 0.0, 600.0]])
    x, act = np.array([0.0, 0.0, 0.0, 2.0, 0.0, 0.0]), np.array([47.0, 0.0])
    rows = []
    for k in range(steps):
        t = k * 0.1
        tr = vessel_fn(t)
        st = ctl.step(x, act, visible_segments(walls, x, 60.0), [[0, 0], [500, 0]], speed,
                      vessels=[tr])
        centres = hull_centres(x)
        c, s = math.cos(x[2]), math.sin(x[2])
        rel = tr.position - x[:2]
        rows.append(dict(t=t, x=x.copy(), gap=float(np.hypot(*(centres - tr.position).T).min()),
                         ahead=c * rel[0] + s * rel[1], abeam=-s * rel[0] + c * rel[1],
                         rules=st.stats.rules, fallback=st.stats.fallback,
                         speed=math.hypot(x[3], x[4])))
        for _ in range(2):
            xn, an, _ = plant(x, act, st.command, p, (0, 0), [10.0, 40.0], 0.05)
            x, act = np.asarray(xn).ravel(), np.asarray(an).ravel()
    return rows


def test_meeting_head_on_the_boat_keeps_to_starboard_and_passes_port_to_port():
    rows = loop(lambda t: vessel_at(t, (150.0, -4.0), (-1.5, 0.0)))
    closest = min(rows, key=lambda r: r["gap"])
    assert closest["abeam"] < 0  # the vessel on the boat's port side
    assert closest["gap"] > 3.0 + 1.75 + 1.3  # hull circle centre to vessel centre
    meeting = [r for r in rows if "meeting" in r["rules"]]
    assert meeting and np.mean([r["x"][1] > 0.5 for r in meeting[len(meeting) // 2:]]) > 0.9
    assert not any(r["fallback"] for r in rows)


def test_a_slow_vessel_ahead_with_no_room_is_followed_at_a_distance():
    rows = loop(lambda t: vessel_at(t, (60.0, 0.0), (0.8, 0.0), 25.0, 5.0), width=14.0,
                steps=900)
    assert any("following" in r["rules"] for r in rows)
    bow_to_stern = min(r["ahead"] - 12.5 - 3.95 for r in rows)
    assert bow_to_stern >= 15.0
    late = [r["speed"] for r in rows if r["t"] > 60.0]
    assert abs(np.mean(late) - 0.8) < 0.1  # matches its speed
    assert not any(r["fallback"] for r in rows)


def test_with_room_the_boat_overtakes_on_the_vessels_port_side():
    rows = loop(lambda t: vessel_at(t, (50.0, 5.0), (0.8, 0.0), 25.0, 5.0), width=26.0,
                steps=900)
    assert any("overtaking" in r["rules"] and "port side" in r["rules"] for r in rows)
    passed = [r for r in rows if r["ahead"] < -20.0]
    assert passed  # the boat got past it
    closest = min(rows, key=lambda r: r["gap"])
    assert closest["abeam"] > 0  # the vessel on the boat's starboard side when closest


def test_a_vessel_crossing_from_starboard_is_given_way_and_one_from_port_is_not():
    # it reaches the boat's track about when the boat would: from starboard (east)
    stbd = loop(lambda t: vessel_at(t, (90.0, 65.0), (0.0, -1.5), 9.0, 3.0), steps=600)
    assert any("give way" in r["rules"] for r in stbd)
    closest = min(stbd, key=lambda r: r["gap"])
    assert closest["gap"] > 5.0 and min(r["speed"] for r in stbd) < 1.7  # slowed down
    port = loop(lambda t: vessel_at(t, (90.0, -65.0), (0.0, 1.5), 9.0, 3.0), steps=600)
    assert not any("give way" in r["rules"] for r in port)  # stand on (Rule 17) ...
    acts = [k for k, r in enumerate(port) if "stand-on acts" in r["rules"]]
    stood = [k for k, r in enumerate(port) if "stand-on acts" not in r["rules"]
             and port[k]["gap"] < 60.0]
    # ... keeping course and speed until the crosser is close, then stopping short (17(b))
    assert acts and stood and min(stood) < min(acts)
    assert min(r["gap"] for r in port) > 5.0


def test_no_vessel_slots_is_the_paper_s_problem():
    ctl = NmpcController(NmpcConfig(vessel_slots=0))
    st = ctl.step([0, 0, 0, 2, 0, 0], [47, 0], np.zeros((0, 4)), [[0, 0], [100, 0]], 2.0,
                  vessels=[vessel_at(0.0, (40.0, 0.0), (-1.0, 0.0))])
    assert st.stats.ok and st.stats.vessels == ()


def test_a_vessel_at_rest_is_a_wall_grown_all_round():
    """A track known for a vessel but not moving (a kayak stopped) becomes its outline with
    every side moved out by the keep: a rectangle (length + 2 k) x (width + 2 k)."""
    from types import SimpleNamespace

    from controller.nmpc.vessel_slots import at_rest, rest_outlines

    kayak = SimpleNamespace(position=np.array([10.0, 2.0]), velocity=np.zeros(2),
                            heading_rad=math.pi / 2, length_m=3.5, width_m=0.8, moving=False,
                            vessel=True)
    quay_piece = SimpleNamespace(**{**vars(kayak), "vessel": False})
    launch = SimpleNamespace(**{**vars(kayak), "moving": True})
    assert at_rest([kayak, quay_piece, launch]) == (kayak,)
    segs = rest_outlines([kayak], 1.5)
    assert segs.shape == (4, 4)
    c, s = np.cos(segs[:, 2]), np.sin(segs[:, 2])
    ends = np.vstack([segs[:, :2] - 0.5 * segs[:, 3:4] * np.column_stack([c, s]),
                      segs[:, :2] + 0.5 * segs[:, 3:4] * np.column_stack([c, s])])
    np.testing.assert_allclose(ends.min(axis=0), [10.0 - 1.9, 2.0 - 3.25], atol=1e-9)
    np.testing.assert_allclose(ends.max(axis=0), [10.0 + 1.9, 2.0 + 3.25], atol=1e-9)
