"""`canalnav bench fmu`: one JSON object with rates and ratios from one run."""

import json

from bridge.main import main


def test_bench_prints_rates_and_ratios(capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert main(["bench", "fmu", "--steps", "200", "--repeat", "1"]) == 0
    result = json.loads(capsys.readouterr().out)
    for v in (2, 3):
        for path in ("fmuboat", "fmpy_api"):
            assert result[f"fmi{v}_{path}_steps_per_s"] > 0
            assert result[f"fmi{v}_{path}_vs_casadi_python"] > 0
    assert result["casadi_python_steps_per_s"] > 0
    # the same simulation: the FMU and the CasADi model end in the same state
    assert result["max_state_difference_vs_casadi_python"] < 1e-9
