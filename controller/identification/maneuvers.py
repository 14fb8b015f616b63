"""The paper's identification manoeuvres (§IV-A, Table "System identification data") simulated
from the model, with seeded sensor noise, as manoeuvre logs.

Runs: an acceleration staircase from rest (nT = 31.0, 34.9, 38.6, 41.0, 50.6 %), a
deceleration staircase from steady state at 50.6 % (39.4, 20.0 %), each step held to steady
state; a 20°/50 % zigzag at nT = 42 % stopped after three overshoots; and a held-out
10°/30 % zigzag at 42 % that identification uses only to check its fit. The plant is the
exact model with the real actuators' rate limits (10 %/s throttle, 40 %/s steering); a log
records the actuator position applied over each 0.1 s sample, as a real logger of the servo
positions would.
"""

from __future__ import annotations

import dataclasses

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .logs import ManeuverLog, with_truth_meta, write_log
from ..params import IDENTIFIED, BoatParams

SAMPLE_S = 0.1  # 10 Hz, as the paper's logs
PLANT_SUBSTEPS = 4  # RK4 sub-steps per sample in the simulated plant
THROTTLE_RATE_PCT_S = 10.0
STEERING_RATE_PCT_S = 40.0


@dataclass(frozen=True)
class SensorNoise:
    """Standard deviations of white Gaussian sensor noise, SI units."""

    position_m: float = 0.02  # RTK GPS
    heading_rad: float = math.radians(0.1)
    speed_mps: float = 0.02  # u and v
    yaw_rate_radps: float = math.radians(0.2)

    def sigmas(self) -> np.ndarray:
        """Per state x, y, psi, u, v, r."""
        return np.array([self.position_m, self.position_m, self.heading_rad,
                         self.speed_mps, self.speed_mps, self.yaw_rate_radps])


NOISE = {"realistic": SensorNoise(), "none": SensorNoise(0.0, 0.0, 0.0, 0.0)}


@dataclass(frozen=True)
class Steady:
    """When a held command counts as at steady state: speed and yaw rate changed less than
    the tolerances over the last `window_s`, after at least `min_hold_s`; at most `max_hold_s`."""

    window_s: float = 10.0
    speed_tol_mps: float = 0.005
    min_hold_s: float = 20.0
    max_hold_s: float = 240.0


@dataclass(frozen=True)
class SurgeRun:
    """A throttle staircase with nS = 0: each level held to steady state.

    `start_pct` is the throttle at whose steady state the run starts (0 = at rest);
    `lead_in_s` seconds of it are logged before the first step.
    """

    name: str
    maneuver: str  # "acceleration" or "deceleration"
    throttle_pct: tuple[float, ...]
    start_pct: float = 0.0
    lead_in_s: float = 5.0
    steady: Steady = Steady()
    use: str = "fit"


@dataclass(frozen=True)
class ZigzagRun:
    """A heading_deg/steering_pct zigzag at constant throttle, from steady straight running.

    First turn to starboard (nS = -steering, psi grows); the steering reverses each time the
    heading passes ±heading_deg; the run ends when the heading turns back for the
    `overshoots`-th time after a reversal (three overshoots in the paper).
    """

    name: str
    heading_deg: float
    steering_pct: float
    throttle_pct: float = 42.0
    overshoots: int = 3
    lead_in_s: float = 5.0
    tail_s: float = 2.0
    max_s: float = 400.0
    use: str = "fit"


Run = SurgeRun | ZigzagRun

PAPER_RUNS: tuple[Run, ...] = (
    SurgeRun("01_acceleration", "acceleration", (31.0, 34.9, 38.6, 41.0, 50.6)),
    SurgeRun("02_deceleration", "deceleration", (39.4, 20.0), start_pct=50.6),
    ZigzagRun("03_zigzag_20_50", 20.0, 50.0, 42.0),
    ZigzagRun("04_heldout_zigzag_10_30", 10.0, 30.0, 42.0, use="heldout"),
)
"""The paper's identification runs plus the held-out zigzag."""

