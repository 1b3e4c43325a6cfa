"""Global planner: shortest paths around fences and obstacles, carrot and cross-track, re-planning."""

from __future__ import annotations

import math

import pytest
from shapely.geometry import LineString, Point, Polygon

from rover_ctl.config import PlannerParams, RobotParams
from rover_ctl.estimation.frame import LocalFrame
from rover_ctl.mission.model import MissionItem
from rover_ctl.navigation.planner import Circle, Fence, Path, PathFollower, Planner

PARAMS = PlannerParams()
ROBOT = RobotParams()
CLEARANCE_M = ROBOT.footprint_width_m / 2 + PARAMS.clearance_margin_m
TOL_M = 1e-6


def clearance_to(path: Path, geometry) -> float:
    return LineString(path.points).distance(geometry)


def test_straight_line_when_nothing_is_in_the_way():
    path = Planner(PARAMS, ROBOT).plan_leg((0, 0), (30, 40))
    assert path.ok and path.points == ((0, 0), (30, 40))
    assert path.length_m == pytest.approx(50.0)


def test_path_goes_around_a_circle_with_clearance_and_near_shortest():
    circle = Circle((10.0, 0.0), 2.0)
    path = Planner(PARAMS, ROBOT, Fence(exclusion_circles=(circle,))).plan_leg((0, 0), (20, 0))
    assert path.ok
    assert clearance_to(path, Point(circle.center_en)) >= circle.radius_m + CLEARANCE_M - TOL_M
    # Shortest way around a disc of radius R = r + c: two tangents and an arc.
    R = circle.radius_m + CLEARANCE_M
    tangent = math.sqrt(10.0**2 - R**2)
    arc = R * (math.pi - 2 * math.acos(R / 10.0))
    assert tangent * 2 + arc <= path.length_m <= (tangent * 2 + arc) * 1.02


def test_path_goes_around_a_polygon_obstacle_with_clearance():
    wall = ((10.0, -8.0), (12.0, -8.0), (12.0, 3.0), (10.0, 3.0))
    path = Planner(PARAMS, ROBOT, polygons=[wall]).plan_leg((0, 0), (20, 0))
    assert path.ok
    assert clearance_to(path, Polygon(wall)) >= CLEARANCE_M - TOL_M
    # The short way is over the top of the wall (it ends at north 3, not south -8).
    assert max(n for _, n in path.points) > 3.0
    assert min(n for _, n in path.points) >= -TOL_M


def test_path_stays_inside_a_concave_inclusion_fence():
    # A U-shaped field: the straight line from one arm to the other leaves the fence.
    u_shape = ((0, 0), (30, 0), (30, 30), (20, 30), (20, 10), (10, 10), (10, 30), (0, 30))
    planner = Planner(PARAMS, ROBOT, Fence(inclusion_polygons=(u_shape,)))
    path = planner.plan_leg((5, 25), (25, 25))
    assert path.ok
    shrunk = Polygon(u_shape).buffer(-CLEARANCE_M + TOL_M)
    assert shrunk.covers(LineString(path.points))
    assert all(planner.is_inside_fence(p) for p in path.points)
    assert path.length_m > 2 * 15  # down one arm and up the other


def test_ardupilot_path_planning_fence(shared_dir):
    """ArduPilot's own rover path-planning test fence: inclusion polygon, exclusion polygon, exclusion circle."""
    items = []
    for line in (shared_dir / "missions/ardupilot_rover_path_planning_fence.txt").read_text().splitlines()[1:]:
        f = line.split("\t")
        items.append(MissionItem(int(f[3]), int(f[2]), *map(float, f[4:11])))
    frame = LocalFrame(40.071377, -105.229790, 1584.0)
    fence = Fence.from_items(items, frame.to_enu)
    assert len(fence.inclusion_polygons) == 1 and len(fence.exclusion_polygons) == 1 and len(fence.exclusion_circles) == 1
    planner = Planner(PARAMS, ROBOT, fence)
    # The mission's waypoint (ardupilot_rover_path_planning_mission.txt), from home.
    goal = frame.to_enu(40.073799, -105.229156)
    path = planner.plan_leg((0.0, 0.0), goal)
    assert path.ok, path.error
    line = LineString(path.points)
    assert Polygon(fence.inclusion_polygons[0]).buffer(-CLEARANCE_M + TOL_M).covers(line)
    assert line.distance(Polygon(fence.exclusion_polygons[0])) >= CLEARANCE_M - TOL_M
    circle = fence.exclusion_circles[0]
    assert line.distance(Point(circle.center_en)) >= circle.radius_m + CLEARANCE_M - TOL_M
    # The straight line leaves the fence: the path winds through the fence's narrows (about
    # 456 m for a 274 m crow-flight distance) without detours beyond that.
    assert not Polygon(fence.inclusion_polygons[0]).covers(LineString([(0, 0), goal]))
    assert 1.5 * math.dist((0, 0), goal) < path.length_m < 1.8 * math.dist((0, 0), goal)
    assert not planner.is_inside_fence(circle.center_en)
    assert not planner.is_inside_fence((-100.0, 0.0))


