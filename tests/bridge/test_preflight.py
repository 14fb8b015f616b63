"""Each pre-flight refusal names the parameter and value; a good setup passes."""

from __future__ import annotations

from dataclasses import replace

import pytest

from bridge.onboard import preflight
from bridge.shared.ardupilot import DEFAULT_PARAMS, MODES
from bridge.onboard.link import Heartbeat

HB = Heartbeat(system_id=1, component_id=1, type=11, autopilot=3, base_mode=1,
               custom_mode=MODES["MANUAL"], system_status=4, received_s=0.0)
GOOD = {k: v for k, v in DEFAULT_PARAMS.items()
        if k in preflight.BASE_PARAMS + ("MAV_GCS_SYSID",)
        or k in preflight.channel_params(DEFAULT_PARAMS)}


def refusals(hb=HB, params=GOOD, system_id=255, mode=None):
    return preflight.refusals(hb, params, system_id=system_id, requested_mode=mode)


def test_good_setup_passes():
    assert refusals() == []
    assert refusals(params={**GOOD, "RC_OPTIONS": 1}) == []  # other bits do not matter
    assert refusals(hb=replace(HB, type=10)) == []  # a rover is fine


def test_rc_options_ignore_overrides():
    (reason,) = refusals(params={**GOOD, "RC_OPTIONS": 2 | 8})
    assert "RC_OPTIONS = 10" in reason and "Ignore MAVLink Overrides" in reason


@pytest.mark.parametrize("name", ["MAV_GCS_SYSID", "SYSID_MYGCS"])
def test_gcs_sysid_differs(name):
    params = {k: v for k, v in GOOD.items() if k != "MAV_GCS_SYSID"}
    params[name] = 250
    (reason,) = refusals(params=params)
    assert reason == (f"{name} = 250: overrides from system id 255 will be ignored; "
                      "use --system-id 250")
    assert refusals(params=params, system_id=250) == []


def test_gcs_sysid_range_of_new_firmware():
    params = {**GOOD, "MAV_GCS_SYSID": 250, "MAV_GCS_SYSID_HI": 254}
    assert refusals(params=params, system_id=252) == []
    (reason,) = refusals(params=params, system_id=255)
    assert "MAV_GCS_SYSID = 250, MAV_GCS_SYSID_HI = 254" in reason and "--system-id 250" in reason


def test_gcs_sysid_unread():
    params = {k: v for k, v in GOOD.items() if k != "MAV_GCS_SYSID"}
    (reason,) = refusals(params=params)
    assert "SYSID_MYGCS / MAV_GCS_SYSID: not read" in reason


def test_unexpected_mode_without_mode_option():
    (reason,) = refusals(hb=replace(HB, custom_mode=MODES["HOLD"]))
    assert "HEARTBEAT.custom_mode = 4 (HOLD)" in reason and "--mode MANUAL" in reason
    assert refusals(hb=replace(HB, custom_mode=MODES["HOLD"]), mode="MANUAL") == []


def test_requested_mode_that_ignores_overrides():
    (reason,) = refusals(mode="AUTO")
    assert reason.startswith("--mode AUTO:")
    (reason,) = refusals(mode="FLY")
    assert "not a Rover mode" in reason
    assert refusals(mode="acro") == []


def test_overrides_disabled():
    (reason,) = refusals(params={**GOOD, "RC_OVERRIDE_TIME": 0})
    assert reason.startswith("RC_OVERRIDE_TIME = 0 disables RC overrides")


def test_vehicle_type():
    (reason,) = refusals(hb=replace(HB, type=2))
    assert reason.startswith("HEARTBEAT.type = 2: system 1 is not a boat or rover")


def test_rcmap_channels_invalid():
    (reason,) = refusals(params={**GOOD, "RCMAP_THROTTLE": 1})
    assert "RCMAP_ROLL and RCMAP_THROTTLE are both channel 1" in reason
    (reason,) = refusals(params={**GOOD, "RCMAP_ROLL": 0})
    assert "RCMAP_ROLL = 0 is not a channel 1..16" in reason
    (reason,) = refusals(params={**GOOD, "RC3_TRIM": 1000})
    assert "RC3: need MIN < TRIM < MAX" in reason


def test_missing_parameters_are_named():
    params = {k: v for k, v in GOOD.items() if k not in ("RC_OPTIONS", "RC1_TRIM")}
    reasons = refusals(params=params)
    assert any(r.startswith("RC_OPTIONS: not read") for r in reasons)
    assert any(r.startswith("RC1_TRIM: not read") for r in reasons)


def test_every_reason_at_once():
    bad = {**GOOD, "RC_OPTIONS": 2, "RC_OVERRIDE_TIME": 0, "MAV_GCS_SYSID": 1}
    reasons = refusals(hb=replace(HB, type=1, custom_mode=MODES["AUTO"]), params=bad)
    assert len(reasons) == 5


def test_notes():
    notes = preflight.notes(HB, {**GOOD, "RC_OVERRIDE_TIME": -1}, arm=False, requested_mode="ACRO")
    assert any("never time out" in n for n in notes)
    assert any("ACRO" in n for n in notes)
    assert any("disarmed and --arm was not given" in n for n in notes)
    assert preflight.notes(replace(HB, base_mode=129), GOOD) == []


def test_channel_params_follow_the_mapping():
    names = preflight.channel_params({"RCMAP_ROLL": 2, "RCMAP_THROTTLE": 9})
    assert names[:5] == ("RC2_MIN", "RC2_MAX", "RC2_TRIM", "RC2_DZ", "RC2_REVERSED")
    assert "RC9_REVERSED" in names and len(names) == 10
