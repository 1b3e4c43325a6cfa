"""Executor + planner + path follower together, closed around a simple unicycle (no SITL)."""

from __future__ import annotations

import math

from rover_ctl.config import ExecutorParams, PlannerParams, RobotParams
from rover_ctl.autopilot.executor import EventKind, MissionExecutor
from rover_ctl.mission.model import MissionItem
from rover_ctl.navigation.planner import Circle, Fence, PathFollower, Planner

ROBOT = RobotParams()
DT_S = 0.1
TURN_GAIN = 2.0  # heading-error gain of the stand-in steering, rad/s per rad
MAX_TURN_RADPS = 2.0


def test_cmac_like_loop_around_an_exclusion_zone():
    params = PlannerParams(lookahead_m=2.0)
    # The cmac_loop legs (ENU from home), an exclusion circle on the first leg, and RTL.
    legs = [(0, 40), (30, 55), (55, 30), (35, 5)]
    items = [MissionItem(16, x=n, y=e) for e, n in legs] + [MissionItem(20)]
    zone = Circle((0.0, 20.0), 4.0)
    fence = Fence(inclusion_polygons=(((-15, -10), (70, -10), (70, 70), (-15, 70)),), exclusion_circles=(zone,))
    planner = Planner(params, ROBOT, fence)
    follower = PathFollower(planner, params)
    executor = MissionExecutor(items, lambda lat, lon: (lon, lat), ExecutorParams(), ROBOT.max_speed_mps)
    executor.start()
    x, y, heading = 0.0, 0.0, math.pi / 2
    reached, closest_m, worst_xt_m, t = [], math.inf, 0.0, 0.0
    while not executor.complete and t < 600.0:
        out = executor.update(t, (x, y))
        reached += [e.seq for e in out.events if e.kind is EventKind.ITEM_REACHED]
        if out.target_en is not None and not out.hold:
            guidance = follower.update(t, (x, y), out.target_en)
            assert guidance.error is None
            worst_xt_m = max(worst_xt_m, abs(guidance.cross_track_m))
            bearing = math.atan2(guidance.target_en[1] - y, guidance.target_en[0] - x)
            error = math.remainder(bearing - heading, math.tau)
            heading += max(-MAX_TURN_RADPS, min(MAX_TURN_RADPS, TURN_GAIN * error)) * DT_S
            x += out.speed_limit_mps * math.cos(heading) * DT_S
            y += out.speed_limit_mps * math.sin(heading) * DT_S
        closest_m = min(closest_m, math.dist((x, y), zone.center_en) - zone.radius_m)
        assert planner.is_inside_fence((x, y))
        t += DT_S
    assert executor.complete and reached == [1, 2, 3, 4, 5]
    assert closest_m > ROBOT.footprint_width_m / 2  # never touched the zone
    assert worst_xt_m < 1.0
    assert math.dist((x, y), (0.0, 0.0)) <= ExecutorParams().rtl_radius_m


def test_a_step_may_ask_for_a_longer_carrot_and_the_next_is_back_to_the_planners():
    """The autopilot's rejoin after stepping aside: the carrot that far along the path for that
    step only, so the rover 1.5 m off its leg heads back at a shallow angle."""
    params = PlannerParams()
    follower = PathFollower(Planner(params, ROBOT), params)
    follower.update(0.0, (0.0, 0.0), (0.0, 30.0))  # the leg north, planned from its start
    off = (-1.5, 4.0)
    far = follower.update(0.1, off, (0.0, 30.0), lookahead_m=8.0).target_en
    near = follower.update(0.2, off, (0.0, 30.0)).target_en
    assert far == (0.0, 12.0) and near == (0.0, 4.0 + params.lookahead_m)
    assert math.degrees(math.atan2(1.5, far[1] - off[1])) < 11.0 < 26.0 < math.degrees(math.atan2(1.5, near[1] - off[1]))
