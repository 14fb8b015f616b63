"""What `canalnav run` tells a user who is not at a terminal (issue 35): a progress line every
few seconds (done, simulated time, time left), and summary.json saying how it was asked for
(the command line and the --set overrides)."""

import io
import json

from scenarios.loop.closed_loop import log_progress


def test_a_progress_line_every_few_seconds_with_the_time_left():
    clock = [0.0]
    out = io.StringIO()
    show = log_progress(out, every_s=5.0, clock=lambda: clock[0])
    for k in range(1, 101):  # 100 steps of 1 s simulated, 0.2 s of wall time each
        clock[0] = 0.2 * k
        show(float(k), 100.0)
    lines = out.getvalue().splitlines()
    assert len(lines) == 4  # at 5, 10, 15 s of wall time and at the end
    assert lines[0] == "run:  25 % (25.0 of 100 s simulated), 5 s so far, about 15 s left"
    assert lines[-1].startswith("run: 100 % (100.0 of 100 s simulated), 20 s so far, about 0 s")


def test_summary_records_the_command_line_and_the_overrides(tmp_path, monkeypatch, capsys):
    from bridge.main import main

    argv = ["run", "scenarios/straight.toml", "--out", str(tmp_path), "--no-plots",
            "--no-mcap", "--set", "scenario.duration_s=3", "--set", "current.east_mps=0.1"]
    main(argv)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["invocation"]["overrides"] == ["scenario.duration_s=3",
                                                  "current.east_mps=0.1"]
    assert summary["invocation"]["command_line"] == " ".join(argv)  # (no quoting needed)
    assert "run: 100 %" in capsys.readouterr().err  # not a terminal: the line, no bar
