"""The vehicle link's budget on serial lines: rates chosen and line use measured, per line rate.

The bundled mission (missions/cmac_loop.waypoints, six rangefinders) over rover-sitl's pty behind
a serial line (``--pty --baud``, lockstep, sim time) at 57600, 115200 and 921600 baud, and over
its TCP port (a network link); then ArduPilot's own firmware behind ``sitl.line_relay`` at 57600
and at 115200 with 1 byte in 10,000 corrupted (speed-up 5, the line scaled with it). Per row: the
rates the daemon's budget chose (its last ``link_plan`` record), the bytes per second it planned,
what crossed the line from vehicle to daemon (the line's own counters; for the network link the
daemon's link-health records), bytes dropped for overflow, and the mission's outcome.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

from rover_ctl.app.firmware import FirmwareOptions, firmware_path, simulate_firmware
from rover_ctl.app.report import read_jsonl
from rover_ctl.app.sim import SimOptions, simulate

ROOT = Path(__file__).resolve().parent.parent
MISSION = ROOT / "missions" / "cmac_loop.waypoints"
WHEELS = ["link.wheel_left_index=1", "link.wheel_right_index=0"]
EMULATOR_LINES = [(57600, 0.0), (115200, 0.0), (921600, 0.0), (None, 0.0)]
FIRMWARE_LINES = [(57600, 0.0), (115200, 1e-4)]
FIRMWARE_SPEEDUP = 5


def _row(vehicle: str, baud: int | None, byte_error: float, out: Path, metrics: dict) -> dict:
    events = read_jsonl(out / "events.jsonl")
    plan = [r for r in events if r["type"] == "link_plan"][-1]
    row = {"vehicle": vehicle, "baud": baud, "byte_error": byte_error, "rates_hz": plan["rates_hz"],
           "planned_bytes_per_s": plan["bytes_per_s"], "line_bytes_per_s": plan["line_bytes_per_s"],
           "success": metrics.get("success"), "duration_s": metrics.get("duration_s"),
           "cross_track_max_m": metrics.get("cross_track_max_m"), "control_rate_hz": metrics.get("control_rate_hz")}  # fmt: skip
    line_path = out / "line.json"
    if line_path.exists():
        line = json.loads(line_path.read_text())
        seconds = line.get("sim_s") or line.get("vehicle_s")
        down = line["downlink"]
        row |= {"received_bytes_per_s": round(down["delivered"] / seconds), "dropped_overflow": down["dropped_overflow"],
                "corrupted": down["corrupted"], "uplink_bytes_per_s": round(line["uplink"]["delivered"] / seconds)}  # fmt: skip
    else:
        # The last link-health record: a window of vehicle time in mid-mission, the plan in force.
        health = [r["rx_bytes_per_s"] for r in events if r["type"] == "link" and r["rx_bytes_per_s"] > 0]
        row |= {"received_bytes_per_s": health[-1] if health else None, "dropped_overflow": None}
    row["line_use"] = round(row["received_bytes_per_s"] / row["line_bytes_per_s"], 3) if row["received_bytes_per_s"] else None
    return row


def run(quick: bool) -> dict:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n, (baud, error) in enumerate(EMULATOR_LINES[:1] if quick else EMULATOR_LINES):
            out = Path(tmp) / f"em{n}"
            metrics = simulate(SimOptions(mission=MISSION, out=out, timeout_s=400, line_baud=baud, line_byte_error=error), plots=False)
            rows.append(_row("rover-sitl (lockstep)", baud, error, out, metrics))
        if firmware_path() is not None and not quick:
            for n, (baud, error) in enumerate(FIRMWARE_LINES):
                out = Path(tmp) / f"fw{n}"
                metrics = simulate_firmware(FirmwareOptions(mission=MISSION, out=out, lockstep=False, speedup=FIRMWARE_SPEEDUP,
                                                            timeout_s=400, rangefinders="six", line_baud=baud,
                                                            line_byte_error=error, config_overrides=list(WHEELS)))  # fmt: skip
                rows.append(_row(f"ArduPilot firmware ({FIRMWARE_SPEEDUP}x)", baud, error, out, metrics))
    lines = [
        "_`python -m bench serial`._ The bundled mission, six rangefinders. Rates: what the daemon's link budget "
        "asked for (EXTRA1 = WHEEL_DISTANCE with ATTITUDE; DISTANCE_SENSOR per rangefinder). Received: bytes per "
        "second from vehicle to daemon, counted by the line (for TCP, the daemon's last link-health record: 2 s of vehicle time).\n",
        "| vehicle | line | EXTRA1 Hz | GPS Hz | rangefinder Hz | SIMSTATE Hz | planned B/s | received B/s | line use | dropped (overflow) | success | time s | cross-track max m |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        rates = r["rates_hz"]
        line = f"{r['baud']} baud" if r["baud"] else "TCP (100 kB/s assumed)"
        if r["byte_error"]:
            line += f", byte error {r['byte_error']:g}"
        lines.append(f"| {r['vehicle']} | {line} | {rates.get('EXTRA1', 0):g} | {rates.get('GPS_RAW_INT', 0):g} | "
                     f"{rates.get('DISTANCE_SENSOR', 0):g} | {rates.get('SIMSTATE', 0):g} | {r['planned_bytes_per_s']} | "
                     f"{r['received_bytes_per_s']} | {100 * r['line_use']:.0f}% | {r['dropped_overflow'] if r['dropped_overflow'] is not None else '-'} | "
                     f"{r['success']} | {r['duration_s']} | {r['cross_track_max_m']} |")  # fmt: skip
    return {"title": "Vehicle link over serial lines (cmac_loop)", "markdown": "\n".join(lines), "runs": rows}
