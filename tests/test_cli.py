"""The `canalnav` entry point: subcommands, errors as one line, README and CI in step."""

import re
import subprocess
import sys
from pathlib import Path

from bridge.main import build_parser, main

ROOT = Path(__file__).resolve().parents[1]


def test_help_lists_subcommands(capsys):
    parser = build_parser()
    text = parser.format_help()
    for name in ("bench", "params"):
        assert name in text


def test_params_round_trips_through_the_cli(tmp_path, capsys):
    out = tmp_path / "p.toml"
    assert main(["params", "-o", str(out)]) == 0
    assert main(["params", "--from", str(out)]) == 0
    assert "m11 = 1914.9" in capsys.readouterr().out


def test_bad_input_is_one_line_and_status_2(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[boat]\nm11 = -1\n")
    assert main(["params", "--from", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and str(bad) in err and "'m11'" in err


def test_console_script_runs():
    exe = Path(sys.executable).with_name("canalnav")
    result = subprocess.run([str(exe), "--help"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0 and "canalnav" in result.stdout


def test_ci_runs_the_readme_test_command():
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text()
    command = ci.strip().splitlines()[-1]
    assert command in readme, "the README's test command and .ci/run must stay the same"
    blocks = re.findall(r"```(?:sh|bash)?\n(.*?)```", readme, re.S)
    assert command in blocks[1], "the test command is the README's second command"


def test_whole_number_options_name_the_option_and_the_bound(capsys):
    import pytest

    for argv, message in ((["run", "scenarios/straight.toml", "--seed", "-1"],
                           "argument --seed: must be >= 0, got -1"),
                          (["run", "scenarios/straight.toml", "--mcap-points", "x"],
                           "argument --mcap-points: expected a whole number >= 0, got 'x'"),
                          (["sweep", "study.toml", "--workers", "0"],
                           "argument --workers: must be >= 1, got 0"),
                          (["bridge", "--mcap-points", "2.5"],
                           "argument --mcap-points: expected a whole number >= 0, got '2.5'")):
        with pytest.raises(SystemExit) as exit_:
            main(argv)
        assert exit_.value.code == 2
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err


def test_an_out_folder_under_a_file_and_a_figure_in_no_folder_are_named(tmp_path, capsys):
    """Issue 35's tracebacks: `run --out` where a parent is a file, `detect -o` into a folder
    that is not there: one line naming the option and the path."""
    blocker = tmp_path / "file"
    blocker.write_text("x")
    straight = Path(__file__).resolve().parents[1] / "scenarios" / "straight.toml"
    assert main(["run", str(straight), "--out", str(blocker / "sub"),
                 "--no-plots"]) == 2
    assert f"--out {blocker / 'sub'}: cannot make the folder" in capsys.readouterr().err
    missing = tmp_path / "nowhere" / "d.png"
    assert main(["detect", "--at", "10", "-o", str(missing)]) == 2
    assert f"-o {missing}: cannot write the figure" in capsys.readouterr().err


def test_a_negative_coordinate_list_after_an_option_is_its_value():
    """Issue 35: `--origin -35.3,149.1` was argparse's "expected one argument"."""
    from bridge.main import _join_negative_values

    args = build_parser().parse_args(_join_negative_values(
        ["bridge", "--connect", "udp:127.0.0.1:14550", "--scenario", "s.toml", "--origin",
         "-35.3,149.1"]))
    assert args.origin == "-35.3,149.1"
    assert _join_negative_values(["run", "a.toml", "--seed", "3"]) == ["run", "a.toml", "--seed", "3"]


def test_a_malformed_scheduler_address_is_named_as_such(capsys):
    """Issue 35: `--scheduler tcp://127.0.0.1` (no port) was reported as unreachable."""
    for bad in ("tcp://127.0.0.1", "udp://h:8786", "h:port"):
        assert main(["bench", "soak", "--seeds", "1", "--scheduler", bad]) == 2
        assert f"--scheduler {bad}: malformed" in capsys.readouterr().err


def _subcommands(parser, words=()):
    """Every `canalnav WORDS...` sub-parser, depth first."""
    for action in parser._actions:
        if action.__class__.__name__ == "_SubParsersAction":
            for name, sub in action.choices.items():
                yield (*words, name), sub
                yield from _subcommands(sub, (*words, name))


def test_every_command_has_a_description_and_no_literal_double_percent():
    """Issue 35: `sysid --help` and `maneuvers --help` showed '%%' (argparse unescapes '%' only
    in option help, not in a description); `bench loop` and `bench soak` had no description."""
    bad = []
    for words, sub in _subcommands(build_parser()):
        text = sub.format_help()
        if "%%" in text:
            bad.append(f"canalnav {' '.join(words)}: '%%' in --help")
        if not (sub.description or "").strip():
            bad.append(f"canalnav {' '.join(words)}: no description")
    assert not bad, bad


def test_run_help_lists_the_controllers_and_plants():
    """Issue 35: `run --help` did not list the controllers (nor compare's)."""
    from scenarios.loop.runner import CONTROLLERS, PLANTS

    run_help = _parser_of(["run"]).format_help()
    compare_help = _parser_of(["compare"]).format_help()
    for name in CONTROLLERS:
        assert name in run_help and name in compare_help, name
    for name in (*PLANTS, "mavlink-sim"):
        assert name in run_help, name


def _parser_of(words):
    return dict(_subcommands(build_parser()))[tuple(words)]


def test_run_and_compare_write_run_mcap_only_when_asked():
    """Issue 35: with the viz extra installed, `canalnav compare` wrote three 42 MB run.mcap
    by default; `run` and `compare` now write it only with --mcap (scenarios/README.md says
    why), whatever is installed; the bridge's --log keeps it (a drive is not run again)."""
    parser = build_parser()
    for argv in (["run", "a.toml"], ["compare", "a.toml"]):
        assert parser.parse_args(argv).mcap is False, argv
        assert parser.parse_args(argv + ["--mcap"]).mcap is True, argv
        assert parser.parse_args(argv + ["--no-mcap"]).mcap is False, argv
    import inspect

    from scenarios.studies.compare import compare

    assert inspect.signature(compare).parameters["mcap"].default is False
