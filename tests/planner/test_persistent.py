"""The planner's persistent obstacles (places the rangefinders echo from repeatedly): planned
around, a re-plan only when the path ahead touches a new one, never a goal made unreachable."""

from __future__ import annotations

from shapely.geometry import LineString, Polygon

from rover_ctl.config import PlannerParams, RobotParams
from rover_ctl.navigation.planner import Fence, PathFollower, Planner

PARAMS = PlannerParams()
ROBOT = RobotParams()
MARGIN_M = 0.2
WALL = ((-2.0, 10.0), (2.0, 10.0), (2.0, 10.5), (-2.0, 10.5))
"""A 4 m wall across the leg (0, 0) -> (0, 20)."""


def follower() -> PathFollower:
    return PathFollower(Planner(PARAMS, ROBOT, persistent_margin_m=lambda: MARGIN_M), PARAMS)


def test_a_persistent_obstacle_on_the_leg_makes_the_follower_replan_around_it():
    f = follower()
    g = f.update(0.0, (0.0, 0.0), (0.0, 20.0))
    assert g.path.points == ((0.0, 0.0), (0.0, 20.0))
    f.update(1.0, (0.0, 2.0), (0.0, 20.0))
    assert f.set_persistent([WALL])
    g = f.update(1.1, (0.0, 2.1), (0.0, 20.0))
    assert g.replanned and g.path.ok
    assert g.path.points[0] == (0.0, 2.1)
    clearance = LineString(g.path.points).distance(Polygon(WALL))
    assert clearance >= ROBOT.footprint_width_m / 2 + MARGIN_M - 1e-6
    assert g.path.length_m < 18.0 + 2 * 2.5  # around the wall's end, not far off


def test_a_persistent_obstacle_off_the_path_changes_the_map_but_not_the_path():
    f = follower()
    f.update(0.0, (0.0, 0.0), (0.0, 20.0))
    aside = ((3.0, 5.0), (4.0, 5.0), (4.0, 6.0), (3.0, 6.0))
    assert f.set_persistent([aside])
    assert not f.set_persistent([aside])  # the same again: no rebuild
    g = f.update(0.5, (0.0, 0.5), (0.0, 20.0))
    assert not g.replanned and g.path.points == ((0.0, 0.0), (0.0, 20.0))


def test_one_behind_the_rover_makes_no_replan():
    f = follower()
    f.update(0.0, (0.0, 0.0), (0.0, 20.0))
    f.update(5.0, (0.0, 15.0), (0.0, 20.0))
    f.set_persistent([WALL])  # the leg crossed it already (the rover went through a gap)
    assert not f.update(5.1, (0.0, 15.1), (0.0, 20.0)).replanned


def test_a_goal_inside_a_persistent_obstacle_stays_reachable():
    planner = Planner(PARAMS, ROBOT, persistent_margin_m=lambda: MARGIN_M)
    planner.set_persistent([WALL])
    path = planner.plan_leg((0.0, 0.0), (0.0, 10.2))
    assert path.ok and path.points[-1] == (0.0, 10.2)


def test_a_start_inside_one_gets_out_by_the_nearest_way():
    planner = Planner(PARAMS, ROBOT, persistent_margin_m=lambda: MARGIN_M)
    planner.set_persistent([WALL])
    path = planner.plan_leg((0.0, 9.9), (0.0, 0.0))
    assert path.ok and path.points[0] == (0.0, 9.9)
    assert path.points[1][1] < 10.0 - ROBOT.footprint_width_m / 2  # out on its own side


