"""Format details: WPL tolerance (spaces, CRLF, comments, Mission Planner home), .plan specifics
(null params, doJumpId, fence and rally), format detection, and atomic, refusing saves."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import pytest

from rover_ctl.mission.files import MissionFileError, load_mission, save_mission
from rover_ctl.mission.model import FRAME_GLOBAL, Cmd, Home, Mission, MissionItem
from rover_ctl.mission.plan import format_plan, parse_plan
from rover_ctl.mission.wpl import format_number, format_wpl, parse_wpl

HOME_ROW = "0\t0\t0\t16\t0.000000\t0.000000\t0.000000\t0.000000\t-35.363261\t149.165230\t584.000000\t1"
WP_ROW = "1\t0\t3\t16\t2.000000\t1.500000\t0.000000\t0.000000\t-35.362900\t149.165230\t0.000000\t1"


def test_wpl_reads_a_mission_with_home_current_and_autocontinue():
    current_no_autocontinue = "1\t1\t3\t16\t2.000000\t1.500000\t0.000000\t0.000000\t-35.362900\t149.165230\t0.000000\t0"
    parsed = parse_wpl(f"QGC WPL 110\n{HOME_ROW}\n{current_no_autocontinue}\n", "m")
    assert parsed.errors == []
    assert parsed.mission.home == Home(-35.363261, 149.165230, 584.0)
    (item,) = parsed.mission.items
    assert (item.command, item.frame, item.param1, item.param2) == (16, 3, 2.0, 1.5)
    assert (item.lat_deg, item.lon_deg, item.autocontinue) == (-35.3629, 149.16523, False)
    assert parsed.labels[(0, 0)] == "m:3"


@pytest.mark.parametrize(
    "text",
    [
        f"QGC WPL 110\r\n{HOME_ROW}\r\n{WP_ROW}\r\n",  # Windows line endings (Mission Planner)
        f"QGC WPL 110\n{HOME_ROW.replace(chr(9), '   ')}\n{WP_ROW.replace(chr(9), ' ')}\n",  # spaces
        f"\ufeffQGC WPL 110\n# home\n{HOME_ROW}\n\n# first leg\n{WP_ROW}\n\n",  # BOM, comments, blanks
    ],
    ids=["crlf", "spaces", "comments"],
)
def test_wpl_tolerates_what_other_tools_write(text):
    parsed = parse_wpl(text, "m")
    assert parsed.errors == []
    assert parsed.mission.same_as(parse_wpl(f"QGC WPL 110\n{HOME_ROW}\n{WP_ROW}\n", "m").mission)


def test_mission_planner_home_command_zero_and_no_home():
    mp = parse_wpl(f"QGC WPL 110\n0\t1\t0\t0\t0\t0\t0\t0\t-35.363261\t149.165230\t584\t1\n{WP_ROW}\n", "m")
    assert mp.errors == [] and mp.mission.home == Home(-35.363261, 149.165230, 584.0)
    unset = parse_wpl(f"QGC WPL 110\n0\t0\t0\t16\t0\t0\t0\t0\t0\t0\t0\t1\n{WP_ROW}\n", "m")
    assert unset.errors == [] and unset.mission.home is None


def test_format_number_is_exact_and_short():
    assert format_number(5.0) == "5.000000"
    assert format_number(-35.3629005) == "-35.3629005"
    assert format_number(11085.900391) == "11085.900391"
    assert float(format_number(0.1 + 0.2)) == 0.1 + 0.2
    assert format_number(math.nan) == "nan"


def test_wpl_nan_params_round_trip():
    mission = Mission(items=[MissionItem(Cmd.NAV_WAYPOINT, param4=math.nan, x=1.0, y=2.0)], home=Home(1.0, 2.0, 3.0))
    text = format_wpl(mission.items, 0, mission.home)
    assert "\tnan\t" in text
    assert parse_wpl(text, "m").mission.same_as(mission)


def test_plan_null_params_are_nan_and_written_back_as_null(shared_dir):
    text = (shared_dir / "missions" / "px4_rover_mission_1.plan").read_text()
    mission = parse_plan(text, "p").mission
    assert all(math.isnan(item.param4) for item in mission.items)
    written = json.loads(format_plan(mission))
    assert [item["params"][3] for item in written["mission"]["items"]] == [None, None, None]
    assert written["mission"]["plannedHomePosition"] == [47.3977419, 8.5455944, 489.0]


def plan_doc(items: list[dict], **extra) -> str:
    doc = {
        "fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
        "mission": {"version": 2, "firmwareType": 3, "items": items, "plannedHomePosition": [40.07, -105.23, 1584]},
    }  # fmt: skip
    doc.update(extra)
    return json.dumps(doc)


def simple(command: int, jump_id: int, params: list) -> dict:
    return {"type": "SimpleItem", "command": command, "frame": 3, "autoContinue": True, "doJumpId": jump_id, "params": params}


def test_plan_do_jump_targets_the_doJumpId_not_the_position():
    items = [
        simple(16, 10, [0, 0, 0, None, 40.071, -105.229, 0]),
        simple(16, 20, [0, 0, 0, None, 40.072, -105.229, 0]),
        simple(177, 30, [20, 2, 0, 0, 0, 0, 0]),
    ]
    parsed = parse_plan(plan_doc(items), "p")
    assert parsed.errors == []
    assert parsed.mission.items[2].param1 == 2.0  # doJumpId 20 is the second item: wire seq 2
    # written back with doJumpId = seq, so QGC maps it to the same item
    written = json.loads(format_plan(parsed.mission))["mission"]["items"]
    assert [item["doJumpId"] for item in written] == [1, 2, 3] and written[2]["params"][0] == 2


def test_plan_fence_circles_return_point_and_rally():
    fence = {
        "version": 2,
        "polygons": [{"inclusion": True, "version": 1, "polygon": [[40.070, -105.231], [40.070, -105.228], [40.073, -105.228]]}],
        "circles": [{"inclusion": False, "version": 1, "circle": {"center": [40.0715, -105.2295], "radius": 12.5}}],
        "breachReturn": [40.0712, -105.2297, 5],
    }
    rally = {"version": 2, "points": [[40.0711, -105.2296, 10]]}
    parsed = parse_plan(plan_doc([], geoFence=fence, rallyPoints=rally), "p")
    assert parsed.errors == []
    mission = parsed.mission
    assert [p.inclusion for p in mission.fence_polygons()] == [True]
    assert mission.fence_polygons()[0].vertices_latlon == ((40.070, -105.231), (40.070, -105.228), (40.073, -105.228))
    (circle,) = mission.fence_circles()
    assert (circle.center_latlon, circle.radius_m, circle.inclusion) == ((40.0715, -105.2295), 12.5, False)
    assert mission.fence_return_point == (40.0712, -105.2297, 5.0)
    assert [(r.command, r.lat_deg, r.lon_deg, r.alt_m) for r in mission.rally] == [(5100, 40.0711, -105.2296, 10.0)]
    assert parse_plan(format_plan(mission), "p").mission.same_as(mission)


def test_format_detected_from_content_not_only_extension(tmp_path):
    plan_as_txt = tmp_path / "plan.txt"
    plan_as_txt.write_text(plan_doc([simple(16, 1, [0, 0, 0, 0, 40.071, -105.229, 0])]))
    assert load_mission(plan_as_txt).format == "plan"
    wpl_as_plan = tmp_path / "wpl.plan"
    wpl_as_plan.write_text(f"QGC WPL 110\n{HOME_ROW}\n{WP_ROW}\n")
    assert load_mission(wpl_as_plan).format == "wpl"


def test_fence_only_mission_saves_as_fence_wpl(shared_dir, tmp_path):
    fence = load_mission(shared_dir / "missions" / "ardupilot_rover_path_planning_fence.txt").mission
    assert fence.home is None and not fence.items
    polygons = fence.fence_polygons()
    assert [(len(p.vertices_latlon), p.inclusion) for p in polygons] == [(19, True), (4, False)]
    assert [(c.radius_m, c.inclusion) for c in fence.fence_circles()] == [(20.0, False)]
    out = tmp_path / "fence.waypoints"
    save_mission(fence, out)
    assert out.read_text().splitlines()[1].split("\t")[3] == "5001"  # no home row


def test_wpl_refuses_two_lists_and_leaves_the_old_file(tmp_path):
    out = tmp_path / "m.waypoints"
    out.write_text("old content\n")
    mission = Mission(
        items=[MissionItem(Cmd.NAV_WAYPOINT, x=1.0, y=2.0)],
        fence=[MissionItem(Cmd.NAV_FENCE_CIRCLE_EXCLUSION, FRAME_GLOBAL, param1=5.0, x=1.0, y=2.0)],
    )
    with pytest.raises(MissionFileError, match=r"m\.waypoints: a WPL file holds one list but this mission has 1 mission, 1 fence items"):
        save_mission(mission, out)
    assert out.read_text() == "old content\n"
    assert os.listdir(tmp_path) == ["m.waypoints"]


def test_save_unknown_extension_and_missing_directory(tmp_path):
    with pytest.raises(MissionFileError, match=r"unknown extension '\.kml': use \.plan, \.waypoints or \.txt"):
        save_mission(Mission(), tmp_path / "m.kml")
    with pytest.raises(MissionFileError, match="does not exist"):
        save_mission(Mission(), tmp_path / "nodir" / "m.plan")


def test_save_is_atomic_when_writing_fails(tmp_path, monkeypatch):
    out = tmp_path / "m.plan"
    save_mission(Mission(home=Home(1.0, 2.0, 3.0)), out)
    before = out.read_bytes()

    def failing_fsync(fd):
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(os, "fsync", failing_fsync)
    with pytest.raises(OSError):
        save_mission(Mission(home=Home(4.0, 5.0, 6.0)), out)
    assert out.read_bytes() == before
    assert os.listdir(tmp_path) == ["m.plan"]


def test_save_replaces_the_file(tmp_path):
    out = tmp_path / "m.waypoints"
    for lat in (1.0, 2.0):
        save_mission(Mission(items=[MissionItem(Cmd.NAV_WAYPOINT, x=lat, y=2.0)], home=Home(1.0, 2.0)), out)
    assert load_mission(out).mission.items[0].lat_deg == 2.0
    assert sorted(os.listdir(tmp_path)) == ["m.waypoints"]


def test_empty_mission_writes_a_home_row(tmp_path):
    out = tmp_path / "empty.waypoints"
    save_mission(Mission(), out)
    assert out.read_text().splitlines()[0] == "QGC WPL 110"
    loaded = load_mission(out).mission
    assert loaded.items == [] and loaded.home is None


def test_plan_written_is_what_qgc_expects(tmp_path):
    mission = load_mission(Path(__file__).resolve().parents[2] / "missions" / "boulder_fence.plan").mission
    doc = json.loads(format_plan(mission))
    assert doc["fileType"] == "Plan" and doc["version"] == 1
    assert doc["mission"]["version"] == 2 and doc["mission"]["vehicleType"] == 10 and doc["mission"]["firmwareType"] == 3
    waypoint = next(item for item in doc["mission"]["items"] if item["command"] == 16)
    assert waypoint["AltitudeMode"] == 1 and waypoint["Altitude"] == waypoint["params"][6]
    assert {p["inclusion"] for p in doc["geoFence"]["polygons"]} == {True, False}
