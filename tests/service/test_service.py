"""A service you can leave running: numbered run folders, tlogs on vehicle time, one-line start-up
errors with exit 2, pymavlink's chatter rate-limited, the one emulator launcher."""

from __future__ import annotations

import logging
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from support import free_port

from rover_ctl.app.logs import LATEST, Chatter, LogClock, LogDirError, new_run_folder, quiet_pymavlink, run_folders
from rover_ctl.cli import main
from sitl.launch import SitlError, rover_sitl

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent.parent
JUMP = ROOT / "missions" / "cmac_jump.waypoints"
ROVER_CTL = [sys.executable, "-m", "rover_ctl"]


# ---- run folders --------------------------------------------------------------------------------


def test_each_start_gets_the_next_numbered_folder_and_latest_follows(tmp_path):
    first = new_run_folder(tmp_path, max_total_mb=0)
    (first / "control.csv").write_text("t_s\n")
    second = new_run_folder(tmp_path, max_total_mb=0)
    assert (first.name, second.name) == ("00000001", "00000002")
    assert (first / "control.csv").read_text() == "t_s\n"  # the earlier run is untouched
    assert (tmp_path / LATEST).resolve() == second.resolve()
    (tmp_path / "00000041").mkdir()  # numbering continues after the highest, as ArduPilot's
    assert new_run_folder(tmp_path, max_total_mb=0).name == "00000042"


def test_oldest_runs_are_removed_past_the_budget_never_the_new_one(tmp_path):
    for _ in range(3):
        (new_run_folder(tmp_path, max_total_mb=0) / "vehicle.tlog").write_bytes(b"x" * 400_000)
    newest = new_run_folder(tmp_path, max_total_mb=1.0)  # 1.2 MB in three runs: the oldest goes
    assert [p.name for p in run_folders(tmp_path)] == ["00000002", "00000003", "00000004"]
    (newest / "vehicle.tlog").write_bytes(b"x" * 3_000_000)
    latest = new_run_folder(tmp_path, max_total_mb=0.1)  # everything older goes, the new run stays
    assert run_folders(tmp_path) == [latest]


