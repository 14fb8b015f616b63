"""LiDAR perception one control period behind the controller, optionally in its own process.

On the boat the LiDAR driver and the wall detector run beside the controller, not inside its
loop: at t_k the NMPC uses the segments of the scan taken at t_(k-1) (the first step waits for
its own). Modelling that latency also frees the scan for step k + 1 from waiting for the
controller and the plant of step k, so a worker process on another core renders and detects it
meanwhile. Serial and parallel runs make the same scans, in the same order, from the same
seed, so they give the same segments bit for bit; only the wall time differs. With
`perceive`, the vessel tracker runs in the loop's process on the returns it reads (a fraction
of the cloud, sent back with the segments): the scan and detection alone are still the larger
share of a period, and the tracks are the same wherever it runs.

The worker is `python -m scenarios.sensors.perception_pipeline`, spoken to over its stdin and stdout
with pickled messages: no fork of a process that holds CasADi, fmpy and OpenCV state, and no
re-import of the caller's `__main__`.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import traceback
import weakref
from pathlib import Path

import numpy as np

from scenarios.sensors.perception import LidarPerception


class PerceptionWorkerError(RuntimeError):
    """The perception worker process died or could not be started."""


WORKER_ENV = "CANALNAV_PERCEPTION_WORKER"


def spare_core() -> bool:
    """Whether a run's perception may have a worker process by default: when the machine has
    a second core, unless $CANALNAV_PERCEPTION_WORKER is 0 (several runs side by side already
    keep every core busy, as the tests under pytest-xdist do: a worker per run then only adds
    processes, and the machine does about a third more work for the same runs)."""
    if os.environ.get(WORKER_ENV, "").strip() == "0":
        return False
    return (os.cpu_count() or 1) > 1


class DelayedLidarPerception:
    """`LidarPerception` with a one-period latency; `parallel` runs it in a worker process
    (default: `spare_core()`). `cloud_points` > 0: `last_cloud` is
    the decimated cloud of the scan whose result the last call returned (see LidarPerception)."""

    name = "lidar"

    def __init__(self, world, seed: int = 0, config=None, detection=None,
                 parallel: bool | None = None, tracking=None, cloud_points: int = 0):
        self.parallel = spare_core() if parallel is None else bool(parallel)
        self.points_per_scan: list[int] = []
        self.time_s = {"lidar_scan": 0.0, "detection": 0.0, "tracking": 0.0,
                       "lidar_scan_cpu": 0.0, "detection_cpu": 0.0, "tracking_cpu": 0.0}
        self._ready = None  # serial: (result, points, timing) of the last request
        self._requested = None  # the method asked for last ("segments" or "perceive")
        self.last_cloud = None
        self._pending = None  # (time, estimated state) of the scan asked for last
        # The tracker runs here, on the returns of the scan the worker (or `_inner`) sends:
        # the two processes' shares of a period are then closer (the worker's, the scan and
        # detection, is still the larger), and the tracks are the same either way.
        self._tracking = None
        if tracking is not False:
            from scenarios.sensors.perception import TrackingHalf, tracker_config

            self._tracking = TrackingHalf(tracking or tracker_config(config, detection))
        args = (world, seed, config, detection, tracking, False, cloud_points)
        if self.parallel:
            self._worker = _Worker(args)
            self._inner = None
        else:
            self._worker = None
            self._inner = LidarPerception(*args)

    def segments(self, time_s, true_state, estimated_state) -> np.ndarray:
        """The segments of the previous call's scan; scans this pose for the next call."""
        return self._call("segments", time_s, true_state, estimated_state)

    def perceive(self, time_s, true_state, estimated_state):
        """The walls and vessel tracks (`Percept`) of the previous call's scan, as `segments`."""
        return self._call("perceive", time_s, true_state, estimated_state)

    def _call(self, method, time_s, true_state, estimated_state):
        request = (method, float(time_s), np.array(true_state, float),
                   np.array(estimated_state, float))
        if self._requested is None:
            self._request(request)
        elif self._requested != method:
            raise RuntimeError(f"DelayedLidarPerception: {method}() after "
                               f"{self._requested}() (use one of the two per run)")
        found, scanned = self._collect(), self._pending
        self._request(request)
        if method == "perceive":  # the scan's returns and segments: track them here
            cropped, segs = found
            if self._tracking is None:
                from controller.perception.feed import Percept

                return None if segs is None else Percept(segs)
            found = self._tracking.track(*scanned, cropped, segs)
            self.time_s["tracking"] = self._tracking.time_s
            self.time_s["tracking_cpu"] = self._tracking.cpu_s
        return found

    def close(self) -> None:
        if self._worker is not None:
            self._worker.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _request(self, request) -> None:
        self._requested = request[0]
        self._pending = (request[1], request[3])
        if request[0] == "perceive":
            request = ("scan_for_tracking", *request[1:])
        if self._worker is not None:
            self._worker.send(request)
            return
        found = getattr(self._inner, request[0])(*request[1:])
        self._ready = (found, self._inner.points_per_scan[-1], dict(self._inner.time_s),
                       self._inner.last_cloud)

    def _collect(self) -> np.ndarray:
        if self._worker is None:
            found, n_points, time_s, cloud = self._ready
        else:
            found, n_points, time_s, cloud = self._worker.receive()
        self.points_per_scan.append(n_points)
        self.last_cloud = cloud
        self.time_s = time_s
        return found


