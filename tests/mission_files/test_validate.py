"""Validation warnings (loaded, listed) and errors (refused) on the model and on files."""

from __future__ import annotations

import pytest

from rover_ctl.config import RobotParams
from rover_ctl.mission.files import load_mission
from rover_ctl.mission.model import FRAME_GLOBAL, FRAME_MISSION, Cmd, Home, Mission, MissionItem
from rover_ctl.mission.validate import validate

MAX_MPS = RobotParams().max_speed_mps


def wp(lat: float = -35.3629, lon: float = 149.1652) -> MissionItem:
    return MissionItem(Cmd.NAV_WAYPOINT, x=lat, y=lon)


def test_speeds_above_the_rover_maximum_are_warned_as_clamped(shared_dir):
    path = shared_dir / "missions" / "ardupilot_rover1.txt"
    loaded = load_mission(path)
    assert loaded.warnings == [
        f"{path}:3: DO_CHANGE_SPEED to 5 m/s is above the rover's maximum {MAX_MPS:.2f} m/s: clamped to {MAX_MPS:.2f} m/s",
        f"{path}:13: DO_CHANGE_SPEED to 5 m/s is above the rover's maximum {MAX_MPS:.2f} m/s: clamped to {MAX_MPS:.2f} m/s",
    ]
    # the model keeps what the file asks for (lossless); the executor applies the limit
    assert [item.param2 for item in loaded.mission.items if item.command == Cmd.DO_CHANGE_SPEED] == [5.0, 1.0, 5.0]
    assert load_mission(path, max_speed_mps=6.0).warnings == []


def test_unsupported_commands_are_listed_with_what_the_rover_does(tmp_path):
    path = tmp_path / "m.waypoints"
    path.write_text(
        "QGC WPL 110\n"
        "0\t0\t0\t16\t0\t0\t0\t0\t-35.363261\t149.165230\t584\t1\n"
        "1\t0\t3\t16\t0\t0\t0\t0\t-35.3629\t149.16523\t0\t1\n"
        "2\t0\t0\t183\t1\t1500\t0\t0\t0\t0\t0\t1\n"
        "3\t0\t3\t17\t0\t0\t0\t0\t-35.3627\t149.16553\t0\t1\n"
        "4\t0\t0\t20\t0\t0\t0\t0\t0\t0\t0\t1\n"
    )
    loaded = load_mission(path)
    assert loaded.warnings == [
        f"{path}:4: DO_SET_SERVO (183) is not supported by this rover: skipped, the rover goes on with the next item",
        f"{path}:5: NAV_LOITER_UNLIM (17) is not supported by this rover: skipped, its position is not visited; "
        "use NAV_WAYPOINT (16) or NAV_LOITER_TIME (19)",
    ]
    assert [item.command for item in loaded.mission.items] == [16, 183, 17, 20]  # nothing dropped


def test_model_messages_use_wire_seq_without_labels():
    mission = Mission(
        items=[
            wp(),
            MissionItem(Cmd.DO_CHANGE_SPEED, FRAME_MISSION, param1=1, param2=3.0, param3=-1),
            MissionItem(Cmd.DO_JUMP, FRAME_MISSION, param1=7, param2=1),
            MissionItem(4242, FRAME_MISSION),
        ],
        home=Home(-35.363261, 149.165230, 584.0),
    )
    errors, warnings = validate(mission, max_speed_mps=2.0)
    assert errors == ["mission item 3: DO_JUMP to item 7, which does not exist (items are 1-4)"]
    assert warnings == [
        "mission item 2: DO_CHANGE_SPEED to 3 m/s is above the rover's maximum 2.00 m/s: clamped to 2.00 m/s",
        "mission item 4: command 4242 is not supported by this rover: skipped, the rover goes on with the next item",
    ]


@pytest.mark.parametrize(
    ("item", "message"),
    [
        (wp(lat=-90.5), "mission item 1: latitude -90.5 out of range [-90, 90]"),
        (wp(lon=180.25), "mission item 1: longitude 180.25 out of range [-180, 180]"),
        (MissionItem(Cmd.NAV_LOITER_TIME, FRAME_MISSION, param1=5), "mission item 1: NAV_LOITER_TIME needs a global frame for its position, got frame 2"),
        (MissionItem(Cmd.DO_JUMP, FRAME_MISSION, param1=1.5, param2=1), "mission item 1: DO_JUMP to item 1.5, which does not exist (items are 1-1)"),
    ],
)
def test_item_errors(item, message):
    assert validate(Mission(items=[item]), MAX_MPS)[0] == [message]


def test_supported_mission_is_clean():
    mission = Mission(
        items=[
            wp(),
            MissionItem(Cmd.NAV_LOITER_TIME, param1=3, x=-35.3628, y=149.1653),
            MissionItem(Cmd.CONDITION_DELAY, FRAME_MISSION, param1=2),
            MissionItem(Cmd.DO_CHANGE_SPEED, FRAME_MISSION, param1=1, param2=MAX_MPS, param3=-1),
            MissionItem(Cmd.DO_JUMP, FRAME_MISSION, param1=1, param2=-1),
            MissionItem(Cmd.NAV_RETURN_TO_LAUNCH, FRAME_MISSION),
        ],
        home=Home(-35.363261, 149.165230, 584.0),
    )
    assert validate(mission, MAX_MPS) == ([], [])


def test_fence_with_two_return_points_and_wrong_items():
    fence = [
        MissionItem(Cmd.NAV_FENCE_RETURN_POINT, x=1.0, y=2.0),
        MissionItem(Cmd.NAV_FENCE_RETURN_POINT, x=1.0, y=2.0),
        MissionItem(Cmd.NAV_WAYPOINT, FRAME_GLOBAL, x=1.0, y=2.0),
    ]
    errors, _ = validate(Mission(fence=fence), MAX_MPS)
    assert errors == [
        "fence item 2: NAV_WAYPOINT (16) is not a fence item",
        "fence item 0: the fence has 2 return points (at most 1)",
    ]
