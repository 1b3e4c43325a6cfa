"""A fence too complex for the planner is an error of ``validate`` and ``rover-ctl mission check``
(the planner's node budget, ``MAX_PLANNER_NODES``)."""

from __future__ import annotations

import math

import pytest

from rover_ctl.cli import main
from rover_ctl.mission.files import load_mission, save_mission
from rover_ctl.mission.model import Mission, MissionItem, MissionType
from rover_ctl.mission.validate import FENCE_CIRCLE_SEGMENTS, MAX_PLANNER_NODES, fence_nodes, ring_vertices, validate
from rover_ctl.vocabulary import Cmd

LAT, LON = -35.363261, 149.165230
AT_BUDGET = MAX_PLANNER_NODES // FENCE_CIRCLE_SEGMENTS


def circles(count: int) -> list[MissionItem]:
    """``count`` exclusion circles of 1 m, 10 m apart in a row eastwards."""
    step = 10.0 / (111_320.0 * math.cos(math.radians(LAT)))
    return [MissionItem(Cmd.NAV_FENCE_CIRCLE_EXCLUSION, param1=1.0, x=LAT, y=LON + k * step) for k in range(count)]


def square(command: int = Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION, half_deg: float = 1e-3) -> list[MissionItem]:
    corners = ((-1, -1), (-1, 1), (1, 1), (1, -1))
    return [MissionItem(command, param1=4.0, x=LAT + a * half_deg, y=LON + b * half_deg) for a, b in corners]


def fence_errors(fence: list[MissionItem], **kwargs) -> list[str]:
    return validate(Mission(fence=fence), math.inf, parts=(MissionType.FENCE,), **kwargs)[0]


def test_a_fence_at_the_budget_is_valid_and_one_circle_more_is_too_complex():
    assert fence_nodes(circles(AT_BUDGET)) == MAX_PLANNER_NODES
    assert fence_errors(circles(AT_BUDGET)) == []
    (error,) = fence_errors(circles(AT_BUDGET + 1))
    nodes = (AT_BUDGET + 1) * FENCE_CIRCLE_SEGMENTS
    assert error == (
        f"fence item 0: the fence is too complex for the planner: {nodes} nodes, max {MAX_PLANNER_NODES} "
        f"({AT_BUDGET + 1} circles x {FENCE_CIRCLE_SEGMENTS} vertices, polygons 0)"
    )
    assert error.field == "size"  # the mission protocol's MAV_MISSION_NO_SPACE


def test_the_count_follows_circle_segments_and_none_leaves_it_to_the_planner():
    assert fence_errors(circles(12), circle_segments=64) == []
    assert "832 nodes" in fence_errors(circles(13), circle_segments=64)[0]
    assert fence_errors(circles(700), circle_segments=None) == []


def test_polygons_count_their_corners_and_the_arcs_the_planner_rounds_them_with():
    # An inclusion square is shrunk: its convex corners stay corners (4). An exclusion square is
    # grown: each 90 deg corner gets an arc of 90 / 22.5 + 1 = 5 more vertices at 16 segments.
    assert fence_nodes(square()) == 4
    assert fence_nodes(square(Cmd.NAV_FENCE_POLYGON_VERTEX_EXCLUSION)) == 24
    assert fence_nodes(square() + circles(3)) == 4 + 3 * FENCE_CIRCLE_SEGMENTS
    # The same ring either way round.
    ring = [(0.0, 0.0), (4.0, 0.0), (4.0, 3.0), (2.0, 1.0), (0.0, 3.0)]
    for grown in (True, False):
        assert ring_vertices(ring, grown, 16) == ring_vertices(ring[::-1], grown, 16)
    # Grown, its four convex corners get arcs; shrunk (an inclusion fence), its one concave corner.
    assert ring_vertices(ring, True, 16) > ring_vertices(ring, False, 16) > len(ring)


def test_a_fence_with_many_polygon_vertices_is_too_complex_too():
    ring = 200
    vertices = [
        MissionItem(Cmd.NAV_FENCE_POLYGON_VERTEX_EXCLUSION, param1=float(ring),
                    x=LAT + 1e-4 * math.sin(2 * math.pi * k / ring) * (1.0 if k % 2 else 0.5),
                    y=LON + 1e-4 * math.cos(2 * math.pi * k / ring) * (1.0 if k % 2 else 0.5))
        for k in range(ring)
    ]  # fmt: skip
    (error,) = fence_errors(vertices)
    assert "the fence is too complex for the planner" in error and "(0 circles x 16 vertices, polygons" in error


def test_an_invalid_fence_reports_its_own_problem_first():
    bad = [MissionItem(Cmd.NAV_FENCE_CIRCLE_EXCLUSION, param1=0.0, x=LAT, y=LON)] + circles(AT_BUDGET + 5)
    errors = fence_errors(bad)
    assert "radius" in errors[0] and "too complex" in errors[-1]


@pytest.mark.parametrize("suffix", [".waypoints", ".plan"])
def test_mission_check_refuses_a_fence_too_complex_in_one_line(tmp_path, capsys, suffix):
    path = tmp_path / f"fence{suffix}"
    save_mission(Mission(fence=circles(700)), path)
    assert main(["mission", "check", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert f"the fence is too complex for the planner: {700 * FENCE_CIRCLE_SEGMENTS} nodes, max {MAX_PLANNER_NODES}" in err
    assert err.startswith(f"rover-ctl: error: {path}")


def test_mission_check_accepts_a_fence_within_the_budget(tmp_path, capsys):
    path = tmp_path / "fence.plan"
    save_mission(Mission(fence=square() + circles(AT_BUDGET - 1)), path)
    assert main(["mission", "check", str(path)]) == 0
    assert len(load_mission(path).mission.fence) == 4 + AT_BUDGET - 1
