"""ArduPilot's own stock Rover firmware driven over a serial line (``sitl.line_relay``: its SERIAL0
relayed to a pty at the line's rate, 2 KB radio buffer, in the firmware's time), six simulated
rangefinders, the bundled mission: issue 15's bar. Over 57600 the mission completes within 5 m of
its legs, the vehicle-to-daemon direction stays under 80% of the line and no byte is dropped for
overflow; over 115200 with 1 byte in 10,000 corrupted it completes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from rover_ctl.app.firmware import FirmwareOptions, firmware_path, simulate_firmware
from rover_ctl.app.report import read_jsonl

ROOT = Path(__file__).resolve().parents[2]
MISSION = ROOT / "missions" / "cmac_loop.waypoints"
ARDUPILOT_WHEELS = ["link.wheel_left_index=1", "link.wheel_right_index=0"]
SPEEDUP = 5
"""The firmware with six rangefinders runs at about 4-5x real time at best on this machine; the
relay scales the line with it, so the line is the same in the firmware's time."""
CROSS_TRACK_MAX_M = 5.0
LINE_USE_MAX = 0.8

if firmware_path() is None:
    pytest.skip("ArduPilot firmware absent: ../shared/ardupilot/ardurover (or $ROVER_CTL_SHARED/ardupilot) not found; "
                "the firmware serial-line tests are skipped", allow_module_level=True)

pytestmark = pytest.mark.sitl


def run(tmp_path: Path, baud: int, byte_error: float = 0.0) -> tuple[dict, dict]:
    out = tmp_path / "run"
    options = FirmwareOptions(mission=MISSION, out=out, lockstep=False, speedup=SPEEDUP, timeout_s=400.0,
                              rangefinders="six", line_baud=baud, line_byte_error=byte_error,
                              config_overrides=list(ARDUPILOT_WHEELS))  # fmt: skip
    metrics = simulate_firmware(options)
    return metrics, json.loads((out / "line.json").read_text())


def test_stock_firmware_over_a_57600_radio(tmp_path):
    metrics, line = run(tmp_path, 57600)
    assert metrics["complete"] and metrics["reached_seqs"] == [1, 2, 3, 4, 5], metrics
    assert metrics["cross_track_max_m"] <= CROSS_TRACK_MAX_M, metrics
    assert line["downlink"]["dropped_overflow"] == 0 and line["uplink"]["dropped_overflow"] == 0, line
    # What the daemon received per 2 s window of the firmware's time, at its highest.
    received = [r["rx_bytes_per_s"] for r in read_jsonl(tmp_path / "run" / "events.jsonl") if r["type"] == "link"]
    assert received and max(received) <= LINE_USE_MAX * 5760.0, received


def test_stock_firmware_over_a_noisy_115200_line(tmp_path):
    metrics, line = run(tmp_path, 115200, byte_error=1e-4)
    assert metrics["complete"] and metrics["reached_seqs"] == [1, 2, 3, 4, 5], metrics
    assert line["downlink"]["corrupted"] > 0, line
