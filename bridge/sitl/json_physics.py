"""The boat FMU as the physics of ArduPilot's own SITL, over its JSON interface (`--model JSON`).

Protocol (ArduPilot `libraries/SITL/examples/JSON/readme.md`, `libraries/SITL/SIM_JSON.{h,cpp}`):
SITL sends a binary servo packet by UDP to port 9002 (+10 per instance) from a random local
port and waits for the answer at that port: `uint16 magic, uint16 frame_rate, uint32
frame_count, uint16 pwm[N]`, little-endian, no padding; N = 16 with magic 18458, N = 32 with
magic 29569 (SERVO_32_ENABLE = 1). The answer is one line of JSON with a newline before and
after: `timestamp`, `imu.gyro`, `imu.accel_body`, `position`, `velocity`, `attitude`.

SITL's parser is not a JSON parser: it finds each name with `strstr`, skips the closing quote
and the colon, and reads vectors with `sscanf("[%f, %f, %f]")`. So the reply is compact (no
space after a colon: a leading space would fail the `[`), and it carries no other key whose
name contains a required one.

Lock-step: SITL counts frames and sends frame k+1 only after it has read the answer to
frame k; it re-sends frame k unchanged when no answer comes (answer it again, do not step
again), and its count starts again at 0 when it restarts (reset the boat). Frame k carries
the servo outputs SITL computed from the state it last received, so the first frame seen is
answered with the initial state and every later frame holds its outputs for 1/frame_rate
seconds before answering.
"""

from __future__ import annotations

import json
import logging
import math
import socket
import struct
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from controller.errors import InputError

from controller.pwm import CommandChannels, PwmChannel
from bridge.shared.boat_physics import BoatPhysics

log = logging.getLogger(__name__)

MAGIC_16 = 18458
MAGIC_32 = 29569
CHANNELS = {MAGIC_16: 16, MAGIC_32: 32}
_HEADER = struct.Struct("<HHI")  # magic, frame_rate, frame_count
PACKET_BYTES = {magic: _HEADER.size + 2 * n for magic, n in CHANNELS.items()}  # 40 and 72

DEFAULT_PORT = 9002  # SITL's default JSON port; instance I uses 9002 + 10 I
DEFAULT_HOST = "127.0.0.1"  # loopback: nothing off this machine can drive the boat by default

# Rover's servo outputs: 1000-2000 us, 1500 neutral, no dead zone (Tools/autotest/default_params/
# rover.parm sets SERVO1/3_MIN 1000 and _MAX 2000; SERVOn_TRIM defaults to 1500).
SERVO_MIN, SERVO_MAX, SERVO_TRIM = 1000.0, 2000.0, 1500.0

GRAVITY = 9.80665  # m/s^2, ArduPilot's GRAVITY_MSS: the accelerometer reads -g on z at rest


@dataclass(frozen=True)
class ServoPacket:
    """One servo packet from SITL: its frame rate (SIM_RATE_HZ), frame count and PWM (us)."""

    frame_rate: int
    frame_count: int
    pwm: tuple[int, ...]


@dataclass(frozen=True)
class Rejected:
    """A datagram that is not a usable servo packet: `kind` groups warnings, `reason` says why."""

    kind: str
    reason: str


def parse_servo_packet(datagram: bytes) -> ServoPacket | Rejected:
    """Decode a servo packet (16 or 32 channels), or say why the datagram is not one."""
    if len(datagram) < _HEADER.size:
        return Rejected("short", f"{len(datagram)} bytes, shorter than the 8-byte header")
    magic, frame_rate, frame_count = _HEADER.unpack_from(datagram)
    if magic not in CHANNELS:
        return Rejected("bad magic", f"magic {magic}, expected {MAGIC_16} (16 channels) "
                        f"or {MAGIC_32} (32 channels)")
    size = PACKET_BYTES[magic]
    if len(datagram) != size:
        kind = "short" if len(datagram) < size else "corrupt"
        return Rejected(kind, f"{len(datagram)} bytes with magic {magic}, expected {size}")
    if frame_rate == 0:
        return Rejected("frame rate", "frame rate 0 Hz: no time step to take")
    pwm = struct.unpack_from(f"<{CHANNELS[magic]}H", datagram, _HEADER.size)
    return ServoPacket(frame_rate, frame_count, pwm)


