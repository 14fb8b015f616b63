"""`canalnav sitl-physics`: the boat FMU as ArduPilot SITL's JSON physics, against a stand-in.

ArduPilot SITL cannot be installed here, so a protocol-level stand-in plays its part, written
from ArduPilot's `libraries/SITL/examples/JSON/readme.md` and `SIM_JSON.{h,cpp}`: servo
packets `<HHI16H` (magic 18458) or `<HHI32H` (magic 29569) sent by UDP from a random port,
lock-step on the frame counter, and a reply read the way SIM_JSON reads it (each name found as
text, the value right after `"name":`, vectors as `[a, b, c]`).
"""

from __future__ import annotations

import json
import logging
import math
import re
import socket
import struct
import threading

import numpy as np
import pytest

from bridge.main import build_parser, main
from bridge.sitl.json_physics import (
    Rejected,
    ServoPacket,
    SitlPhysicsServer,
    encode_servo_packet,
    parse_servo_packet,
    pwm_to_commands,
    servo_calibration,
)
from controller.errors import InputError
from scenarios.plants.plant import ActuatorLimits, ModelPlant
from scenarios.scenario_file import parse_scenario

SCENARIO = """
[scenario]
name = "sitl-test"
duration_s = 60

[canal]
centre_line = [[-200, 0], [400, 0]]
width_m = 200

[route]
waypoints = [[0, 0], [300, 0]]

[initial]
x_m = 5.0
y_m = -3.0
psi_deg = 30.0
u_mps = {u}

[current]
north_mps = {cn}
east_mps = {ce}
"""

REQUIRED = {"timestamp", "imu", "position", "velocity", "attitude"}
G = 9.81


def scenario(u=0.0, current=(0.0, 0.0)):
    return parse_scenario(SCENARIO.format(u=u, cn=current[0], ce=current[1]))


# -- the stand-in for SITL ---------------------------------------------------------------------
def servo_packet(count, rate=50, steer=1500, throttle=1500, channels=16, magic=None):
    """Bytes as SIM_JSON's output_servos sends them: steering on output 1, throttle on 3."""
    pwm = [0] * channels
    pwm[0], pwm[2] = steer, throttle
    if magic is None:
        magic = 18458 if channels == 16 else 29569
    return struct.pack(f"<HHI{channels}H", magic, rate, count, *pwm)


def sitl_reads(reply: bytes) -> dict:
    """Read a reply the way SIM_JSON::parse_sensors does: strstr for the section, then for
    the name after it, the value right after `"name":`; vectors by sscanf("[%f, %f, %f]")."""
    assert reply.startswith(b"\n") and reply.endswith(b"\n")
    line = reply.decode("ascii").strip("\n")
    assert "\n" not in line, "one JSON object per line"
    number = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
    vector = re.compile(rf"\[({number}),\s*({number}),\s*({number})\]")
    read = {}
    for section, key in (("", "timestamp"), ("imu", "gyro"), ("imu", "accel_body"),
                         ("", "position"), ("", "attitude"), ("", "velocity")):
        p = line.find(section)
        assert p >= 0, section
        p = line.find(key, p + len(section) + 1)
        assert p >= 0, key
        value = line[p + len(key) + 2:]  # skips the closing quote and the colon
        if key == "timestamp":
            read[key] = float(re.match(number, value.lstrip()).group(0))
        else:
            m = vector.match(value)  # sscanf's literal '[' does not skip white space
            assert m, f"{key}: SITL could not read {value[:30]!r}"
            read[key] = np.array([float(v) for v in m.groups()])
    return read


class FakeSitl:
    """SITL's side of the UDP exchange: a socket on a random local port, lock-step frames."""

    def __init__(self, server_addr, rate=50):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(5.0)
        self.server_addr, self.rate, self.count = server_addr, rate, 0

    def send(self, datagram: bytes) -> None:
        self.sock.sendto(datagram, self.server_addr)

    def receive(self, timeout=5.0) -> bytes | None:
        self.sock.settimeout(timeout)
        try:
            data, addr = self.sock.recvfrom(65536)
        except socket.timeout:
            return None
        assert addr == self.server_addr, "the reply comes from the port SITL sent to"
        return data

    def frame(self, steer=1500, throttle=1500, count=None) -> bytes:
        """Send one frame and wait for its answer, as SITL's update() does."""
        self.send(servo_packet(self.count if count is None else count, self.rate, steer,
                               throttle))
        reply = self.receive()
        assert reply is not None, "no answer to a servo packet"
        if count is None:
            self.count += 1
        return reply

    def close(self):
        self.sock.close()


