"""BootClock: the autopilot's time since boot on the bridge's clock, from TIMESYNC and arrivals."""

import pytest

from bridge.boot_clock import BootClock

OFFSET = 100.0  # the autopilot booted at bridge time 100 s


def test_timesync_gives_the_offset_and_the_delay():
    bc = BootClock()
    assert bc.to_bridge(1.0) is None and bc.source == "none"
    for k, rtt in enumerate((0.30, 0.32, 0.45, 0.30)):  # one slow trip (queueing)
        sent = 200.0 + k
        bc.timesync(sent, sent + rtt, sent + 0.15 - OFFSET)  # answered half-way
        bc.message(sent + 0.5 - OFFSET, sent + 0.5 + 0.15)  # messages take 150 ms
    assert bc.source == "timesync"
    assert bc.offset_s == pytest.approx(OFFSET, abs=1e-9)
    assert bc.delay_s == pytest.approx(0.155)  # half the median round trip
    assert bc.to_bridge(5.0) == pytest.approx(OFFSET + 5.0)


def test_arrivals_stand_in_without_timesync_or_when_it_is_on_another_clock():
    bc = BootClock()
    bc.fallback_delay_s = 0.1
    for k in range(20):
        t = 10.0 + 0.05 * k
        bc.message(t, t + OFFSET + 0.1 + (0.03 if k % 3 else 0.0))  # 100 ms and some jitter
    assert bc.source == "arrivals"
    assert bc.offset_s == pytest.approx(OFFSET, abs=1e-9)
    bc.timesync(500.0, 500.2, 500.1)  # tc1 on the bridge's clock, not the boot clock
    assert bc.source == "arrivals" and bc.offset_s == pytest.approx(OFFSET, abs=1e-9)
    bc.reset()
    assert bc.offset_s is None