def test_unreachable_goals_give_an_error_not_an_exception():
    fence = Fence(inclusion_polygons=(((0, 0), (50, 0), (50, 50), (0, 50)),), exclusion_circles=(Circle((25, 25), 3),))
    planner = Planner(PARAMS, ROBOT, fence)
    inside_exclusion = planner.plan_leg((5, 5), (25, 26))
    assert not inside_exclusion.ok and "exclusion" in inside_exclusion.error
    outside = planner.plan_leg((5, 5), (60, 10))
    assert not outside.ok and "outside the inclusion fence" in outside.error
    # A goal in a pocket sealed off by a ring of exclusion zones.
    ring = tuple(Circle((40 + 6 * math.cos(a), 10 + 6 * math.sin(a)), 2.0) for a in [k * math.pi / 6 for k in range(12)])
    sealed = Planner(PARAMS, ROBOT, Fence(exclusion_circles=ring)).plan_leg((0, 0), (40, 10))
    assert not sealed.ok and "cannot be reached" in sealed.error


def test_start_outside_the_fence_goes_straight_back_in():
    fence = Fence(inclusion_polygons=(((0, 0), (50, 0), (50, 50), (0, 50)),))
    planner = Planner(PARAMS, ROBOT, fence)
    path = planner.plan_leg((-3, 20), (25, 20))
    assert path.ok
    assert path.points[0] == (-3, 20)
    assert planner.is_inside_fence(path.points[1]) and path.points[1][0] == pytest.approx(CLEARANCE_M, abs=0.05)


def test_goal_in_the_clearance_band_is_reached_by_a_last_segment():
    circle = Circle((10.0, 0.0), 2.0)
    planner = Planner(PARAMS, ROBOT, Fence(exclusion_circles=(circle,)))
    goal = (10.0, 2.4)  # 0.4 m from the zone: inside the clearance band, outside the zone
    path = planner.plan_leg((0, 0), goal)
    assert path.ok and path.points[-1] == goal
    assert LineString(path.points[:-1]).distance(Point(circle.center_en)) >= circle.radius_m + CLEARANCE_M - TOL_M


def test_carrot_and_cross_track():
    path = Path(((0.0, 0.0), (10.0, 0.0), (10.0, 10.0)))
    assert path.length_m == 20.0
    s, xt = path.project((4.0, 1.5))
    assert s == pytest.approx(4.0) and xt == pytest.approx(1.5)  # left of an eastward leg is positive
    assert path.project((4.0, -1.5))[1] == pytest.approx(-1.5)
    assert path.carrot((4.0, 1.5), 3.0) == pytest.approx((7.0, 0.0))
    assert path.carrot((9.0, 0.0), 3.0) == pytest.approx((10.0, 2.0))  # round the corner
    assert path.carrot((10.0, 9.0), 3.0) == pytest.approx((10.0, 10.0))  # clamped at the goal
    # A window keeps the projection on the current stretch of a path that folds back.
    hairpin = Path(((0.0, 0.0), (10.0, 0.0), (10.0, 1.0), (0.0, 1.0)))
    assert hairpin.project((2.0, 0.6))[0] == pytest.approx(19.0)  # nearest: the way back
    assert hairpin.project((2.0, 0.6), 0.0, 5.0)[0] == pytest.approx(2.0)


def test_follower_replans_when_pushed_off_the_path():
    params = PlannerParams(lookahead_m=2.0, replan_off_path_m=3.0, replan_min_interval_s=1.0)
    follower = PathFollower(Planner(params, ROBOT), params)
    first = follower.update(0.0, (0.0, 0.0), (40.0, 0.0))
    assert first.replanned and first.target_en == pytest.approx((2.0, 0.0))
    on_path = follower.update(0.1, (10.0, 1.0), (40.0, 0.0))
    assert not on_path.replanned and on_path.target_en == pytest.approx((12.0, 0.0))
    assert on_path.cross_track_m == pytest.approx(1.0) and on_path.remaining_m == pytest.approx(30.0)
    # Off the path within the re-plan interval of the first plan: wait; after it: re-plan.
    assert not follower.update(0.2, (20.0, -5.0), (40.0, 0.0)).replanned
    pushed = follower.update(1.2, (20.0, -5.0), (40.0, 0.0))
    assert pushed.replanned and pushed.path.points[0] == (20.0, -5.0)
    assert not follower.update(1.3, (20.0, -1.0), (40.0, 0.0)).replanned  # back on the new path
    # A new goal always re-plans.
    assert follower.update(1.4, (21.0, -1.0), (40.0, 10.0)).replanned


