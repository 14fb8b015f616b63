"""Live LiDAR on the bridge: Velodyne packets on loopback at sensor rate (a VirtualClock peer,
so the runs are deterministic), read by `velodyne:PORT`; its clock mapping; the drive of
the short bend to the goal; sensors unplugged, all silent (perception lost, --resume waits
for the LiDAR), garbage packets."""

from __future__ import annotations

import csv
import io
from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("velodyne_decoder")

from bridge.shared.clock import VirtualClock  # noqa: E402
from bridge.lidar import build_lidar  # noqa: E402
from bridge.lidar import velodyne_packets as vp  # noqa: E402
from bridge.lidar.config import parse_lidar_table  # noqa: E402
from bridge.lidar.merge import MergedLidar  # noqa: E402
from bridge.lidar.sources import open_sensor  # noqa: E402
from bridge.lidar.velodyne import VelodynePcapSensor, VelodyneUdpSensor  # noqa: E402
from bridge.onboard.link import AutopilotLink  # noqa: E402
from bridge.autopilot_sim.plant import free_udp_port  # noqa: E402
from bridge.onboard.loop import EXIT_GOAL, EXIT_STOPPED, BridgeOptions, OnboardLoop  # noqa: E402
from bridge.onboard.step_log import StepLog  # noqa: E402
from scenarios.scenario_file import load_scenario, parse_scenario  # noqa: E402

from .lidar_rig import (BOW_MOUNT, ROOT, PcapSender, VelodyneSender,  # noqa: E402
                        moving_sweep_grid, simulator, sweep_ros)

ORIGIN = (52.0, 4.0, 0.0)


def test_a_pcap_replayed_on_loopback_gives_the_captures_sweeps_on_the_bridge_clock(tmp_path):
    """The capture's packets sent at their capture times; polled every 0.1 s, the live reader
    hands the same sweeps as the pcap reader, stamped on the run's clock: the packets' own
    "microseconds past the hour" (here 3599.7 s: the hour turns during the replay) mapped by
    the smallest arrival-minus-stamp seen."""
    grid = vp.sweep_grid(sweep_ros(simulator(), (20.0, 0.5, 0.1)))
    start_us = 3599.7e6
    packets = []
    for k in range(6):
        packets += [(t - 3599.7 + 10.0, p)  # captured from 10 s on
                    for t, p in vp.sweep_packets(grid, start_us + k * vp.SWEEP_S * 1e6)]
    path = tmp_path / "drive.pcap"
    vp.write_pcap(path, packets)
    expected = list(VelodynePcapSensor("x", path, "VLP-16").sweeps())

    clock = VirtualClock(0.001)
    port = free_udp_port()
    live = VelodyneUdpSensor("front", port, "VLP-16", "127.0.0.1")
    sender = PcapSender(clock, path, port)
    try:
        clock.sleep(0.001)  # the sender's first call: capture time 10 s is clock time 0.001
        got = []
        while clock.now() < 0.62:
            clock.sleep(0.1)
            scan = live.poll(clock.now())
            if scan is not None:
                got.append((clock.now(), scan))
    finally:
        sender.close()
        live.close()
    assert live.malformed == 0 and len(got) == len(expected) >= 4
    for (now, scan), (host_stamp, points, _) in zip(got, expected):
        assert np.abs(scan.points - points).max() < 1e-6
        # capture time 10 s was clock time 0.001; a poll sees packets up to 1 ms late
        truth = host_stamp - 10.0 + 0.001
        assert truth - 1e-4 <= scan.stamp_s <= truth + 0.0015 and scan.stamp_s <= now + 1e-9
        # the stamp is the last packet's (its first firing): its points come up to 1.3 ms on
        assert scan.times_s.max() <= scan.stamp_s + 2e-3
        assert scan.times_s.min() >= scan.stamp_s - vp.SWEEP_S - 2e-3
    # across the hour: the sweeps keep coming a sweep apart
    stamps = np.array([s.stamp_s for _, s in got])
    assert np.diff(stamps) == pytest.approx(vp.SWEEP_S, abs=2e-3)


# -- the bridge with velodyne:PORT -------------------------------------------------------------
@pytest.fixture(scope="module")
def short_bend(short_bend_toml):
    s = parse_scenario(short_bend_toml, "short.toml")
    return replace(s, geodetic_origin=ORIGIN, replay_mount=BOW_MOUNT)


