"""Open-loop motion of rover-sitl vs ArduPilot's own skid-steer model, on the same RC commands.

Both vehicles get the same RC_CHANNELS_OVERRIDE (ch1 steering, ch3 throttle, MANUAL, force-armed,
empty field at CMAC heading north): straight lines, pivots and arcs, each held ``HOLD_S`` of
vehicle time, then neutral until the rover stands still. The steady state is measured over the
last ``WINDOW_S`` from ground truth (SIMSTATE: lat, lng, yaw; ``steady_state``), each vehicle's
positions in its own ground frame (``wgs84_frame``, ``ardupilot_frame``):

- rover-sitl in lockstep (``sitl.launch``, ``sitl.client.LockstepClient``), stamped with the frame time;
- ArduPilot's firmware (``rover_ctl.app.firmware.firmware_command``: ``--model rover-skid``, stock
  rover.parm + rover-skid.parm, loopback only, its own temporary folder) free running at
  ``FIRMWARE_SPEEDUP``, SIMSTATE stamped with the ATTITUDE ``time_boot_ms`` it comes with, the
  overrides refreshed every ``REFRESH_WALL_S`` of wall time (well inside its 3 s
  RC_OVERRIDE_TIME of vehicle time).

SERVO_OUTPUT_RAW (servo1 left, servo3 right) is recorded too: the two mixers must agree, so any
difference is the vehicle models'. The firmware's figures are also predicted from its servo
outputs with ArduPilot's SIM_Rover skid-steer model (``ardupilot_model``), which checks that the
source read is the source run. docs/sitl.md discusses the differences.
"""

from __future__ import annotations

import math
import subprocess
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pymavlink import mavutil

from rover_ctl.app.firmware import firmware_command, firmware_path
from rover_ctl.vocabulary import ARM_FORCE_MAGIC, mav
from sitl.client import LockstepClient
from sitl.geodesy import LocalFrame
from sitl.launch import free_port, rover_sitl, stop_process
from sitl.mixer import mix_rc

HOME = (-35.363261, 149.165230, 584.0)
"""ArduPilot's CMAC field (lat, lon, alt), both vehicles heading north."""
NEUTRAL_US = 1500
COMMANDS = [
    # (kind, throttle_us, steering_us)
    ("straight", 1650, 1500), ("straight", 1800, 1500), ("straight", 2000, 1500),
    ("pivot", 1500, 1700), ("pivot", 1500, 2000),
    ("arc", 1700, 1600), ("arc", 1800, 1700), ("arc", 1700, 1800),
]  # fmt: skip
HOLD_S = 6.0
"""Vehicle seconds each command is held (both models settle within about 1 s: time constants
0.27 s and 0.29 s, and the firmware's MOT_SLEWRATE of 100 %/s)."""
WINDOW_S = 3.0
"""The last seconds of a hold that are measured."""
STEADY_TOLERANCE = 0.03
"""A hold is steady when the two halves of its window agree within this fraction (or the floors below)."""
SPEED_FLOOR_MPS = 0.05
"""Speeds below this count as standing (no ratio is taken)."""
TURN_FLOOR_DPS = 2.0
"""Turn rates below this count as not turning (no ratio is taken)."""
STILL_WINDOW_S = 1.0
"""Between commands, neutral until the last second of truth is below both floors..."""
SETTLE_MAX_S = 6.0
"""...or this long has passed (then the next command starts anyway and the run says so)."""
DIFFERENCE_LIMIT = 0.20
"""Emulator vs firmware differences above this fraction of the firmware's figure are flagged (issue 11)."""
TRUTH_RATE_HZ = 20
"""EXTRA1 (ATTITUDE, SIMSTATE) and RC_CHANNELS (SERVO_OUTPUT_RAW) stream rates asked of both."""
FIRMWARE_SPEEDUP = 10.0
REFRESH_WALL_S = 0.05
"""Wall seconds between override refreshes to the firmware (0.5 s of vehicle time at 10x)."""
STALL_WALL_S = 20.0
"""Wall seconds without vehicle time advancing before a vehicle counts as lost."""
BOOT_WALL_S = 60.0
"""Wall seconds for the firmware to boot, stream and accept the forced arming."""
# ArduPilot libraries/SITL/SIM_Rover.{h,cpp}, skid-steer frame (docs/sitl.md).
AP_SKID_MAX_SPEED_MPS = 4.0
AP_SKID_TURN_RATE_DPS = 140.0
AP_MAX_YAW_RATE_DPS = 360.0
AP_EARTH_RADIUS_M = 6378100.0
"""ArduPilot's RADIUS_OF_EARTH: its SITL moves the vehicle in metres of a sphere of this radius
(LOCATION_SCALING_FACTOR, longitude scaled by cos(latitude)), not on the WGS84 ellipsoid: at CMAC
WGS84 metres are 0.33 % shorter north-south and 0.11 % longer east-west, so each vehicle is
measured in its own frame."""


