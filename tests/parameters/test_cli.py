"""``rover-ctl params``: the table from this machine's files or a running daemon, .parm export and
all-or-nothing import; bad values on the command line are one line and exit status 2."""

from __future__ import annotations

import subprocess
import sys

import pytest
from mission_protocol.helpers import LinkThread

from rover_ctl.cli import main
from rover_ctl.config import Config, GcsParams
from rover_ctl.mavlink.gcs import DefaultHandlers
from rover_ctl.parameters import MAVLINK


@pytest.fixture
def store(tmp_path):
    return ["--mission-store", str(tmp_path / "state" / "mission.json")]


def test_show_prints_every_parameter_with_value_default_units_range_description(capsys, store):
    assert main(["params", *store, "--set", "WP_SPEED=0.9"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == ["name", "value", "default", "units", "range", "description"]
    assert len(lines) == 1 + len(MAVLINK)
    wp_speed = next(line for line in lines if line.startswith("WP_SPEED "))
    assert wp_speed.split()[:6] == ["WP_SPEED", "0.9*", "1.2", "m/s", "0", ".."] and "ArduPilot WP_SPEED" in wp_speed
    assert "[read-only: start]" in next(line for line in lines if line.startswith("SYSID_THISMAV "))


def test_export_then_import_round_trips_and_a_bad_file_changes_nothing(tmp_path, capsys, store):
    out = tmp_path / "all.parm"
    assert main(["params", "export", str(out), *store]) == 0
    assert len([line for line in out.read_text().splitlines() if not line.startswith("#")]) == len(MAVLINK)
    changed = tmp_path / "changed.parm"
    changed.write_text(out.read_text().replace("WP_SPEED         1.2", "WP_SPEED         0.6") + "FS_ACTION,2\n")
    assert main(["params", "import", str(changed), *store]) == 0
    assert "2 changed" in capsys.readouterr().out
    stored = (tmp_path / "state" / "params.parm").read_text()
    assert "WP_SPEED         0.6" in stored and "FS_ACTION        2" in stored
    bad = tmp_path / "bad.parm"
    bad.write_text("WP_RADIUS 3\nWP_SPEED 99\n")
    assert main(["params", "import", str(bad), *store]) == 2
    err = capsys.readouterr().err
    assert err == f"rover-ctl: error: {bad}:2: WP_SPEED: 99 is out of range 0 .. 20 m/s\n"
    assert (tmp_path / "state" / "params.parm").read_text() == stored  # the good first line was not applied
    assert main(["params", *store]) == 0
    assert any(line.startswith("WP_SPEED ") and "0.6*" in line for line in capsys.readouterr().out.splitlines())


def test_connect_shows_exports_and_imports_on_a_running_daemon(tmp_path, udp_port, capsys):
    config = Config()
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=GcsParams(heartbeat_period_s=0.2, param_send_rate_hz=1000.0),
                    handlers=DefaultHandlers(config)):  # fmt: skip
        url = ["--connect", f"udpout:127.0.0.1:{udp_port}"]
        out = tmp_path / "live.parm"
        assert main(["params", "export", str(out), *url]) == 0
        assert f"exported {len(MAVLINK)} parameters" in capsys.readouterr().out
        out.write_text(out.read_text().replace("WP_RADIUS        2", "WP_RADIUS        4.5"))
        assert main(["params", "import", str(out), *url]) == 0
        assert config.executor.acceptance_radius_m == 4.5
        (tmp_path / "ro.parm").write_text("SYSID_THISMAV 9\n")
        assert main(["params", "import", str(tmp_path / "ro.parm"), *url]) == 2
        assert "SYSID_THISMAV is read-only over MAVLink" in capsys.readouterr().err
        assert main(["params", *url]) == 0
        assert any(line.startswith("WP_RADIUS ") and "4.5*" in line for line in capsys.readouterr().out.splitlines())


@pytest.mark.parametrize("flag", ["WP_SPEED=99", "link.rangefinders=0,2,9", "executor.acceptance_radius_m=nan"])
def test_run_refuses_a_bad_value_in_one_line_with_status_2(flag):
    done = subprocess.run([sys.executable, "-m", "rover_ctl", "run", "--set", flag, "--mission-store", ""],
                          capture_output=True, text=True, timeout=60)  # fmt: skip
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and done.stderr.startswith("rover-ctl: error: --set: ")


def test_lists_from_the_command_line(capsys, store):
    for value in ("0,2,4,6", "[0,2,4,6]", "[]", "learn"):
        assert main(["params", *store, "--set", f"link.rangefinders={value}"]) == 0
        row = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("RNG_PRESENT "))
        assert row.split()[1].rstrip("*") == {"[]": "0", "learn": "-1"}.get(value, "85")
