"""The foundation: config loading and the CLI shell."""

from __future__ import annotations

import subprocess
import sys

import pytest

from rover_ctl.config import Config, ConfigError, load_config


def test_defaults_are_the_papers_robot():
    cfg = Config()
    assert cfg.robot.track_m == pytest.approx(0.32)
    assert cfg.robot.wheel_radius_m == pytest.approx(0.07)
    # 200 rpm on a 0.07 m wheel is about 1.47 m/s.
    assert cfg.robot.max_speed_mps == pytest.approx(1.466, abs=1e-3)


def test_toml_and_overrides(tmp_path):
    path = tmp_path / "rover.toml"
    path.write_text('[robot]\ntrack_m = 0.5\n[link]\nvehicle_url = "udpin:127.0.0.1:14551"\n')
    cfg = load_config(path, ["link.source_system=42", "robot.max_wheel_rpm=150"])
    assert cfg.robot.track_m == 0.5
    assert cfg.link.vehicle_url == "udpin:127.0.0.1:14551"
    assert cfg.link.source_system == 42
    assert cfg.robot.max_wheel_rpm == 150.0


@pytest.mark.parametrize(
    "text, override, message",
    [
        ("[robot]\ntrak_m = 1\n", [], "unknown key 'trak_m'"),
        ("[nosuch]\nx = 1\n", [], "unknown key 'nosuch'"),
        ("[robot]\ntrack_m = 'wide'\n", [], "robot.track_m: expected a number"),
        ("[robot\n", [], "invalid TOML"),
        ("", ["link.source_system=2.5"], "link.source_system: 2.5 is not a whole number"),
        ("", ["nodot=1"], "expected section.key=value"),
        ("", ["executor.cruise_speed_mps=99"], r"--set: executor.cruise_speed_mps: 99 is out of range 0 \.\. 20 m/s \(WP_SPEED\)"),
        ("[executor]\nacceptance_radius_m = nan\n", [], r"executor.acceptance_radius_m: nan is not a finite number \(WP_RADIUS\)"),
        ("", ["WP_SPEED=inf"], "inf is not a finite number"),
        ("", ["link.rangefinders=0,2,9"], "list item '9' is not an orientation 0-7"),
        ("", ["failsafe.gcs_action=land"], "expected one of 0 continue, 1 rtl, 2 hold"),
        ("", ["NO_SUCH_PARAM=1"], "is no parameter name"),
        ("[gcs]\nmission_store_path = 3\n", [], "expected a string"),
    ],
)
def test_bad_config_is_one_clear_line(tmp_path, text, override, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message) as info:
        load_config(path, override)
    assert "\n" not in str(info.value)


def test_missing_config_file(tmp_path):
    with pytest.raises(ConfigError, match="no such config file"):
        load_config(tmp_path / "absent.toml")


def test_cli_help_and_bad_flag():
    ok = subprocess.run([sys.executable, "-m", "rover_ctl", "--help"], capture_output=True, text=True)
    assert ok.returncode == 0 and "rover-ctl" in ok.stdout
    bad = subprocess.run([sys.executable, "-m", "rover_ctl", "--no-such-flag"], capture_output=True, text=True)
    assert bad.returncode == 2 and "unrecognized arguments: --no-such-flag" in bad.stderr


@pytest.mark.parametrize(
    "args, message",
    [
        (["mission", "upload", "missions/cmac_jump.waypoints", "--timeout", "nan"], "--timeout: expected seconds in (0, 86400], got 'nan'"),
        (["mission", "download", "x.plan", "--timeout", "1e300"], "--timeout: expected seconds in (0, 86400]"),
        (["params", "--connect", "udpin:127.0.0.1:9", "--timeout", "-1"], "--timeout: expected seconds"),
        (["arm", "--source-system", "300"], "--source-system: expected a whole number in 1..255 (a MAVLink id; 0 addresses everyone), got '300'"),
        (["mode", "HOLD", "--source-component", "-1"], "--source-component: expected a whole number in 1..255"),
        (["sim", "missions/cmac_jump.waypoints", "--seed", "-1"], "--seed: expected a whole number >= 0 (a random seed), got '-1'"),
        (["tune", "default", "--scenarios", "open", "--seed", "x"], "--seed: expected a whole number, got 'x'"),
        (["tune", "default", "--scenarios", "open", "--seed", "4294967296"], "--seed: expected a whole number in 1..4294967295"),
        (["tune", "default", "--scenarios", "open", "--seed", "0"], "0 would seed from the clock"),
    ],
)
def test_flag_values_out_of_range_are_one_line_before_anything_runs(capsys, args, message):
    """They reached a socket timeout, struct packing or numpy's seeding and ended in a traceback."""
    from rover_ctl.cli import main

    with pytest.raises(SystemExit) as exit_info:
        main(args)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
