"""The yielder: the speed along the path that lets crossing obstacles pass (pure, no sockets)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rover_ctl.config import YieldParams
from rover_ctl.navigation.tracks import Track
from rover_ctl.navigation.yielding import YieldDecision, Yielder, closest_approach_m, keep_line

NORTH = math.pi / 2
ROBOT_RADIUS_M = 0.3


def yielder(**changes) -> Yielder:
    params = YieldParams(enabled=True)
    for key, value in changes.items():
        setattr(params, key, value)
    return Yielder(params, lambda: ROBOT_RADIUS_M)


def drive(y: Yielder, track_at, cruise_mps: float = 1.2, duration_s: float = 15.0, dt_s: float = 0.05):
    """The rover drives north from the origin at the speed the yielder lets it; ``track_at(t)``
    gives the track seen at t (or None). Returns (closest true distance, limits seen, north reached)."""
    north, closest, limits = 0.0, math.inf, []
    for k in range(int(duration_s / dt_s)):
        t = k * dt_s
        track = track_at(t)
        decision = y.limit(0.0, north, NORTH, cruise_mps, [track] if track else [], t)
        limits.append(decision.speed_limit_mps)
        north += (cruise_mps if decision.speed_limit_mps is None else decision.speed_limit_mps) * dt_s
        truth = crossing(t)
        closest = min(closest, math.hypot(truth.east_m, truth.north_m - north))
    return closest, limits, north


def crossing(t: float) -> Track:
    """A pedestrian from the west crossing the rover's line 5 m ahead at 0.8 m/s, timed to meet it."""
    return Track(1, t, -3.4 + 0.8 * t, 5.0, 0.8, 0.0, hits=20, born_en=(-9.0, 0.0))


def test_closest_approach():
    assert closest_approach_m(0.0, 5.0, 0.0, -1.0, 10.0) == 0.0  # head-on
    assert math.isclose(closest_approach_m(2.0, 5.0, 0.0, -1.0, 10.0), 2.0)  # passes 2 m to the side
    assert math.isclose(closest_approach_m(0.0, 5.0, 0.0, -1.0, 2.0), 3.0)  # not within the horizon
    assert math.isclose(closest_approach_m(0.0, 5.0, 0.0, 1.0, 10.0), 5.0)  # moving away: now is closest


def test_a_pedestrian_crossing_ahead_is_waited_for_and_the_rover_goes_on_behind_it():
    without_yield = drive(yielder(enabled=False), crossing)
    closest, limits, north = drive(yielder(), crossing)
    assert without_yield[0] < 0.5  # at cruise speed the two meet
    assert closest >= ROBOT_RADIUS_M + 0.4  # yielding keeps the margin (less a little for the slowing)
    assert min(limit for limit in limits if limit is not None) < 1.2  # it slowed down...
    assert limits[-1] is None and north > 10.0  # ...and drove on once the pedestrian had passed


def test_a_pedestrian_stepping_out_close_ahead_stops_the_rover():
    """The later a crossing pedestrian is seen, the slower the rover must go: 2.5 m ahead it may
    go on at half speed, 1.2 m ahead only a stop lets it pass."""
    speeds = [yielder().limit(0.0, 0.0, NORTH, 1.2, [Track(1, 0.0, -1.2, ahead, 0.8, 0.0, hits=20, born_en=(-9.0, 0.0))], 0.0).speed_limit_mps
              for ahead in (2.5, 1.5, 1.2)]  # fmt: skip
    assert speeds == sorted(speeds, reverse=True) and speeds[0] >= 0.6 and speeds[-1] == 0.0


def test_a_lost_track_is_waited_for_as_last_seen():
    """The track vanishes as the pedestrian reaches the line: the rover still waits for it."""
    closest, limits, _ = drive(yielder(), lambda t: crossing(t) if t < 3.0 else None)
    assert closest >= ROBOT_RADIUS_M + 0.4
    assert limits[int(4.0 / 0.05)] is not None  # still yielding a second after the loss


def test_the_wait_for_a_lost_track_is_bounded():
    _, limits, _ = drive(yielder(max_wait_s=0.5), lambda t: crossing(t) if t < 3.0 else None)
    assert limits[int(3.6 / 0.05)] is None


