"""The navigation stack outside the closed loop: fed the FMU plant's motion in the loop's
order it gives the loop's run bit for bit; a failing controller becomes a status and a
reason, never an exception."""

from dataclasses import replace

import numpy as np

from scenarios.cosim.nav_model import NavigationModel
from scenarios.cosim.navigation import STATUS_CODES, NavigationStack, status_code
from scenarios.loop.closed_loop import Decision
from scenarios.loop.runner import run_scenario
from scenarios.plants.fmu import FmuPlant
from scenarios.plants.plant import ActuatorLimits


def _drive(scenario, tmp_path, seconds):
    """The stack and the boat FMU stepped as the closed loop steps them."""
    stack = NavigationStack(scenario)
    plant = FmuPlant(scenario.plant_params, ActuatorLimits(*scenario.actuator_rates), tmp_path)
    out = plant.reset(scenario.initial_state, scenario.current_ne)
    stack.start(out.state)
    rows = []
    for k in range(int(round(seconds / 0.1))):
        period = stack.control(k * 0.1, out.state, out.actuators)
        rows.append([*out.state, *period.command])
        for _ in range(10):
            out = plant.step(period.command, 0.01)
            stack.sense(out.state, out.state_dot)
    plant.close()
    return np.array(rows)


def test_the_stack_reproduces_the_closed_loop_bit_for_bit(short_bend, tmp_path):
    scenario = replace(short_bend, duration_s=6.0)
    run_scenario(scenario, tmp_path / "run", plots=False)
    log = np.genfromtxt(tmp_path / "run" / "log.csv", delimiter=",", names=True)
    ours = _drive(scenario, tmp_path, 6.0)
    theirs = np.column_stack([log[f"true_{n}"] for n in
                              ("x_m", "y_m", "psi_rad", "u_mps", "v_mps", "r_radps")]
                             + [log["nT_cmd_pct"], log["nS_cmd_pct"]])
    assert len(theirs) == len(ours) == 60
    assert ours[-1, 0] > 0.5 and ours[-1, 3] > 0.3  # the boat got going
    np.testing.assert_array_equal(ours, theirs)


def test_status_codes_say_what_the_controller_did():
    assert status_code(Decision(np.zeros(2))) == STATUS_CODES["ok"]
    assert status_code(Decision(np.zeros(2), stats={"waiting": "way blocked"})) == 1
    assert status_code(Decision(np.zeros(2), stats={"fallback": "qp"})) == 2
    assert status_code(Decision(np.zeros(2), ok=False, status="infeasible")) == 3


def _started_model(short_bend_file, tmp_path) -> NavigationModel:
    import json

    from scenarios.cosim.build import scenario_document

    (tmp_path / "scenario.json").write_text(json.dumps(scenario_document(short_bend_file)))
    model = NavigationModel(tmp_path)
    model.values["log_path"] = str(tmp_path / "nav.csv")
    model.values.update(dict(zip(("x", "y", "psi"), (0.0, 0.0, 0.0))))
    assert model.start() is None
    return model


def test_a_failing_controller_is_a_status_and_a_reason(short_bend_file, tmp_path):
    model = _started_model(short_bend_file, tmp_path)
    assert model.values["nT"] > 0  # the command for t = 0 is out at initialisation
    model.stack.controller.step = lambda *a, **k: Decision(np.array([50.0, 9.0]), ok=False,
                                                           status="QP infeasible")
    for i in range(9):
        assert model.step(i * 0.01, 0.01)
    assert not model.step(0.09, 0.01)  # the step that ends on t = 0.1 decides for it
    assert "QP infeasible" in model.error and "t = 0.1" in model.error
    assert (model.values["nT"], model.values["nS"], model.values["status"]) == (0.0, 0.0, 3)
    assert not model.step(0.1, 0.01)  # and it stays in its error state
    model.close()
    last = (tmp_path / "nav.csv").read_text().splitlines()[-1]
    assert last.endswith("QP infeasible")


def test_an_exception_in_the_controller_never_reaches_the_master(short_bend_file, tmp_path):
    model = _started_model(short_bend_file, tmp_path)

    def boom(*args, **kwargs):
        raise ZeroDivisionError("division by zero")

    model.stack.controller.step = boom
    assert all(model.step(i * 0.01, 0.01) for i in range(9))
    assert not model.step(0.09, 0.01)
    assert "ZeroDivisionError: division by zero" in model.error and "t = 0.10" in model.error
    assert model.values["status"] == STATUS_CODES["failed"]
    model.close()


def test_a_step_that_does_not_divide_the_imu_period_is_refused(short_bend_file, tmp_path):
    model = _started_model(short_bend_file, tmp_path)
    assert not model.step(0.0, 0.03)
    assert "communication step 0.03 s" in model.error and "0.01 s" in model.error
    model.close()


def test_a_step_finer_than_the_imu_period_samples_every_imu_instant(short_bend_file, tmp_path):
    (tmp_path / "fine").mkdir()
    (tmp_path / "coarse").mkdir()
    fine = _started_model(short_bend_file, tmp_path / "fine")
    coarse = _started_model(short_bend_file, tmp_path / "coarse")
    for i in range(39):
        assert fine.step(i * 0.0025, 0.0025)
    for i in range(9):
        assert coarse.step(i * 0.01, 0.01)
    assert fine.stack._imu_k == coarse.stack._imu_k == 9  # both sampled 0.01 ... 0.09
    np.testing.assert_array_equal(fine.stack._nav.state, coarse.stack._nav.state)


def test_the_perception_parameter_puts_the_simulated_lidar_inside(short_bend_file, tmp_path):
    import json

    from scenarios.cosim.build import scenario_document

    (tmp_path / "scenario.json").write_text(json.dumps(scenario_document(short_bend_file)))
    model = NavigationModel(tmp_path)
    model.values["perception"] = "lidar"
    model.values["log_path"] = str(tmp_path / "nav.csv")
    assert model.start() is None
    assert type(model.stack.perception).__name__ == "DelayedLidarPerception"
    assert all(model.step(i * 0.01, 0.01) for i in range(30))
    rows = (tmp_path / "nav.csv").read_text().splitlines()[1:]
    segments = [int(r.split(",")[13]) for r in rows]
    assert len(rows) == 4 and min(segments) > 0  # decisions at 0.0 ... 0.3 s, walls seen
    model.close()


def test_an_unknown_perception_parameter_is_refused_by_name(short_bend_file, tmp_path):
    import json

    from scenarios.cosim.build import scenario_document

    (tmp_path / "scenario.json").write_text(json.dumps(scenario_document(short_bend_file)))
    model = NavigationModel(tmp_path)
    model.values["perception"] = "radar"
    reason = model.start()
    assert reason is not None and "perception" in reason and "'radar'" in reason
    assert model.error == reason and not model.step(0.0, 0.01)