def encode_servo_packet(packet: ServoPacket) -> bytes:
    """The bytes SITL would send for `packet` (16 or 32 channels, by the length of `pwm`)."""
    magic = {n: m for m, n in CHANNELS.items()}.get(len(packet.pwm))
    if magic is None:
        raise ValueError(f"a servo packet has 16 or 32 channels, got {len(packet.pwm)}")
    return (_HEADER.pack(magic, packet.frame_rate, packet.frame_count)
            + struct.pack(f"<{len(packet.pwm)}H", *packet.pwm))


def servo_calibration(channel: int) -> PwmChannel:
    """A Rover servo output (1000-2000 us, trim 1500, no dead zone) on `channel`."""
    return PwmChannel(channel, SERVO_MIN, SERVO_MAX, SERVO_TRIM)


def pwm_to_commands(pwm: tuple[int, ...], steering: PwmChannel,
                    throttle: PwmChannel) -> tuple[float, float]:
    """Servo PWM to our (nT, nS) percent. Steering above trim turns to starboard, which is
    nS < 0 in our model; throttle below trim is reverse; 0 (or a missing channel) is neutral."""
    live = {channel: value for channel, value in enumerate(pwm, start=1) if value != 0}
    return CommandChannels(steering, throttle).to_commands(live)  # a missing channel reads trim


@dataclass(frozen=True)
class PhysicsState:
    """What SITL reads, in its units and frames (NED, body x forward / y starboard / z down)."""

    timestamp_s: float
    gyro: tuple[float, float, float]  # rad/s, body
    accel_body: tuple[float, float, float]  # m/s^2, body, specific force (gravity included)
    position: tuple[float, float, float]  # m, NED from home
    velocity: tuple[float, float, float]  # m/s, NED
    attitude: tuple[float, float, float]  # roll, pitch, yaw rad


def physics_state(time_s: float, state, state_dot) -> PhysicsState:
    """The boat's 3-DOF state [x, y, psi, u, v, r] and body accelerations [.., u_dot, v_dot,
    r_dot] as SITL reads them: the IMU's specific force is the body-frame acceleration over
    ground, [u_dot - r v, v_dot + r u, 0], minus gravity (so [0, 0, -g] at rest)."""
    x, y, psi, u, v, r = (float(s) for s in state)
    u_dot, v_dot = float(state_dot[3]), float(state_dot[4])
    c, s = math.cos(psi), math.sin(psi)
    yaw = math.atan2(s, c)  # wrapped to (-pi, pi]
    return PhysicsState(
        timestamp_s=float(time_s),
        gyro=(0.0, 0.0, r),
        accel_body=(u_dot - r * v, v_dot + r * u, -GRAVITY),
        position=(x, y, 0.0),
        velocity=(c * u - s * v, s * u + c * v, 0.0),
        attitude=(0.0, 0.0, yaw),
    )


def encode_reply(state: PhysicsState) -> bytes:
    """One compact JSON line with a newline before and after, as SITL's parser needs it."""
    doc = {
        "timestamp": state.timestamp_s,
        "imu": {"gyro": list(state.gyro), "accel_body": list(state.accel_body)},
        "position": list(state.position),
        "velocity": list(state.velocity),
        "attitude": list(state.attitude),
    }
    try:
        text = json.dumps(doc, separators=(",", ":"), allow_nan=False)
    except ValueError:
        raise InputError(f"the boat's state is not finite at t = {state.timestamp_s:g} s: "
                         f"{doc}") from None
    return b"\n" + text.encode("ascii") + b"\n"


