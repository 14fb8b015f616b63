"""`canalnav cosim DIR`: run the system of `canalnav fmu system` through OSP's libcosim and
write the results as `canalnav run` does (log.csv, summary.json with the same metrics).

The master here only watches: libcosim steps both FMUs and passes the values along the
connections; every control period (0.1 s) this reads the boat's state and the navigation's
outputs, scores them against the scenario embedded in navigation.fmu, and stops at the goal,
a collision, a controller failure or the time limit, as the closed loop does.
"""

from __future__ import annotations

import csv
import json
import math
import multiprocessing
import os
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable
from xml.etree import ElementTree

import numpy as np

from controller.errors import CanalnavError, InputError
from controller.geometry import Polyline
from scenarios.cosim.extra import require
from scenarios.cosim.nav_model import SCENARIO_RESOURCE
from scenarios.cosim.navigation import STATUS_CODES
from scenarios.cosim.system import BOAT, NAVIGATION, OSP_FILE, check_step
from scenarios.results import metrics
from scenarios.results.encounters import EncounterWatch

OSP = "{http://opensimulationplatform.com/MSMI/OSPSystemStructure}"
BOAT_OUTPUTS = ("x", "y", "psi", "u", "v", "r", "nT_actual", "nS_actual")
NAV_OUTPUTS = ("nT", "nS", "slack", "clearance", "cross_track")
LOG_COLUMNS = ("time_s", "true_x_m", "true_y_m", "true_psi_rad", "true_u_mps", "true_v_mps",
               "true_r_radps", "nT_cmd_pct", "nS_cmd_pct", "nT_actual_pct", "nS_actual_pct",
               "clearance_bow_m", "clearance_stern_m", "cross_track_m", "canal_width_m",
               "canal_width_min_hull_m", "centre_offset_m", "slack_m", "status")
NAV_LOG = "navigation_log.csv"
NOT_SCORED = ["obstacles (first detected: the segments stay inside the navigation FMU)",
              "tracking", "water", "elastic", "time_blind_s", "missing_scans",
              "segments_cleaned"]
"""What `canalnav run`'s summary has that a master seeing only the FMUs' outputs cannot score."""


@dataclass(frozen=True)
class System:
    """What a system folder holds, checked before anything runs."""

    folder: Path
    osp: Path
    step_s: float
    scenario: object  # scenarios.scenario_file.Scenario, from navigation.fmu's resources
    sources: dict  # simulator name -> FMU path


@dataclass
class CosimResult:
    summary: dict
    timing: dict
    log_path: Path
    scenario: object  # the embedded scenario the run was scored against
    states: np.ndarray = field(default_factory=lambda: np.empty((0, 7)))  # t, x..r per step


