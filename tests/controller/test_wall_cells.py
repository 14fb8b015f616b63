"""The tracker's memory of where walls were seen (`wall_cells`): cells remembered and
forgotten, the share of a cluster's points on them, and a curved quay seen from afar that
is no vessel."""

import numpy as np

from controller.perception import wall_cells
from controller.perception.wall_cells import WallCells, fraction_on, remember


def _arc(radius, a0, a1, n, centre=(0.0, 0.0)):
    a = np.linspace(a0, a1, n)
    return np.column_stack([centre[0] + radius * np.cos(a), centre[1] + radius * np.sin(a)])


def test_cells_are_remembered_refreshed_and_forgotten():
    mem = remember(WallCells.empty(), np.array([[0.1, 0.1], [0.2, 0.2], [5.0, 5.0]]), 0.0,
                   0.5, memory_s=10.0)
    assert len(mem) == 2 and mem.updated_s == 0.0  # two cells, the first holds two points
    mem = remember(mem, np.array([[5.1, 5.1]]), 8.0, 0.5, memory_s=10.0)
    assert len(mem) == 2 and sorted(mem.seen_s.tolist()) == [0.0, 8.0]
    mem = remember(mem, np.zeros((0, 2)), 12.0, 0.5, memory_s=10.0)  # (0, 0)'s cell is old
    assert len(mem) == 1 and mem.seen_s.tolist() == [8.0]
    assert np.all(np.diff(mem.keys) > 0)


def test_share_counts_points_in_or_next_to_a_remembered_cell():
    mem = remember(WallCells.empty(), _arc(30.0, 0.0, 1.0, 400), 0.0, 0.5, 60.0)
    on = _arc(30.3, 0.2, 0.6, 50)  # 0.3 m off the curve: next to its cells
    off = _arc(33.0, 0.2, 0.6, 50)  # 3 m off: a boat lying off the quay
    assert fraction_on(mem, on, 0.5) == 1.0
    assert fraction_on(mem, off, 0.5) == 0.0
    assert fraction_on(mem, np.vstack([on[:10], off]), 0.5) == 10 / 60
    assert fraction_on(WallCells.empty(), on, 0.5) == 0.0
    assert fraction_on(mem, np.zeros((0, 2)), 0.5) == 0.0


def test_due_every_period():
    mem = WallCells.empty()
    assert wall_cells.due(mem, 0.0, 1.0)
    mem = remember(mem, np.zeros((0, 2)), 3.0, 0.5, 60.0)
    assert not wall_cells.due(mem, 3.5, 1.0) and wall_cells.due(mem, 4.0, 1.0)


def test_a_curved_quay_seen_from_afar_is_no_vessel():
    """Issue 34 (3): round a 70 m radius bend, the far quay comes back as thin scatter that
    makes neither a long segment nor one straight line; without the wall cells it became
    static tracks for up to 10 s; with them, no confirmed track lies on a wall. Since the
    hull evidence (a cluster closing an outline of its own), the scatter that still makes
    clusters when the cells are not used is not confirmed either."""
    import math

    from controller.geometry import distance_to_polylines
    from controller.perception.detection import detect_segments
    from controller.perception.tracking import TrackerConfig, VesselTracker
    from scenarios.sensors.lidar import LidarSimulator
    from scenarios.world.canal import CanalWorld

    radius = 70.0
    a = np.linspace(-0.3, 2.2, 120)
    world = CanalWorld.from_centre_line(
        np.column_stack([radius * np.sin(a), radius - radius * np.cos(a)]), 18.0)
    walls = tuple(world.wall_polylines())
    longest, scans_with_tentative = {}, {}
    for share in (0.6, 2.0):  # the default, and the check turned off
        sim = LidarSimulator(world, seed=3)
        tracker = VesselTracker(TrackerConfig(wall_cells_share=share))
        on = {}
        tentative = 0
        for k in range(300):
            t = k / 10
            ang = 2.0 * t / radius
            pose = (radius * math.sin(ang), radius - radius * math.cos(ang), ang)
            scan = sim.scan_labelled(pose, 2.0, time_s=t)
            out = tracker.update(t, scan.points, pose, detect_segments(scan.points, pose))
            tentative += out.tentative > 0
            for track in out.tracks:
                if distance_to_polylines(np.asarray(track.position)[None], walls)[0] <= 1.0:
                    on[track.id] = on.get(track.id, 0.0) + 0.1
        longest[share] = max(on.values(), default=0.0)
        scans_with_tentative[share] = tentative
    assert longest[0.6] <= 1.0
    # Without the cells the scatter makes candidate tracks for many seconds, and the hull
    # evidence alone keeps them from being confirmed for more than a second.
    assert scans_with_tentative[2.0] > 30 and longest[2.0] <= 1.0
