"""``summarize``: the figures ``rover-ctl mission check`` prints."""

from __future__ import annotations

from pathlib import Path

import pytest

from rover_ctl.mission.files import load_mission, summarize
from rover_ctl.mission.summary import nominal_duration_s
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


def _zigzag(legs: int, leg_m: float, **first) -> Mission:
    """Home at CMAC, then ``legs`` waypoints zigzagging north-east ``leg_m`` apart."""
    from rover_ctl.estimation.frame import LocalFrame
    from rover_ctl.mission.model import Home

    frame = LocalFrame(-35.363261, 149.165230, 584.0)
    step = leg_m / 2 ** 0.5
    items = []
    for i in range(1, legs + 1):
        lat, lon = frame.to_geodetic(step * (i % 2), step * i)
        items.append(MissionItem(Cmd.NAV_WAYPOINT, x=lat, y=lon, **(first if i == 1 else {})))
    return Mission(items=items, home=Home(-35.363261, 149.165230, 584.0))


def test_nominal_duration_is_the_route_at_cruise_speed():
    mission = _zigzag(83, 10.0)  # 830 m
    assert summarize(mission).total_length_m == pytest.approx(830.0, abs=0.5)
    assert nominal_duration_s(mission, cruise_speed_mps=1.2, max_speed_mps=1.5) == pytest.approx(830.0 / 1.2, rel=1e-3)
    assert nominal_duration_s(mission, cruise_speed_mps=2.0, max_speed_mps=1.5) == pytest.approx(830.0 / 1.5, rel=1e-3)


def test_nominal_duration_counts_holds_and_speed_changes():
    mission = _zigzag(2, 10.0, param1=7.0)  # hold 7 s at the first waypoint
    slow = Mission(items=[MissionItem(Cmd.DO_CHANGE_SPEED, FRAME_MISSION, param2=0.5), *mission.items,
                          MissionItem(Cmd.CONDITION_DELAY, FRAME_MISSION, param1=3.0),
                          MissionItem(Cmd.DO_CHANGE_SPEED, FRAME_MISSION, param2=-1.0),  # unchanged
                          MissionItem(Cmd.NAV_RETURN_TO_LAUNCH, FRAME_MISSION)], home=mission.home)  # fmt: skip
    back_m = summarize(slow).total_length_m - 20.0
    assert nominal_duration_s(mission, 1.0, 1.5) == pytest.approx(20.0 + 7.0, rel=1e-3)
    assert nominal_duration_s(slow, 1.0, 1.5) == pytest.approx((20.0 + back_m) / 0.5 + 7.0 + 3.0, rel=1e-3)
    assert nominal_duration_s(Mission(), 1.0, 1.5) == 0.0
    nan_hold = Mission(items=[MissionItem(Cmd.CONDITION_DELAY, FRAME_MISSION, param1=float("nan"))])
    assert nominal_duration_s(nan_hold, 1.0, 1.5) == 0.0
