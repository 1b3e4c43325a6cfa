"""Failsafes: each trigger, action and recovery, with hysteresis."""

from __future__ import annotations

import dataclasses
import math

import pytest

from rover_ctl.config import FailsafeParams
from rover_ctl.autopilot.failsafe import Action, FailsafeInputs, Failsafes, Severity

PARAMS = FailsafeParams(recovery_s=2.0)
FRESH_RANGES = {0: 0.02, 2: 0.02, 4: 0.02, 6: 0.02}
HEALTHY = FailsafeInputs(vehicle_age_s=0.02, gcs_age_s=0.5, gps_age_s=0.1, range_ages_s=FRESH_RANGES, driving=True, position_en=(0.0, 0.0))


def step(fs: Failsafes, t: float, **changes):
    return fs.update(t, dataclasses.replace(HEALTHY, **changes))


def texts(decision):
    return [e.text for e in decision.events]


def test_all_healthy_means_no_action_and_no_events():
    fs = Failsafes(PARAMS)
    for k in range(100):
        d = step(fs, k * 0.05)
        assert d.action is Action.NONE and not d.reasons and not d.events and not d.blocked_orientations


def test_vehicle_link_silent_neutral_then_resume_after_recovery():
    fs = Failsafes(PARAMS)
    assert step(fs, 0.0, vehicle_age_s=0.35).action is Action.NONE  # vehicle_timeout_s 0.4
    d = step(fs, 0.2, vehicle_age_s=0.45)
    assert d.action is Action.NEUTRAL and d.reasons == ("vehicle link",)
    assert texts(d) == ["FS vehicle link: motors neutral"] and d.events[0].severity is Severity.CRITICAL
    assert step(fs, 5.0, vehicle_age_s=0.01).action is Action.NEUTRAL  # back, recovery starts
    assert step(fs, 6.9, vehicle_age_s=0.01).action is Action.NEUTRAL
    d = step(fs, 7.0, vehicle_age_s=0.01)
    assert d.action is Action.NONE and texts(d) == ["FS vehicle link cleared"]


def test_hysteresis_a_flapping_link_does_not_chatter():
    fs = Failsafes(PARAMS)
    decisions = []
    for k in range(200):  # a message every 1.5 s: the age saws 0 .. 1.5 s
        t = k * 0.05
        decisions.append(step(fs, t, vehicle_age_s=t % 1.5))
    triggered = [d for d in decisions if "FS vehicle link: motors neutral" in texts(d)]
    assert len(triggered) == 1 and not any("cleared" in x for d in decisions for x in texts(d))
    assert all(d.action is Action.NEUTRAL for d in decisions[decisions.index(triggered[0]) :])


@pytest.mark.parametrize("gcs_action, expected", [("continue", Action.NONE), ("hold", Action.HOLD), ("rtl", Action.RTL)])
def test_gcs_lost_action_is_configurable(gcs_action, expected):
    fs = Failsafes(dataclasses.replace(PARAMS, gcs_action=gcs_action, gcs_timeout_s=5.0))
    assert step(fs, 0.0, gcs_age_s=4.9).action is Action.NONE
    d = step(fs, 0.1, gcs_age_s=5.1)
    assert d.action is expected and "GCS lost" in d.reasons and texts(d) == [f"FS GCS lost: {gcs_action}"]
    assert step(fs, 1.0, gcs_age_s=0.1).action is expected
    assert step(fs, 3.0, gcs_age_s=0.1).action is Action.NONE


def test_no_gcs_failsafe_before_a_gcs_was_ever_seen():
    fs = Failsafes(dataclasses.replace(PARAMS, gcs_action="hold"))
    assert step(fs, 100.0, gcs_age_s=math.inf).action is Action.NONE


def test_silent_rangefinder_not_required_blocks_its_side_at_the_degraded_speed():
    fs = Failsafes(dataclasses.replace(PARAMS, required_rangefinders=[0], degraded_speed_mps=0.4))
    fs.used_rangefinders = frozenset({0, 2, 4, 6})  # the autopilot sets the rangefinder plan's
    d = step(fs, 0.0, range_ages_s={0: 0.02, 2: 0.7, 4: 0.02, 6: 0.02})
    assert d.blocked_orientations == {2} and d.action is Action.NONE and d.speed_limit_mps == 0.4
    assert texts(d) == ["FS rangefinder 2: silent, side blocked"]
    # A used rangefinder never heard from is blocked too; one not used is not watched.
    d = step(fs, 0.1, range_ages_s={0: 0.02, 1: 0.9, 2: 0.02})
    assert d.blocked_orientations == {2, 4, 6}
    assert step(fs, 2.1, range_ages_s=FRESH_RANGES | {1: 0.9}).blocked_orientations == {4, 6}
    d = step(fs, 4.2, range_ages_s=FRESH_RANGES)
    assert d.blocked_orientations == set() and d.speed_limit_mps is None