class SitlPhysicsServer:
    """Serves SITL's JSON physics with a scenario's boat: lock-step on SITL's frame counter.

    `handle(datagram, addr)` is the whole protocol without sockets; `open()` binds the UDP
    port (default 127.0.0.1: bind 0.0.0.0 only when SITL runs on another machine, since any
    sender on the port drives the boat), `serve()` answers packets until stopped.
    """

    def __init__(self, scenario, port: int = DEFAULT_PORT, steering_channel: int = 1,
                 throttle_channel: int = 3, host: str = DEFAULT_HOST,
                 work_dir: str | Path | None = None, plant=None):
        for name, ch in (("steering", steering_channel), ("throttle", throttle_channel)):
            if not 1 <= int(ch) <= 32:
                raise InputError(f"{name} channel {ch} is not a servo output 1..32")
        if steering_channel == throttle_channel:
            raise InputError(f"steering and throttle are both on channel {steering_channel}")
        if not 0 <= int(port) <= 65535:
            raise InputError(f"port {port} is not a UDP port")
        self.scenario = scenario
        self.host, self.port = host, int(port)
        self.steering = servo_calibration(int(steering_channel))
        self.throttle = servo_calibration(int(throttle_channel))
        self.physics = BoatPhysics(scenario, work_dir, plant=plant, tmp_prefix="canalnav-sitl-")
        self._last_count: int | None = None
        self._reply: bytes | None = None
        self._sender = None
        self._sock: socket.socket | None = None
        self._stopping = False
        self.commands = (0.0, 0.0)  # (nT, nS) last applied
        self.frames = 0  # new frames stepped
        self.repeats = 0  # repeated frames answered again
        self.restarts = 0
        self.rejected: Counter = Counter()  # kind -> count
        self._warned: set[str] = set()

    # -- the protocol, without sockets -----------------------------------------------------
    @property
    def output(self):
        """The plant's last output (scenarios.plants.plant.PlantOutput)."""
        return self.physics.output

    def handle(self, datagram: bytes, addr=None) -> bytes | None:
        """Answer one datagram from SITL: the reply bytes, or None for a packet to ignore."""
        packet = parse_servo_packet(datagram)
        if isinstance(packet, Rejected):
            self._warn_once(packet.kind, f"ignored a datagram from {_where(addr)}: "
                            f"{packet.reason}")
            self.rejected[packet.kind] += 1
            return None
        if addr is not None and addr != self._sender:
            log.info("SITL at %s (%d Hz, %d channels)", _where(addr), packet.frame_rate,
                     len(packet.pwm))
            self._sender = addr
        last = self._last_count
        if last is not None and packet.frame_count == last:
            self.repeats += 1
            return self._reply
        if last is not None and packet.frame_count < last:
            log.warning("SITL restarted (frame count %d after %d): the boat starts again "
                        "from the scenario's initial state", packet.frame_count, last)
            self.restarts += 1
            self.physics.reset()
            self.commands = (0.0, 0.0)
            last = None
        if last is not None:
            skipped = packet.frame_count - last - 1
            if skipped > 0:
                self._warn_once("skipped", f"SITL's frame count jumped from {last} to "
                                f"{packet.frame_count}: stepping over the {skipped} missing "
                                "frame(s) with this frame's outputs")
            self.commands = pwm_to_commands(packet.pwm, self.steering, self.throttle)
            dt = (packet.frame_count - last) / packet.frame_rate
            self.physics.step(self.commands, dt)
            self.frames += 1
        out = self.physics.output
        self._last_count = packet.frame_count
        self._reply = encode_reply(physics_state(out.time_s, out.state, out.state_dot))
        return self._reply

    def _warn_once(self, kind: str, message: str) -> None:
        """Log the first datagram of each kind of problem; later ones are only counted."""
        if kind not in self._warned:
            self._warned.add(kind)
            log.warning("%s (further ones of this kind are counted, not shown)", message)

    # -- sockets ---------------------------------------------------------------------------
    def open(self) -> tuple[str, int]:
        """Bind the UDP port (once); return the address it listens on."""
        if self._sock is None:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            try:
                sock.bind((self.host, self.port))
            except OSError as exc:
                sock.close()
                raise InputError(f"cannot listen on udp {self.host}:{self.port}: "
                                 f"{exc.strerror or exc}") from None
            self._sock = sock
        return self._sock.getsockname()[:2]

    def serve_once(self, timeout_s: float | None = 0.2) -> bool:
        """Wait up to `timeout_s` for one datagram and answer it; False if none came."""
        self.open()
        self._sock.settimeout(timeout_s)
        try:
            datagram, addr = self._sock.recvfrom(65536)
        except (socket.timeout, BlockingIOError):
            return False
        reply = self.handle(datagram, addr)
        if reply is not None:
            try:
                self._sock.sendto(reply, addr)
            except OSError as exc:  # SITL gone: it re-sends if it is still there
                self._warn_once("send", f"could not answer {_where(addr)}: {exc}")
        return True

    def serve(self, duration_s: float | None = None) -> None:
        """Answer SITL until `stop()` (from another thread), Ctrl-C, or `duration_s` of wall
        time; the physics itself runs on SITL's frames, never on this clock."""
        self.open()
        self._stopping = False
        end = None if duration_s is None else time.monotonic() + duration_s
        while not self._stopping and (end is None or time.monotonic() < end):
            self.serve_once(0.1 if end is None else max(0.0, min(0.1, end - time.monotonic())))

    def stop(self) -> None:
        """Make `serve()` return after its current wait."""
        self._stopping = True

    def close(self) -> None:
        """Close the socket and the plant (and the FMU's temporary folder)."""
        if self._sock is not None:
            self._sock.close()
            self._sock = None
        self.physics.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _where(addr) -> str:
    """'host:port' of a socket address, or 'SITL' when there is none (direct calls)."""
    return f"{addr[0]}:{addr[1]}" if addr else "SITL"


