"""`canalnav compare` on a short scenario: three runs, their summaries, the table and plot."""

import json

import pytest

from bridge.main import main


@pytest.mark.parametrize("controllers", [
    ("nmpc", "los-pid"),
    # the lexicographic planner (IPOPT, twice a plan) takes about 70 s of the 90: slow set
    pytest.param(("nmpc", "los-pid", "lexicographic"), marks=pytest.mark.slow)])
def test_compare_runs_the_controllers(tmp_path, capsys, short_bend_toml, controllers):
    path = tmp_path / "short.toml"
    path.write_text(short_bend_toml)
    out = tmp_path / "cmp"
    extra = [] if len(controllers) == 3 else ["--controllers", ",".join(controllers)]
    assert main(["compare", str(path), "--out", str(out), *extra]) == 0
    table = capsys.readouterr().out
    rows = json.loads((out / "compare.json").read_text())
    assert [r["controller"] for r in rows] == list(controllers)
    for name in controllers:
        summary = json.loads((out / name / "summary.json").read_text())
        assert summary["controller"] == name and summary["seed"] == 3
        assert summary["reached_goal"], summary
        assert summary["min_clearance_m"] > 3.0, summary  # nobody touches a wall
        assert name in table
    assert (out / "separation.png").stat().st_size > 10_000
    md = (out / "compare.md").read_text()
    assert md.count("\n| ") == len(controllers) + 1 and "J_c" in md