def test_when_persistent_obstacles_close_every_way_the_follower_plans_without_them():
    corridor = Fence(inclusion_polygons=(((-3.0, -5.0), (3.0, -5.0), (3.0, 25.0), (-3.0, 25.0)),))
    f = PathFollower(Planner(PARAMS, ROBOT, corridor, persistent_margin_m=lambda: MARGIN_M), PARAMS)
    f.update(0.0, (0.0, 0.0), (0.0, 20.0))
    across = ((-3.5, 10.0), (3.5, 10.0), (3.5, 10.5), (-3.5, 10.5))  # a gap the echoes made read closed
    f.set_persistent([across])
    g = f.update(0.5, (0.0, 0.5), (0.0, 20.0))
    assert g.replanned and g.path.ok and g.path.points == ((0.0, 0.5), (0.0, 20.0))
    assert not f.planner.has_persistent
    f.set_persistent([across])  # handed again for the same goal: still left out
    assert not f.planner.has_persistent
    assert not f.update(0.6, (0.0, 0.6), (0.0, 20.0)).replanned
    g = f.update(1.0, (0.0, 1.0), (0.0, 5.0))  # a new goal: the persistent obstacles count again
    assert g.replanned and g.path.ok and f.planner.has_persistent


def test_planning_without_persistent_obstacles_lasts_until_the_map_changes():
    """On a long leg the map goes on learning: other obstacles handed to the follower (the gap
    that read closed seen open) are tried again, and the rover plans around them."""
    corridor = Fence(inclusion_polygons=(((-3.0, -5.0), (3.0, -5.0), (3.0, 25.0), (-3.0, 25.0)),))
    f = PathFollower(Planner(PARAMS, ROBOT, corridor, persistent_margin_m=lambda: MARGIN_M), PARAMS)
    f.update(0.0, (0.0, 0.0), (0.0, 20.0))
    f.set_persistent([((-3.5, 10.0), (3.5, 10.0), (3.5, 10.5), (-3.5, 10.5))])
    assert f.update(0.5, (0.0, 0.5), (0.0, 20.0)).path.points == ((0.0, 0.5), (0.0, 20.0))
    opened = [((-3.5, 10.0), (-0.5, 10.0), (-0.5, 10.5), (-3.5, 10.5)), ((1.5, 10.0), (3.5, 10.0), (3.5, 10.5), (1.5, 10.5))]
    f.set_persistent(opened)
    g = f.update(1.0, (0.0, 1.0), (0.0, 20.0))
    assert g.replanned and g.path.ok and f.planner.has_persistent
    assert all(LineString(g.path.points).distance(Polygon(p)) >= ROBOT.footprint_width_m / 2 + MARGIN_M - 1e-6 for p in opened)


def test_a_start_a_hair_outside_an_obstacles_clearance_band_still_finds_its_way():
    """The rover pushed against a wall's clearance band, 0.017 m outside it by a rounded corner
    (walls seed 30 in the runner): every tangent line from there grazes the outline, and rounding
    had hidden them all, so the plan failed and the follower dropped the map."""
    planner = Planner(PARAMS, ROBOT, persistent_margin_m=lambda: MARGIN_M)
    wall = ((0.2, 13.9), (-3.3, 14.0), (-3.3, 14.5), (0.2, 14.4))
    planner.set_persistent([wall])
    path = planner.plan_leg((0.5, 13.6), (-1.645, 39.675))
    assert path.ok and path.points[0] == (0.5, 13.6) and path.points[-1] == (-1.645, 39.675)
    assert LineString(path.points[1:]).distance(Polygon(wall)) >= ROBOT.footprint_width_m / 2 + MARGIN_M - 1e-3


def test_a_changed_margin_applies_to_the_next_plan():
    margin = [MARGIN_M]
    planner = Planner(PARAMS, ROBOT, persistent_margin_m=lambda: margin[0])
    planner.set_persistent([WALL])
    near = LineString(planner.plan_leg((0.0, 0.0), (0.0, 20.0)).points).distance(Polygon(WALL))
    margin[0] = 1.0
    far = LineString(planner.plan_leg((0.0, 0.0), (0.0, 20.0)).points).distance(Polygon(WALL))
    assert far >= ROBOT.footprint_width_m / 2 + 1.0 - 1e-6 > near