def sitl_command(parm_file: Path, port: int = DEFAULT_PORT, host: str = DEFAULT_HOST,
                 geodetic_origin: tuple | None = None) -> str:
    """The sim_vehicle.py command that starts ArduRover (boat) on this backend (`-N`: the
    SITL binary as built, since a rebuild fetches submodules over the network).

    `--model JSON:IP` names where SITL sends its packets; instance I sends to 9002 + 10 I,
    any other port goes to the SITL binary as `--sim-port-out` (through `-A`). Home, where
    the scenario's (0, 0) is on the Earth (positions are NED metres from it), is the
    scenario's geodetic origin, else SITL's own default (given explicitly, so that the
    bridge's `--origin` can match it).
    """
    from bridge.shared.ardupilot import SITL_DEFAULT_HOME

    target = "127.0.0.1" if host in ("", "127.0.0.1") else host
    if target in ("0.0.0.0", "::"):
        target = "<this machine's address>"
    parts = ["sim_vehicle.py -v Rover -f motorboat -N", f"--model JSON:{target}",
             f"--add-param-file={parm_file}"]
    instance, rest = divmod(port - DEFAULT_PORT, 10)
    if port != DEFAULT_PORT:
        if instance > 0 and rest == 0:
            parts.append(f"-I {instance}")
        else:
            parts.append(f'-A "--sim-port-out={port}"')
    lat, lon, alt = geodetic_origin if geodetic_origin is not None else SITL_DEFAULT_HOME
    parts.append(f"--custom-location={lat:.8f},{lon:.8f},{alt:g},0")
    return " ".join(parts)


def bridge_command(scenario_file, geodetic_origin: tuple | None) -> str:
    """The `canalnav bridge` command that drives that SITL through the MAVProxy output
    sim_vehicle.py opens on udp 14550, in the frame SITL's home puts the scenario in: a
    scenario without [origin] needs `--origin` at SITL's default home."""
    from bridge.shared.ardupilot import SITL_DEFAULT_HOME
    from bridge.onboard.loop import format_origin

    parts = ["canalnav bridge --connect udp:127.0.0.1:14550", f"--scenario {scenario_file}"]
    if geodetic_origin is None:
        parts.append(f"--origin={format_origin(SITL_DEFAULT_HOME)}")  # "=": it starts with a minus
    parts.append("--mode MANUAL --arm")
    return " ".join(parts)
