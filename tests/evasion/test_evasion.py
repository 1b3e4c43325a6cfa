"""The evader: stepping aside for a walker coming head-on (pure, no sockets).

The rover is a unicycle that follows the evader's drive while it gives one, and otherwise drives
straight at its target at cruise speed (a navigator that does not avoid anything), so that every
miss below is the evader's doing."""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from rover_ctl.config import EvadeParams
from rover_ctl.navigation.evasion import FRONT, FRONT_LEFT, FRONT_RIGHT, Evader
from rover_ctl.navigation.tracks import Track

NORTH = math.pi / 2
HALF_WIDTH_M = 0.2
CRUISE_MPS = 1.2
TARGET = (0.0, 30.0)
SENSOR_RANGE_M = 4.0


def evader(**changes) -> Evader:
    params = EvadeParams()
    for key, value in changes.items():
        setattr(params, key, value)
    return Evader(params, lambda: HALF_WIDTH_M)


def walker(east_m: float, north_m: float, v_east: float, v_north: float):
    """A walker's true centre at t, and the track of it the rover would have (its estimate)."""

    def at(t: float) -> tuple[float, float]:
        return east_m + v_east * t, north_m + v_north * t

    def track(t: float, ident: int = 1) -> Track:
        e, n = at(t)
        return Track(ident, t, e, n, v_east, v_north, hits=20, born_en=(east_m, north_m))

    return at, track


def drive(ev: Evader, at, track, ranges=None, duration_s: float = 8.0, dt_s: float = 0.04, may_start=lambda t: True,
          start=(0.0, 0.0, NORTH), target=TARGET):  # fmt: skip
    """Closest distance between the rover's and the walker's centres, the sides stepped to
    (+1 left, -1 right, per step while evading) and where the rover ended."""
    (x, y, psi), v = start, CRUISE_MPS
    closest, sides = math.inf, []
    for k in range(int(duration_s / dt_s)):
        t = k * dt_s
        we, wn = at(t)
        seen = math.hypot(we - x, wn - y) <= SENSOR_RANGE_M
        course = math.atan2(target[1] - y, target[0] - x)
        out = ev.step(t, x, y, psi, v, course, CRUISE_MPS, [track(t)] if seen else [], ranges, may_start=may_start(t))
        if out is None:
            speed, omega = CRUISE_MPS, max(-1.5, min(1.5, 3.0 * math.remainder(course - psi, math.tau)))
        else:
            speed, omega = out.speed_mps, out.yaw_rate_radps
            sides.append(1 if omega > 0 else -1 if omega < 0 else 0)
        psi += omega * dt_s
        v += max(-1.0 * dt_s, min(1.0 * dt_s, speed - v))
        x += v * math.cos(psi) * dt_s
        y += v * math.sin(psi) * dt_s
        closest = min(closest, math.hypot(we - x, wn - y))
    return closest, sides, (x, y)


def test_without_evasion_a_walker_coming_down_the_line_walks_into_the_rover():
    at, track = walker(0.0, 6.0, 0.0, -0.9)
    closest, sides, _ = drive(evader(enabled=False), at, track)
    assert closest < 0.1 and not sides


@settings(max_examples=200, deadline=None)
@given(offset_m=st.floats(-0.5, 0.5), speed_mps=st.floats(0.3, 1.0), start_m=st.floats(5.0, 12.0))
def test_a_walker_coming_head_on_is_passed_clear_of_the_rover_whatever_its_offset_and_speed(offset_m, speed_mps, start_m):
    at, track = walker(offset_m, start_m, 0.0, -speed_mps)
    closest, sides, end = drive(evader(), at, track, duration_s=start_m / (speed_mps + CRUISE_MPS) + 4.0)
    # Contact would be the half-width plus a walker's radius of up to 0.5 m.
    assert closest >= HALF_WIDTH_M + 0.5, (closest, sides)
    assert sides  # it did step aside...
    assert end[1] > 5.0 and abs(end[0]) < 2.0  # ...and went on towards its target


def test_it_steps_to_the_side_the_walker_is_not_on_and_right_when_dead_ahead():
    for offset_m, expected in ((0.3, 1), (-0.3, -1), (0.0, -1)):
        at, track = walker(offset_m, 6.0, 0.0, -0.9)
        _, sides, _ = drive(evader(), at, track)
        assert sides[0] == expected, offset_m  # the first turn of the manoeuvre


def test_a_rover_coming_back_to_its_line_at_an_angle_keeps_to_its_own_side_of_a_walker_on_the_line():
    """Heading back across the line from 1.5 m left of it, the walker on the line is left of the
    rover's course: stepping right ("away" from it) would cross the walker's way; turning left, to
    pass on the side the rover is already on, is the smaller manoeuvre."""
    at, track = walker(0.0, 7.0, 0.0, -0.7)
    course = math.atan2(9.0, 3.0)  # towards a target right of the walker's line
    closest, sides, _ = drive(evader(), at, track, start=(-1.5, 0.0, course), target=(1.5, 9.0), duration_s=6.0)
    assert sides[0] == 1 and closest >= HALF_WIDTH_M + 0.5, (sides[:3], closest)


def test_a_side_whose_diagonal_rangefinder_sees_something_near_is_not_stepped_to():
    at, track = walker(0.0, 6.0, 0.0, -0.9)  # dead ahead: right, unless the right is blocked
    closest, sides, _ = drive(evader(), at, track, ranges={FRONT_RIGHT: 0.6, FRONT_LEFT: math.inf})
    assert sides[0] == 1 and closest >= HALF_WIDTH_M + 0.5