def test_follower_routes_around_a_blocked_leg_and_forgets_it():
    params = PlannerParams(blocked_ttl_s=10.0, blocked_radius_m=0.6)
    follower = PathFollower(Planner(params, ROBOT), params)
    assert follower.update(0.0, (0.0, 0.0), (20.0, 0.0)).path.length_m == pytest.approx(20.0)
    follower.block(1.0, (3.0, 0.0))
    around = follower.update(1.0, (1.0, 0.0), (20.0, 0.0))
    assert around.replanned and around.path.length_m > 19.0
    assert clearance_to(around.path, Point(3.0, 0.0)) >= 0.6 + CLEARANCE_M - TOL_M
    expired = follower.update(11.5, (2.0, 2.0), (20.0, 0.0))
    assert expired.replanned and len(expired.path.points) == 2


def test_follower_reports_unreachable_goal_and_retries():
    params = PlannerParams(replan_min_interval_s=1.0)
    follower = PathFollower(Planner(params, ROBOT, Fence(exclusion_circles=(Circle((10, 0), 2),))), params)
    guidance = follower.update(0.0, (0.0, 0.0), (10.0, 0.5))
    assert guidance.target_en is None and "exclusion" in guidance.error
    assert not follower.update(0.5, (0.0, 0.0), (10.0, 0.5)).replanned
    assert follower.update(1.0, (0.0, 0.0), (10.0, 0.5)).replanned


@pytest.mark.parametrize(
    "items, message",
    [
        ([MissionItem(5001, param1=4, x=0, y=0)] * 3, "declares 4 vertices"),
        ([MissionItem(5002, param1=2, x=0, y=0)] * 2, ">= 3"),
        ([MissionItem(5004, param1=0, x=0, y=0)], "radius"),
        ([MissionItem(16)], "not a fence item"),
        ([MissionItem(5001, param1=4, x=x, y=y) for x, y in [(0, 0), (1, 1), (0, 1), (1, 0)]], "intersects itself"),
    ],
)
def test_bad_fence_items_are_left_out_with_the_item_named(items, message, caplog):
    fence, ignored = Fence.checked(items, lambda lat, lon: (lon, lat))
    assert fence == Fence()
    assert ignored and ignored[0].startswith("fence item 0") and message in ignored[0]
    assert Fence.from_items(items, lambda lat, lon: (lon, lat)) == Fence()  # never raises: logs instead
    assert message in caplog.text


def test_only_the_invalid_parts_of_a_fence_are_left_out():
    square = [MissionItem(5002, param1=4, x=x, y=y) for x, y in [(0, 0), (0, 1e-4), (1e-4, 1e-4), (1e-4, 0)]]
    items = [MissionItem(5004, param1=0, x=0, y=0), *square, MissionItem(5004, param1=3, x=1, y=1)]
    fence, ignored = Fence.checked(items, lambda lat, lon: (lon * 1e5, lat * 1e5))
    assert len(fence.exclusion_polygons) == 1 and fence.exclusion_circles == (Circle((1e5, 1e5), 3.0),)
    assert ignored == ["fence item 0: fence circle radius 0 m must be > 0 (as the float32 sent)"]


def test_reduced_visibility_graph_is_as_short_as_the_full_one():
    """Oracle: Dijkstra over every visible vertex pair (no tangency pruning) on random fields."""
    import networkx as nx
    import numpy as np

    rng = np.random.default_rng(7)
    box = ((-10, -25), (60, -25), (60, 25), (-10, 25))
    for _ in range(3):
        circles = tuple(Circle(tuple(rng.uniform((5, -20), (45, 20))), float(rng.uniform(0.5, 3))) for _ in range(8))
        triangles = [tuple(map(tuple, rng.uniform((5, -20), (45, 20)) + rng.uniform(0, 6, (3, 2)))) for _ in range(4)]
        planner = Planner(PARAMS, ROBOT, Fence(inclusion_polygons=(box,), exclusion_circles=circles), polygons=triangles)
        pts = planner._pts
        i, j = np.triu_indices(len(pts), k=1)
        full = nx.Graph()
        visible = planner._visible(pts[i], pts[j])
        full.add_weighted_edges_from((int(a), int(b), math.dist(pts[a], pts[b])) for a, b in zip(i[visible], j[visible]))
        for _ in range(3):
            start, goal = tuple(rng.uniform((-8, -20), (-2, 20))), tuple(rng.uniform((50, -20), (58, 20)))
            path = planner.plan_leg(start, goal)
            if not path.ok:
                continue
            for name, end in (("s", start), ("g", goal)):
                seen = np.flatnonzero(planner._visible(np.repeat([end], len(pts), axis=0), pts))
                full.add_weighted_edges_from((name, int(k), math.dist(end, pts[k])) for k in seen)
            if planner._visible(np.array([start]), np.array([goal]))[0]:
                full.add_edge("s", "g", weight=math.dist(start, goal))
            assert path.length_m == pytest.approx(nx.shortest_path_length(full, "s", "g", weight="weight"), rel=1e-4)
            full.remove_nodes_from(["s", "g"])


