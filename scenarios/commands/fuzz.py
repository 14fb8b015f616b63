"""`canalnav fuzz --cases N --seed S --out DIR`: seeded random encounters, each written as a
scenario file, run on the study engine and judged (`scenarios/studies/fuzz.py`).

DIR gets `cases/` (the scenario files), `fuzz-study.toml` (the study run), the study's
folder (`results.csv`, each run's folder under `runs/`), `fuzz.json` (the figures and each
case's verdict) and `report.md` (the failures worst first, each with the command that
reproduces it; the rules of the road per encounter kind; every case). Prints the figures as
JSON; exits 1 when a case failed the rule.

To try a change on the cases that matter: `--only 3,69,129` runs those cases of the seed
(the same files as in the full run), `--set PATH=VALUE` changes a key of every case (as
`canalnav run --set`, e.g. `--set controller.options.rest_keep_m=1.0`), and `--against DIR` lists
the cases whose outcome changed since the run in DIR.
"""

from __future__ import annotations

import json
from pathlib import Path

from scenarios.commands.arguments import assignment, case_numbers, whole_number


def register(sub) -> None:
    from scenarios.commands.sweep import add_engine_options

    p = sub.add_parser(
        "fuzz", help="seeded random encounters run and judged: no exception, collision or "
        "controller failure, 2 m from every vessel (needs the [sweep] extra)",
        description="Generate --cases encounter scenarios from --seed (canals 12-40 m wide with "
        "a bend or a side canal, moored boats, currents, one to three vessels met, overtaken, "
        "followed, crossing or drifting, timed to meet where it is hardest), run them on the "
        "study engine and judge each from the true poses. The same seed gives the same cases.")
    which = p.add_mutually_exclusive_group()
    which.add_argument("--cases", type=whole_number(1), default=100,
                       help="how many cases: 0 to N-1 (100)")
    which.add_argument("--only", type=case_numbers, metavar="CASES",
                       help="only these cases of the seed, e.g. 3,69,129 or 0-49 (the same "
                       "files as in a full run)")
    p.add_argument("--seed", type=whole_number(0), default=0, help="the fuzz's seed (0)")
    p.add_argument("--out", required=True, metavar="DIR", help="where cases and results go")
    p.add_argument("--perception", choices=("mixed", "lidar", "known-walls"), default="mixed",
                   help="each case's perception (mixed: drawn per case)")
    p.add_argument("--min-hull-m", type=float, default=2.0,
                   help="least hull-to-hull distance a case must keep (2 m)")
    p.add_argument("--set", action="append", default=[], metavar="PATH=VALUE",
                   type=assignment, help="change a key of every case by its dotted path, as "
                   "a TOML value (e.g. --set controller.options.rest_keep_m=1.0); repeatable")
    p.add_argument("--against", metavar="DIR",
                   help="an earlier fuzz's --out: report the cases whose outcome changed")
    add_engine_options(p)
    p.set_defaults(func=run)


def _earlier_verdicts(folder: str) -> list[dict]:
    """The per-case verdicts in an earlier fuzz's fuzz.json (`--against`)."""
    from controller.errors import InputError

    path = Path(folder) / "fuzz.json"
    try:
        figures = json.loads(path.read_text())
    except OSError as exc:
        raise InputError(f"fuzz: --against {folder}: cannot read {path}: "
                         f"{exc.strerror or exc}") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"fuzz: --against {folder}: {path} is not JSON ({exc})") from None
    verdicts = figures.get("verdicts") if isinstance(figures, dict) else None
    if not isinstance(verdicts, list):
        raise InputError(f"fuzz: --against {folder}: {path} holds no per-case verdicts "
                         "(written by an older canalnav fuzz): run that fuzz again")
    return verdicts