@dataclass
class Motion:
    speed_mps: float
    """Signed ground speed along the heading."""
    turn_rate_dps: float
    """Clockwise positive (compass)."""


Frame = Callable[[float, float], Callable]
"""(lat0_deg, lon0_deg) -> to_en(lat_deg, lon_deg) -> (east_m, north_m); arrays in, arrays out."""


def wgs84_frame(lat0_deg: float, lon0_deg: float):
    """rover-sitl's truth frame (sitl/geodesy.py)."""
    return LocalFrame(lat0_deg, lon0_deg).to_en


def ardupilot_frame(lat0_deg: float, lon0_deg: float):
    """ArduPilot's flat-earth metres about (lat0, lon0)."""
    metres_per_deg = math.radians(1.0) * AP_EARTH_RADIUS_M
    east_per_deg = metres_per_deg * math.cos(math.radians(lat0_deg))
    return lambda lat_deg, lon_deg: ((lon_deg - lon0_deg) * east_per_deg, (lat_deg - lat0_deg) * metres_per_deg)


def _heading_integrals(t_s: np.ndarray, yaw_rad: np.ndarray) -> np.ndarray:
    """Per sample interval, the integral of the unit heading vector (east, north) over it, exact
    for a yaw rate constant within the interval: dt * (sin, cos)(yaw_mid) * sinc(dyaw / 2)."""
    dt = np.diff(t_s)
    dyaw = np.diff(yaw_rad)
    mid = yaw_rad[:-1] + dyaw / 2.0
    scale = dt * np.sinc(dyaw / 2.0 / np.pi)  # numpy's sinc is sin(pi x) / (pi x)
    return np.column_stack([scale * np.sin(mid), scale * np.cos(mid)])


def steady_state(samples: list[tuple[float, float, float, float]], window_s: float = WINDOW_S,
                 frame: Frame = wgs84_frame) -> Motion:
    """Speed and turn rate over the last ``window_s`` of truth samples (t_s, lat_deg, lon_deg,
    yaw_rad NED).

    Turn rate: least-squares slope of the unwrapped yaw. Speed: the displacement from the
    window's first sample regressed on the path a unit speed along the measured heading would
    have driven (both models move along their heading, no side slip): exact on straights, arcs
    and pivots alike, and it averages SIMSTATE's 1e-7 degree (about 1 cm) quantisation over the
    whole window instead of summing it chord by chord."""
    end = samples[-1][0]
    window = [s for s in samples if s[0] >= end - window_s - 1e-9]
    if len(window) < 3:
        raise ValueError(f"steady_state: {len(window)} samples in the last {window_s:g} s")
    t = np.array([s[0] for s in window])
    yaw = np.unwrap(np.array([s[3] for s in window]))
    turn_rate_dps = math.degrees(np.polyfit(t - t[0], yaw, 1)[0])
    east, north = frame(window[0][1], window[0][2])(np.array([s[1] for s in window]), np.array([s[2] for s in window]))
    moved = np.column_stack([east, north])[1:]
    unit_path = np.cumsum(_heading_integrals(t, yaw), axis=0)
    norm = float(np.sum(unit_path * unit_path))
    speed_mps = float(np.sum(moved * unit_path)) / norm if norm > 0 else 0.0
    return Motion(speed_mps, turn_rate_dps)