def test_head_on_and_walking_ahead_are_not_yielded_to():
    """An obstacle on the rover's line (head-on, or ahead and slower) is steered around, not
    waited for: waiting for it never ends, or it walks into a stopped rover."""
    y = yielder()
    head_on = Track(1, 0.0, 0.1, 6.0, 0.1, -0.8, hits=20, born_en=(-9.0, 0.0))  # its velocity wobbles 7 degrees off the line
    ahead = Track(2, 0.0, -0.1, 3.0, -0.05, 0.4, hits=20, born_en=(-9.0, 0.0))
    assert y.limit(0.0, 0.0, NORTH, 1.2, [head_on], 0.0).speed_limit_mps is None
    assert y.limit(0.0, 0.0, NORTH, 1.2, [ahead], 0.0).speed_limit_mps is None


def test_when_no_speed_is_free_the_one_that_keeps_the_obstacle_farthest():
    """Crossing 1 m ahead, 1.5 m off the line: every speed comes within the margin (full speed
    0.69 m, a stop 1.0 m), so the rover stops rather than drive on into its path."""
    at_the_rover = Track(1, 0.0, -1.5, 1.0, 0.8, 0.0, hits=20, born_en=(-9.0, 1.0))
    assert yielder().limit(0.0, 0.0, NORTH, 1.2, [at_the_rover], 0.0).speed_limit_mps == 0.0


def test_a_crosser_level_with_the_rover_whose_echo_slides_forward_is_not_stopped_for():
    """Seed 33 of the runner's ``crossing``: a walker 2.5 m to the right, level with the rover,
    crossing at right angles, whose side-beam echo slides forward over its face with the rover
    (its track: 1.7 m/s across, 1.05 m/s along). Taken as estimated it would pass ahead of a
    stopped rover (1.29 m); going straight across, it walks into one standing in its lane."""
    level = Track(1, 0.0, 2.49, -0.02, -1.70, 1.05, hits=20, born_en=(4.0, -0.5))
    assert yielder().limit(0.0, 0.0, NORTH, 1.2, [level], 0.0).speed_limit_mps != 0.0


def test_a_rover_never_stops_in_the_lane_of_a_crosser_whose_echo_slides_forward():
    """Perpendicular crossers from the right at 1 m/s, whose tracks carry 70 % of the rover's
    speed forward (the sliding echo), at any timing: the rover never stands with the crosser's
    lane within its radius while the crosser is still to come, and keeps its distance."""
    for start_east in [2.0 + 0.25 * i for i in range(13)]:
        for lane in [1.0 + 0.25 * j for j in range(13)]:
            y, north, speed, closest = yielder(), 0.0, 1.2, math.inf
            for k in range(300):
                t = k * 0.05
                east = start_east - t
                track = Track(1, t, east, lane, -1.0, 0.7 * speed, hits=20, born_en=(start_east + 3.0, lane))
                limit = y.limit(0.0, north, NORTH, 1.2, [track], t).speed_limit_mps
                speed = 1.2 if limit is None else limit
                assert not (speed == 0.0 and east > 0.0 and abs(lane - north) < ROBOT_RADIUS_M), (start_east, lane, t)
                north += speed * 0.05
                closest = min(closest, math.hypot(east, lane - north))
            assert closest > ROBOT_RADIUS_M + 0.2, (start_east, lane)


def test_when_no_speed_is_free_the_release_margin_does_not_rank_them():
    """A crosser yielded to, level with the rover 1.5 m to its right: no speed is free, and full
    speed keeps it farthest (1.15 m, 75 % 1.0 m). The release margin holds a yield until full speed
    clears the crosser by that much more; it does not count against full speed among speeds that
    are all in conflict (it did, and held the rover at 75 %, nearer the crosser)."""
    level = Track(1, 0.0, 1.5, 0.0, -1.0, 0.0, hits=20, born_en=(4.5, 0.0))
    y = yielder()
    assert y.limit(0.0, -1.0, NORTH, 1.2, [level], 0.0).speed_limit_mps == 0.0  # 1 m further back it stops for it
    assert y.limit(0.0, 0.0, NORTH, 1.2, [level], 0.0).speed_limit_mps is None


def test_unsure_tracks_are_not_yielded_to():
    """Few echoes, or a velocity still uncertain: no yield (a sliding echo makes such tracks)."""
    young = Track(1, 0.0, -1.2, 1.5, 0.8, 0.0, hits=3)
    unsure = Track(1, 0.0, -1.2, 1.5, 0.8, 0.0, hits=20, born_en=(-9.0, 0.0), b=(0.5**2, 0.0, 0.5**2))
    assert yielder().limit(0.0, 0.0, NORTH, 1.2, [young], 0.0).speed_limit_mps is None
    assert yielder().limit(0.0, 0.0, NORTH, 1.2, [unsure], 0.0).speed_limit_mps is None
    wandering = Track(1, 0.0, -1.2, 1.5, 0.8, 0.0, hits=20, born_en=(-1.5, 1.4))  # 0.3 m from its first echo
    assert yielder().limit(0.0, 0.0, NORTH, 1.2, [wandering], 0.0).speed_limit_mps is None


