"""Frame clock, pacing and the lockstep marker (pure; wall clock injected)."""

from __future__ import annotations

import math

import pytest

from sitl.clock import MARKER_RESEND_S, FrameClock, LockstepMarker, Pacer
from sitl.endpoints import mavlink
from sitl.mavlink_vehicle import next_slot


def test_frame_clock_is_exact_in_nanoseconds() -> None:
    clock = FrameClock(0.02)
    for _ in range(150_000):
        clock.advance()
    assert clock.t_ns == 3000 * 10**9 and clock.t_s == 3000.0
    with pytest.raises(ValueError):
        FrameClock(0.0)


def test_pacer_maps_sim_to_wall_time() -> None:
    now = [100.0]
    pacer = Pacer(10.0, now=lambda: now[0])
    assert pacer.wait_s(5.0) == pytest.approx(0.5)
    now[0] = 101.0
    assert pacer.wait_s(5.0) == 0.0  # late: no wait
    assert Pacer(math.inf, now=lambda: 0.0).wait_s(1e9) == 0.0


def test_marker_answer_and_resend() -> None:
    now = [0.0]
    marker = LockstepMarker(now=lambda: now[0])
    marker.sent(20_000_000)
    assert marker.is_answer(mavlink.MAVLink_timesync_message(123, 20_000_000))
    assert not marker.is_answer(mavlink.MAVLink_timesync_message(0, 20_000_000))  # a request, not an answer
    assert not marker.is_answer(mavlink.MAVLink_timesync_message(123, 0))  # another frame
    now[0] = MARKER_RESEND_S + 0.01
    assert marker.resend_in_s() < 0


def test_stream_slots_skip_missed_ones() -> None:
    assert next_slot(0.0, 0.2, 0.0) == pytest.approx(0.2)
    assert next_slot(0.2, 0.2, 1.0) == pytest.approx(1.2)  # a coarse frame does not cause a burst
