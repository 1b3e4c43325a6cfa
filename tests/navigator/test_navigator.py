"""The navigator's mapping, and both rule bases in a closed loop with the kinematic rover."""

import math

import pytest
from navigator.kinematic import PAPER_ORIENTATIONS, Circle, box, drive

from rover_ctl.config import NavigatorParams
from rover_ctl.fuzzy import RuleBaseError, load_rulebase
from rover_ctl.navigation.navigator import Navigator

CLEAR6 = {o: math.inf for o in (0, 1, 2, 4, 6, 7)}
CLEAR4 = {o: math.inf for o in PAPER_ORIENTATIONS}
DEADBAND_RPM = 10.0
"""Turn commands smaller than this (5 % of full speed) do not count as a change of side."""


@pytest.fixture(scope="module")
def default_nav():
    return Navigator(load_rulebase("default"), NavigatorParams(), 200.0)


@pytest.fixture(scope="module")
def paper_nav():
    return Navigator(load_rulebase("paper"), NavigatorParams(), 200.0)


def side_changes(turns):
    signs = [t > 0 for t in turns if abs(t) > DEADBAND_RPM]
    return sum(a != b for a, b in zip(signs, signs[1:]))


# ----- mapping -------------------------------------------------------------------------------


def test_target_direction_follows_the_paper_convention(paper_nav):
    heading = math.radians(30.0)
    left = paper_nav.step(1.0, 2.0, heading, 1.0 + 10 * math.cos(heading + 1.0), 2.0 + 10 * math.sin(heading + 1.0), CLEAR4)
    assert left.inputs["target_direction"] == pytest.approx(math.degrees(1.0))
    assert left.inputs["target_direction_rad"] == pytest.approx(1.0)
    assert left.inputs["target_distance"] == left.inputs["target_distance_m"] == pytest.approx(10.0)
    assert left.right_rpm > left.left_rpm  # turns left, towards it
    right = paper_nav.step(0.0, 0.0, 0.0, 0.0, -10.0, CLEAR4)
    assert right.inputs["target_direction"] == pytest.approx(270.0)
    assert right.left_rpm > right.right_rpm


def test_paper_obstacle_units_are_scaled_metres(paper_nav):
    out = paper_nav.step(0.0, 0.0, 0.0, 10.0, 0.0, {0: 1.5, 2: 4.0, 4: math.inf, 6: 0.5})
    assert out.inputs["obstacle_front"] == pytest.approx(7.5)
    assert out.inputs["obstacle_right"] == pytest.approx(20.0)
    assert out.inputs["obstacle_left"] == pytest.approx(2.5)
    assert out.inputs["obstacle_back"] == math.inf


@pytest.mark.parametrize("nav_name, ranges", [("default_nav", CLEAR6), ("paper_nav", CLEAR4)])
def test_missing_rangefinder_counts_as_blocked(request, nav_name, ranges):
    nav = request.getfixturevalue(nav_name)
    without_front = {o: r for o, r in ranges.items() if o != 0}
    blocked = nav.step(0.0, 0.0, 0.0, 10.0, 0.0, without_front)
    assert blocked.inputs["obstacle_front"] == 0.0
    assert blocked.inputs == nav.step(0.0, 0.0, 0.0, 10.0, 0.0, {**ranges, 0: math.nan}).inputs
    clear = nav.step(0.0, 0.0, 0.0, 10.0, 0.0, ranges)
    assert clear.left_rpm == clear.right_rpm > 100.0
    assert blocked.left_rpm != blocked.right_rpm  # turns away instead of driving on


def test_speed_limit_scales_both_wheels_and_keeps_the_curve(default_nav):
    free = default_nav.step(0.0, 0.0, 0.0, 10.0, 3.0, CLEAR6)
    limited = default_nav.step(0.0, 0.0, 0.0, 10.0, 3.0, CLEAR6, speed_limit_mps=0.5)
    limit_rpm = 0.5 / (2 * math.pi * 0.07) * 60
    assert max(abs(limited.left_rpm), abs(limited.right_rpm)) == pytest.approx(limit_rpm)
    assert limited.left_rpm / limited.right_rpm == pytest.approx(free.left_rpm / free.right_rpm)
    assert max(free.left_rpm, free.right_rpm) == pytest.approx(200.0, abs=1.0)  # full scale = max_wheel_rpm


def test_rule_base_without_navigation_inputs_is_refused(tmp_path):
    path = tmp_path / "odd.toml"
    path.write_text(
        '[inputs.speed]\nrange = [0, 1]\nsets = { lo = [0, 0, 0, 1] }\n'
        '[outputs.left_motor]\nrange = [0, 1]\nsets = { a = [0, 0.5, 1] }\n'
        '[rules]\nlist = ["if speed is lo then left_motor is a"]\n'
    )
    with pytest.raises(RuleBaseError, match="odd.toml: not a navigation rule base .*missing target_distance"):
        Navigator(load_rulebase(path), NavigatorParams(), 200.0)


def test_rule_base_whose_motor_sets_all_peak_at_zero_is_refused(tmp_path):
    """The navigator scales the largest output peak to max_wheel_rpm: 0 divided by zero."""
    path = tmp_path / "still.toml"
    inputs = "".join(f'[inputs.{n}]\nrange = [0, 1]\nsets = {{ lo = [0, 0, 0, 1] }}\n' for n in ("target_distance", "target_direction"))
    outputs = "".join(f'[outputs.{n}]\nrange = [-1, 1]\nsets = {{ stop = [-1, 0, 1] }}\n' for n in ("left_motor", "right_motor"))
    rules = '[rules]\nlist = ["if target_distance is lo and target_direction is lo then left_motor is stop and right_motor is stop"]\n'
    path.write_text(inputs + outputs + rules)
    with pytest.raises(RuleBaseError, match="still.toml: every motor set peaks at 0"):
        Navigator(load_rulebase(path), NavigatorParams(), 200.0)


