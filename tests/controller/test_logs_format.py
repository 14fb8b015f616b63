"""The CSV manoeuvre-log format: round trip, tolerant reading, errors naming file/line/column."""

import math

import numpy as np
import pytest

from controller.errors import InputError
from controller.identification.logs import ManeuverLog, format_log, parse_log, read_log, with_truth_meta, write_log
from controller.params import IDENTIFIED

HEADER = "time [s],x [m],y [m],psi [deg],u [m/s],v [m/s],r [deg/s],nT [%],nS [%]"


def small_log(n=30, steering=0.0):
    t = np.arange(n) * 0.1
    states = np.column_stack([t * 1.5, 0.01 * t, np.radians(5 * np.sin(t)), 1.5 + 0 * t,
                              0.02 * np.cos(t), np.radians(np.cos(t))])
    commands = np.column_stack([np.full(n, 42.0), np.full(n, steering)])
    meta = with_truth_meta({"maneuver": "zigzag", "use": "fit"}, IDENTIFIED)
    return ManeuverLog(t, states, commands, meta, source="mem")


def write(tmp_path, text, name="log.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_round_trip_keeps_values_units_and_truth(tmp_path):
    log = small_log()
    path = tmp_path / "a.csv"
    write_log(path, log)
    back = read_log(path)
    np.testing.assert_allclose(back.time_s, log.time_s, atol=1e-9)
    np.testing.assert_allclose(back.states[:, [0, 1, 3, 4]], log.states[:, [0, 1, 3, 4]], atol=1e-4)
    np.testing.assert_allclose(back.states[:, [2, 5]], log.states[:, [2, 5]], atol=1e-6)
    np.testing.assert_allclose(back.commands, log.commands)
    assert back.truth() == IDENTIFIED
    assert back.meta["maneuver"] == "zigzag" and not back.heldout
    assert "psi [deg]" in path.read_text()  # degrees at this human-facing edge


def test_missing_optional_columns_and_other_rates_are_allowed(tmp_path):
    # no x, y, v; yaw rate only on every other row; commands only when they change
    rows = ["time [s],psi [deg],u [m/s],r [deg/s],nT [%],nS [%],battery [V]"]
    for k in range(10):
        r = f"{0.5 * k:.1f}" if k % 2 == 0 else ""
        cmd = "40,0" if k == 0 else ("45,-10" if k == 5 else ",")
        rows.append(f"{0.1 * k:.1f},{k},{1.0 + 0.1 * k},{r},{cmd},12.5")
    log = read_log(write(tmp_path, "\n".join(rows) + "\n"))
    assert np.isnan(log.states[:, [0, 1, 4]]).all()
    assert log.measured("r").tolist() == [k % 2 == 0 for k in range(10)]
    assert log.commands[:5].tolist() == [[40.0, 0.0]] * 5
    assert log.commands[5:].tolist() == [[45.0, -10.0]] * 5
    assert log.states[3, 2] == pytest.approx(math.radians(3))
    assert log.maneuver == "sway-yaw"  # no header: told by the steering


def test_radians_are_accepted_and_a_straight_log_is_a_surge_run(tmp_path):
    text = "time,psi [rad],u,r [rad/s],nT,nS\n0,0.1,1,0.0,30,0\n0.1,0.1,1.1,0.0,30,0.4\n"
    log = parse_log(text, "x.csv")
    assert log.states[0, 2] == pytest.approx(0.1)
    assert log.maneuver == "surge"


def test_missing_required_column_names_file_line_and_column(tmp_path):
    path = write(tmp_path, "# comment\ntime [s],psi [deg],nT [%],nS [%]\n0,0,10,0\n0.1,0,10,0\n")
    with pytest.raises(InputError) as exc:
        read_log(path)
    msg = str(exc.value)
    assert f"{path}:2" in msg and "'u'" in msg and "missing required column" in msg


def test_time_not_increasing_names_line_and_column(tmp_path):
    rows = [HEADER] + [f"{t},0,0,0,1,0,0,30,0" for t in ("0.0", "0.1", "0.2", "0.2", "0.3")]
    path = write(tmp_path, "\n".join(rows) + "\n")
    with pytest.raises(InputError) as exc:
        read_log(path)
    msg = str(exc.value)
    assert f"{path}:5" in msg and "'time [s]'" in msg and "not increasing" in msg


@pytest.mark.parametrize("cell", ["nan", "NaN", "inf", "fast", "1.2.3"])
def test_nan_or_text_in_a_number_names_line_and_column(tmp_path, cell):
    rows = [HEADER, "0,0,0,0,1,0,0,30,0", f"0.1,0,0,0,{cell},0,0,30,0", "0.2,0,0,0,1,0,0,30,0"]
    path = write(tmp_path, "\n".join(rows) + "\n")
    with pytest.raises(InputError) as exc:
        read_log(path)
    msg = str(exc.value)
    assert f"{path}:3" in msg and "'u [m/s]'" in msg and repr(cell) in msg


def test_a_log_with_one_sample_is_refused(tmp_path):
    path = write(tmp_path, HEADER + "\n0,0,0,0,1,0,0,30,0\n")
    with pytest.raises(InputError) as exc:
        read_log(path)
    assert str(path) in str(exc.value) and "1 data row" in str(exc.value)


def test_angle_without_unit_and_unknown_unit_are_refused(tmp_path):
    with pytest.raises(InputError, match=r"column 'psi'.*give the unit"):
        parse_log("time,psi,u,nT,nS\n0,0,1,0,0\n0.1,0,1,0,0\n", "a.csv")
    with pytest.raises(InputError, match=r"column 'u \[km/h\]'.*unknown unit"):
        parse_log("time,psi [deg],u [km/h],nT,nS\n0,0,1,0,0\n0.1,0,1,0,0\n", "a.csv")


def test_wrong_number_of_fields_and_bad_use_tag(tmp_path):
    with pytest.raises(InputError, match=r"a.csv:3: 3 fields"):
        parse_log("time,psi [deg],u,nT,nS\n0,0,1,0,0\n0.1,0,1\n", "a.csv")
    with pytest.raises(InputError, match=r"header 'use'"):
        parse_log("# use: later\ntime,psi [deg],u,nT,nS\n0,0,1,0,0\n0.1,0,1,0,0\n", "a.csv")


def test_format_writes_empty_cells_for_unmeasured_states():
    log = small_log(5)
    states = log.states.copy()
    states[:, 4] = np.nan
    text = format_log(ManeuverLog(log.time_s, states, log.commands, {}, "m"))
    data_rows = [r for r in text.splitlines() if r and not r.startswith(("#", "time"))]
    assert all(r.split(",")[5] == "" for r in data_rows)
    assert np.isnan(parse_log(text).states[:, 4]).all()
