"""The planner's node budget in the closed loop: a fence too complex to plan (stored before the
budget, or made so by a raised PLN_CIRCLE_SEGS) holds the rover with "No path", the control step
never stalls on it, and a fence within the budget is driven around."""

from __future__ import annotations

import math

from autopilot.harness import Bench, mission, waypoint

from rover_ctl.mission.validate import MAX_PLANNER_NODES
from rover_ctl.vocabulary import Cmd, RoverMode


def circles(count: int, east_m: float = 100.0) -> list:
    """``count`` exclusion circles of 1 m, 6 m apart, east of the route."""
    side = math.ceil(math.sqrt(count))
    return [waypoint(east_m + (k % side) * 6.0, (k // side) * 6.0, Cmd.NAV_FENCE_CIRCLE_EXCLUSION, param1=1.0) for k in range(count)]


def auto(bench: Bench, fence: list) -> None:
    bench.ready(mission((0.0, 40.0), fence=fence))
    assert bench.request(bench.autopilot.set_mode(RoverMode.AUTO)).accepted


def test_a_stored_fence_too_complex_to_plan_holds_with_no_path():
    bench = Bench()
    auto(bench, circles(700))  # a store written before the budget: the upload would refuse it now
    bench.run(3.0)
    assert f"No path: too complex to plan: {700 * 16} nodes, max {MAX_PLANNER_NODES}" in bench.texts
    assert abs(bench.speed_mps) < 0.05 and math.dist(bench.position_en, (0.0, 0.0)) < 0.1
    assert bench.autopilot.mode == RoverMode.AUTO


def test_a_raised_circle_segments_holds_until_lowered_again():
    bench = Bench()
    bench.config.planner.circle_segments = 64  # PLN_CIRCLE_SEGS by PARAM_SET: 40 x 64 = 2560 nodes
    auto(bench, circles(40))
    bench.run(2.0)
    assert f"No path: too complex to plan: 2560 nodes, max {MAX_PLANNER_NODES}" in bench.texts
    assert math.dist(bench.position_en, (0.0, 0.0)) < 0.1
    bench.config.planner.circle_segments = 16  # 640 nodes: the next re-plan (the last one failed) goes
    assert bench.run(20.0, until=lambda b: b.north_m > 10.0)
