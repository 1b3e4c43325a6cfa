"""Signing against a real daemon (``rover-ctl run`` with a key, the emulator behind it, lockstep):
MAVProxy without the key and a ground station with another key change nothing (and the first
is sent nothing); MAVProxy after ``signing setup PASSPHRASE`` uploads a mission, arms and starts it."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest
from mission_protocol.test_interop import MavProxy

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mav  # noqa: E402

from rover_ctl.app.sim import SimOptions, SimRun  # noqa: E402
from rover_ctl.mavlink.mission_client import MissionClient  # noqa: E402
from rover_ctl.mavlink.signing import key_from_passphrase  # noqa: E402
from rover_ctl.mission.files import load_mission  # noqa: E402
from rover_ctl.mission.model import Mission  # noqa: E402
from rover_ctl.vocabulary import RoverMode  # noqa: E402

pytestmark = [pytest.mark.sitl, pytest.mark.interop]

ROOT = Path(__file__).resolve().parents[2]
LOOP = ROOT / "missions" / "cmac_loop.waypoints"
JUMP = ROOT / "missions" / "cmac_jump.waypoints"
PASSPHRASE = "rover-ctl-test-passphrase"
"""One word: MAVProxy takes the first word after ``signing setup``."""
NEGATIVE_WAIT_S = 3.0
"""Wall seconds a refused client is given to take effect (it must not)."""


def _mavproxy(run: SimRun, workdir: Path) -> MavProxy:
    workdir.mkdir()
    return MavProxy(run.gcs_port, workdir)


def _stored(run: SimRun):
    """The daemon's mission, read back with the sim's own (signed) ground station."""
    return run.gcs.download()


def test_only_a_ground_station_with_the_key_changes_anything(tmp_path):
    options = SimOptions(mission=LOOP, out=tmp_path / "run", timeout_s=120.0, signing_key=key_from_passphrase(PASSPHRASE))
    with SimRun(options) as run:
        assert run.wait_for(lambda p: p.position_en is not None, wall_timeout_s=20.0)
        before = _stored(run)

        # MAVProxy without the key: nothing it sends is taken, and it is sent nothing (on udpin the
        # daemon sends only to ground stations whose frames passed the signature check).
        stranger = _mavproxy(run, tmp_path / "stranger")
        try:
            stranger.wait_for("Telemetry log", timeout_s=20.0)
            stranger.send(f"wp load {JUMP}")
            stranger.send("arm throttle")
            stranger.send("mode AUTO")
            assert run.wait_for(lambda p: p.armed or p.mode != RoverMode.HOLD, wall_timeout_s=NEGATIVE_WAIT_S) is False
            with pytest.raises(AssertionError, match="never printed"):
                stranger.wait_for("Detected vehicle", timeout_s=1.0)
        finally:
            stranger.close()

        # A ground station signing with another key.
        impostor = MissionClient(run.gcs_url, signing_key=key_from_passphrase("not the passphrase"), source_component=191)
        try:
            impostor.conn.mav.command_long_send(1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            impostor.conn.mav.command_long_send(1, 1, mav.MAV_CMD_DO_SET_MODE, 0, 1, RoverMode.AUTO, 0, 0, 0, 0, 0)
            impostor.conn.mav.mission_clear_all_send(1, 1, mav.MAV_MISSION_TYPE_ALL)
            assert run.wait_for(lambda p: p.armed or p.mode != RoverMode.HOLD, wall_timeout_s=NEGATIVE_WAIT_S) is False
        finally:
            impostor.close()
        assert _stored(run).same_as(before)
        assert not run.progress.armed and run.progress.mode == RoverMode.HOLD
        daemon_log = (tmp_path / "run" / "daemon.log").read_text()
        assert "dropped an unsigned or wrongly signed frame" in daemon_log

        # MAVProxy with the passphrase: upload, arm, AUTO.
        owner = _mavproxy(run, tmp_path / "owner")
        try:
            owner.send("module load signing")
            owner.send(f"signing setup {PASSPHRASE}")  # the daemon answers signed frames only
            owner.wait_for("Setup signing key")
            owner.wait_for("Detected vehicle 1:1", timeout_s=20.0)
            owner.send(f"wp load {JUMP}")
            owner.wait_for("TYPE_MISSION: ACCEPTED", timeout_s=20.0)
            owner.send("arm throttle")
            owner.wait_for("ARM_DISARM: ACCEPTED", timeout_s=20.0)
            owner.send("mode AUTO")
            owner.wait_for("AUTO>", timeout_s=20.0)
            assert run.wait_for(lambda p: p.armed and p.mode == RoverMode.AUTO, wall_timeout_s=10.0)
        finally:
            owner.close()
        uploaded = _stored(run)  # its home is the vehicle's, as an autopilot reports it
        assert Mission(items=uploaded.items).same_as(Mission(items=load_mission(JUMP).mission.items))


def test_run_refuses_to_start_without_a_required_key(tmp_path):
    import subprocess

    result = subprocess.run([sys.executable, "-m", "rover_ctl", "run", "--require-signing", "--signing-key-file",
                             str(tmp_path / "missing.key"), "--mission-store", ""],
                            capture_output=True, text=True, timeout=30)  # fmt: skip
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        "rover-ctl: error: --require-signing: no signing key (gcs.signing_key_path); run: rover-ctl signing setup PASSPHRASE"
    ]


def test_signing_setup_writes_the_key_mavproxy_makes(tmp_path):
    import subprocess

    key_file = tmp_path / "state" / "signing.key"
    result = subprocess.run([sys.executable, "-m", "rover_ctl", "signing", "setup", PASSPHRASE, "--key-file", str(key_file)],
                            capture_output=True, text=True, timeout=30)  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert key_file.read_text().strip() == key_from_passphrase(PASSPHRASE).hex()
    assert key_file.stat().st_mode & 0o777 == 0o600
    bad = tmp_path / "bad.key"
    bad.write_text("")
    result = subprocess.run([sys.executable, "-m", "rover_ctl", "mission", "upload", str(LOOP), "--signing-key", f"@{tmp_path / 'nope'}",
                             "--connect", "udpout:127.0.0.1:9"], capture_output=True, text=True, timeout=30)  # fmt: skip
    assert result.returncode == 2 and result.stderr.startswith("rover-ctl: error: --signing-key @") and len(result.stderr.splitlines()) == 1


def test_a_failed_key_write_leaves_no_copy_and_remove_says_when_there_was_none(tmp_path, capsys):
    """Writing over a folder failed at the rename and left ``.sign.key.<pid>.tmp`` holding the key;
    removing a key that was never there said it was removed."""
    from rover_ctl.cli import main

    folder = tmp_path / "sign.key"
    folder.mkdir()
    assert main(["signing", "setup", PASSPHRASE, "--key-file", str(folder)]) == 2
    assert capsys.readouterr().err == f"rover-ctl: error: {folder}: is a directory, not a signing key\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sign.key"] and not any(folder.iterdir())
    assert main(["signing", "remove", "--key-file", str(tmp_path / "none.key")]) == 0
    assert "no signing key at" in capsys.readouterr().out


def test_signing_never_overwrites_or_deletes_a_file_that_is_not_a_key(tmp_path, capsys):
    """``signing remove --key-file mission.waypoints`` deleted the mission; ``setup`` replaced it."""
    from rover_ctl.cli import main

    victim = tmp_path / "victim.waypoints"
    victim.write_bytes(LOOP.read_bytes())
    for action in (["setup", PASSPHRASE], ["remove"]):
        assert main(["signing", *action, "--key-file", str(victim)]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"rover-ctl: error: {victim}: exists and is not a signing key") and err.count("\n") == 1, err
        assert victim.read_bytes() == LOOP.read_bytes()
    key_file = tmp_path / "signing.key"
    assert main(["signing", "setup", "first passphrase", "--key-file", str(key_file)]) == 0
    assert main(["signing", "setup", PASSPHRASE, "--key-file", str(key_file)]) == 0  # a key is replaced
    assert key_file.read_text().strip() == key_from_passphrase(PASSPHRASE).hex()
    assert main(["signing", "remove", "--key-file", str(key_file)]) == 0 and not key_file.exists()


def test_unusable_passphrases_and_key_files_are_one_line_errors(tmp_path, capsys):
    from rover_ctl.cli import main

    empty = tmp_path / "empty.key"
    empty.write_text("\nsecond line\n")
    cases = [
        (["signing", "setup", "\udcff", "--key-file", str(tmp_path / "k")], "signing passphrase: not valid UTF-8 text"),
        (["mission", "upload", str(LOOP), "--signing-key", f"@{empty}", "--connect", "udpout:127.0.0.1:9"],
         f"--signing-key @{empty}: the file's first line is empty"),
        (["mission", "upload", str(LOOP), "--signing-key", "@/dev/zero", "--connect", "udpout:127.0.0.1:9"],
         "--signing-key @/dev/zero: cannot read: not a regular file"),
    ]
    for argv, message in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.startswith(f"rover-ctl: error: {message}") and err.count("\n") == 1, err
    assert not (tmp_path / "k").exists()
