"""The soak: every scenario file with 20 seeds ends without an exception, a collision or a
controller failure (slow); and the soak's own bookkeeping (fast)."""

from pathlib import Path

import pytest

from scenarios.studies.soak import SoakRun, report, soak, soak_one

SCENARIOS = sorted((Path(__file__).resolve().parents[2] / "scenarios").glob("*.toml"))


def test_a_run_that_raises_is_recorded_not_raised(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[scenario]\nduration_s = -1\n")
    r = soak_one(str(bad), 3, str(tmp_path))
    assert not r.passed and r.status == "raised InputError" and "duration_s" in r.error


def test_the_report_counts_each_kind_of_failure():
    def run(**kw):
        base = dict(scenario="a", seed=0, status="reached goal", reached_goal=True,
                    collision=False, controller_failed=False, error="",
                    segments_cleaned={"degenerate": 2}, fallback_steps=1, wall_s=1.0)
        return SoakRun(**{**base, **kw})

    out = report([run(), run(seed=1, collision=True, reached_goal=False),
                  run(seed=2, controller_failed=True), run(scenario="b", error="boom")], 5.0)
    assert not out["passed"] and out["runs"] == 4 and out["scenario_files"] == 2
    assert (out["collisions"], out["controller_failures"], out["exceptions"]) == (1, 1, 1)
    assert out["segments_cleaned"] == {"degenerate": 8} and len(out["failures"]) == 3


@pytest.mark.slow
def test_every_scenario_file_with_20_seeds_never_raises_collides_or_fails(tmp_path):
    results = soak(SCENARIOS, range(20), tmp_path)
    out = report(results, 0.0)
    print(f"\nsoak: {out['runs']} runs of {out['scenario_files']} files, "
          f"cleaned {out['segments_cleaned']}, fallback steps {out['fallback_steps']}")
    assert out["runs"] == 20 * len(SCENARIOS)
    assert out["passed"], out["failures"]