def test_no_new_yield_while_the_rover_points_off_its_course():
    """Mid-turn around something (heading 50 degrees off the course, beyond the default 45): its
    tracks' velocities are swept echoes, so no yield starts; at 40 degrees one does (a crosser the
    rule base turned from); once one has started it holds through a turn."""
    track = Track(1, 0.0, -1.2, 1.5, 0.8, 0.0, hits=20, born_en=(-9.0, 1.5))
    y = yielder()
    assert y.limit(0.0, 0.0, NORTH, 1.2, [track], 0.0, heading_rad=NORTH - math.radians(50.0)).speed_limit_mps is None
    assert yielder().limit(0.0, 0.0, NORTH, 1.2, [track], 0.0, heading_rad=NORTH - math.radians(40.0)).speed_limit_mps is not None
    assert y.limit(0.0, 0.0, NORTH, 1.2, [track], 0.0, heading_rad=NORTH - math.radians(10.0)).speed_limit_mps is not None
    assert y.limit(0.0, 0.0, NORTH, 1.2, [track], 0.05, heading_rad=NORTH - math.radians(50.0)).speed_limit_mps is not None


def test_disabled_or_standing_still_no_limit():
    track = crossing(3.0)
    assert yielder(enabled=False).limit(0.0, 0.0, NORTH, 1.2, [track], 3.0).speed_limit_mps is None
    assert yielder().limit(0.0, 0.0, NORTH, 0.0, [track], 3.0).speed_limit_mps is None


@settings(max_examples=300, deadline=None)
@given(start_east=st.floats(-6.0, -1.5), north_m=st.floats(2.0, 8.0), speed=st.floats(0.3, 1.0),
       side=st.sampled_from((-1.0, 1.0)))
def test_perpendicular_crossing_traffic_never_comes_within_the_robot_radius(start_east, north_m, speed, side):
    """Whatever the timing, a rover that obeys the limit is never touched by a perpendicular
    crosser whose track it sees from the start (truth = track)."""
    def track_at(t: float) -> Track:
        return Track(1, t, side * (start_east + speed * t), north_m, side * speed, 0.0, hits=20, born_en=(-9.0, 0.0))

    y = yielder()
    north, closest = 0.0, math.inf
    for k in range(300):
        t = k * 0.05
        track = track_at(t)
        decision = y.limit(0.0, north, NORTH, 1.2, [track], t)
        north += (1.2 if decision.speed_limit_mps is None else decision.speed_limit_mps) * 0.05
        closest = min(closest, math.hypot(track.east_m, track.north_m - north))
    assert closest > ROBOT_RADIUS_M


def test_just_after_stepping_aside_the_heading_limit_is_the_evaders():
    """Turning back to its line after stepping aside from a walker, 40 degrees off the course: a
    second walker's swept track must not start a yield (it is the evader's); once
    ``after_evasion_s`` has passed, the wider limit applies again."""
    track = Track(1, 0.0, -1.2, 1.5, 0.8, 0.0, hits=20, born_en=(-9.0, 1.5))
    off = NORTH - math.radians(40.0)
    y = yielder()
    y.evaded(0.0)
    assert y.limit(0.0, 0.0, NORTH, 1.2, [track], 0.0, heading_rad=off).speed_limit_mps is None
    late = Track(1, 3.5, -1.2, 1.5, 0.8, 0.0, hits=20, born_en=(-9.0, 1.5))
    assert y.limit(0.0, 0.0, NORTH, 1.2, [late], 3.5, heading_rad=off).speed_limit_mps is not None


def test_the_walker_stepped_aside_from_is_yielded_to_at_once_when_it_turns_out_to_cross():
    """The evader stepped aside from track 1 (its first estimate came at the rover); its live
    track now crosses. The narrower limit after an evasion is for a second walker: this one is
    yielded to within ``max_heading_off_deg`` at once, another track is not (SITL crossing 80)."""
    off = NORTH - math.radians(40.0)
    crosser = Track(1, 0.1, -1.2, 1.5, 0.8, 0.0, hits=20, born_en=(-9.0, 1.5))
    other = Track(2, 0.1, -1.2, 1.5, 0.8, 0.0, hits=20, born_en=(-9.0, 1.5))
    assert yielder_after(1, crosser, off) is not None
    assert yielder_after(1, other, off) is None  # a second walker: the evader's narrower limit
    assert yielder_after(2, other, off) is not None


