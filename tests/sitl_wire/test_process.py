"""rover-sitl as a process: endpoints (udp, tcp, pty, several at once), time modes, errors, shutdown."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time

import pytest
from support import free_port
from support.sitl import collect, lockstep_client, of_type, rover_sitl

from sitl.main import main

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

pytestmark = pytest.mark.sitl


def run_sitl(*flags: str, timeout_s: float = 20.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "sitl", *flags], capture_output=True, text=True, timeout=timeout_s)


def one_error_line(result: subprocess.CompletedProcess, status: int = 2) -> str:
    assert result.returncode == status, result
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rover-sitl: error: "), result.stderr
    return lines[0]


def main_error_line(capsys, *argv: str) -> str:
    """rover-sitl's main() in this process (argument and world errors happen before any I/O)."""
    result = subprocess.CompletedProcess(argv, main(list(argv)), "", "")
    result.stdout, result.stderr = capsys.readouterr()
    return one_error_line(result)


@pytest.mark.parametrize(("flags", "needle"), [
    (["--home", "91,0,0,0"], "91,0,0,0"),
    (["--home", "1,2,3"], "LAT,LON,ALT,HEADING"),
    (["--home", "-95,2,3,0"], "-95,2,3,0"),
    (["--home", "1,2,3e6,0"], "<= alt <="),  # GPS_RAW_INT carries millimetres in an int32
    (["--home", "1,2,3,360"], "0 <= heading < 360"),
    (["--speedup", "0"], "--speedup: expected a number >= 0.01"),
    (["--speedup", "1e-300"], ">= 0.01"),  # its wall time overflowed select's timeout
    (["--frame-s", "1e-12"], "--frame-s: expected a number from 0.001 to 1"),
    (["--frame-s", "1e300"], "from 0.001 to 1"),
    (["--frame-s", "nan"], "from 0.001 to 1"),
    (["--speedup", "2", "--lockstep"], "not allowed with"),
    (["--hold-at-s", "30"], "--hold-at-s needs --lockstep"),
    (["--lockstep", "--hold-at-s", "-1"], "--hold-at-s: expected a finite number >= 0"),
    (["--endpoint", "serial:/dev/null"], "unknown scheme"),
    (["--endpoint", "tcpin:localhost"], "HOST:PORT"),
    (["--param", "SIM_NOPE=1"], "SIM_NOPE"),
    (["--param", "SIM_WHEEL_SLIP=3"], "outside"),
    (["--param", "SYSID_MYGCS=nan"], "SYSID_MYGCS: expected a whole number 1..255"),  # int(nan) raised
    (["--param", "RC_OVERRIDE_TIME=-2"], "RC_OVERRIDE_TIME: expected a number -1.0..120.0"),
    (["--param", "ARMING_CHECK=0.5"], "ARMING_CHECK: expected a whole number 0..2147483647"),
    (["--scatter", "3"], "--along"),
    (["--scatter", "-1", "--along", "0,0;0,0.001"], ">= 0"),
    (["--seed", "-1"], "--seed: expected a whole number >= 0"),  # numpy's generators refuse it
    (["--bogus"], "--bogus"),
    (["--set", "gps.nope=1"], "--set gps.nope: unknown numeric field"),
    (["--set", "gps.white_std_m=-1"], "--set gps.white_std_m: expected a finite number >= 0"),
    (["--set", "gps.white_std_m=nan"], "--set gps.white_std_m: expected a finite number"),
    (["--set", "rangefinder.min_m=5"], "--set rangefinder.min_m 5 must be below rangefinder.max_m 4"),
    # these printed "ready", then crashed with a traceback mid-run
    (["--set", "motor.inductance_h=1e-300"], "--set motor.inductance_h: expected a finite number >= 1e-05 and <= 0.1 H, got '1e-300'"),
    (["--set", "robot.track_m=1e-300"], "--set robot.track_m: expected a finite number >= 0.05 and <= 5 m, got '1e-300'"),
    (["--set", "motor.gear_ratio=1e300"], "--set motor.gear_ratio: expected a finite number >= 1 and <= 1000, got '1e300'"),
    (["--set", "motor.ke_v_per_radps=0.001"], "--set the motor.* and robot.* fields give a top speed of 33.6 m/s"),
    (["--param", "SIM_GPS_GLITCH_X=1e300"], "SIM_GPS_GLITCH_X: 1e+300 is outside -10000..10000"),
    (["--rangefinders", "three"], "invalid choice"),
])
def test_bad_flags_give_one_line_error(capsys, flags: list[str], needle: str) -> None:
    assert needle in main_error_line(capsys, *flags, "--duration-s", "0")