def load_system(folder: str | Path) -> System:
    """Read and check the system folder: its structure file, both FMUs, the connections
    against the FMUs' variables, the step. Each problem an InputError naming file/variable."""
    from fmpy import read_model_description

    from scenarios.scenario_file import scenario_from_table

    folder = Path(folder)
    osp = folder / OSP_FILE
    if not osp.is_file():
        raise InputError(f"{folder}: no {OSP_FILE} (make one with `canalnav fmu system`)")
    try:
        root = ElementTree.parse(osp).getroot()
    except ElementTree.ParseError as exc:
        raise InputError(f"{osp}: not valid XML: {exc}") from None
    step_text = root.findtext(f"{OSP}BaseStepSize")
    try:
        step_s = float(step_text)
    except (TypeError, ValueError):
        raise InputError(f"{osp}: BaseStepSize {step_text!r} is not a number") from None
    check_step(step_s, f"{osp}: BaseStepSize")
    sources, variables = {}, {}
    for sim in root.iter(f"{OSP}Simulator"):
        name, source = sim.get("name"), folder / sim.get("source", "")
        if not source.is_file():
            raise InputError(f"{osp}: simulator {name!r}: no FMU at {source}")
        try:
            md = read_model_description(str(source))
        except Exception as exc:  # fmpy: a broken zip or model description, in its words
            raise InputError(f"{source}: not an FMU fmpy can read: {exc}") from None
        if md.fmiVersion != "2.0":
            raise InputError(f"{source}: FMI {md.fmiVersion}: libcosim runs FMI 2.0 FMUs (write "
                             f"the system with `canalnav fmu system --fmi 2`)")
        sources[name] = source
        variables[name] = {v.name: v for v in md.modelVariables}
    for want in (BOAT, NAVIGATION):
        if want not in sources:
            raise InputError(f"{osp}: no simulator named {want!r}")
    for link in root.iter(f"{OSP}VariableConnection"):
        ends = link.findall(f"{OSP}Variable")
        for end, causality in zip(ends, ("output", "input")):
            sim, var = end.get("simulator"), end.get("name")
            found = variables.get(sim, {}).get(var)
            if found is None:
                raise InputError(f"{osp}: connection names variable {var!r} of {sim!r}, which "
                                 f"{sources.get(sim, sim)} does not have")
            if found.causality != causality:
                raise InputError(f"{osp}: connection uses {sim}.{var} as an {causality}, but "
                                 f"{sources[sim]} declares it {found.causality}")
    for name in BOAT_OUTPUTS:
        if name not in variables[BOAT]:
            raise InputError(f"{sources[BOAT]}: no output {name!r} (the boat FMU of "
                             f"`canalnav fmu build` has it)")
    try:
        with zipfile.ZipFile(sources[NAVIGATION]) as z:
            document = json.loads(z.read(f"resources/{SCENARIO_RESOURCE}"))
    except (KeyError, zipfile.BadZipFile, ValueError):
        raise InputError(f"{sources[NAVIGATION]}: holds no embedded scenario (build it with "
                         f"`canalnav fmu build-controller`)") from None
    scenario = scenario_from_table(document, f"{sources[NAVIGATION]}/resources/{SCENARIO_RESOURCE}")
    return System(folder, osp, step_s, scenario, sources)


class _World:
    """The true outlines present at a time (an obstacle may leave the water), with the
    collision test, the canal width and the clearance over them."""

    def __init__(self, cfg):
        self._outlines = tuple(cfg.outlines)
        self._removed = tuple(cfg.outline_removed_at_s) or (None,) * len(self._outlines)
        self._key, self._now = None, None

    def at(self, time_s: float):
        key = tuple(r is None or time_s < r for r in self._removed)
        if key != self._key:
            present = tuple(o for o, here in zip(self._outlines, key) if here)
            self._key, self._now = key, (metrics.HullContact(present),
                                         metrics.CanalWidth(present), metrics.Clearance(present))
        return self._now


_round = metrics.summary_round


def run_cosim(folder: str | Path, out_dir: str | Path, duration_s: float | None = None,
              progress: Callable[[float, float], None] | None = None) -> CosimResult:
    """Run the system in `folder` through libcosim into `out_dir` (log.csv, summary.json,
    timing.json, and the navigation FMU's own log). The system is checked here; the run is a
    process of its own, in which the FMUs' Python lives and ends (pythonfmu 0.7's FMI 2.0
    binary can crash Python's teardown after a long run, README "Known limits")."""
    system = load_system(folder)
    require("libcosimpy.CosimExecution", "canalnav cosim")
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"--out {out}: cannot make the folder: {exc.strerror or exc}") from None
    context = multiprocessing.get_context("spawn")
    receive, send = context.Pipe(duplex=False)
    worker = context.Process(target=_run_in_worker, args=(str(folder), str(out), duration_s, send),
                             name="canalnav-cosim", daemon=True)
    worker.start()
    send.close()
    try:
        while True:
            try:
                kind, *payload = receive.recv()
            except EOFError:
                worker.join(timeout=10)
                raise CanalnavError(f"the co-simulation ended without results (its process "
                                    f"exited with {worker.exitcode})") from None
            if kind == "progress" and progress is not None:
                progress(*payload)
            elif kind == "error":
                raise payload[0]
            elif kind == "done":
                summary, timing, states = payload
                return CosimResult(summary, timing, out / "log.csv", system.scenario, states)
    finally:
        worker.join(timeout=30)
        if worker.is_alive():
            worker.kill()