def test_an_unwritable_log_dir_is_a_log_dir_error(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(LogDirError, match="log dir .*file/logs"):
        new_run_folder(blocker / "logs", max_total_mb=0)


# ---- tlog timestamps ----------------------------------------------------------------------------


def test_a_latest_that_is_not_our_link_is_refused_and_nothing_is_left(tmp_path):
    """A folder named ``latest`` made rename fail after the run folder and the new link were made:
    the message said "Is a directory" and every retry left another empty run and a stray link."""
    (tmp_path / LATEST).mkdir()
    for _ in range(2):
        with pytest.raises(LogDirError, match=r"latest is not the link this program keeps there"):
            new_run_folder(tmp_path, max_total_mb=0)
    assert [p.name for p in tmp_path.iterdir()] == [LATEST]


def test_a_log_dir_that_cannot_be_searched_is_a_log_dir_error(tmp_path, monkeypatch):
    """Path.exists() raises PermissionError under a folder we may not enter (Python 3.11): the
    check for a stray ``latest`` must give the one-line error too, not a traceback."""
    from pathlib import Path

    def denied(self, *args, **kwargs):
        raise PermissionError(13, "Permission denied", str(self))

    monkeypatch.setattr(Path, "exists", denied)
    with pytest.raises(LogDirError, match="Permission denied"):
        new_run_folder(tmp_path / "logs", max_total_mb=0)


def test_log_clock_is_wall_time_until_lockstep_then_vehicle_time_continuously():
    wall = [1000.0]
    vehicle: list[float | None] = [None]
    clock = LogClock(lambda: vehicle[0], wall=lambda: wall[0])
    assert clock() == 1000.0
    wall[0], vehicle[0] = 1001.0, 5.0  # lockstep starts: anchored here
    assert clock() == 1001.0
    wall[0], vehicle[0] = 1002.0, 65.0  # 60 s of sim time in 1 s of wall time
    assert clock() == 1061.0
    vehicle[0] = 1.0  # a rebooted vehicle: the log never goes back
    assert clock() == 1061.0


def test_daemon_tlog_of_a_lockstep_run_spans_sim_time(tmp_path):
    """mavutil (what mavlogdump.py and MAVExplorer read with) sees the vehicle's own clock in the
    tlog: every ATTITUDE is stamped at its time_boot_ms plus one constant, however fast the
    lockstep run went through wall time."""
    from rover_ctl.app.sim import SimOptions, SimRun

    out = tmp_path / "run"
    with SimRun(SimOptions(mission=JUMP, out=out, timeout_s=60.0)) as run:
        assert run.wait_for(lambda p: p.sim_time_s >= 30.0, wall_timeout_s=120.0)
    log = mavutil.mavlink_connection(str(out / "vehicle.tlog"))
    offsets = []
    while (msg := log.recv_match(type="ATTITUDE")) is not None:
        if msg.time_boot_ms >= 2000:  # past the first lockstep marker
            offsets.append(msg._timestamp - msg.time_boot_ms / 1000.0)
    assert len(offsets) > 100
    assert max(offsets) - min(offsets) < 0.1, (min(offsets), max(offsets))


# ---- start-up errors ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--gcs", "bogus"], "--gcs 'bogus': expected SCHEME:HOST:PORT"),
        (["--vehicle", "nonsense:"], "--vehicle 'nonsense:': expected SCHEME:HOST:PORT"),
        (["--gcs", "udpout:127.0.0.1:0"], "--gcs udpout:127.0.0.1:0: expected udpout:HOST:PORT"),
        (["--vehicle", ""], "--vehicle '': expected SCHEME:HOST:PORT"),
        (["--config", "{tmp}/absent.toml"], "absent.toml: no such config file"),
        (["--config", "{tmp}/bad.toml"], "bad.toml: invalid TOML"),
        (["--config", "{tmp}"], "cannot read"),
        (["--log-dir", "{tmp}/bad.toml/logs"], "log dir"),
        (["--bogus-flag"], "unrecognized arguments: --bogus-flag"),
    ],
)
def test_start_up_errors_are_one_line_and_exit_2(tmp_path, args, message):
    (tmp_path / "bad.toml").write_text("[daemon\n")
    args = [a.format(tmp=tmp_path) for a in args]
    result = subprocess.run([*ROVER_CTL, "run", "--mission-store", "", *args], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2, result
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("rover-ctl") and message in lines[0], result.stderr
    assert result.stdout == ""
    assert not list(tmp_path.rglob("0000000*")), "no run folder for a run that never started"


def test_two_starts_leave_two_run_folders_and_pymavlink_chatter_stays_quiet(tmp_path):
    """Nothing listens on the vehicle port: each start gives up (exit 69, which systemd restarts)
    after its run folder was made; pymavlink's retry prints reach the log at most once each."""
    port = free_port(socket.SOCK_STREAM)
    cmd = [*ROVER_CTL, "run", "--vehicle", f"tcp:127.0.0.1:{port}", "--gcs", f"udpout:127.0.0.1:{free_port()}",
           "--mission-store", "", "--log-dir", str(tmp_path), "--set", "daemon.vehicle_wait_s=1"]  # fmt: skip
    for _ in range(2):
        result = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
        assert result.returncode == 69, result
        assert result.stdout == ""  # pymavlink prints nothing of its own
        refused = [line for line in result.stderr.splitlines() if "Connection refused" in line and "pymavlink" in line]
        assert len(refused) <= 1, result.stderr
    assert [p.name for p in run_folders(tmp_path)] == ["00000001", "00000002"]
    assert (tmp_path / LATEST).resolve().name == "00000002"
    assert {"events.jsonl", "control.csv"} <= {p.name for p in (tmp_path / "00000001").iterdir()}


def test_chatter_logs_each_line_once_per_interval_with_a_count(caplog):
    now = [0.0]
    chatter = Chatter(logging.getLogger("pymavlink.test"), interval_s=60.0, clock=lambda: now[0])
    with caplog.at_level(logging.WARNING, logger="pymavlink.test"):
        for k in range(100):
            now[0] = k * 1.0
            chatter(OSError(111, "Connection refused"), "sleeping")
        chatter("EOF on TCP socket")
    assert [r.getMessage() for r in caplog.records] == [
        "[Errno 111] Connection refused sleeping",
        "[Errno 111] Connection refused sleeping (and 59 times more in 60 s)",
        "EOF on TCP socket",
    ]


def test_quiet_pymavlink_catches_the_module_prints(caplog, monkeypatch):
    monkeypatch.setattr(mavutil, "print", print, raising=False)
    quiet_pymavlink(logging.getLogger("pymavlink.test2"), 60.0)
    with caplog.at_level(logging.WARNING, logger="pymavlink.test2"):
        conn = mavutil.mavtcp.__new__(mavutil.mavtcp)
        conn.autoreconnect = False
        conn.handle_disconnect()  # pymavlink prints "Connection reset or closed by peer on TCP socket"
    assert [r.getMessage() for r in caplog.records] == ["Connection reset or closed by peer on TCP socket"]


def test_sim_refuses_a_bad_mission_before_making_a_run_folder(tmp_path, capsys):
    assert main(["sim", str(tmp_path / "absent.waypoints"), "--out", str(tmp_path / "runs")]) == 2
    assert "absent.waypoints" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()


# ---- the emulator launcher ----------------------------------------------------------------------


def test_launcher_reports_the_emulators_own_error_line():
    with pytest.raises(SitlError, match=r"rover-sitl did not start \(exit 2\): rover-sitl: error: .*--bogus"):
        with rover_sitl("--bogus"):
            pass


def test_launcher_stops_with_sigterm_and_keeps_the_output():
    with rover_sitl("--lockstep") as sitl:
        assert sitl.ready_at is not None and sitl.proc.poll() is None
    assert sitl.returncode == 0  # SIGTERM is a clean stop for the emulator
    assert sitl.output[-1].startswith("rover-sitl: stopped")
