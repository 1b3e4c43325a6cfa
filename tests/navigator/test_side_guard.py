"""The side guard: a turn away from what the left and right rangefinders see close (pure)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from rover_ctl.config import SideGuardParams
from rover_ctl.navigation.sensors import FRONT, FRONT_LEFT, FRONT_RIGHT, LEFT, RIGHT
from rover_ctl.navigation.side_guard import against_guard_removed, pass_speed_mps, rear_mover_side, side_turn_radps, way_ahead_clear
from rover_ctl.navigation.tracks import Track
from rover_ctl.vocabulary import RoverMode

PARAMS = SideGuardParams()


def test_nothing_close_or_nothing_seen_turns_nothing():
    assert side_turn_radps({}, PARAMS) == 0.0
    assert side_turn_radps({LEFT: 4.0, RIGHT: math.inf}, PARAMS) == 0.0
    assert side_turn_radps({LEFT: math.nan, RIGHT: PARAMS.range_m}, PARAMS) == 0.0  # NaN: no reading
    assert side_turn_radps({0: 0.2, 1: 0.2, 7: 0.2, 4: 0.2}, PARAMS) == 0.0  # front, diagonals, back: the rule base's


def test_a_close_left_reading_turns_right_and_a_right_one_left_in_proportion():
    at_min = side_turn_radps({LEFT: 0.2}, PARAMS)
    assert at_min == pytest.approx(-PARAMS.max_yaw_rate_radps * (PARAMS.range_m - 0.2) / PARAMS.range_m)
    assert at_min == pytest.approx(-1.18, abs=0.01)  # the figure the config's docstring gives
    assert side_turn_radps({RIGHT: 0.2}, PARAMS) == pytest.approx(-at_min)
    assert side_turn_radps({LEFT: 0.3}, PARAMS) == pytest.approx(at_min / 3.0)
    assert side_turn_radps({LEFT: 0.0}, PARAMS) == pytest.approx(-PARAMS.max_yaw_rate_radps)
    assert side_turn_radps({LEFT: -1.0}, PARAMS) == pytest.approx(-PARAMS.max_yaw_rate_radps)  # bounded


def test_off_it_turns_nothing():
    assert side_turn_radps({LEFT: 0.2}, SideGuardParams(enabled=False)) == 0.0
    assert side_turn_radps({LEFT: 0.2}, SideGuardParams(range_m=0.0)) == 0.0


@given(st.floats(0.0, 5.0), st.floats(0.0, 5.0))
def test_mirror_images_turn_opposite_ways_within_the_limit(left_m, right_m):
    turn = side_turn_radps({LEFT: left_m, RIGHT: right_m}, PARAMS)
    assert side_turn_radps({LEFT: right_m, RIGHT: left_m}, PARAMS) == pytest.approx(-turn)
    assert abs(turn) <= PARAMS.max_yaw_rate_radps
    assert (turn < 0) == (left_m < right_m and left_m < PARAMS.range_m) or turn == 0.0


def test_a_rover_driven_along_a_wall_too_close_is_bent_away_until_clear():
    """A unicycle at 1 m/s northwards, its left side 0.22 m from a wall along x = -0.42 (its
    half-width 0.2 m), steered only by the guard: it turns away and goes on once the wall reads
    beyond ``range_m``, 18 degrees off north (the figure side_guard's docstring gives), not a spin."""
    x, y, heading, half_width_m, wall_x = 0.0, 0.0, math.pi / 2, 0.2, -0.42
    for _ in range(100):  # 4 s at 25 Hz
        # The left rangefinder looks square to the rover's side; it meets the wall at this range.
        beam = heading + math.pi / 2
        range_m = (x - wall_x) / -math.cos(beam) - half_width_m if math.cos(beam) < -1e-6 else math.inf
        heading += side_turn_radps({LEFT: range_m}, PARAMS) * 0.04
        x, y = x + math.cos(heading) * 0.04, y + math.sin(heading) * 0.04
    assert x - half_width_m - wall_x >= PARAMS.range_m - 0.05  # clear of the guard's range, about
    assert math.degrees(math.pi / 2 - heading) == pytest.approx(18.3, abs=1.0)  # bent right, and no more


def test_beside_something_with_the_way_ahead_clear_the_rover_keeps_its_passing_speed():
    ahead_clear = {FRONT: 3.0, FRONT_LEFT: math.inf, FRONT_RIGHT: 2.0}
    assert pass_speed_mps({LEFT: 0.25, **ahead_clear}, 1.5, PARAMS) == PARAMS.pass_speed_mps
    assert pass_speed_mps({RIGHT: 0.25, **ahead_clear}, 0.5, PARAMS) == 0.5  # never above the speed given
    assert pass_speed_mps({LEFT: 0.25, FRONT: 3.0}, 1.5, PARAMS) == PARAMS.pass_speed_mps  # a front sensor only


def test_no_passing_speed_without_a_turn_with_something_ahead_or_no_way_to_see_ahead():
    assert pass_speed_mps({LEFT: 1.0, FRONT: math.inf}, 1.5, PARAMS) is None  # the guard does not turn
    assert pass_speed_mps({LEFT: 0.25, FRONT: math.inf, FRONT_LEFT: PARAMS.front_clear_m}, 1.5, PARAMS) is None
    assert pass_speed_mps({LEFT: 0.25, FRONT: math.nan}, 1.5, PARAMS) is None  # NaN: not clear
    assert pass_speed_mps({LEFT: 0.25}, 1.5, PARAMS) is None  # no front rangefinder: ahead unknown
    assert pass_speed_mps({LEFT: 0.25, FRONT: math.inf}, 1.5, SideGuardParams(pass_speed_mps=0.0)) is None
    assert pass_speed_mps({LEFT: 0.25, FRONT: math.inf}, 1.5, SideGuardParams(enabled=False)) is None


def _mean_speed_beside_a_close_left_reading(params: SideGuardParams, front_m: float) -> float:
    """The autopilot in closed loop (tests/autopilot/harness.py) on a leg 30 m north, its left
    rangefinder at 0.25 m all along, its front ones at ``front_m``: mean speed over 3-6 s."""
    from autopilot.harness import Bench, mission

    bench = Bench()
    bench.config.side_guard = params
    bench.ranges_m.update({LEFT: 0.25, FRONT: front_m, FRONT_LEFT: front_m, FRONT_RIGHT: front_m})
    bench.ready(mission((0.0, 30.0)))
    assert bench.request(bench.autopilot.set_mode(RoverMode.AUTO)).accepted
    bench.run(3.0)
    speeds = []
    bench.run(3.0, until=lambda b: speeds.append(b.speed_mps) and False)
    return sum(speeds) / len(speeds)


def test_the_autopilot_draws_ahead_of_a_flank_reading_only_with_the_way_ahead_clear():
    slowed = _mean_speed_beside_a_close_left_reading(SideGuardParams(pass_speed_mps=0.0), math.inf)
    passing = _mean_speed_beside_a_close_left_reading(PARAMS, math.inf)
    blocked = _mean_speed_beside_a_close_left_reading(PARAMS, 1.0)
    assert slowed < 0.6 * PARAMS.pass_speed_mps  # the rule base, turning back against the guard, slows to turn
    assert passing > 0.8 * PARAMS.pass_speed_mps
    assert blocked == pytest.approx(_mean_speed_beside_a_close_left_reading(SideGuardParams(pass_speed_mps=0.0), 1.0))


def test_a_turn_against_the_guard_is_taken_out_and_the_forward_speed_kept():
    assert against_guard_removed(60.0, 140.0, -1.0) == (100.0, 100.0)  # turning left, the guard right
    assert against_guard_removed(140.0, 60.0, 0.5) == (100.0, 100.0)  # and the mirror image
    assert against_guard_removed(140.0, 60.0, -1.0) == (140.0, 60.0)  # turning the guard's way: kept
    assert against_guard_removed(60.0, 140.0, 0.0) == (60.0, 140.0)  # no guard turn: untouched
    assert against_guard_removed(80.0, 80.0, -1.0) == (80.0, 80.0)


def test_the_way_ahead_is_clear_only_when_every_front_rangefinder_reads_beyond_front_clear():
    assert way_ahead_clear({FRONT: 3.0, FRONT_LEFT: math.inf, LEFT: 0.2}, PARAMS)
    assert not way_ahead_clear({FRONT: 3.0, FRONT_RIGHT: PARAMS.front_clear_m}, PARAMS)
    assert not way_ahead_clear({FRONT: math.nan}, PARAMS)
    assert not way_ahead_clear({LEFT: 4.0, RIGHT: 4.0}, PARAMS)  # nothing looks ahead


def test_beside_a_close_left_reading_the_rule_base_does_not_turn_the_rover_back_into_it():
    """The autopilot in closed loop (tests/autopilot/harness.py), its left rangefinder at 0.25 m
    all along and the way ahead clear, on a leg whose target lies 72 degrees left of its heading.
    The guard turns it right; once the target is far enough off, the rule base turns back towards
    it, into the near side, harder than the guard turns away (so a walker converging on the
    rover's flank struck it, the runner's ``head_on`` seeds 36 and 147; before the turn was taken
    out the heading came back left after about a second). The rover now never turns left."""
    from autopilot.harness import Bench, mission

    bench = Bench()
    bench.ranges_m.update({LEFT: 0.25, FRONT: math.inf, FRONT_LEFT: math.inf, FRONT_RIGHT: math.inf})
    bench.ready(mission((-30.0, 10.0)))
    assert bench.request(bench.autopilot.set_mode(RoverMode.AUTO)).accepted
    headings = [bench.heading_rad]
    bench.run(2.0, until=lambda b: headings.append(b.heading_rad) and False)
    turns = [b - a for a, b in zip(headings, headings[1:])]
    assert max(turns) <= 1e-9  # never left
    assert headings[0] - headings[-1] > math.radians(30.0)  # the guard's turn, away to the right
    assert bench.speed_mps > 0.8 * PARAMS.pass_speed_mps  # drawing ahead, not slowed to turn


def _walker(east_m: float, north_m: float, travel_m: float = 1.0, ident: int = 1, time_s: float = 0.0) -> Track:
    """A moving track at (east_m, north_m) walking north at 0.6 m/s, ``travel_m`` from its first echo."""
    return Track(ident, time_s, east_m, north_m, 0.0, 0.6, hits=20, last_echo_s=time_s, born_en=(east_m, north_m - travel_m))


def test_a_walker_behind_the_side_beams_within_range_is_on_its_side():
    north = math.pi / 2  # the rover at the origin pointing north: left is west
    assert rear_mover_side([_walker(-0.6, -0.5)], 0.0, 0.0, 0.0, north, PARAMS) == 1.0
    assert rear_mover_side([_walker(0.6, -0.5)], 0.0, 0.0, 0.0, north, PARAMS) == -1.0
    assert rear_mover_side([_walker(-0.1, -1.5)], 0.0, 0.0, 0.0, north, PARAMS) == 1.0  # nearly dead astern
    assert rear_mover_side([_walker(-0.6, -0.5), _walker(0.3, -0.3, ident=2)], 0.0, 0.0, 0.0, north, PARAMS) == -1.0  # the nearer
    coming = Track(4, -3.0, -0.6, 1.3, 0.0, -0.6, hits=20, last_echo_s=-3.0, born_en=(-0.6, 3.0))  # ahead 3 s ago
    assert rear_mover_side([coming], 0.0, 0.0, 0.0, north, PARAMS) == 1.0  # where it is now, not where it was
    assert rear_mover_side([_walker(-1.0, -1.0, ident=3)], 0.0, 0.0, 0.0, 0.0, PARAMS) == -1.0  # pointing east: right is south


def test_abeam_a_walker_counts_only_when_the_bearing_limit_lets_it():
    north = math.pi / 2
    bearing = math.radians(PARAMS.rear_min_bearing_deg)

    def at(degrees_off: float) -> Track:  # 1 m from the centre, this far past the bearing limit, on the left
        angle = north + bearing + math.radians(degrees_off)
        return _walker(math.cos(angle), math.sin(angle))

    assert rear_mover_side([at(-5.0)], 0.0, 0.0, 0.0, north, PARAMS) == 0.0  # still in the side beam's reach
    assert rear_mover_side([at(5.0)], 0.0, 0.0, 0.0, north, PARAMS) == 1.0
    assert rear_mover_side([_walker(-0.7, 0.0)], 0.0, 0.0, 0.0, north, PARAMS) == 0.0  # abeam
    assert rear_mover_side([_walker(-0.7, 0.0)], 0.0, 0.0, 0.0, north, SideGuardParams(rear_min_bearing_deg=90.0)) == 1.0


def test_no_side_for_a_walker_ahead_far_off_barely_moved_or_with_the_check_off():
    north = math.pi / 2
    assert rear_mover_side([], 0.0, 0.0, 0.0, north, PARAMS) == 0.0
    assert rear_mover_side([_walker(-0.6, 0.3)], 0.0, 0.0, 0.0, north, PARAMS) == 0.0  # ahead of the centre
    assert rear_mover_side([_walker(-1.5, -1.5)], 0.0, 0.0, 0.0, north, PARAMS) == 0.0  # beyond rear_range_m
    assert rear_mover_side([_walker(-0.6, -0.5, travel_m=0.3)], 0.0, 0.0, 0.0, north, PARAMS) == 0.0  # a static drum's sliding echo
    assert rear_mover_side([_walker(-0.6, -0.5)], 0.0, 0.0, 0.0, north, SideGuardParams(rear_range_m=0.0)) == 0.0
    assert rear_mover_side([_walker(-0.6, -0.5)], 0.0, 0.0, 0.0, north, SideGuardParams(enabled=False)) == 0.0


def _turn_and_travel_with_a_walker_behind_left(params: SideGuardParams) -> tuple[float, float, set]:
    """The autopilot in closed loop (tests/autopilot/harness.py), pointing north with its target
    20 m behind it and a little left, a walker 0.7 m behind its left rear quarter converging on its
    way at 0.42 m/s (a track put into the tracker every step, as the rangefinders would have left it):
    (heading change, distance travelled, the control log's side_rear values) over 1.5 s."""
    from autopilot.harness import Bench, mission

    bench = Bench()
    bench.config.side_guard = params
    bench.ready(mission((-3.0, -20.0)))
    assert bench.request(bench.autopilot.set_mode(RoverMode.AUTO)).accepted
    start = (bench.heading_rad, bench.east_m, bench.north_m, bench.t_s)
    tracker, sides = bench.autopilot.proximity.tracker, set()

    def walker_and_log(b: Bench) -> bool:
        sides.add(b.outputs[-1].log_row["side_rear"])
        walked_m = 0.3 * (b.t_s - start[3])  # north-east at 0.3 m/s each way: never at the rover's own velocity
        tracker.tracks = [Track(1, b.t_s, start[1] - 0.5 + walked_m, start[2] - 0.5 + walked_m, 0.3, 0.3, hits=20, last_echo_s=b.t_s,
                                born_en=(start[1] - 1.5, start[2] - 1.5))]  # fmt: skip
        return False

    walker_and_log(bench)
    bench.run(1.5, until=walker_and_log)
    return bench.heading_rad - start[0], math.dist((bench.east_m, bench.north_m), start[1:3]), sides


def test_with_a_walker_behind_the_rover_drives_on_away_from_it_instead_of_pivoting_into_its_way():
    """The rule base, its target behind, stops to pivot left, towards a walker converging on the
    rover's left rear quarter where no rangefinder looks (most of the runner's ``head_on`` failures):
    with the walker tracked there the rover goes on at the passing speed and does not turn left."""
    turn, travel_m, sides = _turn_and_travel_with_a_walker_behind_left(PARAMS)
    assert turn <= 1e-9 and travel_m > 1.0 and 1.0 in sides
    turn, travel_m, sides = _turn_and_travel_with_a_walker_behind_left(SideGuardParams(rear_range_m=0.0))
    assert turn > math.radians(90.0) and travel_m < 1.0 and 1.0 not in sides  # without it: the pivot round towards the target
