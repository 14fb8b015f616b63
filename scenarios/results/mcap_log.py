"""A run in Foxglove: `run.mcap` as the run goes, and the same channels live over WebSocket.

`VizLog` owns one Foxglove SDK context: the channels below, an MCAP writer on `run.mcap`
(flushed every second of the run, so an interrupted run keeps what it logged) and, if asked,
the SDK's WebSocket server (Foxglove's protocol), which queues messages per client in its own
threads and drops the oldest for a slow client: logging never waits for a viewer. Log times
are the run's clock (simulation seconds, or the bridge's), so a scrub in the viewer lines up
with the rows of log.csv / steps.csv. The messages are built in `foxglove_messages`.

`LoopViz` is the closed loop's use of it (`scenarios.loop.closed_loop`); the bridge has its
own in `bridge.onboard.step_log`. Needs the `viz` extra (`pip install 'canalnav[viz]'`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from controller.errors import InputError
from scenarios.results import foxglove_messages as fm

TOPICS = {
    "tf": "/tf",
    "cloud": "/lidar/points",
    "walls": "/world/walls",
    "segments": "/perception/segments",
    "tracks": "/perception/tracks",
    "plan": "/controller/plan",
    "hull": "/boat/hull",
    "fix": "/gps/fix",
    "figures": "/canalnav/step",
}
"""Channel topics (the shipped layout names them)."""

DEFAULT_CLOUD_POINTS = 3000
"""Points of each LiDAR cloud kept for the viewer (of some 20 000 a scan): 36 kB a step."""

STATIC_EVERY_S = 1.0
"""The true walls are sent again every second (a viewer that joins late still gets them)."""


@dataclass(frozen=True)
class VizOptions:
    """Where the run goes: an MCAP file, a live server (host, port), or both."""

    mcap_path: Path | None = None
    live: tuple[str, int] | None = None
    cloud_points: int = DEFAULT_CLOUD_POINTS
    flush_every_s: float = 1.0

    @property
    def enabled(self) -> bool:
        return self.mcap_path is not None or self.live is not None


def parse_live(text: str, option: str = "--live") -> tuple[str, int]:
    """`[HOST:]PORT` -> (host, port); host 127.0.0.1 unless given (only this machine can
    connect: another address opens the view to the network)."""
    host, _, port = str(text).rpartition(":")
    host = host.strip("[]") or "127.0.0.1"
    try:
        p = int(port)
    except ValueError:
        raise InputError(f"{option} {text!r}: expected [HOST:]PORT, e.g. 8765 or "
                         "0.0.0.0:8765") from None
    if not 0 <= p <= 65535:
        raise InputError(f"{option} {text!r}: port must lie in 0..65535")
    return host, p


class VizLog:
    """The channels of a run in one Foxglove context, to an MCAP file and/or a live server."""

    def __init__(self, options: VizOptions, figures: tuple, texts: tuple = (),
                 name: str = "canalnav"):
        foxglove = fm.require_viz()
        from foxglove import channels as ch
        from foxglove.mcap import MCAPWriteOptions

        self.options = options
        self._ctx = foxglove.Context()
        c = self._ctx
        self._tf = ch.FrameTransformsChannel(TOPICS["tf"], context=c)
        self._cloud = ch.PointCloudChannel(TOPICS["cloud"], context=c)
        self._scene = {k: ch.SceneUpdateChannel(TOPICS[k], context=c)
                       for k in ("walls", "segments", "tracks", "plan", "hull")}
        self._fix = ch.LocationFixChannel(TOPICS["fix"], context=c)
        self._figures = foxglove.Channel(
            TOPICS["figures"], schema=fm.figures_schema(f"{name}.Step", figures, texts), context=c)
        self._mcap = self._server = None
        if options.mcap_path is not None:
            path = Path(options.mcap_path)
            path.parent.mkdir(parents=True, exist_ok=True)
            # one thread: the loop's cores are the NMPC's and the LiDAR worker's
            self._mcap = foxglove.open_mcap(path, allow_overwrite=True, context=c,
                                            writer_options=MCAPWriteOptions(compression_threads=0))
        if options.live is not None:
            host, port = options.live
            try:
                self._server = foxglove.start_server(name=name, host=host, port=port, context=c)
            except Exception as exc:  # noqa: BLE001 - a taken port, a bad address: user input
                self.close()
                raise InputError(f"--live {host}:{port}: cannot serve there: {exc}") from None
        self._last_flush_s = -math.inf
        self._static_s = -math.inf
        self._static_key = None
        self._hull_s = -math.inf
        self._walls_msg = None

    @property
    def live_url(self) -> str | None:
        if self._server is None:
            return None
        return f"ws://{self.options.live[0]}:{self._server.port}"

    # -- channels --------------------------------------------------------------------------
    def frames(self, t, pose, estimate=None, lidars=()) -> None:
        self._tf.log(fm.frame_transforms(t, pose, estimate, lidars), log_time=fm.ns(t))

    def cloud(self, t, points, scan_time_s=None) -> None:
        """A cloud in the body frame, stamped with its scan's time (the frame then is that
        instant's), logged at `t`."""
        stamp = t if scan_time_s is None else scan_time_s
        self._cloud.log(fm.point_cloud(stamp, fm.decimate(points, self.options.cloud_points)),
                        log_time=fm.ns(t))

    def walls(self, t, walls, obstacles=(), key=None) -> None:
        """The true walls and obstacle outlines, when they change (`key`) and every second."""
        if key == self._static_key and t - self._static_s < STATIC_EVERY_S - 1e-9:
            return
        if key != self._static_key or self._walls_msg is None:  # built once per set of outlines
            self._walls_msg = fm.polylines_update(t, [
                ("walls", walls, fm.WALL_RGBA), ("obstacles", obstacles, fm.OBSTACLE_RGBA)])
        self._static_key, self._static_s = key, t
        self._scene["walls"].log(self._walls_msg, log_time=fm.ns(t))

    def segments(self, t, segments) -> None:
        self._scene["segments"].log(fm.segments_update(t, segments), log_time=fm.ns(t))

    def plan(self, t, predicted, hull_radius_m=3.0, separation_m=None) -> None:
        self._scene["plan"].log(fm.plan_update(t, predicted, hull_radius_m=hull_radius_m),
                                log_time=fm.ns(t))
        if t - self._hull_s >= STATIC_EVERY_S - 1e-9:  # frame-locked to the boat: once a second
            self._hull_s = t
            self._scene["hull"].log(fm.hull_update(t, hull_radius_m=hull_radius_m,
                                                   separation_m=separation_m), log_time=fm.ns(t))

    def tracks(self, t, tracks, vessels=()) -> None:
        self._scene["tracks"].log(fm.tracks_update(t, tracks, vessels), log_time=fm.ns(t))

    def fix(self, t, north_m, east_m, origin, sigma_m=0.0) -> None:
        self._fix.log(fm.location_fix(t, north_m, east_m, origin, sigma_m), log_time=fm.ns(t))

    def figures(self, t, values: dict) -> None:
        self._figures.log(values, log_time=fm.ns(t))

    def end_step(self, t) -> None:
        """Flush the MCAP file every `flush_every_s` of the run."""
        if self._mcap is not None and t - self._last_flush_s >= self.options.flush_every_s - 1e-9:
            self._mcap.flush()
            self._last_flush_s = t

    def close(self) -> None:
        if self._mcap is not None:
            self._mcap.close()
            self._mcap = None
        if self._server is not None:
            self._server.stop()
            self._server = None