def test_slow_rangefinders_limit_the_speed_to_a_bounded_travel_per_reading():
    fs = Failsafes(PARAMS)
    fs.used_rangefinders = frozenset({0, 2})
    limits = []
    for k in range(60):  # front at 20 Hz, right at 5 Hz (0.2 s apart: not silent)
        t = k * 0.05
        d = step(fs, t, range_ages_s={0: 0.0, 2: t % 0.2}, range_times_s={0: t, 2: t - t % 0.2})
        limits.append(d.speed_limit_mps)
    assert limits[-1] == pytest.approx(PARAMS.range_travel_m / 0.2, rel=0.02)
    fs.used_rangefinders = frozenset({0})  # the slow one no longer read: only the 20 Hz one counts
    assert step(fs, 3.0, range_ages_s={0: 0.0, 2: 0.1}, range_times_s={0: 3.0, 2: 2.9}).speed_limit_mps == pytest.approx(PARAMS.range_travel_m / 0.05, rel=0.02)


def test_odometry_slower_than_the_minimum_holds_and_says_which():
    fs = Failsafes(PARAMS)
    assert step(fs, 0.0, driving=False, sensor_rates_hz={"WHEEL_DISTANCE": 0.0}).action is Action.NONE  # arming's business
    d = step(fs, 0.0, driving=True, sensor_rates_hz={"ATTITUDE": 25.0, "WHEEL_DISTANCE": 2.5})
    assert d.action is Action.HOLD and texts(d) == ["FS sensor rate: WHEEL_DISTANCE 2.5 Hz, hold"]
    assert step(fs, 0.1, driving=True, sensor_rates_hz={"ATTITUDE": 25.0, "WHEEL_DISTANCE": 10.0}).action is Action.HOLD  # recovery_s
    d = step(fs, 0.1 + PARAMS.recovery_s, driving=True, sensor_rates_hz={"ATTITUDE": 25.0, "WHEEL_DISTANCE": 10.0})
    assert d.action is Action.NONE and texts(d) == ["FS sensor rate cleared"]
    assert step(fs, 10.0, driving=True, sensor_rates_hz={}).action is Action.NONE  # a rover without encoders: nothing measured


def test_silent_required_rangefinder_holds_and_says_which():
    fs = Failsafes(PARAMS)  # required_rangefinders [-1]: every one the navigator reads
    fs.used_rangefinders = frozenset({0, 2, 4, 6})
    d = step(fs, 0.0, range_ages_s={0: 0.02, 2: 0.7, 4: 0.02, 6: 0.02})
    assert d.action is Action.HOLD and d.reasons == ("rangefinder 2",) and d.blocked_orientations == {2}
    assert texts(d) == ["FS rangefinder 2: silent, hold"]
    assert step(fs, 0.5, range_ages_s=FRESH_RANGES).action is Action.HOLD  # until recovery_s of readings
    d = step(fs, 2.6, range_ages_s=FRESH_RANGES)
    assert d.action is Action.NONE and texts(d) == ["FS rangefinder 2 cleared"]
    # Listed but not used (the rover lacks it): never heard, so the rover holds.
    fs = Failsafes(dataclasses.replace(PARAMS, required_rangefinders=[0, 4]))
    fs.used_rangefinders = frozenset({0})
    assert step(fs, 0.0, range_ages_s={0: 0.02}).action is Action.HOLD


def test_no_rangefinder_is_required_until_the_plan_says_so():
    fs = Failsafes(PARAMS)
    assert step(fs, 0.0, range_ages_s={}).blocked_orientations == set()
    assert step(fs, 1.0, range_ages_s={0: 5.0}).blocked_orientations == set()