def test_bad_world_files_name_the_file(capsys, tmp_path) -> None:
    assert "cannot read" in main_error_line(capsys, "--world", str(tmp_path / "absent.geojson"))
    broken = tmp_path / "broken.geojson"
    broken.write_text('{"type": "FeatureCollection", "features": [')
    line = main_error_line(capsys, "--world", str(broken))
    assert str(broken) in line and "JSON" in line
    bad_feature = tmp_path / "bad.geojson"
    bad_feature.write_text(json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "geometry": {"type": "Point", "coordinates": [149.1, -35.3]}, "properties": {}}]}))
    assert str(bad_feature) in main_error_line(capsys, "--world", str(bad_feature))
    huge = tmp_path / "huge.geojson"  # ran with a garbage obstacle after a shapely overflow warning
    huge.write_text(json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "geometry": {"type": "Point", "coordinates": [149.1, -35.3]}, "properties": {"radius_m": 1e300}}]}))
    assert f"{huge}: feature 0: radius_m must be > 0 and <= 10000 m" in main_error_line(capsys, "--world", str(huge))
    assert "/dev/zero: not a regular file" in main_error_line(capsys, "--world", "/dev/zero")  # was read forever


def test_port_in_use_is_an_error_a_launcher_can_tell_apart() -> None:
    """One line, and exit status 69 (EX_UNAVAILABLE) rather than 2: another port may do."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        line = one_error_line(run_sitl("--endpoint", f"tcpin:127.0.0.1:{port}", "--duration-s", "0"), status=69)
    assert f"127.0.0.1:{port}" in line and "in use" in line
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as busy:
        busy.bind(("127.0.0.1", 0))
        port = busy.getsockname()[1]
        line = one_error_line(run_sitl("--endpoint", f"udpin:127.0.0.1:{port}", "--duration-s", "0"), status=69)
    assert f"127.0.0.1:{port}" in line and "in use" in line


def test_scatter_writes_a_world_it_can_reload(tmp_path) -> None:
    out = tmp_path / "scattered.geojson"
    along = "-35.363261,149.165230;-35.362900,149.165230;-35.362900,149.165700"
    result = run_sitl("--scatter", "4", "--along", along, "--seed", "3", "--write-world", str(out),
                      "--endpoint", f"udpout:127.0.0.1:{free_port()}", "--speedup", "inf", "--duration-s", "1")
    assert result.returncode == 0, result.stderr
    assert len(json.loads(out.read_text())["features"]) == 4
    result = run_sitl("--world", str(out), "--endpoint", f"udpout:127.0.0.1:{free_port()}", "--speedup", "inf", "--duration-s", "1")
    assert result.returncode == 0 and "stopped at t=1.00 s" in result.stdout


def test_udp_controller_with_a_tcp_watcher_and_garbage(udp_port: int, tcp_port: int) -> None:
    endpoints = [f"udpin:127.0.0.1:{udp_port}", f"tcpin:127.0.0.1:{tcp_port}"]
    with rover_sitl("--lockstep", endpoints=endpoints) as sitl:
        watcher = mavutil.mavlink_connection(f"tcp:127.0.0.1:{tcp_port}", source_system=250)
        watcher.write(b"\xfd\x09\x00\x00garbage that is not MAVLink\xfe\x05junk" * 20)
        client = lockstep_client(sitl.url)  # udpout to the first endpoint: the controller
        client.arm()
        received = collect(client, 2.0, lambda t: (1700, 1500))
        client.close()
        seen = []
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and len([m for m in seen if m.get_type() == "HEARTBEAT"]) < 2:
            msg = watcher.recv_match(blocking=True, timeout=1)
            if msg is not None:
                seen.append(msg)
        watcher.close()
    assert len(of_type(received, "HEARTBEAT")) == 3  # t = 0, 1, 2 s: the first frame waits for the controller, a UDP one too
    assert {"HEARTBEAT", "ATTITUDE", "GPS_RAW_INT"} <= {m.get_type() for m in seen}  # the watcher saw telemetry
    assert sitl.returncode == 0
    bad = int(sitl.output[-1].split(", ")[1].split()[0])
    assert bad > 0, sitl.output[-1]


def test_serial_endpoint_through_a_pty() -> None:
    with rover_sitl("--lockstep", "--pty") as sitl:
        assert sitl.pty_device and os.path.exists(sitl.pty_device)
        client = lockstep_client(sitl.pty_device)
        client.arm()
        received = collect(client, 1.0, lambda t: (1800, 1500))
        client.close()
    assert of_type(received, "SERVO_OUTPUT_RAW")[-1].servo1_raw == 1785
    assert abs(len(of_type(received, "ATTITUDE")) - 50) <= 2  # 1 s at 50 Hz (+ the arming frames)


def test_speedup_runs_free_and_sigterm_exits_cleanly(tmp_path, udp_port: int) -> None:
    truth = tmp_path / "truth.jsonl"
    with rover_sitl("--speedup", "20", "--truth-log", str(truth), endpoints=[f"udpin:127.0.0.1:{udp_port}"]) as sitl:
        conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{udp_port}", source_system=255)
        conn.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        first = conn.recv_match(type="GPS_RAW_INT", blocking=True, timeout=5)
        second = None
        while second is None or second.time_usec < first.time_usec + 2_000_000:
            second = conn.recv_match(type="GPS_RAW_INT", blocking=True, timeout=5)
            assert second is not None
        conn.close()
        sitl.proc.send_signal(signal.SIGTERM)
        sitl.proc.wait(5)
    assert sitl.returncode == 0
    records = [json.loads(line) for line in truth.read_text().splitlines()]  # complete lines: flushed
    assert records[-1]["t_s"] >= 2.0


def test_link_loss_fault_thins_telemetry_but_not_the_lockstep_marker() -> None:
    with rover_sitl("--lockstep", "--param", "SIM_LINK_LOSS=50") as sitl:
        client = lockstep_client(sitl.url)
        received = collect(client, 4.0)
        client.set_param("SIM_LINK_QUIET", 1)  # may itself be lost: resend until quiet
        for _ in range(20):
            quiet = collect(client, 0.2)
            if not quiet:
                break
            client.set_param("SIM_LINK_QUIET", 1)
        client.close()
    attitude = len(of_type(received, "ATTITUDE"))
    assert 60 < attitude < 140  # about half of 200
    assert quiet == []  # nothing but markers


def test_tcp_endpoint_connects_out_to_a_listening_controller(tcp_port: int) -> None:
    client = lockstep_client(f"tcpin:127.0.0.1:{tcp_port}")  # the controller listens, the emulator dials
    with rover_sitl("--lockstep", endpoints=[f"tcp:127.0.0.1:{tcp_port}"]) as sitl:
        assert f"rover-sitl: connected tcp:127.0.0.1:{tcp_port}" in sitl.output
        client.arm()
        received = collect(client, 1.0, lambda t: (1500, 2000))
        client.close()
    assert of_type(received, "SERVO_OUTPUT_RAW")[-1].servo1_raw == 2000  # pivot right
    assert of_type(received, "SERVO_OUTPUT_RAW")[-1].servo3_raw == 1000


def test_tcp_endpoint_refused_is_an_error(capsys, tcp_port: int) -> None:
    assert "cannot connect" in main_error_line(capsys, "--endpoint", f"tcp:127.0.0.1:{tcp_port}", "--duration-s", "0")


@pytest.mark.parametrize("over", ["tcp", "pty"])
def test_the_vehicles_frames_number_without_gaps_between_the_lockstep_markers(over: str) -> None:
    """A controller skips the markers; the vehicle's own frames must then run on without gaps in
    their sequence, or it reads every marker as a frame lost (a fifth of them at 50 Hz)."""
    with rover_sitl("--lockstep", *(["--pty"] if over == "pty" else [])) as sitl:
        client = lockstep_client(sitl.pty_device if over == "pty" else sitl.url)
        client.arm()
        received = collect(client, 2.0, lambda t: (1600, 1500))
        client.close()
    seqs = [m.get_seq() for _, m in received if m.get_type() != "TIMESYNC" and (m.get_srcSystem(), m.get_srcComponent()) == (1, 1)]
    assert len(seqs) > 400
    gaps = sum((b - a - 1) % 256 for a, b in zip(seqs, seqs[1:]))
    assert gaps == 0


def test_the_clock_held_at_a_time_goes_on_when_the_vehicle_is_armed() -> None:
    """``--hold-at-s``: after the frame at that time is answered, no frame comes (its marker is
    repeated) until an arming command makes the vehicle armed; the next frame follows at once."""
    from sitl.client import FORCE_ARM_MAGIC, LockstepError

    with rover_sitl("--lockstep", "--hold-at-s", "0.5") as sitl:
        client = lockstep_client(sitl.url, timeout_s=1.0)
        client.run(0.5)
        assert client.t_s == pytest.approx(0.5)
        with pytest.raises(LockstepError):  # held: a second of wall time, no new frame
            client.next_frame()
        client.conn.mav.command_long_send(1, 1, mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, FORCE_ARM_MAGIC, 0, 0, 0, 0, 0)
        t_ns, msgs = client.next_frame()
        assert t_ns / 1e9 == pytest.approx(0.52)
        assert any(m.get_type() == "COMMAND_ACK" and m.result == mavutil.mavlink.MAV_RESULT_ACCEPTED for m in msgs)
        client.close()


def test_a_port_picked_free_is_none_of_those_to_avoid(monkeypatch) -> None:
    """The kernel may hand out a just-closed port again: two picks for one run came out the same
    (a daemon's vehicle and GCS links on one UDP port, both bound with SO_REUSEADDR)."""
    import sitl.launch as launch

    handed = iter([40001, 40001, 40001, 40002])

    class FakeSocket:
        def __init__(self, *args) -> None:
            self.port = next(handed)

        def __enter__(self):
            return self

        def __exit__(self, *exc) -> None:
            pass

        def bind(self, address) -> None:
            pass

        def getsockname(self):
            return ("127.0.0.1", self.port)

    import types

    monkeypatch.setattr(launch, "socket", types.SimpleNamespace(socket=FakeSocket, AF_INET=socket.AF_INET, SOCK_DGRAM=socket.SOCK_DGRAM))
    assert launch.free_port(avoid={40001}) == 40002