def run_frames(server, n, start=0, rate=50, steer=1500, throttle=1500):
    """Hand `n` consecutive frames to `server.handle`; the last reply as SITL reads it."""
    reply = None
    for k in range(start, start + n):
        reply = server.handle(servo_packet(k, rate, steer, throttle), ("127.0.0.1", 40000))
    return sitl_reads(reply)


class CountingPlant:
    """A plant that counts its steps (a ModelPlant inside)."""

    def __init__(self, inner):
        self.inner, self.steps, self.resets = inner, 0, 0

    def reset(self, state0, current_ne=(0.0, 0.0)):
        self.resets += 1
        return self.inner.reset(state0, current_ne)

    def step(self, command, dt):
        self.steps += 1
        return self.inner.step(command, dt)

    def close(self):
        self.inner.close()


@pytest.fixture
def sc():
    return scenario()


@pytest.fixture
def server(sc):
    s = SitlPhysicsServer(sc, port=0)
    yield s
    s.close()


# -- packets -----------------------------------------------------------------------------------
def test_parses_16_and_32_channel_packets():
    p = parse_servo_packet(servo_packet(7, 400, 1900, 1100))
    assert p == ServoPacket(400, 7, (1900, 0, 1100) + (0,) * 13)
    raw32 = struct.pack("<HHI32H", 29569, 1200, 2 ** 32 - 1, *range(1000, 1032))
    assert len(raw32) == 72
    p32 = parse_servo_packet(raw32)
    assert p32 == ServoPacket(1200, 2 ** 32 - 1, tuple(range(1000, 1032)))
    assert encode_servo_packet(p32) == raw32 and len(encode_servo_packet(p)) == 40


@pytest.mark.parametrize("datagram, kind", [
    (b"", "short"),
    (b"\x1aH\x32", "short"),
    (servo_packet(1)[:39], "short"),
    (servo_packet(1, channels=32)[:60], "short"),
    (servo_packet(1) + b"\x00", "corrupt"),
    (servo_packet(1, magic=1234), "bad magic"),
    (servo_packet(1, magic=29569), "short"),  # 32-channel magic on a 16-channel packet
    (servo_packet(1, rate=0), "frame rate"),
    (b'{"not": "a servo packet"}\n' * 3, "bad magic"),
])
def test_bad_datagrams_are_ignored_with_one_warning_per_kind(server, caplog, datagram, kind):
    rejected = parse_servo_packet(datagram)
    assert isinstance(rejected, Rejected) and rejected.kind == kind
    with caplog.at_level(logging.WARNING, logger="bridge.sitl.json_physics"):
        for _ in range(20):
            assert server.handle(datagram, ("127.0.0.1", 40000)) is None
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and "127.0.0.1:40000" in warnings[0].getMessage()
    assert server.rejected[kind] == 20 and server.frames == 0
    # the server still answers SITL afterwards
    assert sitl_reads(server.handle(servo_packet(0)))["timestamp"] == 0.0


def test_pwm_to_commands_sense_and_neutral():
    steer, throttle = servo_calibration(1), servo_calibration(3)
    pwm = lambda s, t: (s, 0, t) + (0,) * 13  # noqa: E731
    assert pwm_to_commands(pwm(0, 0), steer, throttle) == (0.0, 0.0)  # no output yet
    assert pwm_to_commands(pwm(1500, 1500), steer, throttle) == (0.0, 0.0)
    assert pwm_to_commands(pwm(2000, 2000), steer, throttle) == (100.0, -100.0)  # starboard
    assert pwm_to_commands(pwm(1000, 1000), steer, throttle) == (-100.0, 100.0)  # port, reverse
    nT, nS = pwm_to_commands(pwm(1700, 1800), steer, throttle)
    assert nT == pytest.approx(60.0) and nS == pytest.approx(-40.0)
    # a channel the packet does not carry reads neutral
    assert pwm_to_commands(pwm(1900, 1900), servo_calibration(20), throttle)[1] == 0.0