def test_gps_lost_dead_reckons_for_a_bounded_time_then_holds():
    fs = Failsafes(dataclasses.replace(PARAMS, gps_timeout_s=1.0, dead_reckoning_max_s=10.0))
    d = step(fs, 0.0, gps_age_s=1.5)
    assert d.dead_reckoning and d.action is Action.NONE and texts(d) == ["FS GPS lost: dead reckoning"]
    assert step(fs, 9.0, gps_age_s=10.5).action is Action.NONE
    d = step(fs, 9.6, gps_age_s=11.1)
    assert d.action is Action.HOLD and d.dead_reckoning and texts(d) == ["FS GPS lost too long: hold"]
    step(fs, 12.0, gps_age_s=0.1)
    d = step(fs, 14.0, gps_age_s=0.1)
    assert d.action is Action.NONE and not d.dead_reckoning
    assert sorted(texts(d)) == ["FS GPS lost cleared", "FS GPS lost too long cleared"]


def test_estimator_unhealthy_holds_after_its_delay():
    fs = Failsafes(dataclasses.replace(PARAMS, estimator_unhealthy_s=0.5))
    assert step(fs, 0.0, estimator_healthy=False).action is Action.NONE
    assert step(fs, 0.4, estimator_healthy=False).action is Action.NONE
    assert step(fs, 0.45, estimator_healthy=True).action is Action.NONE  # a blip does not trigger
    step(fs, 1.0, estimator_healthy=False)
    assert step(fs, 1.5, estimator_healthy=False).action is Action.HOLD
    assert step(fs, 3.0, estimator_healthy=True).action is Action.HOLD
    assert step(fs, 5.0, estimator_healthy=True).action is Action.NONE


@pytest.mark.parametrize("fence_action, expected", [("hold", Action.HOLD), ("rtl", Action.RTL)])
def test_fence_breach_holds_or_returns(fence_action, expected):
    fs = Failsafes(dataclasses.replace(PARAMS, fence_action=fence_action))
    d = step(fs, 0.0, inside_fence=False)
    assert d.action is expected and d.reasons == ("fence breach",)
    step(fs, 1.0, inside_fence=True)
    assert step(fs, 3.0, inside_fence=True).action is Action.NONE


def test_precedence_neutral_over_hold_over_rtl():
    fs = Failsafes(dataclasses.replace(PARAMS, fence_action="rtl"))
    assert step(fs, 0.0, inside_fence=False).action is Action.RTL
    assert step(fs, 0.1, inside_fence=False, gps_age_s=30.0).action is Action.HOLD
    d = step(fs, 0.2, inside_fence=False, gps_age_s=30.0, vehicle_age_s=2.0)
    assert d.action is Action.NEUTRAL and set(d.reasons) >= {"fence breach", "GPS lost too long", "vehicle link"}


def test_bad_action_names_are_refused():
    with pytest.raises(ValueError, match="failsafe.gcs_action: 'land'"):
        Failsafes(dataclasses.replace(PARAMS, gcs_action="land"))
    with pytest.raises(ValueError, match="failsafe.fence_action"):
        Failsafes(dataclasses.replace(PARAMS, fence_action="continue"))


STUCK = dataclasses.replace(PARAMS, stuck_window_s=4.0, stuck_progress_m=0.3, back_off_s=2.0, stuck_max_tries=2, stuck_clear_m=3.0)


def run_stuck(fs, t0, t1, position, speed=0.5, driving=True, dt=0.1):
    out, t = [], t0
    while t < t1 - 1e-9:
        out.append((t, step(fs, t, commanded_speed_mps=speed, position_en=position, driving=driving)))
        t = round(t + dt, 9)
    return out


