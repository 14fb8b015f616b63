"""controller.pwm: percent <-> PWM as ArduPilot Rover reads RC inputs and writes servo outputs."""

from __future__ import annotations

import numpy as np
import pytest

from controller.pwm import (STEERING_UNITS, THROTTLE_UNITS, CommandChannels, PwmChannel,
                            rc_input, servo_output)

COMMANDS = [0.6, 1.0, 2.0, 7.3, 30.9, 50.0, 99.4, 100.0]


@pytest.mark.parametrize("units", [None, THROTTLE_UNITS, STEERING_UNITS])
@pytest.mark.parametrize("dz", [0, 15, 45, 90])
@pytest.mark.parametrize("reversed_", [False, True])
@pytest.mark.parametrize("trim", [1500, 1440])
def test_a_command_lands_beyond_the_dead_zone_both_ways(units, dz, reversed_, trim):
    ch = PwmChannel(1, 1000, 2000, trim, dz, reversed_, units)
    for c in COMMANDS:
        for v in (c, -c):
            pwm = ch.to_pwm(v)
            assert isinstance(pwm, int)
            above = (v > 0) != reversed_
            assert (pwm > trim + dz) if above else (pwm < trim - dz), (v, pwm)
            read = ch.to_percent(pwm)
            assert np.sign(read) == np.sign(v) and read != 0.0  # the smallest correction moves
            assert abs(read - v) <= 0.6, (v, pwm, read)
    ends = (ch.to_pwm(100.0), ch.to_pwm(-100.0))
    assert ends == ((2000, 1000) if not reversed_ else (1000, 2000))  # the largest at the ends
    assert ch.to_pwm(0.0) == trim and ch.to_percent(trim) == 0.0
    assert ch.to_percent(trim + dz) == 0.0 and ch.to_percent(trim - dz) == 0.0  # dead zone
    assert ch.to_pwm(250.0) == ends[0]  # clipped


def test_bad_calibration_names_the_parameter():
    with pytest.raises(ValueError, match="RC3: need MIN < TRIM < MAX, got 1100 / 1000 / 1900"):
        rc_input(3, {"RC3_TRIM": 1000})
    with pytest.raises(ValueError, match="RC1: dead zone 400 us leaves no travel"):
        rc_input(1, {"RC1_DZ": 400})
    with pytest.raises(ValueError, match="is not a number"):
        PwmChannel(1).to_pwm(float("nan"))


def test_servo_outputs_by_function_and_sense():
    params = {"SERVO2_FUNCTION": 26, "SERVO4_FUNCTION": 70, "SERVO2_REVERSED": 1,
              "SERVO4_MIN": 1000, "SERVO4_MAX": 2000}
    ch = CommandChannels.from_servo_params(params)
    assert (ch.steering.channel, ch.throttle.channel) == (2, 4)
    assert ch.steering == servo_output(2, params) and ch.steering.reversed
    pwm = ch.to_pwm(40.0, 25.0)  # nS > 0: port, below trim unless reversed (here it is)
    assert pwm == {4: 1700, 2: 1600}
    assert ch.to_commands(pwm) == pytest.approx((40.0, 25.0))
    assert ch.to_commands({}) == (0.0, 0.0)
    with pytest.raises(ValueError, match="SERVOn_FUNCTION = 26"):
        CommandChannels.from_servo_params({"SERVO3_FUNCTION": 70})


@pytest.mark.parametrize("dz", [0, 30, 47])
@pytest.mark.parametrize("lo, trim, hi", [(1100, 1500, 1900), (982, 1511, 2006)])
def test_throttle_reads_the_whole_percent_meant_and_steering_the_nearest_step(dz, lo, trim, hi):
    """Rover truncates its throttle reading to whole percent and its steering to 1/4500: the
    PWM sent reads as the nearest whole percent of throttle for every command, and steering
    within one microsecond's worth above the command."""
    thr = PwmChannel(3, lo, hi, trim, dz, False, THROTTLE_UNITS)
    steer = PwmChannel(1, lo, hi, trim, dz, True, STEERING_UNITS)
    us_pct = 100.0 / min(hi - trim - dz, trim - dz - lo)  # one microsecond of travel
    for c in np.round(np.arange(-100.0, 100.05, 0.1), 1):
        meant = float(np.sign(c) * np.floor(abs(c) + 0.5))
        assert thr.to_percent(thr.to_pwm(c)) == meant, c
        read = steer.to_percent(steer.to_pwm(c))
        if abs(c) * STEERING_UNITS / 100 >= 0.5:
            half_unit = 50.0 / STEERING_UNITS
            assert np.sign(read) == np.sign(c), (c, read)
            assert -half_unit - 1e-9 <= abs(read) - abs(c) <= us_pct + half_unit, (c, read)
    # what the firmware does with a PWM: integer division, toward zero
    assert thr.to_percent(trim + dz + 1) == 0.0  # 1 us is less than 1 % of travel here
    assert thr.to_percent(trim - dz - 1) == 0.0
    assert thr.to_percent(hi) == 100.0 and thr.to_percent(lo) == -100.0
