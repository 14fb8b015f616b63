"""`canalnav bench nmpc`: closed-loop runs of the NMPC per solver on one canal; JSON out.

The same problem for every solver: a canal with a 90 deg bend and a stretch narrower than
2 (R_b + d_p), the segments of the true walls within 50 m (the paper's simulation), 16 slots,
10 Hz, the smooth model as the plant. Times are wall clock per control step (reference,
segments, solve, command), so they include Python; the machine is shared, so compare the
ratios of one run rather than absolute times across runs. `cpu_ms` is the thread's CPU time
per step: the wall time less the time the OS ran other processes (a loaded machine's p99).
"""

from __future__ import annotations

import json
import os
import sys


def register_bench(sub) -> None:
    p = sub.add_parser(
        "nmpc", help="NMPC per-step time: RTI vs converged SQP vs IPOPT (closed loop)",
        description="Closed-loop runs on a canal with a bend and a narrow stretch: mean, p99 "
        "and max time per control step for real-time iteration (compiled linearisation + "
        "HPIPM), SQP to convergence and IPOPT (CasADi's interpreted functions), their ratios, "
        "where RTI's time goes, and how far RTI's track is from the converged ones.")
    p.add_argument("--steps", type=int, default=600, help="control steps at 10 Hz (600)")
    p.add_argument("--narrow-m", type=float, default=9.0,
                   help="width of the narrow stretch in m (9; below 2 (R_b + d_p) = 10)")
    p.add_argument("--speed", type=float, default=2.0, help="target speed in m/s (2.0)")
    p.add_argument("--segment-slots", type=int, default=None,
                   help="segment slots of the OCP (default: NmpcConfig's, 16); each count is "
                   "compiled once and cached")
    p.add_argument("--solvers", default="rti,sqp,ipopt",
                   help="comma list of rti, sqp, ipopt (all three)")
    p.add_argument("--qp-tol", type=float, default=None,
                   help="HPIPM's residual tolerance for RTI and SQP (default: QpOptions')")
    p.add_argument("--vessel-steps", type=int, default=600,
                   help="steps of the RTI runs with other vessels (a tour boat met port to "
                   "port; one coming down the middle and a crossing launch), with the vessel "
                   "slots and without them; 0 skips them")
    p.add_argument("--hpipm-build", default="auto", choices=("auto", "tuned", "casadi"),
                   help="HPIPM + BLASFEO for the direct interface: 'tuned' (the CPU's kernels, "
                   "from comma-deps-acados installed beside, see README), 'casadi' (its generic "
                   "one), 'auto' (tuned when installed; default)")
    p.add_argument("--warm-start", type=int, default=None, choices=(0, 1, 2),
                   help="HPIPM's warm start (default: QpOptions', 0)")
    p.add_argument("--mu0", type=float, default=None,
                   help="HPIPM's initial barrier (default: QpOptions'; 0 = HPIPM's own)")
    p.add_argument("--no-unsplit-peer", dest="unsplit_peer", action="store_false",
                   help="skip the RTI run without the preparation/feedback split (the peer "
                   "the split's trajectory and latency are compared with)")
    p.add_argument("--qp-compare-steps", type=int, default=200,
                   help="steps of extra RTI runs with each QP solver (hpipm direct, hpipm "
                   "through CasADi, piqp); 0 skips them (200)")
    p.add_argument("--peer", choices=("acados",), default=None,
                   help="also run the same OCP with acados (SQP_RTI, HPIPM) in the same closed "
                   "loop, handed canalnav's per-step inputs ready-made, and report the two side "
                   "by side (needs comma-deps-acados installed beside the project, see README)")
    p.add_argument("--peer-repeats", type=int, default=3,
                   help="runs of canalnav and of the peer, alternating (3); medians reported")
    p.set_defaults(func=run)


def _stats_ms(values) -> dict:
    import numpy as np

    v = np.asarray(values, float) * 1e3
    return {"mean": round(float(v.mean()), 3), "p99": round(float(np.percentile(v, 99)), 3),
            "max": round(float(v.max()), 3)}


