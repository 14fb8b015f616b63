"""`canalnav compare` on a short scenario: three runs, their summaries, the table and plot."""

import json

from bridge.main import main


def test_compare_runs_the_three_controllers(tmp_path, capsys, short_bend_toml):
    path = tmp_path / "short.toml"
    path.write_text(short_bend_toml)
    out = tmp_path / "cmp"
    assert main(["compare", str(path), "--out", str(out)]) == 0
    table = capsys.readouterr().out
    rows = json.loads((out / "compare.json").read_text())
    assert [r["controller"] for r in rows] == ["nmpc", "los-pid", "lexicographic"]
    for name in ("nmpc", "los-pid", "lexicographic"):
        summary = json.loads((out / name / "summary.json").read_text())
        assert summary["controller"] == name and summary["seed"] == 3
        assert summary["reached_goal"], summary
        assert summary["min_clearance_m"] > 3.0, summary  # nobody touches a wall
        assert name in table
    assert (out / "separation.png").stat().st_size > 10_000
    md = (out / "compare.md").read_text()
    assert md.count("\n| ") == 4 and "J_c" in md
