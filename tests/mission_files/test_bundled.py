"""The bundled missions: the committed files are exactly what tests/mission_files/bundled.py
defines, they sit where the shared facts say (ENU offsets from home), and the boulder fence does
what it is for (waypoints inside the inclusion polygon, the exclusion zone across a leg)."""

from __future__ import annotations

import math

import pytest
from shapely.geometry import LineString, Point, Polygon

from mission_files.bundled import BUNDLED, MISSIONS
from rover_ctl.estimation.frame import LocalFrame
from rover_ctl.mission.files import load_mission, summarize
from rover_ctl.mission.model import Cmd
from rover_ctl.mission.plan import format_plan
from rover_ctl.mission.wpl import format_wpl

WIRE_ROUNDING_M = 0.02
"""1e-7 degree of latitude/longitude is at most ~1.1 cm."""


def enu_of_items(path):
    mission = load_mission(path).mission
    frame = LocalFrame(mission.home.lat_deg, mission.home.lon_deg, mission.home.alt_m)
    return mission, frame, [frame.to_enu(i.lat_deg, i.lon_deg) for i in mission.items if i.command == Cmd.NAV_WAYPOINT]


@pytest.mark.parametrize("name", sorted(BUNDLED))
def test_committed_file_is_what_the_definition_gives(name):
    mission = BUNDLED[name]()
    text = format_plan(mission) if name.endswith(".plan") else format_wpl(mission.items, 0, mission.home)
    assert (MISSIONS / name).read_text() == text
    assert load_mission(MISSIONS / name).warnings == []


def close_to(points, expected):
    return len(points) == len(expected) and all(
        math.dist(p, e) <= WIRE_ROUNDING_M for p, e in zip(points, expected)
    )


def test_cmac_loop_matches_the_shared_facts():
    mission, _, points = enu_of_items(MISSIONS / "cmac_loop.waypoints")
    assert (mission.home.lat_deg, mission.home.lon_deg, mission.home.alt_m) == (-35.363261, 149.165230, 584.0)
    assert close_to(points, [(0, 40), (30, 55), (55, 30), (35, 5)])
    assert mission.items[-1].command == Cmd.NAV_RETURN_TO_LAUNCH
    legs = [(0, 0), (0, 40), (30, 55), (55, 30), (35, 5), (0, 0)]
    expected_m = sum(math.dist(a, b) for a, b in zip(legs, legs[1:]))
    assert summarize(mission).total_length_m == pytest.approx(expected_m, abs=0.1)


def test_cmac_jump_matches_the_shared_facts():
    mission, _, points = enu_of_items(MISSIONS / "cmac_jump.waypoints")
    assert close_to(points, [(0, 15), (15, 15), (0, 0)])
    jump = mission.items[2]
    assert (jump.command, jump.param1, jump.param2) == (Cmd.DO_JUMP, 1.0, 1.0)  # back to the first WP, once


def test_boulder_fence_leaves_a_way_around_the_exclusion_zone():
    mission, frame, points = enu_of_items(MISSIONS / "boulder_fence.plan")
    assert (mission.home.lat_deg, mission.home.lon_deg, mission.home.alt_m) == (40.071377, -105.229790, 1584.0)
    polygons = {p.inclusion: Polygon([frame.to_enu(lat, lon) for lat, lon in p.vertices_latlon]) for p in mission.fence_polygons()}
    inclusion, exclusion = polygons[True], polygons[False]
    assert all(inclusion.contains(Point(p)) for p in [(0.0, 0.0), *points])
    assert LineString(points[:2]).crosses(exclusion)  # the straight leg is blocked...
    assert inclusion.contains(exclusion)
    free = inclusion.difference(exclusion)
    assert free.geom_type == "Polygon"  # ...but the free space stays connected around it
    extent_m = max(math.dist(a, b) for a in points for b in points)
    assert 40.0 <= extent_m <= 90.0
    assert len(mission.rally) == 1 and inclusion.contains(Point(frame.to_enu(mission.rally[0].lat_deg, mission.rally[0].lon_deg)))