def test_stuck_backs_off_then_replans_then_holds_after_max_tries():
    fs = Failsafes(STUCK)
    trace = run_stuck(fs, 0.0, 3.9, (0.0, 0.0))
    assert all(d.action is Action.NONE for _, d in trace)
    t, d = run_stuck(fs, 3.9, 4.1, (0.1, 0.0))[-1]  # 4 s commanded, moved 0.1 m < 0.3 m
    assert d.action is Action.BACK_OFF and texts(d) == ["FS stuck: backing off (1/2)"]
    backing = run_stuck(fs, 4.1, 6.0, (0.0, 0.0), speed=-0.3)
    assert all(d.action is Action.BACK_OFF and not d.replan for _, d in backing)
    _, d = run_stuck(fs, 6.0, 6.1, (-0.5, 0.0))[0]
    assert d.replan and d.action is Action.NONE  # back-off over: re-plan once
    assert d.stuck_tries == 1
    trace = run_stuck(fs, 6.1, 10.2, (-0.5, 0.0))
    assert [d.action for _, d in trace].count(Action.BACK_OFF) == 1  # second try
    run_stuck(fs, 10.2, 12.2, (-0.7, 0.0), speed=-0.3)
    trace = run_stuck(fs, 12.2, 16.4, (-0.7, 0.0))
    gave_up = [d for _, d in trace if d.action is Action.HOLD]
    assert gave_up and texts(gave_up[0]) == ["FS stuck: gave up, hold"]
    assert step(fs, 30.0, commanded_speed_mps=0.0, position_en=(-0.7, 0.0)).action is Action.HOLD  # stays
    # Leaving AUTO/RTL (the GCS takes over) clears it.
    d = step(fs, 31.0, driving=False, position_en=(-0.7, 0.0))
    assert d.action is Action.NONE and texts(d) == ["FS stuck cleared"]


def test_progress_and_no_command_are_not_stuck():
    fs = Failsafes(STUCK)
    for k in range(200):  # slow but steady: 0.1 m/s
        assert step(fs, k * 0.1, commanded_speed_mps=0.5, position_en=(k * 0.01, 0.0)).action is Action.NONE
    for k in range(200):  # standing still with no command (holding at a waypoint)
        assert step(fs, 20 + k * 0.1, commanded_speed_mps=0.0, position_en=(2.0, 0.0)).action is Action.NONE


def test_a_rule_base_parked_where_it_should_move_is_stuck_after_the_parked_window():
    """Given a speed to make, the rule base may settle on near-zero wheel speeds facing obstacles
    on both sides (the runner's ``dense_clutter`` seed 63 stood 40 s so); that is stuck too, after
    ``parked_window_s``; asked for nothing (a yield, a hold), it is not."""
    fs = Failsafes(STUCK)
    window = STUCK.parked_window_s
    for k in range(int(window * 10) - 1):
        d = step(fs, k * 0.1, commanded_speed_mps=0.02, wants_progress=True, position_en=(0.0, 0.0))
        assert d.action is Action.NONE
    d = step(fs, window + 0.1, commanded_speed_mps=0.02, wants_progress=True, position_en=(0.05, 0.0))
    assert d.action is Action.BACK_OFF and texts(d) == ["FS stuck: backing off (1/2)"]
    fs = Failsafes(STUCK)
    for k in range(int(window * 30)):  # held back by a yield: waiting, not stuck
        assert step(fs, k * 0.1, commanded_speed_mps=0.0, wants_progress=False, position_en=(0.0, 0.0)).action is Action.NONE
    fs = Failsafes(dataclasses.replace(STUCK, parked_window_s=0.0))  # off
    for k in range(int(window * 30)):
        assert step(fs, k * 0.1, commanded_speed_mps=0.0, wants_progress=True, position_en=(0.0, 0.0)).action is Action.NONE


def test_stuck_tries_start_over_after_getting_free():
    fs = Failsafes(STUCK)
    run_stuck(fs, 0.0, 4.1, (0.0, 0.0))
    run_stuck(fs, 4.1, 6.1, (-0.3, 0.0), speed=-0.3)
    for k in range(50):  # drives 5 m away: free again
        step(fs, 6.1 + k * 0.1, commanded_speed_mps=0.5, position_en=(-0.3 + k * 0.1, 0.0))
    trace = run_stuck(fs, 11.1, 15.3, (4.7, 0.0))
    assert any(texts(d) == ["FS stuck: backing off (1/2)"] for _, d in trace)


def test_nothing_to_lose_before_the_first_fix_and_the_first_estimate():
    """A vehicle still booting (no GPS fix yet, no estimate) is not a GPS or estimator failsafe:
    the arming checks wait for a position instead."""
    fs = Failsafes(PARAMS)
    for k in range(40):
        d = step(fs, k * 0.5, gps_age_s=math.inf, estimator_healthy=False, position_en=None, driving=False)
        assert d.action is Action.NONE and not d.reasons
    d = step(fs, 20.0, gps_age_s=1.5)  # once there was a fix, losing it counts
    assert "GPS lost" in d.reasons