QUICK_RUNS: tuple[Run, ...] = (
    SurgeRun("01_acceleration", "acceleration", (31.0, 41.0, 50.6),
             steady=Steady(window_s=5.0, speed_tol_mps=0.02, min_hold_s=15.0)),
    SurgeRun("02_deceleration", "deceleration", (20.0,), start_pct=50.6,
             steady=Steady(window_s=5.0, speed_tol_mps=0.02, min_hold_s=15.0)),
    ZigzagRun("03_zigzag_20_50", 20.0, 50.0, 42.0),
    ZigzagRun("04_heldout_zigzag_10_30", 10.0, 30.0, 42.0, overshoots=2, use="heldout"),
)
"""A shorter set (fewer throttle steps, looser steady state) for fast tests and demos."""

MAX_OVERSHOOTS = 50


def with_overshoots(runs: tuple[Run, ...], overshoots: int | None) -> tuple[Run, ...]:
    """`runs` with the fit zigzags' overshoots set to `overshoots` (None: as they are). A
    longer zigzag gives the sway-yaw fit more to work with where the state is noisy (an EKF's
    estimate); the held-out zigzag stays as it is."""
    if overshoots is None:
        return tuple(runs)
    if not (isinstance(overshoots, int) and 1 <= overshoots <= MAX_OVERSHOOTS):
        from ..errors import InputError

        raise InputError(f"--overshoots must be a whole number from 1 to {MAX_OVERSHOOTS}, "
                         f"got {overshoots!r}")
    return tuple(dataclasses.replace(r, overshoots=overshoots)
                 if isinstance(r, ZigzagRun) and r.use == "fit" else r for r in runs)


@dataclass
class _Plant:
    """The exact model stepped at SAMPLE_S with rate-limited actuators held over each sample."""

    params: BoatParams
    x: np.ndarray = field(default_factory=lambda: np.zeros(6))
    act: np.ndarray = field(default_factory=lambda: np.zeros(2))

    def __post_init__(self) -> None:
        from ..model import EXACT, step_function

        self._step = step_function(SAMPLE_S, PLANT_SUBSTEPS, EXACT)
        self._p = self.params.as_vector()
        self.t: list[float] = []
        self.xs: list[np.ndarray] = []
        self.us: list[np.ndarray] = []
        self.k = 0  # samples since the log's start

    @property
    def time_s(self) -> float:
        return self.k * SAMPLE_S

    def step(self, command: tuple[float, float]) -> None:
        """Log the state now, move the actuators toward `command`, integrate one sample."""
        limit = np.array([THROTTLE_RATE_PCT_S, STEERING_RATE_PCT_S]) * SAMPLE_S
        self.act = np.clip(self.act + np.clip(np.asarray(command) - self.act, -limit, limit),
                           -100.0, 100.0)
        self.t.append(self.time_s)
        self.xs.append(self.x.copy())
        self.us.append(self.act.copy())
        self.x = np.asarray(self._step(self.x, self.act, self._p, [0.0, 0.0])).ravel()
        self.k += 1

    def settle(self, throttle_pct: float, seconds: float = 600.0) -> None:
        """Run at `throttle_pct` straight without logging, then forget the history."""
        for _ in range(int(round(seconds / SAMPLE_S))):
            self.step((throttle_pct, 0.0))
        self.t.clear(), self.xs.clear(), self.us.clear()
        self.x[:3] = 0.0
        self.k = 0

    def hold_to_steady(self, command: tuple[float, float], steady: Steady) -> None:
        n_window = int(round(steady.window_s / SAMPLE_S))
        start = len(self.xs)
        while True:
            self.step(command)
            held = (len(self.xs) - start) * SAMPLE_S
            if held >= steady.max_hold_s:
                return
            if held >= steady.min_hold_s and len(self.xs) - start > n_window:
                window = np.array(self.xs[-n_window:])
                if np.ptp(window[:, 3]) < steady.speed_tol_mps:
                    return


