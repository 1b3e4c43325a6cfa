"""rover-sitl --pty --baud: the pty carried by the serial line model, in sim time, both ways."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import pytest
from support.sitl import rover_sitl

from sitl.client import LockstepClient
from sitl.main import main

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

mav = mavutil.mavlink
pytestmark = pytest.mark.sitl

BAUD = 57600
RATE_BPS = BAUD / 10
FRAME_S = 0.02


class MeteredClient(LockstepClient):
    """A lockstep client that counts every byte it gets from the vehicle (good frames and
    BAD_DATA alike), except the lockstep markers, which are not line traffic: neither are the
    zeros sent before a marker repeated under load (its answer was late)."""

    def __init__(self, url: str) -> None:
        self.bytes_in = 0
        self.bad: list = []
        super().__init__(url)

    def _read(self, wait_s: float) -> list:
        msgs = super()._read(wait_s)
        for m in msgs:
            if m.get_type() == "BAD_DATA" and not any(m.get_msgbuf()):
                continue  # the zeros sent before a repeated marker (sitl.endpoints.PtyEndpoint.send_marker): not line traffic
            if not (m.get_type() == "TIMESYNC" and m.tc1 == 0):
                self.bytes_in += len(m.get_msgbuf())
            if m.get_type() == "BAD_DATA":
                self.bad.append(m)
        return msgs

    def modest_streams(self) -> None:
        """About 3.5 KB/s: every stream off, then status 2 Hz, EXTRA1 10 Hz, rangefinders 5 Hz."""
        for stream, hz in ((mav.MAV_DATA_STREAM_ALL, 0), (mav.MAV_DATA_STREAM_EXTENDED_STATUS, 2),
                           (mav.MAV_DATA_STREAM_EXTRA1, 10), (mav.MAV_DATA_STREAM_EXTRA3, 5)):  # fmt: skip
            self.conn.mav.request_data_stream_send(1, 1, stream, hz, 1 if hz else 0)


def stats_of(path) -> dict:
    return json.loads(path.read_text())


def run_line(tmp_path, seconds_sim: float, *flags: str, modest: bool, override=None) -> tuple[dict, MeteredClient]:
    stats = tmp_path / "line.json"
    with rover_sitl("--lockstep", "--pty", "--line-stats", str(stats), *flags) as sitl:
        client = MeteredClient(sitl.pty_device)
        if modest:
            client.modest_streams()  # written before the first answer: applied from the second frame
        client.run(seconds_sim, (lambda t_s, msgs: override) if override else None)
        client.close()
    assert sitl.returncode == 0, sitl.stderr
    assert any(line.startswith("rover-sitl: line ") for line in sitl.output), sitl.output
    return stats_of(stats), client


@pytest.mark.parametrize(("flags", "needle"), [
    (["--pty", "--baud", "0"], "--baud: expected a positive number"),
    (["--pty", "--baud", "-9600"], "--baud: expected a positive number"),
    (["--pty", "--baud", "inf"], "--baud: expected a positive number"),  # the line refused it with a traceback
    (["--pty", "--baud", "fast"], "--baud: expected a number"),
    (["--pty", "--baud", "57600", "--byte-error", "1"], "--byte-error: expected a probability"),
    (["--pty", "--baud", "57600", "--byte-error", "-0.1"], "--byte-error: expected a probability"),
    (["--pty", "--baud", "57600", "--line-buffer-bytes", "0"], "--line-buffer-bytes"),
    (["--baud", "57600"], "add --pty"),
    (["--pty", "--byte-error", "0.01"], "--byte-error needs --baud"),
    (["--pty", "--line-stats", "x.json"], "--line-stats needs --baud"),
])  # fmt: skip
def test_bad_line_flags_give_one_line_error(capsys, flags: list[str], needle: str) -> None:
    assert main([*flags, "--duration-s", "0"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rover-sitl: error: ") and needle in lines[0], lines


def test_an_unwritable_stats_file_is_refused_at_start(tmp_path) -> None:
    result = subprocess.run([sys.executable, "-m", "sitl", "--pty", "--baud", "57600", "--line-stats",
                             str(tmp_path / "no" / "dir.json"), "--duration-s", "0"], capture_output=True, text=True, timeout=30)  # fmt: skip
    assert result.returncode == 2 and result.stderr.count("\n") == 1 and "--line-stats" in result.stderr, result


def test_modest_streams_fit_a_57600_line_without_a_drop(tmp_path) -> None:
    stats, client = run_line(tmp_path, 10.0, "--baud", str(BAUD), modest=True, override=(1500, 1500))
    down, up = stats["downlink"], stats["uplink"]
    assert down["dropped_overflow"] == up["dropped_overflow"] == 0, stats
    assert 2500 * 10 < client.bytes_in <= RATE_BPS * stats["sim_s"], (client.bytes_in, stats)
    assert client.bad == [] and stats["bad_frames"] == 0
    assert down["offered"] == down["delivered"] + down["buffered"]
    assert up["offered"] > 50 * 10 * 20  # the overrides (about 20 bytes each frame) went through the line


def test_an_overloaded_line_carries_its_rate_and_drops_the_rest(tmp_path) -> None:
    """The default streams (about 13.6 KB/s, as ArduPilot's stream defaults swamp a radio)."""
    stats, client = run_line(tmp_path, 10.0, "--baud", str(BAUD), modest=False)
    down = stats["downlink"]
    sim_s = stats["sim_s"]
    assert down["delivered"] <= RATE_BPS * sim_s and client.bytes_in <= down["delivered"]
    assert client.bytes_in >= 0.95 * RATE_BPS * sim_s, (client.bytes_in, stats)  # the line stays busy
    assert down["offered"] > 2 * RATE_BPS * sim_s and down["dropped_overflow"] > RATE_BPS * sim_s, stats
    assert down["peak_buffer_bytes"] == stats["buffer_bytes"] == 2048
    assert client.bad == [] and stats["bad_frames"] == 0  # whole frames dropped, never cut


def test_byte_errors_are_caught_by_crc_both_ways(tmp_path) -> None:
    stats, client = run_line(tmp_path, 10.0, "--baud", "115200", "--byte-error", "0.001", modest=True,
                             override=(1500, 1500))  # fmt: skip
    down, up = stats["downlink"], stats["uplink"]
    assert down["dropped_overflow"] == up["dropped_overflow"] == 0
    assert down["corrupted"] >= 10 and up["corrupted"] >= 5, stats  # ~0.001 x 35 KB and x 20 KB
    crc = [m for m in client.bad if "CRC" in m.reason]
    assert 1 <= len(crc) <= down["corrupted"], [m.reason for m in client.bad]
    assert 1 <= stats["bad_frames"] <= 2 * up["corrupted"], stats  # the emulator's parser rejects them too


def test_a_plain_serial_client_at_speedup_gets_the_line_rate_in_sim_time(tmp_path) -> None:
    """Free running at 10x: pymavlink's serial connection on the pty sees baud/10 bytes per sim second."""
    stats_path = tmp_path / "line.json"
    with rover_sitl("--speedup", "10", "--pty", "--baud", str(BAUD), "--line-stats", str(stats_path)) as sitl:
        conn = mavutil.mavlink_connection(sitl.pty_device, baud=BAUD, source_system=255)
        first = last = None
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and (first is None or last.time_boot_ms - first.time_boot_ms < 5000):
            msg = conn.recv_match(type="ATTITUDE", blocking=True, timeout=1)
            if msg is None:
                continue
            if first is None:
                first, bytes_at_first = msg, conn.mav.total_bytes_received
            last = msg
        received = conn.mav.total_bytes_received - bytes_at_first
        conn.close()
    assert first is not None and last.time_boot_ms - first.time_boot_ms >= 5000, "no 5 s of telemetry in 20 s"
    span_s = (last.time_boot_ms - first.time_boot_ms) / 1000
    # each ATTITUDE waited up to a full buffer (2048 B = 0.36 s at 57600) in the line
    assert 0.85 * RATE_BPS * span_s <= received <= RATE_BPS * (span_s + 2048 / RATE_BPS + FRAME_S), (received, span_s)
    assert stats_of(stats_path)["downlink"]["dropped_overflow"] > 0