# ----- closed loop, default rule base ---------------------------------------------------------


@pytest.mark.parametrize("target", [(20.0, 0.0), (20.0, 5.0), (0.0, 15.0), (8.0, -12.0), (-15.0, -3.0)])
def test_open_field_reaches_target_without_oscillation(default_nav, target):
    run = drive(default_nav, target, time_limit_s=40.0)
    assert run.reached and not run.collided
    assert side_changes(run.turn_rpm) == 0
    if target[1] == 0.0:
        assert all(t == 0.0 for t in run.turn_rpm)  # dead ahead: no steering at all
    # once the heading points at the target it stays within 3 degrees of it
    bearing_errors = [abs(math.remainder(math.atan2(target[1] - y, target[0] - x) - h, math.tau))
                      for (x, y), h in zip(run.path, run.headings_rad)]  # fmt: skip
    settled = next(i for i, e in enumerate(bearing_errors) if e < math.radians(3.0))
    assert max(bearing_errors[settled:]) < math.radians(3.0)


def test_slows_down_near_the_target(default_nav):
    far = default_nav.step(0.0, 0.0, 0.0, 10.0, 0.0, CLEAR6)
    near = default_nav.step(0.0, 0.0, 0.0, 0.8, 0.0, CLEAR6)
    assert 0.0 < near.left_rpm < far.left_rpm / 2


@pytest.mark.parametrize(
    "target, obstacles",
    [
        ((20.0, 0.0), [Circle(8.0, 0.0, 1.0)]),
        ((20.0, 0.0), [Circle(8.0, 0.4, 1.0)]),
        ((20.0, 2.0), [box(6.0, -1.0, 8.0, 1.0), Circle(12.0, 3.0, 0.8)]),
        ((20.0, 0.0), [box(6.0, -4.0, 7.0, 4.0)]),
    ],
    ids=["circle-on-line", "circle-offset", "box-and-circle", "wall-8m"],
)
def test_goes_around_obstacles_without_collision(default_nav, target, obstacles):
    run = drive(default_nav, target, obstacles, time_limit_s=60.0)
    assert run.reached and not run.collided
    assert run.min_clearance_m > 0.1


@pytest.mark.parametrize("target", [(20.0, 0.0), (20.0, 3.0), (20.0, -4.0)])
def test_passes_a_1_5_m_gap(default_nav, target):
    gap = [box(8.0, 0.75, 9.0, 8.0), box(8.0, -8.0, 9.0, -0.75)]
    run = drive(default_nav, target, gap, time_limit_s=60.0)
    assert run.reached and not run.collided
    assert any(8.0 <= x <= 9.0 for x, _ in run.path)  # through the gap, not around the walls


# ----- closed loop, paper rule base on the paper's four sensors -------------------------------


@pytest.mark.parametrize("target", [(20.0, 5.0), (0.0, 15.0), (-15.0, -3.0)])
def test_paper_reaches_targets_in_open_field(paper_nav, target):
    run = drive(paper_nav, target, orientations=PAPER_ORIENTATIONS, time_limit_s=60.0)
    assert run.reached and not run.collided


def test_paper_passes_a_gap_straight_ahead(paper_nav):
    gap = [box(8.0, 0.75, 9.0, 8.0), box(8.0, -8.0, 9.0, -0.75)]
    run = drive(paper_nav, (20.0, 0.0), gap, orientations=PAPER_ORIENTATIONS, time_limit_s=60.0)
    assert run.reached and not run.collided


def test_paper_turns_away_from_an_obstacle_in_front(paper_nav):
    ahead = paper_nav.step(0.0, 0.0, 0.0, 10.0, 0.0, {**CLEAR4, 0: 0.5})
    assert ahead.left_rpm > ahead.right_rpm  # veers right, away
    walled_right = paper_nav.step(0.0, 0.0, 0.0, 10.0, 0.0, {**CLEAR4, 0: 0.5, 2: 0.3})
    assert walled_right.right_rpm > walled_right.left_rpm  # then left, away from the right wall


def test_distance_input_is_the_real_target_distance_not_the_steering_point(paper_nav, default_nav):
    """Steering at a carrot 3 m ahead while the waypoint is 20 m away: the paper's controller sees
    20 m (far: full speed), not 3 m (near: its stop rules), and the default is unchanged."""
    clear = {o: math.inf for o in (0, 1, 2, 4, 6, 7)}
    paper_carrot = paper_nav.step(0.0, 0.0, 0.0, 3.0, 0.0, clear)
    paper_far = paper_nav.step(0.0, 0.0, 0.0, 3.0, 0.0, clear, target_distance_m=20.0)
    assert paper_far.inputs["target_distance"] == 20.0
    assert paper_far.left_rpm > 1.5 * paper_carrot.left_rpm > 0.0
    assert paper_far.inputs["target_direction"] == paper_carrot.inputs["target_direction"]  # still steers to the carrot
    default_carrot = default_nav.step(0.0, 0.0, 0.0, 3.0, 0.0, clear)
    default_far = default_nav.step(0.0, 0.0, 0.0, 3.0, 0.0, clear, target_distance_m=20.0)
    assert (default_far.left_rpm, default_far.right_rpm) == pytest.approx((default_carrot.left_rpm, default_carrot.right_rpm))
