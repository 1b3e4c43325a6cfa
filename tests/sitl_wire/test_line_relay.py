"""python -m sitl.line_relay: a UDP serial port (ArduPilot SITL's --serial0 udpclient) served on a
pty through the serial line model. A fake firmware (a loopback UDP socket) checks the relay itself;
ArduPilot's own firmware, when ../shared/ardupilot is present, checks it end to end."""

from __future__ import annotations

import os
import socket
import subprocess
import time

import pytest

from sitl.launch import line_relay, stop_process
from sitl.line_relay import main

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mav  # noqa: E402  (MAVLink 2 whatever mavutil was imported with)

pytestmark = pytest.mark.sitl

BAUD = 57600
RATE_BPS = BAUD / 10
DEADLINE_S = 20.0


def packer(sysid: int = 1):
    return mav.MAVLink(None, srcSystem=sysid, srcComponent=1)


def frames(n: int) -> list[bytes]:
    """n numbered MAVLink frames (SYSTEM_TIME, seq 0..n-1; 21 to 24 bytes each, zeros truncated),
    all at the same firmware boot time: the relay's line clock follows it, so they are one burst."""
    m = packer()
    out = []
    for i in range(n):
        out.append(mav.MAVLink_system_time_message(1_700_000_000_000_000 + i, 1000).pack(m))
        m.seq = (m.seq + 1) % 256
    return out


def read_until(conn, predicate, deadline_s: float = DEADLINE_S) -> list:
    """Messages from ``conn`` until ``predicate(all so far)`` holds or the deadline passes."""
    got: list = []
    deadline = time.monotonic() + deadline_s
    while time.monotonic() < deadline and not predicate(got):
        msg = conn.recv_msg()
        if msg is None:
            conn.select(0.05)
        else:
            got.append(msg)
    return got


@pytest.mark.parametrize(("flags", "needle"), [
    (["--baud", "57600"], "--udpin"),
    (["--udpin", "0.0.0.0:14550", "--baud", "57600"], "loopback only"),
    (["--udpin", "localhost", "--baud", "57600"], "127.0.0.1:PORT"),
    (["--udpin", "127.0.0.1:14550", "--baud", "0"], "--baud"),
    (["--udpin", "127.0.0.1:14550", "--baud", "57600", "--byte-error", "1"], "--byte-error"),
    (["--udpin", "127.0.0.1:14550", "--baud", "57600", "--speedup", "-1"], "--speedup"),
])  # fmt: skip
def test_bad_flags_give_one_line_error(capsys, flags, needle) -> None:
    assert main(flags) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("line-relay: error: ") and needle in lines[0], lines


def test_relays_both_ways_at_the_line_rate_and_counts(tmp_path) -> None:
    stats_path = tmp_path / "line.json"
    burst = frames(80)  # 1680 bytes: fits the 2048-byte buffer
    size = sum(map(len, burst))
    with line_relay(BAUD, stats_path) as relay, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as firmware:
        firmware.bind(("127.0.0.1", 0))
        conn = mavutil.mavlink_connection(relay.pty_device, baud=BAUD, source_system=255)
        firmware.sendto(b"".join(burst), ("127.0.0.1", relay.port))
        got = read_until(conn, lambda got: len(got) >= 80)
        assert [m.get_seq() for m in got] == list(range(80)), [m.get_type() for m in got]
        conn.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        firmware.settimeout(DEADLINE_S)
        parser, back, data = packer(), [], b""
        while not back:  # the line hands bytes over as they leave: a frame may span datagrams
            chunk, _ = firmware.recvfrom(65536)
            data += chunk
            back = parser.parse_buffer(chunk) or []
        assert back[0].get_type() == "HEARTBEAT" and back[0].get_srcSystem() == 255
        conn.close()
    assert relay.returncode == 0 and relay.output[-1].startswith("line-relay: stopped"), relay.output
    stats = relay.stats()
    assert stats["downlink"] | {"buffered": 0} == {"offered": size, "delivered": size, "dropped_overflow": 0, "corrupted": 0,
                                                  "buffered": 0, "peak_buffer_bytes": size}  # fmt: skip
    assert stats["uplink"]["delivered"] == len(data) and stats["pty_overrun"] == 0