def test_inclusion_circle_fence_is_exact_and_kept_with_clearance():
    field_ = Circle((0.0, 0.0), 20.0)
    wall = ((-2.0, -19.0), (2.0, -19.0), (2.0, 15.0), (-2.0, 15.0))  # leaves a gap only at the north rim
    planner = Planner(PARAMS, ROBOT, Fence(inclusion_circles=(field_,), exclusion_polygons=(wall,)))
    assert planner.is_inside_fence((0.0, 19.99)) and not planner.is_inside_fence((0.0, 20.01))
    assert not planner.is_inside_fence((0.0, 0.0))
    path = planner.plan_leg((-10.0, 0.0), (10.0, 0.0))
    assert path.ok
    assert Point(0, 0).buffer(20.0 - CLEARANCE_M + TOL_M, quad_segs=64).covers(LineString(path.points))
    assert clearance_to(path, Polygon(wall)) >= CLEARANCE_M - TOL_M
    assert max(n for _, n in path.points) > 15.0


def test_non_finite_positions_give_an_error():
    planner = Planner(PARAMS, ROBOT, Fence(exclusion_circles=(Circle((5, 0), 1),)))
    assert "not a finite position" in planner.plan_leg((math.nan, 0.0), (10.0, 0.0)).error
    assert "not a finite position" in planner.plan_leg((0.0, 0.0), (math.inf, 0.0)).error


def test_carrot_is_pulled_back_at_a_bend_so_the_line_to_it_stays_near_the_path():
    path = Path(((0.0, 0.0), (10.0, 0.0), (10.0, 10.0)))
    assert path.carrot((4.0, 0.0), 3.0, max_cut_m=0.25) == pytest.approx((7.0, 0.0))  # no bend between
    for here in [(8.5, 0.0), (9.0, 0.0), (9.5, 0.3), (8.0, -1.0)]:
        target = path.carrot(here, 3.0, max_cut_m=0.25)
        cut = LineString([here, target]).distance(Point(10.0, 0.0))
        assert cut <= 0.25 + 1e-3, (here, target, cut)
        assert target[0] == pytest.approx(10.0) and target[1] > 0.0  # still round the corner, not at it
    assert path.carrot((9.0, 0.0), 3.0) == pytest.approx((10.0, 2.0))  # unlimited: the plain carrot


def test_carrot_stops_at_the_first_bend_when_nothing_beyond_it_is_in_line():
    # A hairpin: past its first corner every point ahead is far off the straight line from here.
    path = Path(((0.0, 0.0), (5.0, 0.0), (5.0, 0.2), (0.0, 0.2)))
    target = path.carrot((4.0, 0.0), 3.0, max_cut_m=0.05)
    assert math.dist(target, (5.0, 0.0)) < 0.1
    assert path.carrot((4.0, 0.0), 3.0, max_cut_m=2.0) == pytest.approx((3.2, 0.2))  # loose: the plain carrot


def test_follower_pulls_its_carrot_back_around_a_tight_detour():
    """Backed off from an unseen obstacle, the rover plans round a circle blocked just ahead (the
    stuck failsafe's re-plan): the plain 3 m carrot would have it cut through the circle, the
    follower's carrot keeps the straight line to it within PLN_CORNER_CUT of the planned bends."""
    params = PlannerParams()
    planner = Planner(params, ROBOT)
    planner.block(0.0, (0.0, 1.05), 0.6)
    follower = PathFollower(planner, params)
    guidance = follower.update(0.0, (0.0, 0.0), (0.0, 10.0))
    assert guidance.path.ok and len(guidance.path.points) > 3
    touching = Point(0.0, 1.05).buffer(0.6 + ROBOT.footprint_width_m / 2)
    plain = guidance.path.point_at(params.lookahead_m)
    assert LineString([(0.0, 0.0), plain]).intersects(touching)  # what the plain carrot asked for
    line = LineString([(0.0, 0.0), guidance.target_en])
    assert not line.intersects(touching)