def _simulate_surge(run: SurgeRun, plant: _Plant) -> None:
    if run.start_pct:
        plant.settle(run.start_pct)
        plant.act[:] = (run.start_pct, 0.0)
    for _ in range(int(round(run.lead_in_s / SAMPLE_S))):
        plant.step((run.start_pct, 0.0))
    for level in run.throttle_pct:
        plant.hold_to_steady((level, 0.0), run.steady)


def _simulate_zigzag(run: ZigzagRun, plant: _Plant) -> None:
    plant.settle(run.throttle_pct)
    plant.act[:] = (run.throttle_pct, 0.0)
    for _ in range(int(round(run.lead_in_s / SAMPLE_S))):
        plant.step((run.throttle_pct, 0.0))
    limit = math.radians(run.heading_deg)
    side = 1.0  # +1: turning to starboard (nS < 0), heading growing
    overshoots, reversed_at = 0, False
    t_end = None
    start = plant.time_s
    while plant.time_s - start < run.max_s:
        plant.step((run.throttle_pct, -side * run.steering_pct))
        psi, r = plant.x[2], plant.x[5]
        if side * psi >= limit:
            side, reversed_at = -side, True
        elif reversed_at and side * r > 0 and t_end is None:
            # the heading has turned back toward the new side: one overshoot completed
            overshoots += 1
            reversed_at = False
            if overshoots >= run.overshoots:
                t_end = plant.time_s + run.tail_s
        if t_end is not None and plant.time_s >= t_end:
            return


def simulate_run(run: Run, params: BoatParams = IDENTIFIED,
                 noise: SensorNoise = NOISE["realistic"], seed: int = 0,
                 run_index: int = 0, noise_name: str = "realistic") -> ManeuverLog:
    """One run as a log at 10 Hz; noise from `np.random.default_rng([seed, run_index])`."""
    plant = _Plant(params)
    if isinstance(run, SurgeRun):
        _simulate_surge(run, plant)
        description = (f"{run.maneuver} staircase nT = "
                       + ", ".join(f"{v:.1f}" for v in run.throttle_pct)
                       + f" % from {'rest' if not run.start_pct else f'steady {run.start_pct:.1f} %'}"
                       ", nS = 0, each held to steady state")
        maneuver = run.maneuver
    else:
        _simulate_zigzag(run, plant)
        description = (f"{run.heading_deg:g} deg/{run.steering_pct:g} % zigzag at "
                       f"nT = {run.throttle_pct:g} %, {run.overshoots} overshoots")
        maneuver = "zigzag"
    truth = np.array(plant.xs)
    rng = np.random.default_rng([seed, run_index])
    measured = truth + rng.standard_normal(truth.shape) * noise.sigmas()
    meta = {
        "maneuver": maneuver,
        "use": run.use,
        "description": description,
        "generator": "canalnav maneuvers (exact model, actuator rate limits "
                     f"{THROTTLE_RATE_PCT_S:g} and {STEERING_RATE_PCT_S:g} %/s)",
        "noise": noise_name,
        "seed": str(seed),
    }
    return ManeuverLog(np.array(plant.t), measured, np.array(plant.us),
                       with_truth_meta(meta, params), source=run.name)


def generate(params: BoatParams = IDENTIFIED, seed: int = 1, noise: str = "realistic",
             runs: tuple[Run, ...] = PAPER_RUNS) -> dict[str, ManeuverLog]:
    """Every run of `runs` as a log, keyed by run name. Same seed, same logs."""
    if noise not in NOISE:
        from ..errors import InputError

        raise InputError(f"noise {noise!r}: expected one of {', '.join(NOISE)}")
    return {run.name: simulate_run(run, params, NOISE[noise], seed, k, noise)
            for k, run in enumerate(runs)}


def write_logs(directory: str | Path, logs: dict[str, ManeuverLog]) -> list[Path]:
    """Write each log as `<directory>/<name>.csv`; returns the paths."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, log in logs.items():
        path = directory / f"{name}.csv"
        write_log(path, log)
        paths.append(path)
    return paths