def test_the_line_takes_its_time_and_overflow_is_dropped(tmp_path) -> None:
    """10 KB at once into a 2 KB buffer: about 8 KB dropped, the rest spread over >= 2048/5760 s."""
    stats_path = tmp_path / "line.json"
    burst = b"".join(frames(480))  # MAVLink 2: 21 to 24 bytes each
    assert len(burst) > 10_000
    with line_relay(BAUD, stats_path) as relay, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as firmware:
        conn = mavutil.mavlink_connection(relay.pty_device, baud=BAUD, source_system=255)
        for start in range(0, len(burst), 1400):
            firmware.sendto(burst[start:start + 1400], ("127.0.0.1", relay.port))
        times = []
        deadline = time.monotonic() + DEADLINE_S
        while time.monotonic() < deadline and conn.mav.total_bytes_received < 2000:
            if conn.recv_msg() is not None:
                times.append(time.monotonic())
            else:
                conn.select(0.01)
        conn.close()
    stats = relay.stats()["downlink"]
    assert stats["offered"] == len(burst) and stats["offered"] == stats["delivered"] + stats["dropped_overflow"] + stats["buffered"]
    # the datagrams arrive within a few ms, while the line carries 5.76 bytes a ms
    assert len(burst) - 2048 - 300 < stats["dropped_overflow"] <= len(burst) - 2048 and stats["peak_buffer_bytes"] == 2048, stats
    assert times[-1] - times[0] >= 0.5 * 1900 / RATE_BPS  # a lower bound only: never faster than the line


def test_byte_errors_reach_the_pty_as_crc_failures(tmp_path) -> None:
    stats_path = tmp_path / "line.json"
    with line_relay(BAUD, stats_path, byte_error=0.01, seed=5) as relay, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as firmware:
        conn = mavutil.mavlink_connection(relay.pty_device, baud=BAUD, source_system=255)
        firmware.sendto(b"".join(burst := frames(60)), ("127.0.0.1", relay.port))
        got = read_until(conn, lambda got: sum(len(m.get_msgbuf()) for m in got) >= sum(map(len, burst)))
        conn.close()
    stats = relay.stats()["downlink"]
    assert stats["corrupted"] >= 5, stats  # 0.01 x 1300 bytes
    assert any(m.get_type() == "BAD_DATA" and "CRC" in m.reason for m in got), [str(m) for m in got if m.get_type() == "BAD_DATA"]
    assert len([m for m in got if m.get_type() == "SYSTEM_TIME"]) < 60


def test_ardupilot_firmware_over_a_57600_line(tmp_path) -> None:
    """ArduPilot's Rover firmware at 10x: its HEARTBEAT reaches a pymavlink serial connection on the
    relay's pty, and a PARAM_REQUEST_READ written there is answered (both directions). Only
    SERIAL0 is open: SERIAL1 and SERIAL2 would listen on TCP 5762/5763 on all addresses."""
    from rover_ctl.app.firmware import DEFAULT_PARAMS, FIRMWARE_DIR, firmware_path

    binary = firmware_path()
    if binary is None:
        pytest.skip(f"ArduPilot firmware absent: ../shared/ardupilot/ardurover ({FIRMWARE_DIR / 'ardurover'}; "
                    "set ROVER_CTL_SHARED when the checkout is not beside ../shared)")  # fmt: skip
    speedup = 10
    stats_path = tmp_path / "line.json"
    with line_relay(BAUD, stats_path, speedup=speedup) as relay:
        conn = mavutil.mavlink_connection(relay.pty_device, baud=BAUD, source_system=255)
        defaults = ",".join(str(FIRMWARE_DIR / name) for name in DEFAULT_PARAMS)
        firmware = subprocess.Popen([str(binary), "--model", "rover-skid", "--speedup", str(speedup), "-w",
                                     "--home=-35.363261,149.165230,584,353", "--defaults", defaults,
                                     "--serial0", f"udpclient:127.0.0.1:{relay.port}",
                                     "--serial1", "none", "--serial2", "none"],
                                    cwd=tmp_path, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                    stderr=subprocess.DEVNULL)  # fmt: skip
        try:
            beats = read_until(conn, lambda got: any(m.get_type() == "HEARTBEAT" for m in got), 60.0)
            beat = next((m for m in beats if m.get_type() == "HEARTBEAT"), None)
            assert beat is not None, f"no HEARTBEAT through the relay in 60 s; firmware exit {firmware.poll()}"
            assert (beat.type, beat.autopilot) == (mav.MAV_TYPE_GROUND_ROVER, mav.MAV_AUTOPILOT_ARDUPILOTMEGA)
            conn.mav.param_request_read_send(1, 1, b"", 0)  # by index: parameter names change between versions

            def answered(got: list) -> bool:
                return any(m.get_type() == "PARAM_VALUE" and m.param_index == 0 for m in got)

            answer = next((m for m in read_until(conn, answered) if answered([m])), None)
            assert answer is not None, "PARAM_REQUEST_READ not answered through the line"
        finally:
            stop_process(firmware)
            conn.close()
    stats = relay.stats()
    down, up = stats["downlink"], stats["uplink"]
    assert 0 < down["delivered"] <= RATE_BPS * stats["vehicle_s"] + 1
    assert up["delivered"] > 0 and up["dropped_overflow"] == 0 and stats["no_firmware"] == 0
