"""The vehicle link's byte budget (rover_ctl.mavlink.budget): only what the daemon reads, at rates
picked in priority order so that the total fits the line."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from rover_ctl.config import Config
from rover_ctl.mavlink import budget

C = Config()
MEASURED = {"WHEEL_DISTANCE": 149, "ATTITUDE": 40, "GPS_RAW_INT": 52, "DISTANCE_SENSOR": 25, "SYS_STATUS": 43, "HEARTBEAT": 21}
"""Frame sizes measured on ArduPilot Rover's link (zero-truncated MAVLink 2)."""


def plan(url: str, rangefinders: int = 6, measured=MEASURED, config: Config = C) -> budget.StreamPlan:
    return budget.plan(config.daemon, config.link, config.failsafe, url, rangefinders, measured_bytes=measured)


def test_line_capacity_from_the_connection_string():
    assert budget.line_bytes_per_s("/dev/ttyUSB0,57600", C.link) == (5760.0, "57600 baud")
    assert budget.line_bytes_per_s("COM4,115200", C.link) == (11520.0, "115200 baud")
    assert budget.line_bytes_per_s("udpin:127.0.0.1:14550", C.link) == (C.link.network_bytes_per_s, "network link")
    assert budget.line_bytes_per_s("tcp:127.0.0.1:5760", C.link)[1] == "network link"
    assert budget.serial_baud("/dev/ttyUSB0") is None and budget.serial_baud("/dev/ttyUSB0,fast") is None
    config = Config()
    config.link.line_bytes_per_s = 2000.0  # a radio bridged to UDP: the user says what it carries
    assert budget.line_bytes_per_s("udpin:127.0.0.1:14550", config.link) == (2000.0, "LINK_LINE_BPS")


def test_57600_radio_gets_odometry_rangefinders_and_gps_inside_the_budget():
    p = plan("/dev/ttyUSB0,57600")
    assert p.shortfall is None and p.bytes_per_s <= C.link.line_use_max * 5760
    assert p.rates_hz["GPS_RAW_INT"] == C.daemon.gps_rate_hz  # position first: cheap
    assert p.rates_hz[budget.EXTRA1] >= C.daemon.core_rate_hz and p.rates_hz["DISTANCE_SENSOR"] >= C.daemon.core_rate_hz
    assert p.rates_hz[budget.EXTRA1] < C.daemon.control_rate_hz  # the line cannot carry more
    assert p.rates_hz.get("SIMSTATE", 0) == 0  # evaluation only: nothing left for it


def test_a_fast_line_gets_every_wanted_rate():
    p = plan("/dev/ttyUSB0,921600")
    assert p.rates_hz == {budget.EXTRA1: C.daemon.sensor_rate_hz, "GPS_RAW_INT": C.daemon.gps_rate_hz,
                          "SYS_STATUS": C.daemon.status_rate_hz, "DISTANCE_SENSOR": C.daemon.rangefinder_rate_hz,
                          "SIMSTATE": C.daemon.truth_rate_hz}  # fmt: skip
    assert p.line_use < 0.2


def test_a_line_too_slow_for_the_minimums_says_why():
    p = plan("/dev/ttyUSB0,9600")
    assert p.shortfall is not None and "9600 baud" in p.shortfall and "minimum" in p.shortfall
    assert p.rates_hz[budget.EXTRA1] == budget.MIN_RATE_MARGIN * C.failsafe.min_sensor_rate_hz  # the least it drives on


def test_before_sizes_are_measured_the_plan_assumes_full_frames():
    worst, measured = plan("/dev/ttyUSB0,57600", measured=None), plan("/dev/ttyUSB0,57600")
    assert worst.sizes["DISTANCE_SENSOR"] == budget.frame_bytes("DISTANCE_SENSOR") == 51
    assert worst.bytes_per_s <= C.link.line_use_max * 5760
    assert worst.rates_hz["DISTANCE_SENSOR"] <= measured.rates_hz["DISTANCE_SENSOR"]


def test_without_rangefinders_odometry_gets_their_share():
    assert "DISTANCE_SENSOR" not in plan("/dev/ttyUSB0,57600", 0).rates_hz
    assert plan("/dev/ttyUSB0,57600", 0).rates_hz[budget.EXTRA1] > plan("/dev/ttyUSB0,57600", 6).rates_hz[budget.EXTRA1]


@given(baud=st.integers(1200, 2_000_000), rangefinders=st.integers(0, 12))
def test_every_plan_fits_or_says_why_and_never_goes_below_the_minimums(baud, rangefinders):
    p = plan(f"/dev/ttyS0,{baud}", rangefinders)
    assert (p.shortfall is None) == (p.bytes_per_s <= p.budget_bytes_per_s + 1e-6)
    assert p.rates_hz[budget.EXTRA1] == int(p.rates_hz[budget.EXTRA1])  # a stream rate is whole hertz
    assert p.rates_hz[budget.EXTRA1] >= budget.MIN_RATE_MARGIN * C.failsafe.min_sensor_rate_hz
    assert p.rates_hz["GPS_RAW_INT"] >= max(C.daemon.min_gps_rate_hz, budget.MIN_RATE_MARGIN / C.failsafe.gps_timeout_s)
    if rangefinders:
        assert p.rates_hz["DISTANCE_SENSOR"] >= C.daemon.min_rangefinder_rate_hz
    for name, hz in p.rates_hz.items():
        assert hz <= {budget.EXTRA1: C.daemon.sensor_rate_hz, "GPS_RAW_INT": C.daemon.gps_rate_hz,
                      "SYS_STATUS": C.daemon.status_rate_hz, "DISTANCE_SENSOR": C.daemon.rangefinder_rate_hz,
                      "SIMSTATE": C.daemon.truth_rate_hz}[name]  # fmt: skip


@pytest.mark.parametrize("baud", [57600, 115200])
def test_a_faster_line_never_gets_lower_rates(baud):
    slow, fast = plan(f"/dev/ttyS0,{baud}"), plan(f"/dev/ttyS0,{baud * 2}")
    assert all(fast.rates_hz[n] >= hz for n, hz in slow.rates_hz.items())
