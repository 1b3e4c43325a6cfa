"""The control loop's rate in vehicle time: a loop that falls behind a fast vehicle says so and
limits the speed to a bounded travel per step; one that keeps up is never limited."""

from __future__ import annotations

import math

from autopilot.harness import Bench, mission

from rover_ctl.autopilot.loop_rate import ControlTicks, LoopRate
from rover_ctl.config import DaemonParams
from rover_ctl.vocabulary import RoverMode, Severity


def feed(monitor: LoopRate, start_s: float, rate_hz: float, seconds: float):
    states, t_s = [], start_s
    while t_s < start_s + seconds:
        states.append(monitor.step(t_s))
        t_s += 1.0 / rate_hz
    return states, t_s


def test_a_loop_that_keeps_up_is_never_slow_or_limited():
    states, _ = feed(LoopRate(DaemonParams()), 0.0, 25.0, 20.0)
    assert states[0].rate_hz is None  # no figure before a whole window
    rates = [s.rate_hz for s in states if s.rate_hz is not None]
    assert rates and all(abs(r - 25.0) < 0.01 for r in rates)
    assert not any(s.slow or s.changed or s.speed_limit_mps is not None for s in states)


def test_a_slow_loop_is_reported_once_limited_and_recovers():
    params = DaemonParams()
    monitor = LoopRate(params)
    _, t_s = feed(monitor, 0.0, 25.0, 5.0)
    slow, t_s = feed(monitor, t_s, 6.8, 10.0)
    back, _ = feed(monitor, t_s, 25.0, 10.0)
    assert [s.changed for s in slow].count(True) == 1 and slow[-1].slow
    assert math.isclose(slow[-1].speed_limit_mps, params.max_step_travel_m * 6.8, rel_tol=1e-6)
    first = next(s for s in slow if s.changed)  # measured while the window still held fast steps
    assert 6.8 < first.rate_hz < 20.0
    assert first.text(0.1) == f"Control loop slow: {first.rate_hz:.1f} Hz of 25 Hz, speed limited to 0.1 m per step"
    assert [s.changed for s in back].count(True) == 1 and not back[-1].slow and back[-1].speed_limit_mps is None
    recovered = next(s for s in back if s.changed)  # above the midpoint, 22.5 Hz
    assert recovered.rate_hz >= 22.5 and recovered.text(0.1) == f"Control loop back to {recovered.rate_hz:.1f} Hz of 25 Hz"


def test_hysteresis_between_the_slow_threshold_and_the_target():
    monitor = LoopRate(DaemonParams())  # slow below 20 Hz, recovered from 22.5 Hz
    _, t_s = feed(monitor, 0.0, 15.0, 5.0)
    assert monitor.slow
    states, _ = feed(monitor, t_s, 21.0, 10.0)  # between the two: stays slow, no flapping
    assert monitor.slow and not any(s.changed for s in states)


def test_one_gap_in_the_vehicle_data_is_not_a_slow_loop():
    monitor = LoopRate(DaemonParams())
    _, t_s = feed(monitor, 0.0, 25.0, 3.0)
    states, t_s = feed(monitor, t_s + 1.0, 25.0, 3.0)  # a 1 s hole (the link failsafe's business)
    assert not any(s.slow for s in states)


def test_a_loop_on_a_stream_that_skips_messages_keeps_up():
    """ArduPilot's 50 Hz stream skips about one message in ten: steps at 40, 40, 40, 60, 20 ms."""
    monitor, t_s, states = LoopRate(DaemonParams()), 0.0, []
    for _ in range(100):
        for interval_s in (0.04, 0.04, 0.04, 0.06, 0.02):
            states.append(monitor.step(t_s))
            t_s += interval_s
    assert not any(s.slow for s in states)
    assert all(abs(s.rate_hz - 25.0) < 0.5 for s in states if s.rate_hz is not None)


def test_a_loop_that_stalls_often_is_slow():
    """A starved loop: four steps on time, then nothing for 0.2 s, again and again."""
    monitor, t_s = LoopRate(DaemonParams()), 0.0
    for _ in range(40):
        for interval_s in (0.04, 0.04, 0.04, 0.2):
            state = monitor.step(t_s)
            t_s += interval_s
    assert state.slow and state.rate_hz < 20.0


def test_a_restarted_vehicle_clock_starts_a_new_measurement():
    monitor = LoopRate(DaemonParams())
    feed(monitor, 100.0, 25.0, 3.0)
    assert monitor.step(0.5).rate_hz is None


def test_the_autopilot_warns_and_drives_slower_when_its_loop_falls_behind():
    bench = Bench(step_period_s=1.0 / 3.0)  # 3 steps per second of vehicle time instead of 25
    bench.ready(mission((0.0, 60.0)))
    assert bench.request(bench.autopilot.set_mode(RoverMode.AUTO)).accepted
    bench.run(15.0)
    warnings = [e for e in bench.events if getattr(e, "text", "").startswith("Control loop slow")]
    assert len(warnings) == 1 and warnings[0].severity == Severity.WARNING, bench.texts
    limit_mps = DaemonParams().max_step_travel_m * 3.0
    assert bench.outputs[-1].log_row["speed_limit_mps"] <= limit_mps + 1e-9
    assert 0.1 < bench.speed_mps <= limit_mps * 1.1  # still driving, at the bounded speed


def test_the_autopilot_at_full_rate_drives_at_cruise():
    bench = Bench()
    bench.ready(mission((0.0, 60.0)))
    assert bench.request(bench.autopilot.set_mode(RoverMode.AUTO)).accepted
    bench.run(15.0)
    assert not [t for t in bench.texts if t.startswith("Control loop")]
    assert bench.speed_mps > 0.9


def test_a_loop_limited_by_a_slow_line_is_not_a_slow_loop():
    """Odometry at 11 Hz (a 57600 radio): the loop cannot step faster than its data; measured
    against that, 10 Hz of steps is keeping up."""
    monitor = LoopRate(DaemonParams())
    for k in range(200):
        state = monitor.step(k * 0.1, expected_hz=11.0)
    assert not state.slow and state.target_hz == 11.0
    assert monitor.step(20.0, expected_hz=None).target_hz == 25.0


def test_control_ticks_every_period_and_no_replay_after_a_gap():
    ticks = ControlTicks(lambda: 0.04)
    due = [t for t in (round(k * 0.01, 2) for k in range(20)) if ticks.due(t)]
    assert due == [0.0, 0.04, 0.08, 0.12, 0.16]
    assert ticks.due(1.0)  # after a 0.8 s gap: one step, not the twenty missed
    assert not ticks.due(1.03) and ticks.due(1.04)
    assert ticks.due(1.5) and not ticks.due(1.51) and ticks.due(1.52)  # after a gap, back on the multiples of the period


def test_control_ticks_fall_on_multiples_of_the_period_whenever_they_start():
    """Which 20 ms frame the daemon sees first depends on the wall clock; its steps must not."""
    for first_s in (0.0, 0.02, 0.06, 7.98):
        ticks = ControlTicks(lambda: 0.04)
        due = [t for t in (round(first_s + k * 0.02, 2) for k in range(6)) if ticks.due(t)]
        assert all(abs(t / 0.04 - round(t / 0.04)) < 1e-6 for t in due) and len(due) == 3, (first_s, due)
