"""Pivot turns: a target far off the heading is faced by turning in place (pure), and the
autopilot does so on a mission whose next waypoint lies behind the rover (closed loop, no sockets)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from rover_ctl.config import PivotParams
from rover_ctl.navigation.pivot import Pivot
from rover_ctl.navigation.sensors import BACK, FRONT, FRONT_LEFT, FRONT_RIGHT, LEFT, RIGHT

PARAMS = PivotParams(angle_deg=60.0)
CLEAR = dict.fromkeys((FRONT, FRONT_LEFT, FRONT_RIGHT, LEFT, RIGHT, BACK), math.inf)
RATE = math.radians(PARAMS.rate_dps)
AT = (0.0, 0.0)
"""Where the rover stands (it only turns)."""


def deg(d: float) -> float:
    return math.radians(d)


def test_off_or_a_target_within_the_angle_turns_nothing():
    assert Pivot(PivotParams(angle_deg=0.0)).step(0.0, deg(170), CLEAR, False, AT) is None
    assert Pivot(PivotParams(angle_deg=PARAMS.accuracy_deg)).step(0.0, deg(170), CLEAR, False, AT) is None
    assert Pivot(PARAMS).step(0.0, deg(59), CLEAR, False, AT) is None
    assert Pivot(PARAMS).step(0.0, deg(-59), CLEAR, False, AT) is None


def test_a_target_beyond_the_angle_is_turned_to_at_the_rate_then_slower_until_within_accuracy():
    pivot = Pivot(PARAMS)
    assert pivot.step(0.0, deg(90), CLEAR, False, AT) == pytest.approx(RATE)  # left, capped
    assert pivot.step(0.1, deg(-120), CLEAR, False, AT) == pytest.approx(-RATE)  # the way it started: the heading passed it
    assert pivot.step(0.2, deg(20), CLEAR, False, AT) == pytest.approx(PARAMS.heading_gain * deg(20))  # inside the angle: goes on
    assert pivot.active
    assert pivot.step(0.3, deg(PARAMS.accuracy_deg * 0.9), CLEAR, False, AT) is None  # done
    assert not pivot.active
    assert pivot.step(0.4, deg(30), CLEAR, False, AT) is None  # a new one needs the angle again
    assert pivot.step(0.4 + PARAMS.rest_s * 0.9, deg(120), CLEAR, False, AT) is None  # and waits
    assert pivot.step(0.3 + PARAMS.rest_s * 1.01, deg(120), CLEAR, False, AT) is not None


def test_near_half_a_turn_it_keeps_the_way_it_started():
    """The shorter way flips as the heading estimate wobbles about 180 degrees; the turn does not."""
    pivot = Pivot(PARAMS)
    assert pivot.step(0.0, deg(175), CLEAR, False, AT) > 0.0
    assert pivot.step(0.1, deg(-178), CLEAR, False, AT) == pytest.approx(RATE)  # still left
    assert pivot.step(0.2, deg(-150), CLEAR, False, AT) < 0.0  # within the lock's release: the shorter way again


def test_something_close_held_or_a_blocked_way_to_the_target_starts_none():
    assert Pivot(PARAMS).step(0.0, deg(120), {**CLEAR, BACK: PARAMS.clear_m}, False, AT) is None  # a turn sweeps the corners
    assert Pivot(PARAMS).step(0.0, deg(120), CLEAR, True, AT) is None  # yielding, rejoining, a walker near
    # The target lies to the left: a wall there would hand the rule base a rover that turns away again.
    assert Pivot(PARAMS).step(0.0, deg(90), {**CLEAR, LEFT: PARAMS.open_m}, False, AT) is None
    assert Pivot(PARAMS).step(0.0, deg(90), {**CLEAR, FRONT_LEFT: 1.0}, False, AT) is None  # 45 deg from it
    assert Pivot(PARAMS).step(0.0, deg(90), {**CLEAR, RIGHT: 1.0, FRONT: 1.0}, False, AT) is not None  # elsewhere: free to turn
    assert Pivot(PARAMS).step(0.0, deg(90), {**CLEAR, LEFT: math.nan}, False, AT) is not None  # no reading is no echo


@pytest.mark.parametrize("why", ["near", "held", "timeout"])
def test_a_pivot_ends_when_something_comes_close_something_holds_the_rover_or_it_takes_too_long(why):
    """The next one waits ``rest_s``; after a timeout, until the rover has moved ``retry_after_m``
    (it could not turn: the stuck failsafe, which a turn in place never trips, has to see it)."""
    pivot = Pivot(PARAMS)
    assert pivot.step(0.0, deg(150), CLEAR, False, AT) is not None
    ranges, held, t_s = CLEAR, False, 1.0
    if why == "near":
        ranges = {**CLEAR, RIGHT: 0.25}
    elif why == "held":
        held = True
    else:
        t_s = PARAMS.timeout_s + 0.1
    assert pivot.step(t_s, deg(150), ranges, held, AT) is None
    assert not pivot.active
    assert pivot.step(t_s + PARAMS.rest_s * 0.9, deg(150), CLEAR, False, AT) is None  # the rule base drives a while
    if why == "timeout":  # a rover that could not turn: not asked again until it has moved
        assert pivot.step(t_s + PARAMS.rest_s * 5, deg(150), CLEAR, False, (0.0, PARAMS.retry_after_m * 0.9)) is None
        assert pivot.step(t_s + PARAMS.rest_s * 6, deg(150), CLEAR, False, (0.0, PARAMS.retry_after_m * 1.1)) is not None
    else:
        assert pivot.step(t_s + PARAMS.rest_s * 1.01, deg(150), CLEAR, False, AT) is not None


@given(st.floats(-179.0, 179.0).filter(lambda d: abs(d) > PARAMS.angle_deg), st.sampled_from([10, 25, 50]))
def test_in_closed_loop_it_turns_the_short_way_no_faster_than_the_rate_and_stops_within_accuracy(start_deg, rate_hz):
    """A rover that turns at exactly the rate asked for, stepped at ``rate_hz``."""
    pivot, direction, dt = Pivot(PARAMS), math.radians(start_deg), 1.0 / rate_hz
    turned, t_s = 0.0, 0.0
    while (omega := pivot.step(t_s, direction, CLEAR, False, AT)) is not None:
        assert abs(omega) <= RATE + 1e-12
        assert omega * start_deg > 0.0 or abs(math.degrees(direction)) < 90.0  # never away the long way
        direction = math.remainder(direction - omega * dt, math.tau)
        turned += omega * dt
        t_s += dt
        assert t_s < PARAMS.timeout_s
    assert abs(math.degrees(direction)) <= PARAMS.accuracy_deg
    assert abs(math.degrees(turned) - start_deg) <= PARAMS.accuracy_deg


def test_the_autopilot_turns_in_place_to_a_waypoint_behind_it_then_drives_there():
    """Facing north, the first waypoint 8 m south: with pivots, the rover turns round on the spot
    (the wheels opposite, the centre within a few centimetres) and drives a straight line; without,
    the rule base swings round on an arc."""
    from rover_ctl.vocabulary import RoverMode
    from tests.autopilot.harness import Bench, mission, rover_config

    def drive(angle_deg: float) -> tuple[Bench, float]:
        config = rover_config()
        config.pivot.angle_deg = angle_deg
        bench = Bench(config)
        bench.ready(mission((0.0, -8.0)))
        assert bench.request(bench.autopilot.set_mode(RoverMode.AUTO)).accepted
        farthest_m = 0.0
        while bench.t_s < 6.0 and abs(math.remainder(bench.heading_rad + math.pi / 2, math.tau)) > math.radians(10):
            bench.step()
            farthest_m = max(farthest_m, math.hypot(*bench.position_en))
        assert bench.run(40.0, until=lambda b: b.autopilot.mode == RoverMode.HOLD)
        return bench, farthest_m

    pivoting, turned_within_m = drive(60.0)
    rows = [o.log_row for o in pivoting.outputs]
    assert any(r["pivot_radps"] != "" for r in rows)
    assert all(r["left_set_rpm"] == pytest.approx(-r["right_set_rpm"]) for r in rows if r["pivot_radps"] != "")
    assert turned_within_m < 0.1
    swinging, swung_within_m = drive(0.0)
    assert all(o.log_row["pivot_radps"] == "" for o in swinging.outputs)
    assert swung_within_m > 0.3


def test_a_mode_change_ends_a_pivot():
    from rover_ctl.vocabulary import RoverMode
    from tests.autopilot.harness import Bench, mission

    bench = Bench()
    bench.ready(mission((0.0, -8.0)))
    assert bench.request(bench.autopilot.set_mode(RoverMode.AUTO)).accepted
    bench.run(0.5)
    assert bench.autopilot.pivot.active
    assert bench.request(bench.autopilot.set_mode(RoverMode.HOLD)).accepted
    assert not bench.autopilot.pivot.active