class _Worker:
    """The client side of one worker process."""

    def __init__(self, args):
        root = str(Path(__file__).resolve().parents[2])  # the folder holding the packages
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
        try:
            self._proc = subprocess.Popen(
                [sys.executable, "-m", "scenarios.sensors.perception_pipeline"],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env)
        except OSError as exc:
            raise PerceptionWorkerError(f"perception worker: could not start "
                                        f"{sys.executable}: {exc}") from None
        self._finalizer = weakref.finalize(self, _stop, self._proc)
        for pipe in (self._proc.stdin, self._proc.stdout):
            _widen(pipe)
        self.send(args)

    def send(self, message) -> None:
        try:
            pickle.dump(message, self._proc.stdin, protocol=pickle.HIGHEST_PROTOCOL)
            self._proc.stdin.flush()
        except (BrokenPipeError, OSError, ValueError):
            raise self._died() from None

    def receive(self):
        try:
            kind, *rest = pickle.load(self._proc.stdout)
        except (EOFError, OSError, ValueError, pickle.UnpicklingError):
            raise self._died() from None
        if kind == "error":
            exc, where = rest
            exc.add_note("(raised in the LiDAR perception worker)\n" + where)
            raise exc
        return rest

    def close(self) -> None:
        self._finalizer()

    def _died(self) -> PerceptionWorkerError:
        try:
            code = self._proc.wait(timeout=2.0)
        except subprocess.TimeoutExpired:
            code = None
        self.close()
        return PerceptionWorkerError(
            f"perception worker (pid {self._proc.pid}) stopped answering "
            f"(exit code {code}); its error, if any, is on stderr above")


def _widen(pipe, size: int = 1 << 20) -> None:
    """Let a pipe hold a whole reply (a scan's segments and the tracker's returns, a few
    hundred kB): the worker then writes it at once and goes on, instead of waiting in 64 kB
    pieces for the loop to read. Linux only, and only as far as the system allows."""
    try:
        import fcntl
    except ImportError:  # (not on Windows)
        return
    setsize = getattr(fcntl, "F_SETPIPE_SZ", None)
    if setsize is None:
        return
    try:
        with open("/proc/sys/fs/pipe-max-size") as f:
            size = min(size, int(f.read()))
    except (OSError, ValueError):
        pass
    try:
        fcntl.fcntl(pipe.fileno(), setsize, size)
    except OSError:
        pass


def _stop(proc: subprocess.Popen) -> None:
    """Ask the worker to finish (None, then end of input); kill it if it does not."""
    try:
        pickle.dump(None, proc.stdin)
        proc.stdin.close()
    except (OSError, ValueError):
        pass
    try:
        proc.wait(timeout=5.0)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    if proc.stdout is not None:
        proc.stdout.close()


def _serve(inp, out) -> int:
    """The worker: build the perception from the first message, then answer each request
    (method, time, true state, estimated state) with ("ok", result, points, timing, cloud)
    or ("error", exception, traceback); the cloud is None unless it was asked to keep it."""
    args = pickle.load(inp)
    try:
        perception, failure = LidarPerception(*args), None
    except Exception as exc:  # reported on the first request, where the caller waits
        perception, failure = None, (exc, traceback.format_exc())
    while True:
        try:
            request = pickle.load(inp)
        except EOFError:
            return 0
        if request is None:
            return 0
        if failure is not None:
            reply = ("error", *failure)
        else:
            try:
                method, *inputs = request
                if method not in ("segments", "scan_for_tracking"):  # (tracking: the caller's)
                    raise ValueError(f"perception worker: no method {method!r}")
                found = getattr(perception, method)(*inputs)
                reply = ("ok", found, perception.points_per_scan[-1], dict(perception.time_s),
                         perception.last_cloud)
            except Exception as exc:
                reply = ("error", exc, traceback.format_exc())
        try:
            data = pickle.dumps(reply, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception:  # an exception that does not pickle: send its text
            data = pickle.dumps(("error", RuntimeError(repr(reply[1])), reply[2]))
        out.write(data)
        out.flush()


if __name__ == "__main__":
    _out = sys.stdout.buffer
    sys.stdout = sys.stderr  # nothing but replies may reach the pipe
    sys.exit(_serve(sys.stdin.buffer, _out))
