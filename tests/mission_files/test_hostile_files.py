"""Mutated mission files that once ended in a traceback: now a one-line error and exit 2."""

from __future__ import annotations

import pytest

from rover_ctl.cli import main

WPL_HOME = "0\t1\t0\t16\t0\t0\t0\t0\t-35.363261\t149.165230\t584.0\t1\n"


@pytest.mark.parametrize(
    "name, text, first_error",
    [
        ("huge_int.waypoints", "QGC WPL 110\n" + WPL_HOME.replace("\t16\t", "\t" + "9" * 400 + "\t"), "column 4 (command)"),
        ("huge_seq.waypoints", "QGC WPL 110\n" + "1" * 5000 + WPL_HOME[1:], "column 1 (seq)"),
        ("huge_float.waypoints", "QGC WPL 110\n" + WPL_HOME.replace("-35.363261", "9" * 400), "column 9 (latitude/x)"),
        ("huge_frame.waypoints", "QGC WPL 110\n" + WPL_HOME.replace("\t0\t16", "\t" + "7" * 30 + "\t16"), "frame"),
        ("nan_command.plan", '{"fileType": "Plan", "version": 1, "mission": {"version": 2, "items": '
         '[{"type": "SimpleItem", "command": NaN, "frame": 3, "params": [0, 0, 0, 0, 1, 2, 3]}]}}', "command"),
        ("inf_frame.plan", '{"fileType": "Plan", "version": 1, "mission": {"version": 2, "items": '
         '[{"type": "SimpleItem", "command": 16, "frame": Infinity, "params": [0, 0, 0, 0, 1, 2, 3]}]}}', "frame"),
        ("huge_command.plan", '{"fileType": "Plan", "version": 1, "mission": {"version": 2, "items": '
         '[{"type": "SimpleItem", "command": 1e30, "frame": 3, "params": [0, 0, 0, 0, 1, 2, 3]}]}}', "command"),
        ("huge_json_int.plan", '{"fileType": "Plan", "version": ' + "1" * 5000 + "}", "invalid JSON"),
        ("deep.plan", "[" * 100_000 + "]" * 100_000, "invalid JSON"),
        ("huge_int_param.plan", '{"fileType": "Plan", "version": 1, "mission": {"version": 2, "items": '
         '[{"type": "SimpleItem", "command": 16, "frame": 3, "params": [0, 0, 0, 0, ' + "9" * 400 + ', 2, 3]}]}}', "out of range (400 digits)"),
        ("huge_int_rally.plan", '{"fileType": "Plan", "version": 1, "mission": {"version": 2, "items": []}, '
         '"rallyPoints": {"version": 2, "points": [[' + "4" * 310 + ', 149.1, 10]]}}', "rallyPoints.points[0][0]"),
        ("empty_polygon.plan", '{"fileType": "Plan", "version": 1, "mission": {"version": 2, "items": []}, '
         '"geoFence": {"version": 2, "polygons": [{"polygon": [], "inclusion": true, "version": 1}]}}', "polygons[0].polygon: no vertices"),
        ("tiny_circle.plan", '{"fileType": "Plan", "version": 1, "mission": {"version": 2, "items": []}, "geoFence": {"version": 2, '
         '"circles": [{"circle": {"center": [-35.36, 149.16], "radius": 1e-300}, "inclusion": false, "version": 1}]}}', "radius 1e-300 m must be > 0"),
        ("version_true.plan", '{"fileType": "Plan", "version": true, "mission": {"version": 2, "items": []}}', "plan version true"),
        ("rally_array.plan", '{"fileType": "Plan", "version": 1, "mission": {"version": 2, "items": []}, "rallyPoints": []}',
         "rally_array.plan: rallyPoints: expected an object"),
        ("nan_latitude.plan", '{"fileType": "Plan", "version": 1, "mission": {"version": 2, "items": '
         '[{"type": "SimpleItem", "command": 16, "frame": 3, "params": [0, 0, 0, 0, NaN, 2, 3]}]}}', "latitude"),
    ],
)
def test_a_mutated_file_is_a_one_line_error_with_exit_2(tmp_path, capsys, name, text, first_error):
    path = tmp_path / name
    path.write_text(text)
    assert main(["mission", "check", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"rover-ctl: error: {path}") and first_error in err.splitlines()[0]
    assert "Traceback" not in err


def test_check_gives_the_first_error_and_counts_the_rest_or_lists_all(tmp_path, capsys):
    path = tmp_path / "three_bad.waypoints"
    rows = [f"{seq}\t0\t3\t16\t0\t0\t0\t0\t95.0\t149.1\t0\t1\n" for seq in (1, 2, 3)]
    path.write_text("QGC WPL 110\n" + WPL_HOME + "".join(rows))
    assert main(["mission", "check", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{path}:3: latitude 95 out of range" in err and "(and 2 more errors;" in err
    assert main(["mission", "check", "--all", str(path)]) == 2
    assert capsys.readouterr().err.count("latitude 95 out of range") == 3


def test_a_home_altitude_of_nan_is_driven_from_altitude_0(tmp_path):
    """``mission check`` accepts NaN for the home's altitude (MAVLink's "unset"); ``rover-ctl sim``
    then started nothing (its local frame refused NaN): the emulator now boots at altitude 0."""
    from rover_ctl.app.sim import SimOptions, SimRun

    path = tmp_path / "nan_home.waypoints"
    path.write_text("QGC WPL 110\n" + WPL_HOME.replace("584.0", "nan") + "1\t0\t3\t16\t0\t0\t0\t0\t-35.3632\t149.1653\t0\t1\n")
    assert main(["mission", "check", str(path)]) == 0
    run = SimRun(SimOptions(mission=path, out=tmp_path / "run"))
    assert "--home=-35.363261,149.16523,0.0,0.0" in run._sitl_flags()