def _run_in_worker(folder: str, out_dir: str, duration_s, send) -> None:
    """The worker's side of `run_cosim`: the run, its progress and its end, down the pipe."""
    try:
        result = _run(load_system(folder), Path(out_dir), duration_s,
                      lambda t, total: send.send(("progress", t, total)))
        send.send(("done", result.summary, result.timing, result.states))
    except CanalnavError as exc:
        send.send(("error", exc))
    except Exception as exc:  # noqa: BLE001 - said to the caller in one line
        send.send(("error", CanalnavError(f"the co-simulation failed: {type(exc).__name__}: "
                                          f"{exc}")))
    finally:
        send.close()
    os._exit(0)  # the results are out: no teardown for pythonfmu's binary to crash in


def _run(system: System, out: Path, duration_s, progress) -> CosimResult:
    """The run itself: libcosim steps the two FMUs; this reads, scores and logs each period."""
    from scenarios.loop.runner import R_B_M, loop_config

    cosim = require("libcosimpy.CosimExecution", "canalnav cosim")
    observers = require("libcosimpy.CosimObserver", "canalnav cosim")
    scenario = system.scenario
    cfg = loop_config(scenario, scenario.seed)
    duration = scenario.duration_s if duration_s is None else float(duration_s)

    logging = require("libcosimpy.CosimLogging", "canalnav cosim")
    logging.log_output_level(logging.CosimLogLevel.WARNING)  # not a line per FMI call
    execution = cosim.CosimExecution.from_osp_config_file(str(system.osp))
    index = {s.name.decode(): s.index for s in execution.slave_infos()}
    refs = {name: {v.name.decode(): v.reference for v in execution.slave_variables(i)}
            for name, i in index.items()}
    log_vr = refs[NAVIGATION]["log_path"]
    execution.string_initial_value(index[NAVIGATION], log_vr, str((out / NAV_LOG).resolve()))
    watch = observers.CosimObserver.create_last_value()
    execution.add_observer(watch)

    per_period = int(round(cfg.control_period_s / system.step_s))
    n_steps = int(math.floor(duration / cfg.control_period_s + 1e-9))
    path, goal = Polyline(cfg.waypoints), np.asarray(cfg.waypoints, float)[-1]
    world = _World(cfg)
    encounters = EncounterWatch(cfg.vessels)
    boat_vr = [refs[BOAT][n] for n in BOAT_OUTPUTS]
    nav_vr = [refs[NAVIGATION][n] for n in NAV_OUTPUTS]
    status_vr = [refs[NAVIGATION]["status"]]

    def boat_now():
        return np.array(watch.last_real_values(index[BOAT], boat_vr), float)

    def advance(steps: int) -> bool:
        return bool(execution.step(steps))

    rows_t, rows_clear, rows_cmd, rows_xt, rows_width, rows_wait, rows_speed, rows_xy = (
        [] for _ in range(8))
    states = []
    status, reached, collided, fallback = "time limit", False, False, 0
    now = np.concatenate([scenario.initial_state, [0.0, 0.0]])  # the boat's outputs at t = 0
    wall0 = time.perf_counter()
    with (out / "log.csv").open("w", newline="") as fh:
        log = csv.writer(fh)
        log.writerow(LOG_COLUMNS)
        for k in range(n_steps):
            t = k * cfg.control_period_s
            ok = advance(1)  # (the navigation's decision for t came out with the step to t)
            nav = np.array(watch.last_real_values(index[NAVIGATION], nav_vr), float)
            code = int(watch.last_integer_values(index[NAVIGATION], status_vr)[0])
            state, actuators = now[:6], now[6:8]
            contact, width_of, clearance = world.at(t)
            clear = clearance.of(state)
            xt = path.cross_track(state[:2])
            width = width_of.at(state)
            if cfg.vessels:  # other vessels count for clearance where they are now
                rings = [np.vstack([h, h[:1]]) for h in (v.outline_at(t) for v in cfg.vessels)]
                clear = np.minimum(clear, metrics.clearance(state[None, :3], rings)[0])
            vessel_gap = encounters.update(t, state, width[2])
            log.writerow([f"{t:.3f}", *(repr(float(v)) for v in state),
                          *(repr(float(v)) for v in (*nav[:2], *actuators, *clear, xt, *width,
                                                     nav[2])), code])
            fh.flush()
            states.append([t, *state])
            rows_t.append(t)
            rows_clear.append(clear)
            rows_cmd.append(nav[:2])
            rows_xt.append(xt)
            rows_width.append(width)
            rows_wait.append(code == STATUS_CODES["waiting"])
            rows_speed.append(float(np.hypot(state[3], state[4])))
            rows_xy.append((float(state[0]), float(state[1])))
            fallback += code == STATUS_CODES["fallback"]
            if not ok or code == STATUS_CODES["failed"]:
                status = f"controller failed: {_failure_reason(out / NAV_LOG)}"
                break
            if min(clear) <= contact.reach_m and contact.touches(state):
                status, collided = f"collision at t = {t:.1f} s", True
                break
            if vessel_gap <= 0.0:
                hit = cfg.vessels[int(np.argmin(encounters.min_distance))].name
                status, collided = f"collision with vessel {hit!r} at t = {t:.1f} s", True
                break
            if per_period > 1 and not advance(per_period - 1):
                status = f"controller failed: {_failure_reason(out / NAV_LOG)}"
                break
            now = boat_now()
            if np.hypot(*(now[:2] - goal)) <= cfg.goal_radius_m:
                status, reached = "reached goal", True
                break
            if progress is not None:
                progress(t + cfg.control_period_s, duration)
    wall = time.perf_counter() - wall0
    final = now
    dt = cfg.control_period_s
    duration_run = (rows_t[-1] + dt) if rows_t else 0.0
    summary = {
        "scenario": scenario.name,
        "controller": scenario.controller,
        "seed": scenario.seed,
        "status": status,
        "reached_goal": reached,
        "collision": collided,
        **metrics.track_figures(rows_t, rows_clear, rows_cmd, rows_xt, final, goal,
                                R_B_M + scenario.d_p_m, dt),
        "fallback_steps": int(fallback),
    }
    episodes = metrics.waiting_episodes(rows_wait, rows_speed, dt, xy=rows_xy)
    summary.update({k: _round(v) for k, v in episodes.items()})
    summary.update(metrics.separation_figures(rows_clear, rows_width, R_B_M + scenario.d_p_m,
                                              dt))
    if cfg.vessels:
        summary["vessels"] = encounters.summary(dt)
    summary["cosim"] = {"master": "libcosim (libcosimpy)", "step_s": system.step_s,
                        "system": str(system.osp), "not_scored": NOT_SCORED}
    timing = {"wall_time_s": wall,
              "real_time_factor": duration_run / wall if wall > 0 else None,
              "steps": len(rows_t) * per_period}
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    (out / "timing.json").write_text(json.dumps(timing, indent=2) + "\n")
    return CosimResult(summary, timing, out / "log.csv", scenario, np.array(states, float))


def _failure_reason(nav_log: Path) -> str:
    """The navigation FMU's reason for its error state, from the last row of its log."""
    try:
        with nav_log.open(newline="") as fh:
            rows = list(csv.reader(fh))
    except OSError:
        rows = []
    if len(rows) > 1 and rows[-1][-1]:
        return rows[-1][-1]
    return "the navigation FMU went into its error state (its reason is in the FMU log)"