def _summary(run, label: str) -> dict:
    import numpy as np

    t = run.step_times_s * 1e3
    st = [s.stats for s in run.steps]
    cpu = np.array([s.cpu_time_s for s in st]) * 1e3
    out = {
        "steps": len(run.steps),
        "feedback_latency_ms": _stats_ms([s.time_feedback_s for s in st]),
        "preparation_ms": _stats_ms([s.time_preparation_s for s in st]),
        "fed_back_steps": int(sum(s.fed_back for s in st)),
        "set_up_in_preparation_steps": int(sum(s.set_up_in_preparation for s in st)),
        "mean_ms": round(float(t.mean()), 3),
        "p99_ms": round(float(np.percentile(t, 99)), 3),
        "max_ms": round(float(t.max()), 3),
        "cpu_ms": {"mean": round(float(cpu.mean()), 3),
                   "p99": round(float(np.percentile(cpu, 99)), 3),
                   "max": round(float(cpu.max()), 3)},
        "breakdown_mean_ms": {
            "linearisation": round(1e3 * float(np.mean([s.time_linearisation_s for s in st])), 3),
            "qp": round(1e3 * float(np.mean([s.time_qp_s for s in st])), 3),
            "glue": round(1e3 * float(np.mean([s.time_glue_s for s in st])), 3),
            "feedback_glue": round(1e3 * float(np.mean([s.time_feedback_glue_s for s in st])), 3),
            "preparation": round(1e3 * float(np.mean([s.time_preparation_s for s in st])), 3),
        },
        "qp_iterations_mean": round(float(np.mean([s.qp_iterations for s in st])), 2),
        "sqp_iterations_mean": round(float(np.mean([s.sqp_iterations for s in st])), 2),
        "converged_steps": int(sum(s.converged for s in st)),
        "failed_steps": int(sum(not s.ok for s in st)),
        "fallback_steps": int(sum(bool(s.fallback) for s in st)),
        "clipped_steps": int(sum(s.command_clipped for s in st)),
        "segments_dropped": {"steps": int(sum(s.segments_dropped > 0 for s in st)),
                             "max": int(max(s.segments_dropped for s in st)),
                             "nearest_to_plan_m": _finite_min(s.dropped_nearest_m for s in st)},
        "min_clearance_m": round(float(run.clearance_m.min()), 3),
        "max_slack_m": round(max(s.max_slack_m for s in run.steps), 3),
        "final_state": [round(float(v), 3) for v in run.states[-1]],
        "stopped_by_failure": run.failure or None,
    }
    if label == "ipopt":
        out["breakdown_mean_ms"] = {"ipopt": out["breakdown_mean_ms"]["qp"],
                                    "glue": out["breakdown_mean_ms"]["glue"]}
    return out


def _vessel_cases(config, qp, canal, x0, act0, args) -> dict:
    """RTI on the same canal without vessel slots, with them and no vessel, with them and a
    tour boat meeting the boat on the first leg, keeping to its own starboard side (the two
    pass port to port), and with them and two vessels: a tour boat coming down the first leg
    3 m off its middle (room for the two to pass only with less than R_b + d_v beside it:
    the boat keeps to starboard and passes, some of the vessel's clearance given up) and a
    launch crossing that leg; in one session, the one-phase step (`split=False`), so that
    each case's time is its whole step. `least_distance_to_vessel_m`: the least distance
    from the boat's origin to a vessel's centre."""
    from dataclasses import replace

    import numpy as np

    from controller.nmpc.bench import BenchVessel, closed_loop
    from controller.nmpc.controller import NmpcController

    meeting = (BenchVessel(1, (45.0, -4.5), (-1.5, 0.0)),)
    vessels = (BenchVessel(1, (70.0, -3.0), (-1.5, 0.0)), BenchVessel(2, (25.0, 30.0), (0.0, -1.0),
                                                                       9.0, 3.0))
    cases = {"no_vessel_slots": (replace(config, vessel_slots=0), ()),
             "vessel_slots_no_vessels": (config, ()),
             "vessel_slots_meeting": (config, meeting),
             "vessel_slots_two_vessels": (config, vessels)}
    out = {}
    for name, (cfg, vs) in cases.items():
        print(f"bench nmpc: RTI, {name.replace('_', ' ')} ...", file=sys.stderr, flush=True)
        controller = NmpcController(cfg, method="rti", qp=qp, split=False)  # the whole step
        run = closed_loop(controller, canal, x0, act0, args.vessel_steps, args.speed,
                          vessels=vs)
        s = _summary(run, "rti")
        out[name] = {k: s[k] for k in ("feedback_latency_ms", "preparation_ms", "mean_ms",
                                       "p99_ms", "max_ms", "cpu_ms",
                                       "breakdown_mean_ms", "qp_iterations_mean",
                                       "max_slack_m", "final_state", "failed_steps",
                                       "fallback_steps", "stopped_by_failure")}
        out[name]["vessel_slots"] = cfg.vessel_slots
        out[name]["least_distance_to_vessel_m"] = round(min(
            (float(np.hypot(*(run.states[k, :2] - v.at(k * config.control_period_s).position)))
             for k in range(len(run.states)) for v in vs), default=float("inf")), 3)
    base = out["no_vessel_slots"]["mean_ms"]
    out["ratio_mean_over_no_vessel_slots"] = {
        k: round(v["mean_ms"] / base, 2) for k, v in out.items() if k != "no_vessel_slots"}
    out["goal"] = {name: {"mean_ms<=1": out[name]["mean_ms"] <= 1.0,
                          "p99_ms<=2": out[name]["p99_ms"] <= 2.0}
                   for name in ("vessel_slots_meeting", "vessel_slots_two_vessels")}
    return out