def is_steady(samples: list[tuple[float, float, float, float]], window_s: float = WINDOW_S, frame: Frame = wgs84_frame) -> bool:
    """The two halves of the window agree (within STEADY_TOLERANCE or the floors)."""
    end = samples[-1][0]
    first = steady_state([s for s in samples if s[0] <= end - window_s / 2.0], window_s / 2.0, frame)
    second = steady_state(samples, window_s / 2.0, frame)
    return (abs(first.speed_mps - second.speed_mps) <= max(SPEED_FLOOR_MPS, STEADY_TOLERANCE * abs(second.speed_mps))
            and abs(first.turn_rate_dps - second.turn_rate_dps) <= max(TURN_FLOOR_DPS, STEADY_TOLERANCE * abs(second.turn_rate_dps)))  # fmt: skip


def is_still(motion: Motion) -> bool:
    return abs(motion.speed_mps) < SPEED_FLOOR_MPS and abs(motion.turn_rate_dps) < TURN_FLOOR_DPS


def ardupilot_model(left_us: float, right_us: float) -> Motion:
    """ArduPilot's SIM_Rover skid-steer steady state for servo1 (left) and servo3 (right):
    motors m = (pwm - 1500) / 500, throttle (m1 + m2) / 2 times max_speed 4 m/s, yaw rate
    (m1 - m2) * skid_turn_rate 140 deg/s clamped to MAX_YAW_RATE 360 deg/s."""
    m1, m2 = (left_us - 1500.0) / 500.0, (right_us - 1500.0) / 500.0
    turn = max(-AP_MAX_YAW_RATE_DPS, min(AP_MAX_YAW_RATE_DPS, (m1 - m2) * AP_SKID_TURN_RATE_DPS))
    return Motion(0.5 * (m1 + m2) * AP_SKID_MAX_SPEED_MPS, turn)


def relative_difference(emulator: float, firmware: float, floor: float) -> float | None:
    """(emulator - firmware) / |firmware|; 0 when both are below ``floor``; None when only the
    firmware is (no meaningful ratio)."""
    if abs(firmware) < floor:
        return 0.0 if abs(emulator) < floor else None
    return (emulator - firmware) / abs(firmware)


# ---- the two vehicles ---------------------------------------------------------------------------


@dataclass
class Truth:
    """What a vehicle reported: truth samples and the latest servo outputs."""

    t_s: float = 0.0
    samples: list[tuple[float, float, float, float]] = field(default_factory=list)
    servos_us: tuple[int, int] | None = None

    def simstate(self, t_s: float, msg) -> None:
        if self.samples and t_s <= self.samples[-1][0]:
            return  # a repeat of the last stamp (the firmware bursts at a speed-up)
        self.samples.append((t_s, msg.lat / 1e7, msg.lng / 1e7, msg.yaw))

    def since(self, t0_s: float) -> list[tuple[float, float, float, float]]:
        return [s for s in self.samples if s[0] >= t0_s]


class Emulator:
    """rover-sitl in lockstep; one ``step`` is one frame."""

    name = "rover-sitl"
    frame = staticmethod(wgs84_frame)

    def __init__(self, client: LockstepClient) -> None:
        self.client = client
        self.truth = Truth()
        self._command = (NEUTRAL_US, NEUTRAL_US)

    def start(self) -> None:
        self.client.arm(force=True)
        for stream in (mav.MAV_DATA_STREAM_EXTRA1, mav.MAV_DATA_STREAM_RC_CHANNELS):
            self.client.conn.mav.request_data_stream_send(1, 1, stream, TRUTH_RATE_HZ, 1)

    def _on_frame(self, t_s: float, msgs: list) -> tuple[int, int]:
        self.truth.t_s = t_s
        for msg in msgs:
            if msg.get_type() == "SIMSTATE":
                self.truth.simstate(t_s, msg)
            elif msg.get_type() == "SERVO_OUTPUT_RAW":
                self.truth.servos_us = (msg.servo1_raw, msg.servo3_raw)
        return self._command

    def step(self, throttle_us: int, steering_us: int) -> None:
        self._command = (throttle_us, steering_us)
        self.client.run(0.0, self._on_frame)  # exactly one frame


