"""``summarize``: the figures ``rover-ctl mission check`` prints."""

from __future__ import annotations

from pathlib import Path

import pytest

from rover_ctl.mission.files import load_mission, summarize
from rover_ctl.mission.model import FRAME_MISSION, Cmd, Mission, MissionItem

MISSIONS = Path(__file__).resolve().parents[2] / "missions"


def test_boulder_fence_summary():
    summary = summarize(load_mission(MISSIONS / "boulder_fence.plan").mission)
    assert (summary.items, summary.nav_waypoints, summary.legs) == (5, 3, 4)
    assert (summary.fence_inclusion_polygons, summary.fence_exclusion_polygons) == (1, 1)
    assert (summary.fence_inclusion_circles, summary.fence_exclusion_circles, summary.fence_return_point) == (0, 0, False)
    assert summary.rally_points == 1
    assert summary.commands == {"DO_CHANGE_SPEED": 1, "NAV_WAYPOINT": 3, "NAV_RETURN_TO_LAUNCH": 1}
    # home (0,0) -> (10,25) -> (60,25) -> (60,-10) -> home, metres
    assert summary.total_length_m == pytest.approx(26.93 + 50 + 35 + 60.83, abs=0.1)
    assert str(summary).splitlines() == [
        "items: 5 (3 navigation waypoints)",
        f"route: 4 legs, {summary.total_length_m:.1f} m",
        "commands: DO_CHANGE_SPEED x1, NAV_WAYPOINT x3, NAV_RETURN_TO_LAUNCH x1",
        "fence: 1 inclusion / 1 exclusion polygons, 0 inclusion / 0 exclusion circles",
        "rally points: 1",
    ]


def test_waypoint_at_zero_means_here_and_adds_no_leg():
    mission = Mission(
        items=[
            MissionItem(Cmd.NAV_WAYPOINT, x=0.0, y=0.0),
            MissionItem(Cmd.NAV_WAYPOINT, x=40.0, y=-105.0),
            MissionItem(Cmd.NAV_WAYPOINT, x=40.001, y=-105.0),
            MissionItem(Cmd.NAV_RETURN_TO_LAUNCH, FRAME_MISSION),  # no home: nowhere to return to
        ]
    )
    summary = summarize(mission)
    assert (summary.nav_waypoints, summary.legs) == (3, 1)
    assert summary.total_length_m == pytest.approx(111.03, abs=0.05)  # 0.001 deg of latitude at 40 N
    assert "(no home: from the first waypoint)" in str(summary)