def _acados_peer(config, qp, canal, x0, act0, args) -> dict:
    """canalnav's RTI (split, as the controller runs) against acados on the same OCP, runs
    alternating: the whole step's CPU time (canalnav: everything from the inputs to the
    command and its preparation; acados: its driver handed canalnav's inputs), the feedback
    latency (state in, command out), QP iterations and how far the trajectories part."""
    import numpy as np

    from controller.nmpc.acados_peer import run_peer
    from controller.nmpc.bench import closed_loop
    from controller.nmpc.controller import NmpcController

    if args.peer_repeats < 1:
        from controller.errors import InputError

        raise InputError(f"--peer-repeats: need at least 1, got {args.peer_repeats}")
    ours, theirs = [], []
    for k in range(args.peer_repeats):
        print(f"bench nmpc: RTI and acados, run {k + 1} of {args.peer_repeats} ...",
              file=sys.stderr, flush=True)
        record: list = []
        controller = NmpcController(config, method="rti", qp=qp)
        run_ = closed_loop(controller, canal, x0, act0, args.steps, args.speed, record=record,
                           scan_ahead=True)
        peer = run_peer(config, qp, record, x0, act0, args.speed)
        ours.append((run_, record))
        theirs.append(peer)
    run_, record = ours[0]
    peer = theirs[0]
    n = min(len(run_.states), len(peer["states"]))
    d = np.hypot(*(run_.states[:n, :2] - peer["states"][:n, :2]).T)

    def med(values):
        return round(float(np.median(values)), 3)

    st = [s.stats for s in run_.steps]
    canalnav = {
        "step_cpu_ms": {"mean": med([1e3 * np.mean([r[0] for r in rec]) for _, rec in ours]),
                        "p99": med([1e3 * np.percentile([r[0] for r in rec], 99)
                                    for _, rec in ours])},
        "feedback_latency_ms": {
            "mean": med([1e3 * np.mean([s.stats.time_feedback_s for s in r.steps])
                         for r, _ in ours]),
            "p99": med([1e3 * np.percentile([s.stats.time_feedback_s for s in r.steps], 99)
                        for r, _ in ours])},
        "feedback_cpu_ms": med([1e3 * np.mean([s.stats.cpu_time_s for s in r.steps])
                                for r, _ in ours]),
        "qp_iterations_mean": round(float(np.mean([s.qp_iterations for s in st])), 2),
        "failed_steps": int(sum(not s.ok for s in st)),
        "elastic_steps": int(sum(s.elastic_segments > 0 or s.elastic_vessels > 0 for s in st)),
        "set_up_in_feedback_steps": int(sum(not s.set_up_in_preparation for s in st)),
    }
    acados = {
        "step_cpu_ms": {"mean": med([1e3 * p["cpu_s"].mean() for p in theirs]),
                        "p99": med([1e3 * np.percentile(p["cpu_s"], 99) for p in theirs])},
        "feedback_latency_ms": {"mean": med([1e3 * p["feedback_s"].mean() for p in theirs]),
                                "p99": med([1e3 * np.percentile(p["feedback_s"], 99)
                                            for p in theirs])},
        "feedback_cpu_ms": med([1e3 * p["feedback_cpu_s"].mean() for p in theirs]),
        "qp_iterations_mean": round(float(peer["qp_iterations"].mean()), 2),
        "failed_steps": int(np.count_nonzero(peer["status"])),
    }
    out = {"canalnav": canalnav, "acados": acados, "repeats": args.peer_repeats,
           "max_position_diff_m": float(f"{d.max():.3g}"),
           "final_position_diff_m": float(f"{d[-1]:.3g}"),
           "canalnav_over_acados": {
               "step_cpu": round(canalnav["step_cpu_ms"]["mean"] / acados["step_cpu_ms"]["mean"], 3),
               "feedback_latency": round(canalnav["feedback_latency_ms"]["mean"]
                                         / acados["feedback_latency_ms"]["mean"], 3)},
           "inputs": "the walls seen at a step reach canalnav's preparation after its command "
                     "and are the next step's (scan_ahead: a scan is processed while the boat "
                     "moves); acados gets canalnav's per-step parameters, reference and first "
                     "warm start ready-made (not timed on its side), its own state and plan"}
    out["goal"] = {"step_cpu<=acados": out["canalnav_over_acados"]["step_cpu"] <= 1.0,
                   "feedback<=acados": out["canalnav_over_acados"]["feedback_latency"] <= 1.0,
                   "trajectory<=0.01m": out["max_position_diff_m"] <= 0.01}
    return out


