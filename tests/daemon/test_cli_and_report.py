"""`rover-ctl run` / `rover-ctl sim` bad input and exit codes; report metrics from a synthetic run."""

from __future__ import annotations

import json
import math
import os
import signal
import socket
import subprocess

import pytest

from rover_ctl.cli import main
from rover_ctl.estimation.frame import LocalFrame
from rover_ctl.app.report import ReportError, write_report
from rover_ctl.app.sim import BUDGET_FLOOR_S, BUDGET_MARGIN, ROVER_CTL, SimOptions, SimRun, time_budget_s
from rover_ctl.mission.files import save_mission
from rover_ctl.mission.model import Cmd, Home, Mission, MissionItem
from support import free_port

HOME = (-35.363261, 149.165230, 584.0)


def test_run_without_a_vehicle_exits_69(tmp_path, caplog):
    port = free_port(socket.SOCK_STREAM)
    with socket.socket() as server:  # a TCP port that accepts but never speaks MAVLink
        server.bind(("127.0.0.1", port))
        server.listen()
        code = main(["run", "--vehicle", f"tcp:127.0.0.1:{port}", "--gcs", f"udpout:127.0.0.1:{free_port()}",
                     "--set", "daemon.vehicle_wait_s=0.5", "--mission-store", "", "--log-dir", str(tmp_path)])  # fmt: skip
    assert code == 69
    assert "no vehicle heartbeat within 0.5 s" in caplog.text


