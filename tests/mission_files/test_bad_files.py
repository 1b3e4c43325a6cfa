"""The malformed corpus (tests/mission_files/bad/): every file is refused whole, with the expected
one-line message naming the file and the line (or the .plan item) and what is wrong."""

from __future__ import annotations

from pathlib import Path

import pytest

from rover_ctl.mission.files import MissionFileError, load_mission

BAD = Path(__file__).resolve().parent / "bad"

# file name -> its first error, after the "path" prefix
EXPECTED = {
    "bad_header.waypoints": ":1: bad header 'QGC WPL 100': expected 'QGC WPL 110'",
    "no_header.waypoints": ":1: bad header '0\\t0\\t0\\t16\\t0.000000\\t0.000000\\t0.000000\\t0.00': expected 'QGC WPL 110'",
    "empty.waypoints": ":1: empty file",
    "header_only.waypoints": ":2: no items after the header (a mission file needs at least the home row)",
    "not_utf8.waypoints": ":2: not a text file (invalid UTF-8 at byte 12)",
    "wrong_column_count.waypoints": (
        ":3: expected 12 columns (seq current frame command param1-4 lat lon alt autocontinue), got 11"
    ),
    "non_numeric_latitude.waypoints": ":3: column 9 (latitude/x) is not a number: 'abc'",
    "non_integer_command.waypoints": ":3: column 4 (command) is not a whole number: '16.5'",
    "bad_current_flag.waypoints": ":3: column 2 (current) must be 0 or 1, got 2",
    "infinite_param.waypoints": ":3: column 5 (param1) is infinite",
    "seq_out_of_order.waypoints": ":4: seq 3 out of order (expected 2)",
    "home_not_a_waypoint.waypoints": ":2: row 0 must be the home position (command 16), got command 20",
    "latitude_out_of_range.waypoints": ":3: latitude 95 out of range [-90, 90]",
    "longitude_out_of_range.waypoints": ":3: longitude 200 out of range [-180, 180]",
    "waypoint_without_position.waypoints": ":3: latitude is missing (NaN)",
    "jump_to_missing_item.waypoints": ":5: DO_JUMP to item 9, which does not exist (items are 1-3)",
    "jump_to_itself.waypoints": ":4: DO_JUMP to itself",
    "jump_bad_repeat.waypoints": ":4: DO_JUMP repeat count -3 is not a whole number >= -1",
    "negative_delay.waypoints": ":4: CONDITION_DELAY time -5 s must be >= 0",
    "fence_item_in_mission.waypoints": (
        ":4: command 5003 does not belong in a mission file "
        "(missions, fences (5000-5004) and rally points (5100) are separate WPL files)"
    ),
    "fence_vertex_count_mismatch.txt": ":2: inclusion polygon declares 4 vertices but has 3",
    "fence_polygon_too_few_vertices.txt": ":2: exclusion polygon vertex count 2 must be a whole number >= 3",
    "fence_circle_zero_radius.txt": ":2: fence circle radius 0 m must be > 0 (as the float32 sent)",
    "fence_latitude_out_of_range.txt": ":2: latitude -91 out of range [-90, 90]",
    "rally_wrong_column_count.txt": (
        ":1: expected 7 columns (RALLY latitude longitude altitude break_alt land_dir flags), got 4"
    ),
    "rally_non_numeric.txt": ":1: altitude is not a number: 'low'",
    "rally_latitude_out_of_range.txt": ":1: latitude 140.071553 out of range [-90, 90]",
    "rally_mixed_lines.txt": ":2: expected a line 'RALLY lat lon alt break_alt land_dir flags', got 'FENCE'",
    "invalid_json.plan": ":59: invalid JSON: Expecting property name enclosed in double quotes (column 5)",
    "top_level_array.plan": ": expected a JSON object at the top, got an array",
    "wrong_file_type.plan": ': fileType is "Mission", expected "Plan"',
    "missing_mission.plan": ": missing 'mission'",
    "old_mission_version.plan": (
        ": mission version 1 is not supported (expected 2; re-save the plan with a current QGroundControl)"
    ),
    "complex_survey_item.plan": (
        ": mission.items[1]: complex item 'survey' is not supported: expand it into waypoints in QGroundControl first"
    ),
    "unknown_item_type.plan": ': mission.items[0]: unknown item type "Waypoint" (expected "SimpleItem")',
    "params_wrong_length.plan": ": mission.items[1].params: expected an array of 7 numbers or nulls",
    "command_not_a_number.plan": ': mission.items[0].command: expected a whole number, got "16"',
    "param_not_a_number.plan": ': mission.items[1].params[5]: expected a number, got "-105.2292"',
    "latitude_out_of_range.plan": ": mission.items[0]: latitude 91.5 out of range [-90, 90]",
    "jump_to_unknown_jump_id.plan": ": mission.items[2]: DO_JUMP to doJumpId 7, which no item has",
    "fence_circle_bad_center.plan": ": geoFence.circles[0].circle.center: expected [lat, lon], got [40.0716]",
    "fence_polygon_two_vertices.plan": (
        ": geoFence.polygons[0].polygon[0]: inclusion polygon vertex count 2 must be a whole number >= 3"
    ),
    "rally_point_missing_altitude.plan": (
        ": rallyPoints.points[0]: expected [lat, lon, alt], got [40.0716, -105.2297]"
    ),
    "unknown_format.mission": (
        ":1: unknown mission file format (starts with \"<mission><wp lat='1' lon='2'/></mission>\"): "
        "expected 'QGC WPL 110', a QGroundControl .plan (JSON) or MAVProxy RALLY lines"
    ),
}


def test_every_bad_file_has_an_expected_message():
    assert sorted(p.name for p in BAD.iterdir()) == sorted(EXPECTED)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_bad_file_is_refused_with_its_message(name):
    path = BAD / name
    with pytest.raises(MissionFileError) as refused:
        load_mission(path)
    assert str(refused.value) == f"{path}{EXPECTED[name]}"
    assert refused.value.errors[0] == str(refused.value)
    assert all(error.startswith(str(path)) and "\n" not in error for error in refused.value.errors)


def test_all_problems_are_listed(tmp_path):
    path = tmp_path / "many.waypoints"
    path.write_text(
        "QGC WPL 110\n"
        "0\t0\t0\t16\t0\t0\t0\t0\t-35.363261\t149.165230\t584\t1\n"
        "1\t0\t3\t16\t0\t0\t0\t0\tnorth\t149.165230\t0\t1\n"
        "2\t0\t3\t16\t0\t0\t0\t0\t-35.36\n"
        "3\t0\t3\t16\t0\t0\t0\t0\t-35.36\t149.16\t0\t7\n"
    )
    with pytest.raises(MissionFileError) as refused:
        load_mission(path)
    assert refused.value.errors == [
        f"{path}:3: column 9 (latitude/x) is not a number: 'north'",
        f"{path}:4: expected 12 columns (seq current frame command param1-4 lat lon alt autocontinue), got 9",
        f"{path}:5: column 12 (autocontinue) must be 0 or 1, got 7",
    ]


def test_missing_file_and_directory(tmp_path):
    with pytest.raises(MissionFileError, match=r"nope\.waypoints: no such file$"):
        load_mission(tmp_path / "nope.waypoints")
    with pytest.raises(MissionFileError, match="is a directory, not a mission file$"):
        load_mission(tmp_path)