def run(args) -> int:
    from controller.errors import InputError
    from scenarios.commands.sweep import check_engine_options
    from scenarios.studies.fuzz import (changes_against, conformance, generate, judge,
                                        report_markdown, tracking_bar, verdict_record)
    from scenarios.studies.overrides import toml_value
    from scenarios.studies.sweep import require_dask, run_study
    from scenarios.studies.sweep_spec import parse_study

    check_engine_options(args)
    if not args.min_hull_m >= 0:
        raise InputError(f"fuzz: --min-hull-m must be >= 0, got {args.min_hull_m}")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError(f"fuzz: --out {out} is a file, not a folder")
    before = _earlier_verdicts(args.against) if args.against else None
    require_dask()
    numbers = args.only if args.only is not None else range(args.cases)
    cases = [generate(args.seed, k, args.perception) for k in numbers]
    folder = out / "cases"
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"fuzz: cannot make {folder}: {exc.strerror}") from None
    paths = []
    for case in cases:
        path = folder / f"{case.name}.toml"
        path.write_text(case.text)
        paths.append(str(path.resolve()))
    text = (f"# canalnav fuzz: {len(cases)} cases of seed {args.seed}\n[study]\n"
            f"name = \"fuzz-{args.seed}\"\nscenarios = {toml_value(paths)}\n")
    if args.set:  # every case with the same changes: one value each
        text += "[overrides]\n" + "".join(f"{toml_value(path)} = [{toml_value(value)}]\n"
                                         for path, value in args.set)
    study_file = out.resolve() / "fuzz-study.toml"
    study_file.write_text(text)  # (what ran; and a bad --set names it in its error)
    study = parse_study(text, study_file)
    outcome = run_study(study, out / "study", scheduler=args.scheduler, workers=args.workers,
                        resume=args.resume, progress=not args.quiet,
                        timeout_s=args.connect_timeout)
    by_case = {case.name: case for case in cases}
    summaries, verdicts = {}, []
    for row in outcome.rows:
        name = Path(str(row.get("scenario_file", ""))).stem
        if name not in by_case:
            continue
        summary_path = out / "study" / str(row.get("folder", "")) / "summary.json"
        summary = json.loads(summary_path.read_text()) if summary_path.is_file() else None
        summaries[name] = summary
        verdicts.append(judge(name, row, summary, args.min_hull_m))
    conform = conformance(cases, summaries)
    changes = None if before is None else changes_against(before, verdicts)
    (out / "report.md").write_text(report_markdown(
        verdicts, by_case, str(out), args.seed, conform, outcome.wall_s,
        against=None if changes is None else (args.against, changes), overrides=args.set))
    hulls = [v.min_hull_m for v in verdicts if v.min_hull_m is not None]
    figures = {
        "seed": args.seed, "cases": len(cases), "ran": len(verdicts),
        "failed": sum(not v.passed for v in verdicts),
        "exceptions": sum(v.severity == 5 for v in verdicts),
        "controller_failures": sum(v.severity == 4 for v in verdicts),
        "collisions": sum(v.severity == 3 for v in verdicts),
        "closer_than_min_hull": sum(v.severity == 2 for v in verdicts),
        "least_hull_to_hull_m": round(min(hulls), 3) if hulls else None,
        "reached_goal": sum(v.reached_goal for v in verdicts),
        "reached_goal_share": round(sum(v.reached_goal for v in verdicts)
                                    / max(len(verdicts), 1), 4),
        "fallback_steps": sum(v.fallback_steps for v in verdicts),
        "elastic_steps": sum(v.elastic_steps for v in verdicts),
        "wall_tracks": sum(v.wall_tracks for v in verdicts),
        **tracking_bar(verdicts),
        "rules": conform, "wall_time_s": round(outcome.wall_s, 1),
        "workers": outcome.workers, "report": str(out / "report.md"),
        "failures": [{"case": v.case, "why": v.why,
                      "command": f"canalnav run {out}/cases/{v.case}.toml"}
                     for v in sorted(verdicts, key=lambda v: -v.severity) if not v.passed],
        "set": [f"{path}={toml_value(value)}" for path, value in args.set],
    }
    if changes is not None:
        figures["against"] = {"folder": args.against, **changes}
    figures["verdicts"] = [verdict_record(v) for v in sorted(verdicts, key=lambda v: v.case)]
    (out / "fuzz.json").write_text(json.dumps(figures, indent=2) + "\n")
    print(json.dumps(figures, indent=2))
    return 0 if figures["failed"] == 0 and len(verdicts) == len(cases) else 1