@pytest.mark.parametrize(
    "args, message",
    [
        (["run", "--set", "daemon.control_rate_hz=fast"], "daemon.control_rate_hz: expected a number"),
        (["run", "--config", "/nonexistent/rover.toml"], "no such config file"),
        (["run", "--rulebase", "/nonexistent/rules.toml"], "--rulebase /nonexistent/rules.toml"),
        (["sim", "/nonexistent/m.waypoints"], "/nonexistent/m.waypoints: no such file"),
        (["sim", "missions/cmac_jump.waypoints", "--world", "/nonexistent/w.geojson"], "--world /nonexistent/w.geojson: no such file"),
        (["sim", "missions/cmac_jump.waypoints", "--obstacles", "-2"], "--obstacles -2: expected a count >= 0"),
        (["sim", "missions/cmac_jump.waypoints", "--sitl-param", "SIM_FOO=1"], "--sitl-param SIM_FOO=1: expected NAME=VALUE"),
        (["sim", "missions/cmac_jump.waypoints", "--sitl-param", "SIM_LINK_LOSS=nan"], "--sitl-param SIM_LINK_LOSS=nan: SIM_LINK_LOSS"),
        # Files that are not files: /dev/zero was read until memory ran out.
        (["mission", "check", "/dev/zero"], "/dev/zero: cannot read: not a regular file"),
        (["run", "--config", "/dev/zero"], "/dev/zero: cannot read: not a regular file"),
        (["params", "import", "/dev/zero"], "/dev/zero: cannot read: not a regular file"),
        (["fuzzy", "eval", "--rulebase", "default", "--input", "/dev/zero"], "/dev/zero: cannot read: not a regular file"),
        # Connection strings the clients handed to pymavlink as they came (a traceback from bind).
        (["arm", "--connect", "udpin:127.0.0.1:99999"], "--connect udpin:127.0.0.1:99999: expected udpin:HOST:PORT with PORT in 1..65535"),
        (["params", "show", "--connect", "tcp:127.0.0.1:0"], "--connect tcp:127.0.0.1:0: expected tcp:HOST:PORT"),
        (["mission", "clear", "--connect", "ws:127.0.0.1:1"], "--connect 'ws:127.0.0.1:1': expected SCHEME:HOST:PORT"),
        # Output places checked before anything runs (a download said so after the transfer).
        (["mission", "download", "README.md/out.waypoints", "--connect", "udpin:127.0.0.1:9"], "README.md is not an existing folder"),
        (["run", "--log-dir", "README.md", "--vehicle", "tcp:127.0.0.1:9"], "log dir README.md: a file is in the way"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(args, message, capsys):
    assert main(args) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_a_fifo_or_a_plain_file_where_a_device_or_file_belongs_is_one_line(tmp_path, capsys):
    """A FIFO given as a mission waited for a writer for ever; a plain file as the vehicle link was
    opened by pymavlink as a log to replay (the daemon waited for a heartbeat for ever) and as a
    client's link was written to."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    plain = tmp_path / "victim.waypoints"
    plain.write_text("QGC WPL 110\n")
    cases = [
        (["mission", "check", str(fifo)], f"{fifo}: cannot read: not a regular file"),
        (["mode", "HOLD", "--connect", str(plain)], f"--connect {plain}: {plain} is not a serial device"),
        (["run", "--vehicle", f"{plain},57600", "--mission-store", ""], f"--vehicle {plain},57600: {plain} is not a serial device"),
    ]
    for argv, message in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.startswith(f"rover-ctl: error: {message}") and err.count("\n") == 1, err
    assert plain.read_text() == "QGC WPL 110\n"


def test_sim_with_a_mission_the_daemon_refuses_says_why_in_one_line(tmp_path, capsys):
    """The daemon refuses the upload (here: more items than GCS_MIS_MAX allows); the refusal came
    out of ``SimRun.start`` as a MissionClientError traceback."""
    argv = ["sim", "missions/cmac_jump.waypoints", "--lockstep", "--out", str(tmp_path / "runs"), "--set", "gcs.mission_max_items=2"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "mission upload refused by the vehicle: MAV_MISSION_NO_SPACE" in err[0], err


@pytest.mark.parametrize(
    "world, message",
    [(b"", "not valid JSON"), (b'{"type": "FeatureCo', "not valid JSON"), (b"[1, 2]", "expected a GeoJSON FeatureCollection"),
     (b"\xff\xfe\x00garbage", "not UTF-8 text")],
)
def test_sim_refuses_a_bad_world_or_rulebase_before_making_a_run_folder(tmp_path, capsys, world, message):
    """The emulator's own reader decides (it was read with a bare json.loads first: a traceback),
    and nothing is left in the output folder."""
    path = tmp_path / "w.geojson"
    path.write_bytes(world)
    out = tmp_path / "runs"
    assert main(["sim", "missions/cmac_jump.waypoints", "--world", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0] and message in err[0], err
    assert main(["sim", "missions/cmac_jump.waypoints", "--rulebase", str(path), "--out", str(out)]) == 2
    assert "--rulebase" in capsys.readouterr().err
    assert not out.exists() or not any(out.iterdir())


def test_sim_refuses_a_home_the_emulator_cannot_boot_at_before_making_a_run_folder(tmp_path, capsys):
    """mission check takes any float32 altitude; the emulator boots between -1000 and 10000 m."""
    mission = tmp_path / "high.waypoints"
    mission.write_text("QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t-35.363261\t149.165230\t12000\t1\n"
                       "1\t0\t3\t16\t0\t0\t0\t0\t-35.3632\t149.1653\t0\t1\n")
    assert main(["mission", "check", str(mission)]) == 0
    out = tmp_path / "runs"
    assert main(["sim", str(mission), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "home: the emulator cannot boot there" in err[0] and "10000" in err[0], err
    assert not out.exists()


def test_sigterm_stops_cleanly_with_neutral_first(tmp_path):
    from pymavlink import mavutil

    port = free_port(socket.SOCK_STREAM)
    vehicle = mavutil.mavlink_connection(f"tcpin:127.0.0.1:{port}", source_system=1, dialect="ardupilotmega")
    proc = subprocess.Popen([*ROVER_CTL, "run", "--vehicle", f"tcp:127.0.0.1:{port}",
                             "--gcs", f"udpout:127.0.0.1:{free_port()}", "--mission-store", "", "--log-dir", str(tmp_path)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)  # fmt: skip
    try:
        hb = vehicle.recv_match(type="HEARTBEAT", blocking=True, timeout=20)  # the daemon's, once it connected
        assert hb is not None and hb.type == mavutil.mavlink.MAV_TYPE_GCS
        vehicle.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GROUND_ROVER, mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0)
        mode = vehicle.recv_match(type="COMMAND_LONG", condition="COMMAND_LONG.command==176", blocking=True, timeout=10)
        assert mode is not None and mode.param2 == 0  # MANUAL
        vehicle.mav.command_ack_send(mode.command, mavutil.mavlink.MAV_RESULT_ACCEPTED)
        # Nothing drives before the first GPS fix, so every override is neutral.
        proc.send_signal(signal.SIGTERM)
        seen = []
        while True:
            msg = vehicle.recv_match(type=["RC_CHANNELS_OVERRIDE", "COMMAND_LONG"], blocking=True, timeout=10)
            assert msg is not None, f"no disarm after SIGTERM; saw {seen}"
            if msg.get_type() == "RC_CHANNELS_OVERRIDE":
                seen.append(("override", msg.chan1_raw, msg.chan3_raw))
            elif msg.command == mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
                seen.append(("arm", msg.param1))
                break
        # Neutral before the disarm, and nothing but neutral (under load the vehicle-silence
        # failsafe may already have sent neutral of its own before the SIGTERM).
        assert seen[-1] == ("arm", 0.0) and seen[:-1] and set(seen[:-1]) == {("override", 1500, 1500)}, seen
        assert proc.wait(10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
        vehicle.close()


def synthetic_run(folder, complete: bool = True):
    """A straight 10 m drive north at 1 m/s; the estimate is 0.3 m east of the truth."""
    frame = LocalFrame(*HOME)
    events = [
        {"t_s": 0.0, "type": "frame", "lat_deg": HOME[0], "lon_deg": HOME[1], "alt_m": HOME[2]},
        {"t_s": 0.0, "type": "mission", "waypoints_total": 1, "items": 1, "waypoints_en": [[0.0, 10.0]]},
        {"t_s": 1.0, "type": "mode", "mode": 10, "name": "AUTO"},
        {"t_s": 1.0, "type": "plan", "goal_seq": 1, "length_m": 10.0, "path_en": [[0, 0], [0, 10]]},
    ]
    if complete:
        events += [{"t_s": 11.0, "type": "reached", "seq": 1}, {"t_s": 11.0, "type": "complete", "seq": 1}]
    (folder / "events.jsonl").write_text("".join(json.dumps(e) + "\n" for e in events))
    truth = []
    for k in range(0, 121):
        t = k * 0.1
        north = max(0.0, t - 1.0)
        lat, lon = frame.to_geodetic(0.0, north)
        truth.append({"t_s": t, "type": "state", "lat_deg": lat, "lon_deg": lon, "east_m": 0.0, "north_m": north,
                      "yaw_deg": 0.0, "speed_mps": 1.0 if t > 1 else 0.0})  # fmt: skip
        if k % 2 == 0:
            truth.append({"t_s": t, "type": "gps", "dropped": False, "err_white_e_m": 0.3, "err_white_n_m": 0.0,
                          "err_bias_e_m": 0.0, "err_bias_n_m": 0.4, "err_glitch_e_m": 0.0, "err_glitch_n_m": 0.0})  # fmt: skip
    (folder / "truth.jsonl").write_text("".join(json.dumps(r) + "\n" for r in truth))
    from rover_ctl.app.daemon import CSV_COLUMNS

    rows = [",".join(CSV_COLUMNS)]
    for k in range(0, 300):
        t = k * 0.04
        row = dict.fromkeys(CSV_COLUMNS, "")
        row.update(t_s=t, est_east_m=0.3, est_north_m=max(0.0, t - 1.0), est_heading_rad=math.pi / 2, cross_track_m=0.1,
                   latency_ms=1.0 + (k % 100) / 100.0, left_set_rpm=100, right_set_rpm=100, left_meas_rpm=99,
                   right_meas_rpm=101, range_front_m="inf", target_distance_m=3.0, target_direction_rad=0.0)  # fmt: skip
        rows.append(",".join(str(row[c]) for c in CSV_COLUMNS))
    (folder / "control.csv").write_text("\n".join(rows) + "\n")


def test_report_metrics_from_a_known_run(tmp_path):
    synthetic_run(tmp_path)
    metrics = write_report(tmp_path, plots=True)
    assert metrics["success"] and metrics["collisions"] == 0
    assert metrics["path_length_m"] == pytest.approx(10.0, abs=0.05)
    assert metrics["planned_length_m"] == 10.0
    assert metrics["duration_s"] == pytest.approx(10.0)
    assert metrics["position_rmse_m"] == pytest.approx(0.3, abs=1e-3)
    assert metrics["gps_rmse_m"] == pytest.approx(0.5, abs=1e-6)
    assert metrics["gps_bias_rms_m"] == pytest.approx(0.4, abs=1e-6)
    assert metrics["heading_rmse_deg"] == pytest.approx(0.0, abs=1e-6)
    assert metrics["cross_track_rms_m"] == pytest.approx(0.1)
    assert 1.9 < metrics["loop_latency_p99_ms"] <= 2.0
    assert (metrics["waypoints_reached"], metrics["waypoints_total"]) == (1, 1)
    assert json.loads((tmp_path / "metrics.json").read_text())["success"] is True
    assert {"map.png", "motors.png", "tracking.png"} <= {p.name for p in tmp_path.iterdir()}


def test_report_of_an_unfinished_run_and_of_an_empty_folder(tmp_path):
    synthetic_run(tmp_path, complete=False)
    metrics = write_report(tmp_path, timed_out=True, plots=False)
    assert not metrics["success"] and metrics["timed_out"] and metrics["waypoints_reached"] == 0
    with pytest.raises(ReportError, match="control.csv: no control log"):
        write_report(tmp_path / "nothing")


def test_sigterm_while_waiting_for_the_vehicle_exits_0(tmp_path):
    with socket.socket() as server:  # accepts, never speaks MAVLink
        server.bind(("127.0.0.1", 0))
        server.listen()
        port = server.getsockname()[1]
        proc = subprocess.Popen([*ROVER_CTL, "run", "--vehicle", f"tcp:127.0.0.1:{port}", "--gcs", f"udpout:127.0.0.1:{free_port()}",
                                 "--mission-store", ""], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)  # fmt: skip
        try:
            server.settimeout(30)
            conn, _ = server.accept()  # connected: the signal handlers are installed by now
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(10) == 0
            conn.close()
        finally:
            if proc.poll() is None:
                proc.kill()


def test_sim_time_budget_scales_with_the_mission():
    assert time_budget_s(0.0) == BUDGET_FLOOR_S
    assert time_budget_s(10.0) == BUDGET_FLOOR_S
    assert time_budget_s(692.0) == pytest.approx(BUDGET_MARGIN * 692.0)  # an 830 m mission at 1.2 m/s
    assert time_budget_s(692.0) > 700.0 + 300.0  # what it needs, with room for detours


def test_sim_budget_from_the_mission_and_the_daemon_speed_unless_given(tmp_path):
    frame = LocalFrame(*HOME)
    lat, lon = frame.to_geodetic(0.0, 830.0)
    path = tmp_path / "long.waypoints"
    save_mission(Mission(items=[MissionItem(Cmd.NAV_WAYPOINT, x=lat, y=lon)], home=Home(*HOME)), path)
    budget = SimRun(SimOptions(mission=path, out=tmp_path / "a")).budget_s
    assert budget == pytest.approx(BUDGET_MARGIN * 830.0 / 1.2, rel=1e-3)  # executor.cruise_speed_mps default
    slower = SimRun(SimOptions(mission=path, out=tmp_path / "b", config_overrides=["executor.cruise_speed_mps=0.6"])).budget_s
    assert slower == pytest.approx(2.0 * budget, rel=1e-3)
    assert SimRun(SimOptions(mission=path, out=tmp_path / "c", timeout_s=50.0)).budget_s == 50.0


def test_sigterm_to_sim_stops_its_emulator_and_daemon(tmp_path):
    """`rover-ctl sim` under a service manager or `timeout` gets SIGTERM: it must take its two
    children with it (it used to die at once and leave both running)."""
    import time
    from pathlib import Path

    mission = Path(__file__).resolve().parents[2] / "missions" / "cmac_loop.waypoints"
    proc = subprocess.Popen([*ROVER_CTL, "sim", str(mission), "--lockstep", "--out", str(tmp_path / "runs"), "--json"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    children_file = Path(f"/proc/{proc.pid}/task/{proc.pid}/children")
    children: list[str] = []
    try:
        deadline = time.monotonic() + 30.0
        while len(children) < 2 and time.monotonic() < deadline:  # the emulator, then the daemon
            time.sleep(0.1)
            children = children_file.read_text().split() if children_file.exists() else []
        assert len(children) >= 2, children
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(20) == 128 + signal.SIGTERM
        assert not [pid for pid in children if Path(f"/proc/{pid}").exists()], "a child outlived rover-ctl sim"
    finally:
        if proc.poll() is None:
            proc.kill()
        for pid in children:  # a failed run must not leave them behind either
            try:
                os.kill(int(pid), signal.SIGKILL)
            except ProcessLookupError:
                pass


def test_sim_output_piped_puts_its_verdict_on_its_own_line(tmp_path, capsys):
    """Off a terminal (make demo's log, CI) rich's live table ended without a newline and the
    verdict followed its bottom border on the same line."""
    assert main(["sim", "missions/cmac_jump.waypoints", "--lockstep", "--out", str(tmp_path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    verdict = next(i for i, line in enumerate(lines) if "waypoints," in line)
    assert lines[verdict].startswith("success: 3/3 waypoints") and lines[verdict - 1].rstrip().endswith("┘"), lines[verdict - 1:]