# -- the reply ---------------------------------------------------------------------------------
def test_reply_fields_and_units_for_a_boat_at_rest(server):
    reply = server.handle(servo_packet(0), ("127.0.0.1", 40000))
    doc = json.loads(reply)
    assert set(doc) == REQUIRED and set(doc["imu"]) == {"gyro", "accel_body"}
    assert b": " not in reply and b", " not in reply  # compact, as SITL's sscanf needs
    r = sitl_reads(reply)
    assert r["timestamp"] == 0.0
    np.testing.assert_allclose(r["accel_body"], [0, 0, -G], atol=0.005)
    np.testing.assert_allclose(r["gyro"], 0, atol=0)
    # the initial state from the scenario: NED from home (the scenario's frame origin)
    np.testing.assert_allclose(r["position"], [5.0, -3.0, 0.0])
    np.testing.assert_allclose(r["velocity"], 0, atol=0)
    np.testing.assert_allclose(r["attitude"], [0, 0, math.radians(30)])
    # at rest with neutral servos for 2 s: still at rest, the timestamp at 2 s
    r = run_frames(server, 100, start=1)
    assert r["timestamp"] == pytest.approx(2.0)
    np.testing.assert_allclose(r["accel_body"], [0, 0, -G], atol=0.005)
    np.testing.assert_allclose(r["position"], [5.0, -3.0, 0.0], atol=1e-12)


def test_initial_speed_from_the_scenario_is_in_the_ned_velocity():
    with SitlPhysicsServer(scenario(u=1.5), port=0) as s:
        r = sitl_reads(s.handle(servo_packet(0)))
    psi = math.radians(30)
    np.testing.assert_allclose(r["velocity"], [1.5 * math.cos(psi), 1.5 * math.sin(psi), 0])


# -- lock-step ---------------------------------------------------------------------------------
def test_repeated_frame_is_answered_again_without_a_step(sc):
    plant = CountingPlant(ModelPlant(sc.plant_params))
    s = SitlPhysicsServer(sc, plant=plant)
    first = s.handle(servo_packet(0, throttle=1900))
    assert plant.steps == 0  # the first frame is answered with the initial state
    a = s.handle(servo_packet(1, throttle=1900))
    b = s.handle(servo_packet(1, throttle=1900))
    c = s.handle(servo_packet(1, throttle=1100))  # SITL re-sends frame 1 unchanged; even if not
    assert plant.steps == 1 and a == b == c != first
    assert sitl_reads(a)["timestamp"] == pytest.approx(0.02) and s.repeats == 2
    d = s.handle(servo_packet(2, throttle=1900))
    assert plant.steps == 2 and sitl_reads(d)["timestamp"] == pytest.approx(0.04)
    s.close()


def test_frame_count_going_back_resets_the_boat(server, caplog):
    moved = run_frames(server, 501, throttle=1900, steer=1700)  # throttle ramps at 10 %/s
    assert moved["timestamp"] == pytest.approx(10.0)
    assert np.hypot(*(moved["position"][:2] - [5.0, -3.0])) > 1.0
    with caplog.at_level(logging.WARNING, logger="bridge.sitl.json_physics"):
        r = sitl_reads(server.handle(servo_packet(0, throttle=1900)))
    assert "restarted" in caplog.text and server.restarts == 1
    assert r["timestamp"] == 0.0
    np.testing.assert_allclose(r["position"], [5.0, -3.0, 0.0])
    np.testing.assert_allclose(r["velocity"], 0, atol=0)
    np.testing.assert_allclose(r["attitude"], [0, 0, math.radians(30)])
    # and it runs again from there, as the first run did
    again = run_frames(server, 500, start=1, throttle=1900, steer=1700)
    np.testing.assert_allclose(again["position"], moved["position"], atol=1e-9)
    assert again["timestamp"] == pytest.approx(10.0)


def test_a_jump_forward_steps_over_the_missing_frames(sc, caplog):
    plant = CountingPlant(ModelPlant(sc.plant_params))
    s = SitlPhysicsServer(sc, plant=plant)
    s.handle(servo_packet(0, rate=100))
    s.handle(servo_packet(1, rate=100))
    with caplog.at_level(logging.WARNING, logger="bridge.sitl.json_physics"):
        r = sitl_reads(s.handle(servo_packet(5, rate=100)))
    assert r["timestamp"] == pytest.approx(0.05) and plant.steps == 2
    assert "jumped from 1 to 5" in caplog.text
    s.close()


def test_frame_rate_sets_the_time_step(server):
    r = run_frames(server, 1201, rate=1200)  # SITL's default SIM_RATE_HZ in older releases
    assert r["timestamp"] == pytest.approx(1.0)