class Firmware:
    """ArduPilot's firmware free running at a speed-up; one ``step`` is one short wait for its messages."""

    name = "ArduPilot"
    frame = staticmethod(ardupilot_frame)

    def __init__(self, conn, proc: subprocess.Popen, log_path: Path) -> None:
        self.conn = conn
        self.proc = proc
        self.log_path = log_path
        self.truth = Truth()
        self.armed = False
        self._boot_ms: int | None = None
        self._sent: tuple[int, int] | None = None
        self._next_refresh = self._next_second = 0.0
        self._last_progress = time.monotonic()

    def _housekeeping(self) -> None:
        now = time.monotonic()
        if now >= self._next_second:
            self._next_second = now + 1.0
            self.conn.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            if self.conn.target_system:
                for stream in (mav.MAV_DATA_STREAM_EXTRA1, mav.MAV_DATA_STREAM_RC_CHANNELS):
                    self.conn.mav.request_data_stream_send(self.conn.target_system, 1, stream, TRUTH_RATE_HZ, 1)

    def _read(self, wait_s: float) -> None:
        msg = self.conn.recv_match(blocking=True, timeout=wait_s)
        while msg is not None:
            kind = msg.get_type()
            if kind == "ATTITUDE":
                self._boot_ms = msg.time_boot_ms
                if msg.time_boot_ms / 1000.0 > self.truth.t_s:
                    self.truth.t_s = msg.time_boot_ms / 1000.0
                    self._last_progress = time.monotonic()
            elif kind == "SIMSTATE" and self._boot_ms is not None:
                self.truth.simstate(self._boot_ms / 1000.0, msg)
            elif kind == "SERVO_OUTPUT_RAW":
                self.truth.servos_us = (msg.servo1_raw, msg.servo3_raw)
            elif kind == "HEARTBEAT" and msg.get_srcSystem() == 1 and msg.get_srcComponent() == 1:
                self.armed = bool(msg.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)
            msg = self.conn.recv_msg()
        if self.proc.poll() is not None:
            lines = self.log_path.read_text(errors="replace").strip().splitlines()
            raise RuntimeError(f"ardurover exited with status {self.proc.returncode}: {lines[-1] if lines else 'no output'}")
        if time.monotonic() - self._last_progress > STALL_WALL_S:
            raise RuntimeError(f"ardurover: no ATTITUDE for {STALL_WALL_S:g} s of wall time")

    def start(self) -> None:
        """Wait for its heartbeat and truth stream, then force-arm (asked again until it holds)."""
        deadline = time.monotonic() + BOOT_WALL_S
        next_arm = 0.0
        while not (self.armed and len(self.truth.samples) >= 3):
            if time.monotonic() > deadline:
                raise RuntimeError(f"ardurover: not streaming and armed within {BOOT_WALL_S:g} s (armed={self.armed})")
            self._housekeeping()
            if self.conn.target_system and not self.armed and time.monotonic() >= next_arm:
                next_arm = time.monotonic() + 1.0
                self.conn.mav.command_long_send(self.conn.target_system, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0,
                                                1, ARM_FORCE_MAGIC, 0, 0, 0, 0, 0)  # fmt: skip
            self._last_progress = time.monotonic()  # booting: vehicle time may not run yet
            self._read(0.05)

    def step(self, throttle_us: int, steering_us: int) -> None:
        self._housekeeping()
        now = time.monotonic()
        if (throttle_us, steering_us) != self._sent or now >= self._next_refresh:
            ignore = 65535  # RC_CHANNELS_OVERRIDE "leave this channel alone"
            self.conn.mav.rc_channels_override_send(self.conn.target_system, 1, steering_us, ignore, throttle_us,
                                                    ignore, ignore, ignore, ignore, ignore)  # fmt: skip
            self._sent, self._next_refresh = (throttle_us, steering_us), now + REFRESH_WALL_S
        self._read(0.01)


