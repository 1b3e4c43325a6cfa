"""The planner's node budget in the closed loop: a fence too complex to plan (stored before the
budget, or made so by a raised PLN_CIRCLE_SEGS) refuses arming, and while driving (force-armed, or
the parameter raised on the way) holds the rover with "No path"; the control step never stalls on
it, and a fence within the budget is driven around."""

from __future__ import annotations

import math

from autopilot.harness import Bench, mission, waypoint

from rover_ctl.mission.validate import MAX_PLANNER_NODES
from rover_ctl.vocabulary import Cmd, RoverMode


def circles(count: int, east_m: float = 100.0) -> list:
    """``count`` exclusion circles of 1 m, 6 m apart, east of the route."""
    side = math.ceil(math.sqrt(count))
    return [waypoint(east_m + (k % side) * 6.0, (k // side) * 6.0, Cmd.NAV_FENCE_CIRCLE_EXCLUSION, param1=1.0) for k in range(count)]


def auto(bench: Bench, fence: list, force: bool = False) -> None:
    bench.home(mission((0.0, 40.0), fence=fence))
    bench.step()
    assert bench.request(bench.autopilot.arm(True, force=force)).accepted, bench.texts
    bench.step()
    assert bench.request(bench.autopilot.set_mode(RoverMode.AUTO)).accepted


def test_a_stored_fence_too_complex_to_plan_refuses_arming_and_forced_holds_with_no_path():
    bench = Bench()
    bench.home(mission((0.0, 40.0), fence=circles(700)))  # a store written before the budget: the upload would refuse it now
    bench.step()
    assert not bench.request(bench.autopilot.arm(True)).accepted
    assert bench.texts[-1] == f"PreArm: fence too complex to plan: {700 * 16} nodes, max {MAX_PLANNER_NODES} (PLN_CIRCLE_SEGS)"
    auto(bench, circles(700), force=True)
    bench.run(3.0)
    assert f"No path: too complex to plan: {700 * 16} nodes, max {MAX_PLANNER_NODES}" in bench.texts
    assert abs(bench.speed_mps) < 0.05 and math.dist(bench.position_en, (0.0, 0.0)) < 0.1
    assert bench.autopilot.mode == RoverMode.AUTO


def test_a_raised_circle_segments_holds_until_lowered_again():
    bench = Bench()
    auto(bench, circles(40))
    bench.config.planner.circle_segments = 64  # PLN_CIRCLE_SEGS by PARAM_SET while driving: 40 x 64 = 2560 nodes
    bench.run(2.0)
    assert f"No path: too complex to plan: 2560 nodes, max {MAX_PLANNER_NODES}" in bench.texts
    assert math.dist(bench.position_en, (0.0, 0.0)) < 0.1
    bench.config.planner.circle_segments = 16  # 640 nodes: the next re-plan (the last one failed) goes
    assert bench.run(20.0, until=lambda b: b.north_m > 10.0)


def test_arming_is_refused_while_the_fence_is_too_complex_at_the_circle_segments_in_force():
    bench = Bench()
    bench.home(mission((0.0, 40.0), fence=circles(40)))
    bench.step()
    bench.config.planner.circle_segments = 64  # PLN_CIRCLE_SEGS raised after the upload
    reply = bench.request(bench.autopilot.arm(True))
    assert not reply.accepted
    assert bench.texts[-1] == f"PreArm: fence too complex to plan: 2560 nodes, max {MAX_PLANNER_NODES} (PLN_CIRCLE_SEGS)"
    bench.config.planner.circle_segments = 16
    assert bench.request(bench.autopilot.arm(True)).accepted