LOOP_FIGURES = (
    "time_s", "nT_cmd_pct", "nS_cmd_pct", "dnT_pctps", "dnS_pctps", "nT_actual_pct",
    "nS_actual_pct", "speed_mps", "u_mps", "v_mps", "r_radps", "clearance_bow_m",
    "clearance_stern_m", "clearance_m", "desired_separation_m", "cross_track_m", "solve_ms",
    "slack_m", "segments", "segments_cleaned", "perception_age_s", "blind", "tracks",
    "position_error_m",
)
LOOP_TEXTS = ("status", "waiting", "rules")


class LoopViz:
    """The closed loop's picture: true pose as `boat`, the estimate as `boat_estimate`, the
    LiDAR cloud (from the perception that scanned it), true walls, segments the controller
    used, its plan and hull circles, tracks and true vessels, GPS fixes (when the scenario
    has a geodetic origin) and the per-step figures of log.csv."""

    def __init__(self, options: VizOptions, lidar_mounts=(), origin=None,
                 hull_radius_m: float = 3.0, separation_m: float | None = None,
                 gps_sigma_m: float = 0.0, n_walls: int = 0):
        self.log = VizLog(options, LOOP_FIGURES, LOOP_TEXTS)
        self.lidars = fm.lidar_frames(lidar_mounts)
        self.origin = origin
        self.hull_radius_m = hull_radius_m
        self.separation_m = separation_m
        self.gps_sigma_m = gps_sigma_m
        self.n_walls = n_walls  # the first n outlines are walls, the rest obstacles

    @property
    def live_url(self):
        return self.log.live_url

    def gps_fix(self, t, position_ne) -> None:
        if self.origin is not None:
            self.log.fix(t, float(position_ne[0]), float(position_ne[1]), self.origin,
                         self.gps_sigma_m)

    def step(self, t, true_state, est, outlines, segments, decision, view, command, rate,
             actuators, clearance, cross_track, solve_ms, cloud=None, vessels=()) -> None:
        """One control step (what log.csv's row says, and the scene around it)."""
        log = self.log
        log.frames(t, true_state, est, self.lidars)
        walls = [o for o in outlines[:self.n_walls]]
        log.walls(t, walls, outlines[self.n_walls:], key=len(outlines))
        if cloud is not None:
            scan_t, points = cloud
            log.cloud(t, points, scan_t)
        log.segments(t, segments)
        log.plan(t, decision.predicted, self.hull_radius_m, self.separation_m)
        tracks = view.tracks if view is not None else ()
        if tracks or vessels:
            log.tracks(t, tracks, vessels)
        stats = decision.stats
        f = fm.finite
        log.figures(t, {
            "time_s": round(float(t), 6), "nT_cmd_pct": f(command[0]), "nS_cmd_pct": f(command[1]),
            "dnT_pctps": f(rate[0]), "dnS_pctps": f(rate[1]), "nT_actual_pct": f(actuators[0]),
            "nS_actual_pct": f(actuators[1]), "speed_mps": f(np.hypot(true_state[3], true_state[4])),
            "u_mps": f(true_state[3]), "v_mps": f(true_state[4]), "r_radps": f(true_state[5]),
            "clearance_bow_m": f(clearance[0]), "clearance_stern_m": f(clearance[1]),
            "clearance_m": f(min(clearance)), "desired_separation_m": self.separation_m,
            "cross_track_m": f(cross_track), "solve_ms": f(solve_ms),
            "slack_m": f(decision.slack_m), "segments": len(np.asarray(segments).reshape(-1, 4)),
            "segments_cleaned": sum(view.dropped.values()) if view is not None else 0,
            "perception_age_s": f(view.age_s) if view is not None else 0.0,
            "blind": int(view.blind) if view is not None else 0, "tracks": len(tracks),
            "position_error_m": f(np.hypot(*(np.asarray(est[:2]) - true_state[:2]))),
            "status": str(decision.status), "waiting": str(stats.get("waiting", "")),
            "rules": str(stats.get("rules", "")),
        })
        log.end_step(t)

    def close(self) -> None:
        self.log.close()