# ---- the schedule -------------------------------------------------------------------------------


def _settle(vehicle) -> bool:
    """Neutral until the last STILL_WINDOW_S of truth is still (True) or SETTLE_MAX_S passed."""
    start = vehicle.truth.t_s
    while vehicle.truth.t_s < start + SETTLE_MAX_S:
        vehicle.step(NEUTRAL_US, NEUTRAL_US)
        recent = vehicle.truth.since(start)
        if vehicle.truth.t_s >= start + STILL_WINDOW_S and len(recent) >= 3 and is_still(steady_state(recent, STILL_WINDOW_S, vehicle.frame)):
            return True
    return False


def drive(vehicle, commands=COMMANDS) -> list[dict]:
    """Each command held HOLD_S, measured over its last WINDOW_S, then neutral until still."""
    results = []
    settled = _settle(vehicle)
    for kind, throttle_us, steering_us in commands:
        start = vehicle.truth.t_s
        while vehicle.truth.t_s < start + HOLD_S:
            vehicle.step(throttle_us, steering_us)
        held = vehicle.truth.since(start)
        motion = steady_state(held, WINDOW_S, vehicle.frame)
        results.append({"kind": kind, "throttle_us": throttle_us, "steering_us": steering_us,
                        "speed_mps": round(motion.speed_mps, 3), "turn_rate_dps": round(motion.turn_rate_dps, 1),
                        "steady": is_steady(held, WINDOW_S, vehicle.frame), "started_still": settled,
                        "servos_us": list(vehicle.truth.servos_us) if vehicle.truth.servos_us else None})  # fmt: skip
        settled = _settle(vehicle)
    return results


def run_emulator(commands=COMMANDS) -> list[dict]:
    lat, lon, alt = HOME
    with rover_sitl("--lockstep", "--home", f"{lat},{lon},{alt},0") as sitl:
        client = LockstepClient(sitl.url)
        try:
            emulator = Emulator(client)
            emulator.start()
            return drive(emulator, commands)
        finally:
            client.close()


def run_firmware(commands=COMMANDS, speedup: float = FIRMWARE_SPEEDUP) -> list[dict]:
    binary = firmware_path()
    if binary is None:
        raise SystemExit("bench motion: ../shared/ardupilot/ardurover is absent (set ROVER_CTL_SHARED)")
    port = free_port()
    with tempfile.TemporaryDirectory(prefix="bench-motion-") as tmp:
        workdir = Path(tmp)
        conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, source_component=190,
                                          dialect="ardupilotmega")  # fmt: skip
        log = open(workdir / "ardurover.log", "w")
        proc = subprocess.Popen(firmware_command(binary, workdir, HOME, {}, speedup, [port]), cwd=workdir,
                                stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT)  # fmt: skip
        try:
            firmware = Firmware(conn, proc, workdir / "ardurover.log")
            firmware.start()
            return drive(firmware, commands)
        finally:
            stop_process(proc)
            conn.close()
            log.close()


# ---- the report ---------------------------------------------------------------------------------


def _cell(difference: float | None, firmware: float, floor: float) -> str:
    if difference is None:
        return "**-**"
    if abs(firmware) < floor:
        return "both ~0"
    text = f"{difference:+.0%}"
    return f"**{text}**" if abs(difference) > DIFFERENCE_LIMIT else text


def compare(firmware: list[dict], emulator: list[dict]) -> list[dict]:
    rows = []
    for fw, em in zip(firmware, emulator, strict=True):
        speed = relative_difference(em["speed_mps"], fw["speed_mps"], SPEED_FLOOR_MPS)
        turn = relative_difference(em["turn_rate_dps"], fw["turn_rate_dps"], TURN_FLOOR_DPS)
        model = ardupilot_model(*fw["servos_us"]) if fw["servos_us"] else None
        rows.append({
            "command": f"{fw['kind']} thr {fw['throttle_us']} / str {fw['steering_us']}",
            "firmware": fw, "emulator": em,
            "speed_difference": speed, "turn_difference": turn,
            "flagged": any(d is None or abs(d) > DIFFERENCE_LIMIT for d in (speed, turn)),
            "mixers_agree": fw["servos_us"] == em["servos_us"] == list(mix_rc(fw["steering_us"], fw["throttle_us"])),
            "ardupilot_model": None if model is None else {"speed_mps": round(model.speed_mps, 3),
                                                           "turn_rate_dps": round(model.turn_rate_dps, 1)},
        })  # fmt: skip
    return rows


