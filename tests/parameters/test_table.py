"""The parameter table: one declaration per tunable, names and ranges as ArduPilot users expect."""

from __future__ import annotations

import dataclasses
import math
import re

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from rover_ctl.config import Config, sections
from rover_ctl.parameters import BY_NAME, CONFIG_ONLY, MAVLINK, TABLE, Access, Kind, ParamError, format_parm, lookup, parse_parm, values


def test_every_config_field_is_a_parameter_or_a_text_setting():
    fields = {f"{name}.{f.name}" for name, section in sections(Config()).items() for f in dataclasses.fields(section)}
    declared = {p.key for p in TABLE}
    missing = sorted(fields - declared - CONFIG_ONLY)
    assert not missing, f"config fields without a parameter declaration (add them to rover_ctl/parameters.py): {missing}"
    assert declared <= fields and CONFIG_ONLY <= fields
    assert all(isinstance(getattr(getattr(Config(), k.split(".")[0]), k.split(".")[1]), str) for k in CONFIG_ONLY)


def test_names_fit_param_id_and_are_unique():
    names = [p.name for p in TABLE]
    assert len(names) == len(set(names))
    assert all(re.fullmatch(r"[A-Z][A-Z0-9_]{0,15}", n) for n in names), [n for n in names if len(n) > 16]


def test_ardupilot_names_where_ardupilot_has_them():
    expected = {"WP_RADIUS": "executor.acceptance_radius_m", "WP_SPEED": "executor.cruise_speed_mps",
                "RTL_SPEED": "executor.rtl_speed_mps", "FS_GCS_TIMEOUT": "failsafe.gcs_timeout_s",
                "FS_ACTION": "failsafe.gcs_action", "FENCE_ACTION": "failsafe.fence_action",
                "SYSID_THISMAV": "gcs.system_id", "WENC_RADIUS": "robot.wheel_radius_m",
                "SCHED_LOOP_RATE": "daemon.control_rate_hz"}  # fmt: skip
    assert {name: BY_NAME[name].key for name in expected} == expected


def test_defaults_lie_in_their_ranges_and_every_parameter_is_described():
    for p in TABLE:
        assert p.minimum <= p.default <= p.maximum, p.name
        p.decode(p.default)  # the default itself is accepted
        assert p.description and "\n" not in p.description, p.name


def test_whole_numbers_choices_and_masks_are_integer_types():
    assert BY_NAME["WP_SPEED"].mav_type == mav.MAV_PARAM_TYPE_REAL32
    assert BY_NAME["FS_ACTION"].mav_type == mav.MAV_PARAM_TYPE_INT8
    assert BY_NAME["SYSID_THISMAV"].mav_type == mav.MAV_PARAM_TYPE_INT16  # 1..255 does not fit INT8, as AP_Int16
    assert BY_NAME["GCS_MIS_MAX"].mav_type == mav.MAV_PARAM_TYPE_INT32
    assert all((p.mav_type == mav.MAV_PARAM_TYPE_REAL32) == (p.kind is Kind.FLOAT) for p in TABLE)


def test_choices_and_masks_map_as_ardupilot_numbers_them():
    fs, mask = BY_NAME["FS_ACTION"], BY_NAME["RNG_PRESENT"]
    assert [fs.decode(n) for n in (0.0, 1.0, 2.0)] == ["continue", "rtl", "hold"]
    assert BY_NAME["FENCE_ACTION"].decode(1.0) == "rtl" and BY_NAME["FENCE_ACTION"].decode(2) == "hold"
    assert mask.default == -1 and mask.decode(-1.0) == [-1] and mask.encode([-1]) == -1.0 and mask.parse("learn") == [-1]
    assert mask.decode(85.0) == [0, 2, 4, 6] and mask.encode([6, 0]) == 65
    assert mask.parse("0,2") == mask.parse("[0, 2]") == mask.parse([2, 0]) == [0, 2] and mask.parse("[]") == []
    assert mask.parse(5) == [0, 2] and fs.parse("hold") == "hold" and fs.parse("2") == "hold"


@pytest.mark.parametrize(
    "name, value, message",
    [
        ("WP_SPEED", 99.0, "99 is out of range 0 .. 20 m/s"),
        ("WP_SPEED", -0.1, "out of range"),
        ("WP_RADIUS", math.nan, "nan is not a finite number"),
        ("WP_RADIUS", math.inf, "inf is not a finite number"),
        ("FS_STUCK_TRIES", 2.5, "2.5 is not a whole number"),
        ("FS_ACTION", 3.0, "3 is not one of 0 continue, 1 rtl, 2 hold"),
        ("RNG_PRESENT", 256.0, "out of range"),
        ("RNG_PRESENT", -2.0, "out of range"),
        ("WP_SPEED", "fast", "expected a number"),
    ],
)
def test_refusals_say_why_in_one_line(name, value, message):
    with pytest.raises(ParamError, match=re.escape(message)) as info:
        BY_NAME[name].decode(value) if not isinstance(value, str) else BY_NAME[name].parse(value)
    assert "\n" not in str(info.value)


def test_values_and_lookup():
    config = Config()
    table = values(config)
    assert list(table) == [p.name for p in MAVLINK] and "CLI_RETRY" not in table
    assert table["WP_RADIUS"] == config.executor.acceptance_radius_m and table["RNG_PRESENT"] == -1.0
    assert lookup("wp_speed") is lookup("executor.cruise_speed_mps") is BY_NAME["WP_SPEED"] and lookup("nope") is None
    assert all(p.access is not Access.CONFIG for p in MAVLINK)


def test_parm_text_round_trips_and_a_bad_line_is_named():
    text = format_parm({"WP_SPEED": 1.5, "FS_ACTION": 2.0, "RNG_PRESENT": 5.0}, "a header")
    assert text.startswith("# a header\n") and "FS_ACTION        2\n" in text
    parsed = parse_parm(text + "WP_RADIUS,3  # Mission Planner's comma\n", "f.parm")
    assert {n: v for n, (_, v) in parsed.items()} == {"WP_SPEED": 1.5, "FS_ACTION": "hold", "RNG_PRESENT": [0, 2], "WP_RADIUS": 3.0}
    for bad, message in (("WP_SPEED 99\n", "f.parm:2: WP_SPEED: 99 is out of range"), ("NOPE 1\n", "f.parm:2: unknown parameter 'NOPE'"),
                         ("WP_SPEED\n", "f.parm:2: expected NAME VALUE"), ("WP_SPEED x\n", "f.parm:2: WP_SPEED: 'x' is not a number")):  # fmt: skip
        with pytest.raises(ParamError, match=re.escape(message)):
            parse_parm("# ok\n" + bad, "f.parm")
