"""run.mcap and the live view: read back with the mcap reader, watched over WebSocket, and
the run's results the same with and without them."""

import base64
import csv
import json
import math
import socket
import struct
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("foxglove")  # the test extra installs it; without it see the last tests

from mcap.reader import make_reader  # noqa: E402
from mcap_protobuf.decoder import DecoderFactory  # noqa: E402

from controller.errors import InputError  # noqa: E402
from scenarios.commands.run import load_with_overrides  # noqa: E402
from scenarios.loop.runner import run_scenario  # noqa: E402
from scenarios.results.mcap_log import TOPICS  # noqa: E402
from scenarios.studies.overrides import parse_assignment  # noqa: E402

STRAIGHT = Path(__file__).resolve().parents[2] / "scenarios" / "straight.toml"
ORIGIN = (52.37, 4.89)


def scenario(duration_s=6.0):
    """The straight canal with the LiDAR, a geodetic origin (so there is a GPS fix), short."""
    sets = [f"scenario.duration_s={duration_s}", f"origin.lat_deg={ORIGIN[0]}",
            f"origin.lon_deg={ORIGIN[1]}"]
    return load_with_overrides(str(STRAIGHT), [parse_assignment(s) for s in sets])


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The same run with run.mcap and without (python-model plant, LiDAR in this process)."""
    root = tmp_path_factory.mktemp("mcap")
    sc = scenario()
    out = {}
    for name, mcap in (("with", True), ("without", False)):
        out[name] = run_scenario(sc, root / name, plant="python-model", plots=False,
                                 parallel_perception=False, mcap=mcap)
    return root, out


def read_mcap(path):
    """{topic: [(log_time_ns, schema name, decoded message)]}."""
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        out = {}
        for schema, channel, message, decoded in _decoded(reader):
            out.setdefault(channel.topic, []).append((message.log_time, schema.name, decoded))
    return out


def _decoded(reader):
    """Protobuf through the mcap decoder, JSON by hand (no JSON decoder ships with mcap)."""
    factory = DecoderFactory()
    decoders = {}
    for schema, channel, message in reader.iter_messages():
        if channel.message_encoding == "json":
            yield schema, channel, message, json.loads(message.data)
            continue
        if schema.id not in decoders:
            decoders[schema.id] = factory.decoder_for(channel.message_encoding, schema)
        yield schema, channel, message, decoders[schema.id](message.data)


def read_csv(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_results_are_the_same_with_and_without_mcap(runs):
    root, res = runs
    assert (root / "with" / "run.mcap").stat().st_size > 0
    assert not (root / "without" / "run.mcap").exists()
    for name in ("summary.json", "segments.csv", "snapshots.json"):
        assert (root / "with" / name).read_bytes() == (root / "without" / name).read_bytes(), name
    assert "viz" in res["with"].timing["where_the_time_goes_s"]


def test_run_mcap_has_every_channel_one_message_a_step(runs):
    root, res = runs
    steps = res["with"].summary["steps"]
    msgs = read_mcap(root / "with" / "run.mcap")
    schemas = {topic: {m[1] for m in v} for topic, v in msgs.items()}
    assert schemas[TOPICS["tf"]] == {"foxglove.FrameTransforms"}
    assert schemas[TOPICS["cloud"]] == {"foxglove.PointCloud"}
    assert schemas[TOPICS["fix"]] == {"foxglove.LocationFix"}
    assert schemas[TOPICS["figures"]] == {"canalnav.Step"}
    for k in ("walls", "segments", "plan", "hull"):
        assert schemas[TOPICS[k]] == {"foxglove.SceneUpdate"}, k
    for k in ("tf", "cloud", "segments", "plan", "figures"):
        assert len(msgs[TOPICS[k]]) == steps, k
    assert len(msgs[TOPICS["fix"]]) == pytest.approx(steps / 2, abs=1)  # GPS at 5 Hz
    for topic, v in msgs.items():
        times = [m[0] for m in v]
        assert all(b > a for a, b in zip(times, times[1:])), topic
    cloud = msgs[TOPICS["cloud"]][10][2]
    pts = np.frombuffer(cloud.data, np.float32).reshape(-1, 3)
    assert cloud.frame_id == "boat" and cloud.point_stride == 12 and 100 < len(pts) <= 3000
    assert np.all(np.isfinite(pts)) and np.abs(pts[:, 1]).max() < 130  # body frame, in range


def test_pose_and_figures_at_step_k_match_log_csv(runs):
    root, _ = runs
    rows = read_csv(root / "with" / "log.csv")
    msgs = read_mcap(root / "with" / "run.mcap")
    tf = msgs[TOPICS["tf"]]
    figures = msgs[TOPICS["figures"]]
    for k in (0, len(rows) // 2, len(rows) - 1):
        row = rows[k]
        t_ns, _, frames = tf[k]
        assert t_ns == round(float(row["time_s"]) * 1e9)
        boat = {f.child_frame_id: f for f in frames.transforms}["boat"]
        assert boat.parent_frame_id == "world"
        assert boat.translation.x == pytest.approx(float(row["true_x_m"]), abs=1e-9)
        assert boat.translation.y == pytest.approx(float(row["true_y_m"]), abs=1e-9)
        psi = 2 * math.atan2(boat.rotation.z, boat.rotation.w)
        assert math.remainder(psi - float(row["true_psi_rad"]), 2 * math.pi) == pytest.approx(
            0, abs=1e-9)
        f = figures[k][2]
        assert f["time_s"] == pytest.approx(float(row["time_s"]))
        assert f["nS_cmd_pct"] == pytest.approx(float(row["nS_cmd_pct"]))
        assert f["clearance_bow_m"] == pytest.approx(float(row["clearance_bow_m"]))
        assert f["status"] == row["status"]


def test_a_segment_message_matches_segments_csv(runs):
    root, _ = runs
    seg_rows = read_csv(root / "with" / "segments.csv")
    msgs = read_mcap(root / "with" / "run.mcap")[TOPICS["segments"]]
    k = 30
    t = f"{k * 0.1:.3f}"
    want = np.array([[float(r[c]) for c in ("x_c_m", "y_c_m", "theta_rad", "length_m")]
                     for r in seg_rows if r["time_s"] == t])
    assert len(want), "the straight canal's walls are seen by step 30"
    entity = msgs[k][2].entities[0]
    assert entity.frame_id == "world"
    pts = np.array([[p.x, p.y] for p in entity.lines[0].points])
    a, b = pts[0::2], pts[1::2]
    centre = 0.5 * (a + b)
    length = np.hypot(*(b - a).T)
    assert np.allclose(centre, want[:, :2], atol=1e-9)
    assert np.allclose(length, want[:, 3], atol=1e-9)


def test_gps_fix_is_near_the_boat_on_the_earth(runs):
    from controller.geodetic import geodetic_to_ned

    root, _ = runs
    rows = read_csv(root / "with" / "log.csv")
    t_ns, _, fix = read_mcap(root / "with" / "run.mcap")[TOPICS["fix"]][10]
    n, e = geodetic_to_ned(fix.latitude, fix.longitude, ORIGIN)
    k = int(round(t_ns / 1e8))  # the fix comes at the end of step k - 1 = the pose of row k
    assert np.hypot(n - float(rows[k]["true_x_m"]), e - float(rows[k]["true_y_m"])) < 0.2


def test_shipped_layout_is_the_built_one_and_names_our_topics():
    from scenarios.results.foxglove_layout import LAYOUT_PATH, build_layout

    text = LAYOUT_PATH.read_text()
    assert text == build_layout()
    named = set()

    def walk(node):
        if isinstance(node, dict):
            for key, v in node.items():
                if key == "topics":
                    named.update(v)
                elif key in ("value", "followTopic") and isinstance(v, str):
                    named.add(v.split(".")[0])
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)

    walk(json.loads(text))
    assert named and named <= set(TOPICS.values())
    assert TOPICS["cloud"] in named and TOPICS["figures"] in named


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class LiveClient(threading.Thread):
    """A Foxglove WebSocket client: subscribe to the pose and the cloud, keep the first of
    each (decoded with the schema the server advertised)."""

    def __init__(self, port):
        super().__init__(daemon=True)
        self.port = port
        self.subscribed = threading.Event()
        self.got = {}
        self.error = None

    def run(self):
        try:
            self._run()
        except Exception as exc:  # noqa: BLE001 - reported by the test
            self.error = exc
        finally:
            self.subscribed.set()

    def _run(self):
        import time

        from mcap.records import Schema
        from websockets.sync.client import connect

        deadline = time.monotonic() + 30
        while True:
            try:
                ws = connect(f"ws://127.0.0.1:{self.port}",
                             subprotocols=["foxglove.sdk.v1", "foxglove.websocket.v1"],
                             open_timeout=5)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.05)
        with ws:
            wanted = {TOPICS["tf"]: 1, TOPICS["cloud"]: 2}
            decoders = {}
            factory = DecoderFactory()
            while len(decoders) < len(wanted):
                msg = json.loads(ws.recv(timeout=20))
                if msg.get("op") != "advertise":
                    continue
                for ch in msg["channels"]:
                    if ch["topic"] in wanted:
                        schema = Schema(id=ch["id"], name=ch["schemaName"],
                                        encoding=ch.get("schemaEncoding", "protobuf"),
                                        data=base64.b64decode(ch["schema"]))
                        decoders[wanted[ch["topic"]]] = (ch["topic"], factory.decoder_for(
                            ch["encoding"], schema))
                        ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                            {"id": wanted[ch["topic"]], "channelId": ch["id"]}]}))
            self.subscribed.set()
            while len(self.got) < len(wanted):
                data = ws.recv(timeout=20)
                if isinstance(data, str) or data[0] != 0x01:  # 0x01: message data
                    continue
                sub_id, t_ns = struct.unpack_from("<IQ", data, 1)
                topic, decode = decoders[sub_id]
                self.got.setdefault(topic, (t_ns, decode(data[13:])))


def test_live_view_serves_pose_and_cloud_and_changes_nothing(runs, tmp_path):
    root, _ = runs
    port = _free_port()
    client = LiveClient(port)
    client.start()

    def progress(t, total):  # the first step waits (bounded) until the viewer has subscribed
        client.subscribed.wait(30)

    live = run_scenario(scenario(), tmp_path, plant="python-model", plots=False,
                        parallel_perception=False, mcap=False, live=("127.0.0.1", port),
                        progress=progress)
    client.join(30)
    assert client.error is None, client.error
    t_ns, frames = client.got[TOPICS["tf"]]
    assert "boat" in {f.child_frame_id for f in frames.transforms}
    _, cloud = client.got[TOPICS["cloud"]]
    assert cloud.frame_id == "boat" and len(cloud.data) > 12 * 100
    assert (tmp_path / "summary.json").read_bytes() == (root / "without" /
                                                        "summary.json").read_bytes()
    assert (tmp_path / "segments.csv").read_bytes() == (root / "without" /
                                                         "segments.csv").read_bytes()
    assert live.summary["steps"] == 60


def test_without_the_extra_mcap_and_live_name_it_and_the_rest_works(tmp_path, monkeypatch):
    from bridge.main import main

    monkeypatch.setitem(sys.modules, "foxglove", None)  # import foxglove -> ImportError
    monkeypatch.setitem(sys.modules, "foxglove.messages", None)
    sc = scenario(1.0)
    with pytest.raises(InputError, match=r"canalnav\[viz\]"):
        run_scenario(sc, tmp_path / "a", plant="python-model", plots=False, mcap=True)
    with pytest.raises(InputError, match=r"canalnav\[viz\]"):
        run_scenario(sc, tmp_path / "a", plant="python-model", plots=False, mcap=False,
                     live=("127.0.0.1", 0))
    r = run_scenario(sc, tmp_path / "b", plant="python-model", plots=False,
                     parallel_perception=False, mcap=None)  # when the extra is there
    assert r.summary["steps"] == 10 and not (tmp_path / "b" / "run.mcap").exists()
    assert main(["run", str(STRAIGHT), "--live", "8765", "--out", str(tmp_path / "c")]) == 2
