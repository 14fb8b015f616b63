"""The soak: every scenario file with 20 seeds on the study engine ends without an
exception, a collision or a controller failure (slow); and the soak's own bookkeeping (fast)."""

import pytest

from scenarios.studies.soak import SPEC, report, scenario_files, soak_study
from scenarios.studies.sweep_spec import load_study

SCENARIOS = scenario_files()


def _row(**kw):
    base = dict(run_id="x", scenario="a", seed=0, status="ok", outcome="reached goal",
                reached_goal=True, collision=False, controller_failed=False,
                criteria_passed=True, error="", segments_cleaned={"degenerate": 2},
                fallback_steps=1)
    return {**base, **kw}


def test_the_report_counts_each_kind_of_failure():
    out = report([_row(), _row(seed=1, collision=True, reached_goal=False),
                  _row(seed=2, controller_failed=True),
                  _row(scenario="b", status="error", outcome="raised KeyError", error="boom")],
                 5.0)
    assert not out["passed"] and out["runs"] == 4 and out["scenario_files"] == 2
    assert (out["collisions"], out["controller_failures"], out["exceptions"]) == (1, 1, 1)
    assert out["segments_cleaned"] == {"degenerate": 8} and len(out["failures"]) == 3
    assert report([_row(), _row(seed=1)], 1.0)["passed"] and not report([], 1.0)["passed"]


def test_the_soak_is_every_scenario_file_with_every_seed():
    study = soak_study(SCENARIOS, range(20))
    assert len(study.runs) == 20 * len(SCENARIOS) and len(SCENARIOS) >= 10
    assert {r.scenario_file for r in study.runs} == {str(p) for p in SCENARIOS}
    documented = load_study(SPEC)  # the same soak as a study file for `canalnav sweep`
    assert sorted(r.run_id for r in documented.runs) == sorted(r.run_id for r in study.runs)


@pytest.mark.slow
def test_every_scenario_file_with_20_seeds_never_raises_collides_or_fails(tmp_path):
    from scenarios.studies.sweep import run_study

    outcome = run_study(soak_study(SCENARIOS, range(20)), tmp_path / "soak", progress=False)
    out = report(outcome.rows, outcome.wall_s)
    print(f"\nsoak: {out['runs']} runs of {out['scenario_files']} files in "
          f"{out['wall_time_s']} s, cleaned {out['segments_cleaned']}, fallback steps "
          f"{out['fallback_steps']}")
    assert out["runs"] == 20 * len(SCENARIOS)
    assert out["passed"], out["failures"]