# -- the physics -------------------------------------------------------------------------------
def test_boat_under_thrust_moves_as_the_model_does(server, sc):
    """Same commands, same time: the FMU behind SITL and the Python model agree."""
    ref = ModelPlant(sc.plant_params, ActuatorLimits(*sc.actuator_rates))
    ref.reset(sc.initial_state, sc.current_ne)
    rate, steps = 50, 600
    server.handle(servo_packet(0, rate))
    for k in range(1, steps + 1):
        steer = 1700 if (k // 150) % 2 == 0 else 1250
        r = sitl_reads(server.handle(servo_packet(k, rate, steer=steer, throttle=1800)))
        out = ref.step([60.0, -(steer - 1500) / 5.0], 1.0 / rate)
    assert r["timestamp"] == pytest.approx(12.0) and out.time_s == pytest.approx(12.0)
    np.testing.assert_allclose(r["position"][:2], out.state[:2], atol=1e-6)
    assert np.hypot(*(out.state[:2] - sc.initial_state[:2])) > 5.0  # it did move
    c, s = math.cos(out.state[2]), math.sin(out.state[2])
    u, v, rr = out.state[3:6]
    np.testing.assert_allclose(r["velocity"][:2], [c * u - s * v, s * u + c * v], atol=1e-6)
    np.testing.assert_allclose(r["gyro"], [0, 0, rr], atol=1e-6)
    np.testing.assert_allclose(r["attitude"][2], math.atan2(s, c), atol=1e-6)
    np.testing.assert_allclose(server.output.actuators, out.actuators, atol=1e-9)


def test_specific_force_is_the_acceleration_over_ground_in_body_axes(server):
    """accel_body + g matches the NED velocity's rate of change turned into body axes."""
    rate = 200
    server.handle(servo_packet(0, rate))
    prev = None
    checked = 0
    for k in range(1, 8 * rate):
        r = sitl_reads(server.handle(servo_packet(k, rate, steer=1900, throttle=1900)))
        if prev is not None and k > 2 * rate:
            a_ned = (r["velocity"] - prev["velocity"]) * rate  # over the step just taken
            yaw = 0.5 * (r["attitude"][2] + prev["attitude"][2])
            c, s = math.cos(yaw), math.sin(yaw)
            a_body = [c * a_ned[0] + s * a_ned[1], -s * a_ned[0] + c * a_ned[1]]
            mean = 0.5 * (r["accel_body"][:2] + prev["accel_body"][:2])
            np.testing.assert_allclose(mean, a_body, atol=2e-3)
            checked += 1
        prev = r
    assert checked > 1000
    assert prev["gyro"][2] > 0.05 and prev["accel_body"][1] > 0.05  # turning: centripetal


@pytest.mark.parametrize("steer, sign", [(1900, 1), (1100, -1)])
def test_steering_sense(server, steer, sign):
    """PWM above trim turns to starboard (yaw rate > 0, heading grows), below to port."""
    r = run_frames(server, 251, steer=steer, throttle=1800)
    assert sign * r["gyro"][2] > 0.02
    assert sign * (r["attitude"][2] - math.radians(30)) > 0.1


def test_throttle_below_trim_is_reverse(server):
    r = run_frames(server, 501, throttle=1100)
    psi = r["attitude"][2]
    u = r["velocity"][0] * math.cos(psi) + r["velocity"][1] * math.sin(psi)
    assert u < -0.3
    assert server.output.state[3] < -0.3 and server.commands[0] == pytest.approx(-80.0)


def test_current_carries_a_boat_without_thrust():
    with SitlPhysicsServer(scenario(current=(0.4, -0.3)), port=0) as s:
        r = run_frames(s, 1501)  # 30 s, no output yet (pwm 0)
    d = r["position"][:2] - [5.0, -3.0]
    assert d[0] > 2.0 and d[1] < -1.5  # downstream: north and west
    np.testing.assert_allclose(r["velocity"][:2], [0.4, -0.3], atol=0.1)


# -- over UDP ----------------------------------------------------------------------------------
def test_udp_lock_step_with_a_fake_sitl(server, caplog):
    host, port = server.open()
    assert host == "127.0.0.1"
    thread = threading.Thread(target=server.serve, daemon=True)
    thread.start()
    sitl = FakeSitl((host, port))
    try:
        first = sitl_reads(sitl.frame())
        assert first["timestamp"] == 0.0
        for _ in range(100):
            reply = sitl.frame(steer=1900, throttle=1900)
        # SITL re-sends the frame it has no answer to: the same answer, no second step
        again = sitl.frame(steer=1900, throttle=1900, count=sitl.count - 1)
        assert again == reply and server.frames == 100
        assert sitl_reads(reply)["timestamp"] == pytest.approx(2.0)
        # garbage gets no answer, and the next frame is still answered
        with caplog.at_level(logging.WARNING, logger="bridge.sitl.json_physics"):
            sitl.send(b"\x00" * 12)
            assert sitl.receive(timeout=0.3) is None
        assert "bad magic" in caplog.text or "magic 0" in caplog.text
        assert sitl_reads(sitl.frame())["timestamp"] == pytest.approx(2.02)
        # SITL restarts: a new random port, the count from 0
        sitl2 = FakeSitl((host, port))
        try:
            r = sitl_reads(sitl2.frame())
            assert r["timestamp"] == 0.0 and server.restarts == 1
            np.testing.assert_allclose(r["position"], [5.0, -3.0, 0.0])
        finally:
            sitl2.close()
    finally:
        server.stop()
        thread.join(timeout=5)
        sitl.close()
    assert not thread.is_alive()


def test_32_channel_packets_over_udp(server):
    host, port = server.open()
    sitl = FakeSitl((host, port))
    try:
        for k in range(51):
            sitl.send(servo_packet(k, 50, 1500, 1900, channels=32))
            assert server.serve_once(5.0)
            reply = sitl.receive()
        assert sitl_reads(reply)["timestamp"] == pytest.approx(1.0)
        assert server.commands == (pytest.approx(80.0), 0.0)
    finally:
        sitl.close()


# -- configuration and the command -------------------------------------------------------------
def test_bad_configuration_is_an_input_error(sc):
    plant = ModelPlant(sc.plant_params)
    with pytest.raises(InputError, match="both on channel 1"):
        SitlPhysicsServer(sc, steering_channel=1, throttle_channel=1, plant=plant)
    with pytest.raises(InputError, match="channel 0"):
        SitlPhysicsServer(sc, steering_channel=0, plant=plant)
    taken = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    taken.bind(("127.0.0.1", 0))
    try:
        s = SitlPhysicsServer(sc, port=taken.getsockname()[1], plant=ModelPlant(sc.plant_params))
        with pytest.raises(InputError, match="cannot listen"):
            s.open()
        s.close()
    finally:
        taken.close()


def test_command_line(tmp_path, capsys):
    args = build_parser().parse_args(["sitl-physics", "--scenario", "x.toml"])
    assert (args.port, args.instance, args.host, args.steering_channel,
            args.throttle_channel) == (None, 0, "127.0.0.1", 1, 3)
    path = tmp_path / "s.toml"
    path.write_text(SCENARIO.format(u=0.0, cn=0.0, ce=0.0)
                    + "\n[origin]\nlat_deg = 52.0\nlon_deg = 4.5\n")
    assert main(["sitl-physics", "--scenario", str(path), "--port", "0",
                 "--duration", "0.2"]) == 0
    out = capsys.readouterr()
    line, then = out.out.strip().splitlines()
    assert "udp 127.0.0.1:" in line
    assert "sim_vehicle.py -v Rover -f motorboat -N --model JSON:127.0.0.1" in line
    assert "sitl_boat.parm" in line and "--custom-location=52.00000000,4.50000000,0,0" in line
    assert then == (f"then drive it with: canalnav bridge --connect udp:127.0.0.1:14550 "
                    f"--scenario {path} --mode MANUAL --arm")  # the scenario has an [origin]
    assert "stopped: 0 frames" in out.err
    # without [origin]: SITL's default home, explicitly, and the bridge's --origin to match
    path.write_text(SCENARIO.format(u=0.0, cn=0.0, ce=0.0))
    assert main(["sitl-physics", "--scenario", str(path), "--port", "0",
                 "--duration", "0.1"]) == 0
    line, then = capsys.readouterr().out.strip().splitlines()
    assert "--custom-location=-35.36326100,149.16523000,584,0" in line
    assert "--origin=-35.363261,149.16523,584 --mode MANUAL --arm" in then


def test_sigterm_stops_with_the_summary(tmp_path):
    """A supervisor or a script stops sitl-physics with SIGTERM: it prints its summary and
    exits 0, as on Ctrl-C."""
    import signal
    import subprocess
    import sys
    import time

    path = tmp_path / "s.toml"
    path.write_text(SCENARIO.format(u=1.0, cn=0.0, ce=0.0))
    proc = subprocess.Popen([sys.executable, "-m", "bridge.main", "sitl-physics", "--scenario",
                             str(path), "--port", "0"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        first = proc.stdout.readline()  # serving: the FMU is built and the port bound
        assert "serving SITL JSON physics" in first, first
        port = int(re.search(r"udp 127\.0\.0\.1:(\d+)", first).group(1))
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sitl:
            sitl.settimeout(5.0)
            for k in range(3):  # three frames, so the summary has something to say
                sitl.sendto(encode_servo_packet(ServoPacket(50, k, (1500,) * 16)),
                            ("127.0.0.1", port))
                sitl.recvfrom(65536)
        time.sleep(0.2)
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, (proc.returncode, err)
    assert "stopped: 2 frames, 0 repeated" in err and "boat at t = 0.04 s" in err, err