def drive(scenario, tmp_path, lidar_specs, senders, controller, duration_s, config=None,
          autopilot="sim", resume=False, state=(0.0, 0.0, 0.0, 2.0, 0.0, 0.0)):
    """The onboard loop against an autopilot, with the LiDAR from `lidar_specs` fed by
    `senders(clock, autopilot, ports)` on the same virtual clock."""
    from bridge.autopilot_sim.rover import AutopilotSim

    from .conftest import FakeAutopilot

    clock = VirtualClock(0.01)
    if autopilot == "sim":
        port = free_udp_port()
        ap = AutopilotSim(scenario, f"udpin:127.0.0.1:{port}", clock, seed=4, ekf_delay_s=2.0,
                          init_s=1.0, work_dir=tmp_path)
        clock.add_peer(ap.pump)
        url = f"udpout:127.0.0.1:{port}"
    else:
        ap = FakeAutopilot(clock, state=state)
        url = ap.url
    ports = [free_udp_port() for _ in lidar_specs]
    specs = [s.format(port=p) for s, p in zip(lidar_specs, ports)]
    if config is not None:
        lidar = MergedLidar([open_sensor(c) for c in config(ports).sensors],
                            [c.mount for c in config(ports).sensors])
    else:
        lidar = build_lidar(specs, None, scenario)
    made = senders(clock, ap, ports)
    link = AutopilotLink(url, clock)
    console = io.StringIO()
    log = StepLog(tmp_path)
    options = BridgeOptions(mode="MANUAL", arm=True, duration_s=duration_s, ekf_timeout_s=30.0,
                            origin=ORIGIN, resume=resume)
    loop = OnboardLoop(link, scenario, controller, lidar, options, console=console, log=log)
    try:
        result = loop.run()
        clock.sleep(0.05)  # the autopilot reads what was sent last
    finally:
        log.close()
        link.close()
        for s in made:
            s.close()
        getattr(lidar, "close", lambda: None)()
        ap.close()
    with open(tmp_path / "steps.csv") as fh:
        rows = list(csv.DictReader(fh))
    return result, rows, console.getvalue(), loop, ap


@pytest.mark.slow
def test_the_bridge_drives_the_short_bend_on_live_velodyne_packets(short_bend, tmp_path):
    """The NMPC on `--lidar velodyne:PORT`: a simulated VLP-16 at the bow sends each sweep of
    the canal as seen from the boat's true pose (the autopilot simulator's) at sensor rate;
    the bridge detects the walls from those packets alone and reaches the goal."""
    from scenarios.loop.controllers import NmpcController

    sim = simulator(short_bend)

    def senders(clock, ap, ports):
        render = lambda t: moving_sweep_grid(sim, ap.true_state)  # noqa: E731
        return [VelodyneSender(clock, ports[0], render)]

    result, rows, console, loop, ap = drive(short_bend, tmp_path, ["velodyne:{port}"], senders,
                                             NmpcController(short_bend), 150.0)
    print(console[-2000:])
    assert result.exit_code == EXIT_GOAL and result.failsafes == [], result
    steps = [r for r in rows if r["x_m"]]
    seen = [int(r["segments"]) >= 1 for r in steps]
    near = [float(r["nearest_segment_m"]) for r in steps if r["nearest_segment_m"] not in ("", "inf")]
    print(f"live velodyne drive: {len(steps)} steps, walls seen in {sum(seen)}, nearest wall "
          f"{min(near):.2f} m, tracks up to {max(int(r['tracks'] or 0) for r in steps)}")
    # walls in every step to the canal's end: the short wall pieces of the last leg, whose
    # near ends the cabin cuts from this lone bow unit's view, stay walls (free space judged
    # from the unit, `TrackerConfig.viewpoints`), not vessel tracks moving with the boat
    assert all(seen[5:]) and len(steps) > 500
    assert min(near) > 3.0
    assert loop.lidar.malformed == {"lidar": 0}


# -- faults on the bridge: a straight canal, the boat along it at 2 m/s -----------------------
@pytest.fixture(scope="module")
def straight():
    s = load_scenario(ROOT / "scenarios" / "straight.toml")
    return replace(s, geodetic_origin=ORIGIN, replay_mount=BOW_MOUNT,
                   waypoints=np.array([[0.0, 0.0], [400.0, 0.0]]))


@pytest.fixture(scope="module")
def straight_grid(straight):
    """One sweep at the start: in a straight canal, going along its centre, the same sweep
    is what the unit sees all along (so it is rendered once)."""
    return vp.sweep_grid(sweep_ros(simulator(straight), (20.0, 0.0, 0.0)))


class Constant:
    name = "constant"

    def __init__(self):
        self.segments = []

    def step(self, time_s, state, actuators, segments):
        from scenarios.loop.closed_loop import Decision

        self.segments.append(len(segments))
        return Decision(command=np.array([20.0, 0.0]))

    def reset(self):
        pass


def two_sensors(ports):
    rows = [{"name": n, "source": f"velodyne:{p}", "model": "VLP-16", "host": "127.0.0.1",
             "mount": {"x_m": 3.5, "z_m": -1.3, "roll_deg": 180}}
            for n, p in zip(("port", "starboard"), ports)]
    return parse_lidar_table({"sensor": rows}, "two.toml", "")


