"""The planner's node budget: it never builds a visibility graph over ``MAX_PLANNER_NODES`` (the
build is quadratic in the nodes), and its count is an upper bound of the nodes it builds."""

from __future__ import annotations

import math
import random
from dataclasses import replace

import numpy as np
import pytest
from shapely.geometry import LineString, Point

import rover_ctl.navigation.planner as planner_module
from rover_ctl.config import PlannerParams, RobotParams
from rover_ctl.mission.validate import MAX_PLANNER_NODES, ring_vertices
from rover_ctl.navigation.planner import Circle, Fence, PathFollower, Planner, _polygons, _tangent, _tangent_pairs

ROBOT = RobotParams()
SEGMENTS = PlannerParams().circle_segments


def circle_grid(count: int, spacing_m: float = 6.0, radius_m: float = 1.0, east_m: float = 0.0) -> tuple[Circle, ...]:
    side = math.ceil(math.sqrt(count))
    return tuple(Circle((east_m + (i % side) * spacing_m, (i // side) * spacing_m), radius_m) for i in range(count))


AT_BUDGET = MAX_PLANNER_NODES // SEGMENTS
"""Exclusion circles that make exactly the budget at the default circle_segments."""


def test_a_fence_at_the_budget_is_built_and_planned_around():
    fence = Fence(exclusion_circles=circle_grid(AT_BUDGET))
    planner = Planner(PlannerParams(), ROBOT, fence)
    assert planner.node_count() == MAX_PLANNER_NODES == len(planner._nodes)
    path = planner.plan_leg((-5.0, 1.0), (50.0, 1.0))  # along a row of circles: it weaves round them
    assert path.ok and path.length_m > 55.0
    line = LineString(path.points)
    assert all(line.distance(Point(c.center_en)) > c.radius_m + planner.clearance_m - 1e-6 for c in fence.exclusion_circles)


def test_a_fence_over_the_budget_is_refused_without_building_the_graph(monkeypatch):
    def quadratic(*args):
        raise AssertionError("the graph was built")

    monkeypatch.setattr(planner_module, "_tangent_pairs", quadratic)
    planner = Planner(PlannerParams(), ROBOT, Fence(exclusion_circles=circle_grid(700)))
    path = planner.plan_leg((-5.0, -5.0), (-50.0, -5.0))  # the goal is nowhere near a circle
    assert not path.ok and path.points == ((-5.0, -5.0),)
    assert path.error == f"too complex to plan: {700 * SEGMENTS} nodes, max {MAX_PLANNER_NODES}"
    assert planner.plan_route((-5.0, -5.0), [(-50.0, -5.0)]).error == path.error
    assert planner.is_inside_fence((-5.0, -5.0)) and not planner.is_inside_fence((0.0, 0.0))  # the failsafe's test still works


def test_raising_circle_segments_at_run_time_refuses_the_next_plan_and_lowering_it_plans_again():
    params = PlannerParams()
    planner = Planner(params, ROBOT, Fence(exclusion_circles=circle_grid(20)))
    assert planner.plan_leg((-5.0, 1.0), (40.0, 1.0)).ok
    params.circle_segments = 64  # PLN_CIRCLE_SEGS's maximum: 20 x 64 = 1280 nodes
    assert planner.plan_leg((-5.0, 1.0), (40.0, 1.0)).error == f"too complex to plan: 1280 nodes, max {MAX_PLANNER_NODES}"
    assert len(planner._nodes) == 0
    params.circle_segments = 32
    assert planner.plan_leg((-5.0, 1.0), (40.0, 1.0)).ok and len(planner._nodes) == 640


def test_blocked_circles_over_the_budget_are_forgotten_oldest_first():
    planner = Planner(PlannerParams(), ROBOT, Fence(exclusion_circles=circle_grid(AT_BUDGET - 2, east_m=100.0)))
    for k in range(4):
        planner.block(float(k), (10.0 * k, 0.0))
    # Two fit: the two newest stay, and the plan goes round them.
    assert [c.center_en for _, c in planner._blocked] == [(20.0, 0.0), (30.0, 0.0)]
    assert planner.node_count() == MAX_PLANNER_NODES
    path = planner.plan_leg((15.0, 0.0), (35.0, 0.0))
    assert path.ok and path.length_m > 20.0


def test_a_fence_over_the_budget_alone_keeps_its_blocked_circles():
    planner = Planner(PlannerParams(), ROBOT, Fence(exclusion_circles=circle_grid(AT_BUDGET + 1, east_m=100.0)))
    planner.block(0.0, (10.0, 0.0))
    assert len(planner._blocked) == 1 and not planner.plan_leg((0.0, 0.0), (20.0, 0.0)).ok


def test_persistent_obstacles_over_the_budget_are_planned_without():
    """The follower's existing fallback: a plan that fails with persistent obstacles is made without them."""
    params = PlannerParams()
    planner = Planner(params, ROBOT, Fence(exclusion_circles=circle_grid(AT_BUDGET - 4, east_m=100.0)))
    follower = PathFollower(planner, params)
    squares = [((x, 5.0), (x + 1.0, 5.0), (x + 1.0, 6.0), (x, 6.0)) for x in range(0, 40, 4)]
    assert follower.set_persistent(squares)
    assert planner.node_count() > MAX_PLANNER_NODES
    guidance = follower.update(0.0, (0.0, 0.0), (30.0, 0.0))
    assert guidance.error is None and guidance.target_en is not None and guidance.path.ok


def test_the_count_bounds_the_nodes_of_random_fences_and_obstacles():
    rnd = random.Random(7)
    for trial in range(40):
        segments = rnd.choice([4, 8, 16, 32])
        spikes = rnd.randint(3, 30)
        star = tuple(
            ((60.0 if i % 2 == 0 else rnd.uniform(20.0, 55.0)) * math.cos(math.pi * i / spikes),
             (60.0 if i % 2 == 0 else rnd.uniform(20.0, 55.0)) * math.sin(math.pi * i / spikes))
            for i in range(2 * spikes)
        )  # fmt: skip
        zigzag = tuple((x * 2.0, 10.0 + (3.0 if x % 2 else 0.0)) for x in range(rnd.randint(2, 12))) + ((24.0, 0.0), (0.0, 0.0))
        zigzag = tuple((x - 12.0, y - 30.0) for x, y in zigzag)
        fence = Fence(
            inclusion_polygons=(star,) if trial % 2 else (tuple(reversed(star)),),
            exclusion_polygons=(zigzag,) if trial % 3 else (tuple(reversed(zigzag)),),
            exclusion_circles=tuple(Circle((rnd.uniform(-30, 30), rnd.uniform(-30, 30)), rnd.uniform(0.5, 4.0)) for _ in range(3)),
        )
        planner = Planner(replace(PlannerParams(), circle_segments=segments), ROBOT, fence, polygons=[((5.0, 5.0), (9.0, 5.0), (7.0, 8.0))])
        assert 0 < len(planner._nodes) <= planner.node_count(), trial
        # Each shape's own vertex count, after the planner's buffer, is within its ring's count.
        for poly, grown in ((star, False), (zigzag, True)):
            r = planner.clearance_m + planner_module.NODE_OFFSET_M
            quad = max(1, segments // 4)
            shape = planner_module.Polygon(poly).buffer(r if grown else -r, quad_segs=quad)
            built = sum(len(ring.coords) - 1 for part in _polygons(shape) for ring in (part.exterior, *part.interiors))
            assert built <= ring_vertices(poly, grown, segments), (trial, grown)


@pytest.mark.parametrize("block", [1, 7, 1 << 16])
def test_tangent_pairs_are_those_of_the_pairwise_test(monkeypatch, block):
    monkeypatch.setattr(planner_module, "PAIR_BLOCK", block)
    planner = Planner(PlannerParams(), ROBOT, Fence(exclusion_circles=circle_grid(6), exclusion_polygons=(((20.0, 20.0), (26.0, 21.0), (22.0, 25.0)),)))
    pts, prev, nxt = planner._pts, planner._prev, planner._next
    i, j = np.triu_indices(len(pts), k=1)
    useful = _tangent(pts[i], prev[i], nxt[i], pts[j]) & _tangent(pts[j], prev[j], nxt[j], pts[i])
    got_i, got_j = _tangent_pairs(pts, prev, nxt)
    assert np.array_equal(got_i, i[useful]) and np.array_equal(got_j, j[useful])