def yielder_after(evaded_ident: int, track: Track, heading_rad: float) -> float | None:
    """The speed limit for ``track`` just after stepping aside from track ``evaded_ident``."""
    y = yielder()
    y.evaded(0.0, track_ident=evaded_ident)
    return y.limit(0.0, 0.0, NORTH, 1.2, [track], 0.1, heading_rad=heading_rad).speed_limit_mps


def test_a_rover_pointing_off_its_course_drives_on_out_of_a_walkers_lane_rather_than_stopping_in_it():
    """The rover points north, its target 40 degrees to the left (it is turning back to its
    course); a walker 1.5 m to the left walks east, across the spot the rover stands on. Going on
    along the course would walk the rover into it, but the rover goes where it points: the speeds
    are tried along the heading, and full speed takes it out of the lane."""
    course_rad = NORTH + math.radians(40.0)

    def closest_and_slowest(heading_rad: float | None, dt_s: float = 0.05) -> tuple[float, float]:
        y, north, closest, slowest = yielder(), 0.0, math.inf, math.inf
        for k in range(int(6.0 / dt_s)):
            t = k * dt_s
            walker = Track(2, t, -1.5 + 0.5 * t, 0.0, 0.5, 0.0, hits=50, born_en=(-2.5, 0.0))
            limit = y.limit(0.0, north, course_rad, 1.2, [walker], t, heading_rad=heading_rad).speed_limit_mps
            speed = 1.2 if limit is None else limit
            north, slowest = north + speed * dt_s, min(slowest, speed)
            closest = min(closest, math.hypot(walker.east_m, walker.north_m - north))
        return closest, slowest

    assert closest_and_slowest(NORTH) == (pytest.approx(1.41, abs=0.01), 1.2)  # never slowed, kept 1.4 m
    stopped_closest, stopped_slowest = closest_and_slowest(None)  # the course alone: it stops in the lane
    assert stopped_slowest == 0.0 and stopped_closest < ROBOT_RADIUS_M + 0.2


def test_a_walker_sliding_down_a_diagonal_beam_is_waited_for_not_raced():
    """The runner's ``crossing`` seed 118: a walker 0.74 m ahead and 0.8 m to the right walks
    across to the left; its echo slides down the front-right beam, so its track also comes back at
    the rover at 0.29 m/s. Taken as estimated, even a stopped rover is walked into and racing ahead
    of it ranked best; going straight across, it passes ahead of a stopped rover, which stops."""
    walker = Track(1, 0.0, 0.80, 0.74, -0.49, -0.29, hits=72, born_en=(2.5, 0.5))
    decision = yielder().limit(0.0, 0.0, NORTH, 1.2, [walker], 0.0, heading_rad=NORTH)
    assert decision.speed_limit_mps == 0.0 and decision.track_ident == 1
    assert decision.across_mps == pytest.approx(0.49)  # it walks to the rover's left


def test_while_yielding_the_rover_does_not_turn_the_way_the_crosser_walks():
    walks_left = YieldDecision(0.3, 1, across_mps=0.5)
    assert keep_line(20.0, 40.0, walks_left) == (20.0, 20.0)  # a left turn, after it: taken out
    assert keep_line(40.0, 20.0, walks_left) == (40.0, 20.0)  # a right turn, behind it: kept
    assert keep_line(40.0, 20.0, YieldDecision(0.3, 1, across_mps=-0.5)) == (20.0, 20.0)
    assert keep_line(20.0, 40.0, YieldDecision(None)) == (20.0, 40.0)  # not yielding: untouched


def test_a_turn_taken_out_never_drives_on_faster_than_its_inside_wheel():
    """A hard turn away from something close (here a static drum a false track stands on) must not
    become a straight drive at half speed into it (runner dense_clutter seed 56)."""
    walks_right = YieldDecision(0.9, 22, across_mps=-0.25)
    assert keep_line(100.0, 0.0, walks_right) == (0.0, 0.0)
    assert keep_line(60.0, -10.0, walks_right) == (0.0, 0.0)  # a spin: no wheel goes backwards