def _finite_min(values):
    """The smallest finite value, rounded; None when there is none."""
    finite = [v for v in values if v != float("inf")]
    return round(min(finite), 3) if finite else None


def run(args) -> int:
    import numpy as np

    from controller.errors import InputError
    from controller.nmpc.problem import NmpcConfig
    from controller.nmpc.bench import bend_canal, closed_loop
    from controller.nmpc.controller import METHODS, NmpcController
    from controller.nmpc.rti import QpOptions

    solvers = [s.strip() for s in args.solvers.split(",") if s.strip()]
    unknown = set(solvers) - set(METHODS)
    if unknown or not solvers:
        raise InputError(f"--solvers: choose from {', '.join(METHODS)}, got {args.solvers!r}")
    if args.steps < 10:
        raise InputError(f"--steps: need at least 10, got {args.steps}")
    if not 0 < args.narrow_m:
        raise InputError(f"--narrow-m: must be positive, got {args.narrow_m}")
    if args.segment_slots is not None and args.segment_slots < 1:
        raise InputError(f"--segment-slots: need at least 1, got {args.segment_slots}")
    config = NmpcConfig() if args.segment_slots is None \
        else NmpcConfig(segment_slots=args.segment_slots)
    from dataclasses import replace

    from controller.nmpc.hpipm_qp import choose_build

    qp = QpOptions(hpipm_build=args.hpipm_build)
    if args.qp_tol is not None:
        qp = replace(qp, tol=args.qp_tol)
    if args.warm_start is not None:
        qp = replace(qp, warm_start=args.warm_start)
    if args.mu0 is not None:
        qp = replace(qp, mu0=args.mu0)
    build = choose_build(qp.hpipm_build)
    canal = bend_canal(narrow_m=args.narrow_m)
    x0, act0 = np.array([0.0, 0.0, 0.0, args.speed, 0.0, 0.0]), np.array([47.0, 0.0])

    result: dict = {
        "problem": {
            "canal": canal.name, "steps": args.steps, "control_hz": 1 / config.control_period_s,
            "horizon": config.horizon, "step_s": config.step_s,
            "segment_slots": config.segment_slots, "segment_range_m": config.segment_range_m,
            "target_speed_mps": args.speed,
            "plant": "smooth model, RK4 2 x 0.05 s, actuator rate limits 10 and 40 %/s",
        },
        "machine": {"cpus": os.cpu_count(), "load_avg_1min": round(os.getloadavg()[0], 2)},
        "solvers": {},
    }
    runs = {}
    plan = [(m, m, True) for m in solvers]
    if "rti" in solvers and args.unsplit_peer:
        plan.insert(solvers.index("rti") + 1, ("rti_unsplit", "rti", False))
    for label, method, split in plan:
        print(f"bench nmpc: {label} ...", file=sys.stderr, flush=True)
        controller = NmpcController(config, method=method, qp=qp, split=split)
        if controller.compiled_info is not None and "codegen" not in result:
            info = controller.compiled_info
            result["codegen"] = {"compiled": info.compiled, "cache_hit": info.cache_hit,
                                 "compile_s": round(info.compile_s, 2),
                                 "library": str(info.library) if info.library else None}
        runs[label] = closed_loop(controller, canal, x0, act0, args.steps, args.speed)
        result["solvers"][label] = _summary(runs[label], method)
        if method != "ipopt":
            result["solvers"][label]["qp"] = {
                "solver": controller._qp.options.solver, "mode": qp.hpipm_mode, "tol": qp.tol,
                "warm_start": qp.warm_start, "mu0": qp.mu0,
                "hpipm_build": f"{build.name} ({build.target})"}

    if "rti" in runs:
        rti_mean = result["solvers"]["rti"]["mean_ms"]
        result["ratios_mean_over_rti"] = {
            m: round(result["solvers"][m]["mean_ms"] / rti_mean, 2) for m in runs if m != "rti"}
        if "rti_unsplit" in runs:
            n = min(len(runs["rti"].states), len(runs["rti_unsplit"].states))
            d = np.hypot(*(runs["rti"].states[:n, :2] - runs["rti_unsplit"].states[:n, :2]).T)
            result["rti_vs_rti_unsplit_max_position_diff_m"] = float(f"{d.max():.3g}")
            u, r_ = result["solvers"]["rti_unsplit"], result["solvers"]["rti"]
            result["split_over_unsplit"] = {
                "feedback_latency_mean": round(r_["feedback_latency_ms"]["mean"]
                                               / u["feedback_latency_ms"]["mean"], 3),
                "step_mean": round(r_["mean_ms"] / u["mean_ms"], 3)}
        for other in ("sqp", "ipopt"):
            if other in runs:  # over the steps both ran (a failure stops a run early)
                n = min(len(runs["rti"].states), len(runs[other].states))
                d = np.hypot(*(runs["rti"].states[:n, :2] - runs[other].states[:n, :2]).T)
                result[f"rti_vs_{other}_max_position_diff_m"] = round(float(d.max()), 4)
        r = result["solvers"]["rti"]
        complete = all(not run_.failure and len(run_.steps) == args.steps
                       for run_ in runs.values())
        result["goal"] = {
            "rti_feedback_mean_ms<=0.2": r["feedback_latency_ms"]["mean"] <= 0.2,
            "rti_feedback_p99_ms<=0.35": r["feedback_latency_ms"]["p99"] <= 0.35,
            "rti_step_mean_ms<=0.5": r["mean_ms"] <= 0.5,
            "rti_vs_unsplit<=0.01m": result.get("rti_vs_rti_unsplit_max_position_diff_m",
                                                1e9) <= 0.01,
            "rti_mean_ms<=2": r["mean_ms"] <= 2.0, "rti_p99_ms<=5": r["p99_ms"] <= 5.0,
            "ipopt/rti>=30": result["ratios_mean_over_rti"].get("ipopt", 0) >= 30,
            "rti_vs_sqp<=0.2m": complete
            and result.get("rti_vs_sqp_max_position_diff_m", 1e9) <= 0.2,
            "every_run_complete": complete,
        }

    if args.peer == "acados":
        result["peer_acados"] = _acados_peer(config, qp, canal, x0, act0, args)

    if args.vessel_steps > 0:
        result["vessels"] = _vessel_cases(config, qp, canal, x0, act0, args)

    if args.qp_compare_steps > 0:
        compare = {}
        options = {"hpipm (casadi's BLASFEO)": replace(qp, hpipm_build="casadi"),
                   "hpipm-casadi": replace(qp, solver="hpipm-casadi"),
                   "piqp": replace(qp, solver="piqp")}
        if build.name == "tuned":
            options = {f"hpipm (tuned BLASFEO, {build.target})": replace(qp, hpipm_build="tuned"),
                       **options}
        for name, options_ in options.items():
            print(f"bench nmpc: RTI with {name} ...", file=sys.stderr, flush=True)
            controller = NmpcController(config, method="rti", qp=options_, split=False)
            run_ = closed_loop(controller, canal, x0, act0, args.qp_compare_steps, args.speed)
            s = _summary(run_, "rti")
            compare[name] = {k: s[k] for k in ("feedback_latency_ms", "preparation_ms",
                                                "mean_ms", "p99_ms", "max_ms", "cpu_ms",
                                                "breakdown_mean_ms", "qp_iterations_mean",
                                                "failed_steps")}
        result["qp_solvers_rti"] = compare
    print(json.dumps(result, indent=2))
    return 0