def test_something_else_near_ahead_hands_the_rover_back_to_the_rule_base():
    """The rollouts see only the walker: with a second obstacle read 0.6 m ahead no manoeuvre
    starts, and one under way ends, so that the rover is not driven into it at full speed."""
    _, track = walker(0.0, 6.0, 0.0, -0.9)
    clear, blocked = {FRONT: math.inf}, {FRONT: 0.6}

    def step(ev: Evader, t: float, ranges):
        return ev.step(t, 0.0, 0.0, NORTH, CRUISE_MPS, NORTH, CRUISE_MPS, [track(t)], ranges)

    assert step(evader(), 1.0, blocked) is None  # the walker 5.1 m ahead, closing at 2.1 m/s
    assert step(evader(front_free_m=0.0), 1.0, blocked) is not None  # 0: off
    ev = evader()
    assert step(ev, 1.0, clear) is not None and step(ev, 1.04, blocked) is None
    assert step(ev, 1.08, clear) is not None  # the way clear again, the walker still coming: it steps aside again


def test_crossing_overtaken_and_standing_obstacles_are_not_stepped_aside_from():
    for v_east, v_north in ((0.9, 0.0), (0.0, 0.4), (0.0, 0.0)):  # a crosser (the yielder's), a walker ahead, a post
        at, track = walker(-2.0 if v_east else 0.0, 5.0, v_east, v_north)
        _, sides, _ = drive(evader(), at, track, duration_s=3.0)
        assert not sides, (v_east, v_north)


def test_no_manoeuvre_starts_while_the_rover_yields_and_one_under_way_goes_on():
    at, track = walker(0.0, 6.0, 0.0, -0.9)
    _, sides, _ = drive(evader(), at, track, may_start=lambda t: False)
    assert not sides
    _, sides, _ = drive(evader(), at, track, may_start=lambda t: t < 1.0)  # the yield begins mid-manoeuvre
    assert len(sides) > 10


def test_a_velocity_corrupted_by_the_turn_does_not_replace_the_latched_one():
    """As the rover turns, its beams slide over the walker and the track's velocity swings sideways:
    the manoeuvre goes on with the estimate it started with."""
    for jump_mps, expect_clear in ((EvadeParams().max_velocity_jump_mps, True), (10.0, False)):
        at, true_track = walker(0.0, 6.0, 0.0, -0.9)
        ev = evader(max_velocity_jump_mps=jump_mps)
        started = []

        def track(t: float) -> Track:
            live = true_track(t)
            if ev.active and not started:
                started.append(t)
            if started and t < started[0] + 2.0:  # turning right: the walker seems to go west at 1 m/s
                live.v_east_mps = -1.0
            return live

        closest, sides, _ = drive(ev, at, track)
        assert (closest >= HALF_WIDTH_M + 0.5) == expect_clear, (jump_mps, closest)


def test_a_track_that_stops_closing_on_the_rover_ends_the_manoeuvre():
    """SITL ``crossing`` world 80: a crosser's first estimate came at the rover; once the manoeuvre
    had started, its live track walked across and away, and the latched estimate kept the rover
    stepping aside into the crosser's way for 1.8 s, to a contact. With ``not_oncoming_s`` the
    manoeuvre ends once the live track has not closed for that long (the yielder's turn), and none
    starts again for that track, whatever its estimate then does (the runner's ``moving`` seed 236:
    a pacing walker's track came and went, and the rover stepped aside and back in turn); a live
    velocity only swung sideways, still closing, does not end it (the test above)."""
    for wait_s, ends in ((0.5, True), (0.0, False)):
        ev = evader(not_oncoming_s=wait_s)
        at, true_track = walker(0.0, 6.0, 0.0, -0.9)
        started_s, active_after = None, []
        for k in range(50):
            t = k * 0.04
            live = true_track(t)
            if started_s is not None:
                live.v_east_mps, live.v_north_mps = 0.8, 0.3  # across and away
            ev.step(t, 0.0, CRUISE_MPS * t, NORTH, CRUISE_MPS, NORTH, CRUISE_MPS, [live])
            started_s = t if started_s is None and ev.active else started_s
            if started_s is not None and t > started_s:
                active_after.append((round(t - started_s, 2), ev.active))
        assert started_s is not None
        assert all(active for dt, active in active_after if dt < wait_s)
        assert any(not active for dt, active in active_after) == ends, (wait_s, active_after)
        if ends:  # coming at the rover again: the same track starts nothing, another one does
            for ident, started in ((1, False), (2, True)):
                again = true_track(2.0, ident)
                again.north_m = CRUISE_MPS * 2.0 + 4.0
                again.born_en = (0.0, again.north_m + 1.0)
                assert (ev.step(2.0, 0.0, CRUISE_MPS * 2.0, NORTH, CRUISE_MPS, NORTH, CRUISE_MPS, [again]) is not None) == started


def test_the_manoeuvre_ends_once_the_walker_is_behind():
    at, track = walker(0.0, 6.0, 0.0, -0.9)
    ev = evader()
    _, sides, (x, y) = drive(ev, at, track, duration_s=8.0)
    assert sides and not ev.active
    assert y > 7.0  # driving on: the walker is long behind