def statustexts(ap):
    """The STATUSTEXTs the autopilot got, long ones joined from their 50-character chunks."""
    out = []
    for m in ap.messages("STATUSTEXT"):
        if m.chunk_seq > 0 and out:
            out[-1] += m.text
        else:
            out.append(m.text)
    return out


def test_one_of_two_sensors_unplugged_for_3_s_mid_run_and_garbage(straight, straight_grid,
                                                                  tmp_path):
    def senders(clock, ap, ports):
        a = VelodyneSender(clock, ports[0], lambda t: straight_grid,
                           garbage=lambda t: 3 if 1.0 <= t < 1.1 else 0)
        b = VelodyneSender(clock, ports[1], lambda t: straight_grid,
                           unplugged=lambda t: 2.0 <= t < 5.0, device_offset_s=77.0)
        return [a, b]

    ctrl = Constant()
    result, rows, console, loop, ap = drive(straight, tmp_path, ["", ""], senders, ctrl, 7.0,
                                             config=two_sensors, autopilot="fake")
    assert result.exit_code == EXIT_STOPPED and result.reason == "time limit"
    assert result.failsafes == [] and result.steps == 70  # the run went on
    events = [r["status"] for r in rows if not r["x_m"]]
    silent = [e for e in events if "'starboard'" in e and "left out of the merge" in e]
    back = [e for e in events if "'starboard'" in e and "back: merged again" in e]
    bad = [e for e in events if "'port'" in e and "3 malformed packets" in e]
    assert len(silent) == 1 and "(1 of 2 sensors merged)" in silent[0]
    assert len(back) == 1 and len(bad) == 1
    assert "bridge: lidar 'starboard' (velodyne:" in console and "left out of the merge" in console
    texts = statustexts(ap)
    assert any("left out of the merge" in t for t in texts)
    assert any("back: merged again" in t for t in texts)
    assert loop.lidar.malformed == {"port": 3, "starboard": 0}
    # walls all along: from both sensors, then the port one alone, then both again
    assert min(ctrl.segments[5:]) >= 2


def test_all_sensors_silent_for_3_s_is_perception_lost_and_resume_waits_for_them(
        straight, straight_grid, tmp_path):
    def senders(clock, ap, ports):
        off = lambda t: 2.0 <= t < 5.0  # noqa: E731
        return [VelodyneSender(clock, p, lambda t: straight_grid, unplugged=off,
                               device_offset_s=o) for p, o in zip(ports, (5.0, 900.0))]

    # without --resume: the failsafe, and the log is complete
    out = tmp_path / "stop"
    out.mkdir()
    result, rows, console, loop, ap = drive(straight, out, ["", ""], senders, Constant(), 8.0,
                                             config=two_sensors, autopilot="fake")
    assert result.exit_code == EXIT_STOPPED and result.reason.startswith("perception lost")
    assert result.failsafes == [result.reason]
    assert "FAILSAFE perception lost: no LiDAR sweep for 1." in console
    events = [r["status"] for r in rows if not r["x_m"]]
    assert events[-1].startswith("FAILSAFE perception lost")
    assert sum("left out of the merge" in e for e in events) == 2
    t_lost = float([r for r in rows if r["status"].startswith("FAILSAFE")][0]["time_s"])
    # the last sweep came at ~2 s (clock), lost 1 s later (+ up to a sweep to decode it);
    # the event is logged once the boat is safe (neutral, release: 6 x 50 ms)
    assert 3.2 <= t_lost + loop._t0 <= 3.5
    assert any(t.startswith("canalnav: FAILSAFE perception lost") for t in statustexts(ap))

    # with --resume: the link is fine all along, but control comes back only with a sweep
    out = tmp_path / "resume"
    out.mkdir()
    result, rows, console, loop, ap = drive(straight, out, ["", ""], senders, Constant(), 8.0,
                                             config=two_sensors, autopilot="fake", resume=True)
    assert result.exit_code == EXIT_STOPPED and result.reason == "time limit"
    assert len(result.failsafes) == 1 and result.failsafes[0].startswith("perception lost")
    assert "and a LiDAR sweep to come back (--resume)" in console
    marks = {r["status"].split(":")[0]: float(r["time_s"]) for r in rows if not r["x_m"]}
    # not before the sensors sent again (from clock time 5 s; the run's time 0 is when the
    # bridge took control)
    assert marks["resumed"] >= 5.0 - loop._t0
    steps = [float(r["time_s"]) for r in rows if r["x_m"]]
    assert not [t for t in steps if marks["FAILSAFE perception lost"] < t < marks["resumed"]]
    assert max(steps) > 7.5