def _markdown(rows: list[dict], speedup: float) -> str:
    lines = [
        "Same RC overrides (MANUAL, force-armed, empty field) into ArduPilot's Rover firmware SITL "
        f"(`rover-skid`, stock parameters, {speedup:g}x) and into rover-sitl (lockstep). Each command held "
        f"{HOLD_S:g} s of vehicle time and measured over the last {WINDOW_S:g} s from SIMSTATE ground truth; "
        "turn rate clockwise positive. Cells: **firmware / emulator**; difference = (emulator - firmware) / firmware, "
        f"**bold** beyond {DIFFERENCE_LIMIT:.0%} (\"-\": only one of them moves; \"both ~0\": neither does).\n",
        "| command (thr / str us) | servos L/R us | speed m/s | speed diff | turn deg/s | turn diff | steady |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        fw, em = row["firmware"], row["emulator"]
        servos = f"{'/'.join(map(str, fw['servos_us'] or []))}" + ("" if row["mixers_agree"] else f" vs {'/'.join(map(str, em['servos_us'] or []))}")
        diffs = [_cell(row["speed_difference"], fw["speed_mps"], SPEED_FLOOR_MPS),
                 _cell(row["turn_difference"], fw["turn_rate_dps"], TURN_FLOOR_DPS)]
        lines.append(f"| {fw['kind']} {fw['throttle_us']} / {fw['steering_us']} | {servos} "
                     f"| {fw['speed_mps']:.2f} / {em['speed_mps']:.2f} | {diffs[0]} "
                     f"| {fw['turn_rate_dps']:.1f} / {em['turn_rate_dps']:.1f} | {diffs[1]} "
                     f"| {'yes' if fw['steady'] and em['steady'] else 'no'} |")  # fmt: skip
    model_errors = [
        (abs(r["ardupilot_model"]["speed_mps"] - r["firmware"]["speed_mps"]), abs(r["ardupilot_model"]["turn_rate_dps"] - r["firmware"]["turn_rate_dps"]))
        for r in rows if r["ardupilot_model"]
    ]  # fmt: skip
    agree = all(r["mixers_agree"] for r in rows)
    lines += [
        "",
        f"Mixers: the firmware's servo outputs {'equal' if agree else 'differ from'} rover-sitl's and `sitl.mixer.mix_rc` "
        f"on {'every' if agree else 'some'} command{'' if agree else ' (both shown)'}: the differences are the vehicle models'. "
        "ArduPilot's SIM_Rover skid-steer formula (4 m/s x mean motor, 140 deg/s x motor difference, clamp 360 deg/s) "
        + (f"applied to those servo outputs predicts the firmware's figures within {max(e[0] for e in model_errors):.2f} m/s "
           f"and {max(e[1] for e in model_errors):.1f} deg/s. " if model_errors else "was not checked: no servo outputs received. ")
        + f"{sum(r['flagged'] for r in rows)} of {len(rows)} commands differ by more than {DIFFERENCE_LIMIT:.0%}: "
        "docs/sitl.md, \"Motion: rover-sitl vs ArduPilot's skid-steer model\".",
    ]  # fmt: skip
    return "\n".join(lines)


def run(quick: bool) -> dict:
    commands = COMMANDS[::3] if quick else COMMANDS
    firmware = run_firmware(commands)
    emulator = run_emulator(commands)
    rows = compare(firmware, emulator)
    return {"title": "Open-loop motion: ArduPilot's skid-steer model vs rover-sitl", "markdown": _markdown(rows, FIRMWARE_SPEEDUP),
            "firmware_speedup": FIRMWARE_SPEEDUP, "hold_s": HOLD_S, "window_s": WINDOW_S, "rows": rows}  # fmt: skip
