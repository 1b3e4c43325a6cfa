"""A mission run against ArduPilot's own Rover firmware built for SITL (``ardurover``), not rover-sitl.

``FirmwareRun`` is ``rover_ctl.app.sim.SimRun`` with the vehicle swapped: the firmware runs in a
temporary folder of the run's output (it writes ``eeprom.bin`` and ``logs/`` into its working
directory), on loopback only, its SERIAL0 dialling the daemon (``--serial0 udpclient`` ->
``rover-ctl run --vehicle udpin``) and its SERIAL1 a watcher (sysid 254, never allowed to drive)
that records the simulator's ground truth (SIMSTATE, stamped with the ATTITUDE boot time that comes
with it) as ``truth.jsonl`` ``state`` records, so the run report measures path and estimate error
as it does for rover-sitl.

The parameters are ArduPilot's stock ``rover.parm`` and ``rover-skid.parm`` plus only what
docs/ardupilot.md documents for a rover driven by rover_ctl: wheel encoders (``WENC*``) and
rangefinders (``RNGFNDn_*``). Mission completion is read from MISSION_ITEM_REACHED (every
navigation item's seq), never from STATUSTEXT wording.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import signal
import socket
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402  (MAVLINK20 first: mavutil's default dialect is MAVLink 1 without it)
from pymavlink.dialects.v20 import ardupilotmega as mav

from rover_ctl.app.sim import STOP_TIMEOUT_S, WATCHER_SYSID, Progress, SimError, SimOptions, SimRun
from rover_ctl.vocabulary import PILOT_STEER_TYPE, STEER_UNCHANGED_WHEN_REVERSING
from sitl.launch import free_port, line_relay, signals_held, stop_process

SHARED_DIR = Path(os.environ.get("ROVER_CTL_SHARED") or Path(__file__).resolve().parents[2].parent / "shared")
"""../shared beside the checkout, or $ROVER_CTL_SHARED (a git worktree elsewhere)."""
FIRMWARE_DIR = SHARED_DIR / "ardupilot"
"""Where the firmware fixture lives."""
FIRMWARE = "ardurover"
DEFAULT_PARAMS = ("rover.parm", "rover-skid.parm")
"""ArduPilot's stock default parameter files for the skid-steer model (Tools/autotest/default_params)."""
TRUTH_RATE_HZ = 10
"""EXTRA1 rate asked on the watcher link (ATTITUDE and SIMSTATE come together in that stream)."""

WHEEL_ENCODERS = {
    "WENC_TYPE": 10, "WENC2_TYPE": 10,  # 10 = SITL quadrature encoders
    "WENC_RADIUS": 0.07, "WENC2_RADIUS": 0.07,
    "WENC_POS_Y": 0.16, "WENC2_POS_Y": -0.16,
}  # fmt: skip
"""Two simulated wheel encoders (docs/ardupilot.md); the simulator's instance 0 is the RIGHT wheel."""
RANGEFINDER_LAYOUTS = {
    "six": (0, 7, 1, 6, 2, 4),
    "paper": (0, 2, 4, 6),
    "three": (0, 2, 6),
    "none": (),
}
"""Rangefinder orientations (MAV_SENSOR_ORIENTATION) per named layout: the bundled six, the
paper's four, a rover without a back one, none."""
RANGEFINDER_MAX_M = 4.0
FIRMWARE_NICE = 10
"""Niceness added to the firmware's process. The firmware is the clock of the run: short of CPU,
a deprioritised firmware only slows its own time, whereas a starved daemon falls behind the
vehicle (its loop rate falls, and with it the speed it allows, SCHED_STEP_TRVL per step). On a
rover the autopilot has its own processor; this keeps the daemon's share of this one closer to
that."""
SERIALS_DEFAULT_TCP = (1, 2)
"""SITL serials that otherwise open TCP servers on every address (ports 5762, 5763, fixed: a second
firmware process fails to bind them); ``firmware_command`` turns off those it is not given."""


def firmware_path(directory: Path = FIRMWARE_DIR) -> Path | None:
    """The firmware binary, or None when ../shared/ardupilot is absent."""
    binary = directory / FIRMWARE
    return binary if binary.is_file() and os.access(binary, os.X_OK) else None


def lower_priority(pid: int, nice: int) -> None:
    """Add ``nice`` to process ``pid``'s niceness (at most 19); a no-op where the OS has no
    niceness or refuses."""
    try:
        os.setpriority(os.PRIO_PROCESS, pid, min(19, os.getpriority(os.PRIO_PROCESS, pid) + nice))
    except (AttributeError, OSError):
        pass


def extra_params(rangefinders: tuple[int, ...], wheel_encoders: bool = True) -> dict[str, float]:
    """The documented parameters on top of the stock files: PILOT_STEER_TYPE 3 (the steering never
    reversed in reverse, which the daemon's pre-arm check requires), encoders and one simulated
    rangefinder per orientation (``RNGFNDn_TYPE 100`` = SITL, ``SIM_SONAR_ROT 0`` so each one
    follows its own ``RNGFNDn_ORIENT``)."""
    params: dict[str, float] = {PILOT_STEER_TYPE: STEER_UNCHANGED_WHEN_REVERSING}
    params |= dict(WHEEL_ENCODERS) if wheel_encoders else {}
    if rangefinders:
        params["SIM_SONAR_ROT"] = 0
    for n, orientation in enumerate(rangefinders, 1):
        params |= {f"RNGFND{n}_TYPE": 100, f"RNGFND{n}_ORIENT": orientation, f"RNGFND{n}_MIN": 0.2,
                   f"RNGFND{n}_MAX": RANGEFINDER_MAX_M}  # fmt: skip
    return params


def firmware_command(binary: Path, workdir: Path, home: tuple[float, float, float], params: dict[str, float],
                     speedup: float, serial_ports: list[int], firmware_dir: Path = FIRMWARE_DIR) -> list[str]:
    """The firmware's command line, to run in ``workdir``: the skid-steer model, the eeprom wiped,
    ArduPilot's stock defaults plus ``params`` (written to ``workdir/extra.parm``), heading north
    at ``home`` (lat, lon, alt), SERIALn dialling ``udp 127.0.0.1:serial_ports[n]`` and its other
    TCP serials off (loopback only, no listening port: SITL's RC input socket on UDP 5501, bound
    to every address in its source, is the one it cannot be told to drop)."""
    parm = workdir / "extra.parm"
    parm.write_text("".join(f"{name} {value:g}\n" for name, value in params.items()))
    defaults = ",".join([str(firmware_dir / name) for name in DEFAULT_PARAMS] + [str(parm)])
    lat_deg, lon_deg, alt_m = home
    serials = [arg for n, port in enumerate(serial_ports) for arg in (f"--serial{n}", f"udpclient:127.0.0.1:{port}")]
    serials += [arg for n in SERIALS_DEFAULT_TCP if n >= len(serial_ports) for arg in (f"--serial{n}", "none:")]
    return [str(binary), "--model", "rover-skid", "--speedup", f"{speedup:g}", "-w",
            f"--home={lat_deg},{lon_deg},{alt_m},0", "--defaults", defaults, *serials]  # fmt: skip


@dataclass
class FirmwareOptions(SimOptions):
    rangefinders: str = "six"
    """A key of RANGEFINDER_LAYOUTS."""
    params: dict[str, float] = field(default_factory=dict)
    """More parameters on top of ``extra_params`` (tests use it for what they vary)."""
    firmware_dir: Path = FIRMWARE_DIR


class FirmwareProcess(subprocess.Popen):
    """The firmware's process, stopped as ``SimRun.stop`` stops the emulator."""

    def stop(self, timeout_s: float = STOP_TIMEOUT_S) -> int:
        return stop_process(self, timeout_s=timeout_s)


class FirmwareRun(SimRun):
    """ArduPilot's firmware, the daemon and our GCS and watcher connections (see the module doc)."""

    def __init__(self, options: FirmwareOptions):
        super().__init__(options)
        if options.rangefinders not in RANGEFINDER_LAYOUTS:
            raise SimError(f"rangefinders: {options.rangefinders!r} is not one of {', '.join(RANGEFINDER_LAYOUTS)}")
        binary = firmware_path(options.firmware_dir)
        if binary is None:
            raise SimError(f"{options.firmware_dir / FIRMWARE}: no ArduPilot firmware")
        self.binary = binary
        self.vehicle_port = free_port(socket.SOCK_DGRAM, avoid={self.gcs_port, self.watch_port})
        self.workdir = self.out / "ardupilot"
        self._truth_file: Any = None
        self._boot_ms: int | None = None
        self._next_watcher_wall = 0.0
        self._relay_stack = contextlib.ExitStack()
        self._relay: Any = None

    def _firmware_command(self) -> list[str]:
        o: FirmwareOptions = self.options  # type: ignore[assignment]
        home = self.home
        if home is None:
            raise SimError("the firmware needs a mission with a home position")
        params = extra_params(RANGEFINDER_LAYOUTS[o.rangefinders]) | o.params
        return firmware_command(self.binary, self.workdir, (home.lat_deg, home.lon_deg, self.home_alt_m), params,
                                speedup=1.0 if o.lockstep else o.speedup,
                                serial_ports=[self.vehicle_port, self.watch_port], firmware_dir=o.firmware_dir)  # fmt: skip

    def _vehicle_url(self) -> str:
        """The daemon's vehicle link: the firmware's SERIAL0 on UDP, or the line relay's pty."""
        if self.options.line_baud:
            return f"{self._relay.pty_device},{self.options.line_baud}"
        return f"udpin:127.0.0.1:{self.vehicle_port}"

    def start(self) -> None:
        """The daemon (behind the line relay, with ``line_baud``) and the watcher listen first,
        then the firmware dials both. A port picked free can be taken by another process before
        the daemon binds it (it then exits EX_UNAVAILABLE): the daemon, watcher and firmware start
        again on new ports, as ``SimRun`` does for its daemon."""
        o = self.options
        if o.line_baud:
            # SERIAL0 dials the relay, which serves the line on a pty in the firmware's time.
            self._relay = self._relay_stack.enter_context(line_relay(
                o.line_baud, self.line_stats_path, byte_error=o.line_byte_error, speedup=1.0 if o.lockstep else o.speedup,
                seed=o.seed, port=self.vehicle_port))  # fmt: skip
        self._start_until_bound(self._start_children, self._restart_on_new_ports)
        self._upload_mission()

    def _start_children(self) -> None:
        if self.workdir.exists():
            shutil.rmtree(self.workdir)
        self.workdir.mkdir(parents=True)
        self._start_daemon()
        self.watcher = mavutil.mavlink_connection(f"udpin:127.0.0.1:{self.watch_port}", source_system=WATCHER_SYSID,
                                                  source_component=mav.MAV_COMP_ID_MISSIONPLANNER, dialect="ardupilotmega")  # fmt: skip
        self._truth_file = open(self.out / "truth.jsonl", "w", encoding="utf-8")
        self._logs.append(self._truth_file)
        sitl_log = open(self.out / "sitl.log", "w")
        sitl_out = open(self.out / "sitl.out", "w")
        self._logs += [sitl_log, sitl_out]
        with signals_held():  # stop() must know the firmware whenever Ctrl-C or SIGTERM comes
            self.sitl = FirmwareProcess(self._firmware_command(), cwd=self.workdir, stdin=subprocess.DEVNULL,
                                        stdout=sitl_out, stderr=sitl_log)  # fmt: skip
        lower_priority(self.sitl.pid, FIRMWARE_NICE)

    def _restart_on_new_ports(self) -> None:
        """Undo ``_start_children`` after a daemon that could not bind its ports; pick new ones."""
        stop_process(self.daemon, signal.SIGINT, STOP_TIMEOUT_S)
        self.sitl.stop(STOP_TIMEOUT_S)
        for conn in (self.gcs, self.watcher):
            if conn is not None:
                conn.close()
        self.gcs = self.watcher = None
        self._truth_file.close()
        taken = {self.vehicle_port} if self.options.line_baud else set()  # the relay's port is bound already
        self.gcs_port = free_port(socket.SOCK_DGRAM, avoid=taken)
        self.watch_port = free_port(socket.SOCK_DGRAM, avoid=taken | {self.gcs_port})
        self.gcs_url = self.progress.gcs_url = f"udpout:127.0.0.1:{self.gcs_port}"
        if not self.options.line_baud:
            self.vehicle_port = free_port(socket.SOCK_DGRAM, avoid={self.gcs_port, self.watch_port})

    def _check_children(self) -> None:
        for name, proc, log_path in (("ardurover", self.sitl, self.out / "sitl.log"), ("rover-ctl run", self.daemon, self.daemon_output)):
            if proc is not None and proc.poll() is not None:
                text = log_path.read_text(errors="replace").strip().splitlines()
                raise SimError(f"{name} exited with status {proc.returncode}: {text[-1] if text else 'no output'}")

    def stop(self) -> None:
        super().stop()
        self._relay_stack.close()  # the relay writes the line's counters as it stops
        if self._truth_file is not None and not self._truth_file.closed:
            self._truth_file.close()

    def arm(self, timeout_s: float = 60.0) -> None:
        """Arm and wait until the daemon's heartbeat says armed: the firmware refuses arming for a
        few seconds after start ("Arm: Accels inconsistent") while its simulated IMUs settle, after
        the daemon has already accepted the request; so ask again until it holds."""
        if not self.wait_for(lambda p: p.position_en is not None, wall_timeout_s=timeout_s):
            raise SimError(f"no position from the daemon within {timeout_s:g} s: {self.progress.last_text}")
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            self.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1)
            if self.wait_for(lambda p: p.armed, wall_timeout_s=2.0):
                return
        raise SimError(f"the rover did not arm within {timeout_s:g} s: {self.progress.last_text}")

    # ---- watching ----------------------------------------------------------------------------

    def poll(self, wait_s: float = 0.05) -> None:
        """As ``SimRun.poll``, with the firmware's watcher port: our heartbeat and a stream request
        there every wall second (its streams on that port are slow by default), SIMSTATE as truth."""
        self._heartbeat()
        if time.monotonic() >= self._next_watcher_wall:
            self._next_watcher_wall = time.monotonic() + 1.0
            self.watcher.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            if self.watcher.target_system:
                self.watcher.mav.request_data_stream_send(1, 1, mav.MAV_DATA_STREAM_EXTRA1, TRUTH_RATE_HZ, 1)
        msg = self.gcs.conn.recv_match(blocking=True, timeout=wait_s)
        while msg is not None:
            self._observe(msg)
            self._heartbeat()
            msg = self.gcs.conn.recv_msg()
        while (msg := self.watcher.recv_msg()) is not None:
            kind = msg.get_type()
            if kind == "ATTITUDE":
                self._boot_ms = msg.time_boot_ms
                self.progress.sim_time_s = max(self.progress.sim_time_s, msg.time_boot_ms / 1000.0)
                self._heartbeat()  # the daemon ages our heartbeat in the firmware's time
            elif kind == "SIMSTATE" and self._boot_ms is not None:
                record = {"t_s": self._boot_ms / 1000.0, "type": "state", "lat_deg": msg.lat / 1e7,
                          "lon_deg": msg.lng / 1e7, "yaw_deg": math.degrees(msg.yaw)}  # fmt: skip
                self._truth_file.write(json.dumps(record) + "\n")
        self._check_children()


def simulate_firmware(options: FirmwareOptions, on_tick: Callable[[Progress], None] | None = None, plots: bool = False) -> dict[str, Any]:
    """Run the mission on the firmware, stop, write the report; returns the metrics."""
    from rover_ctl.app.report import write_report

    with FirmwareRun(options) as run:
        complete = run.run_mission(on_tick)
        reached = sorted(run.progress.reached)
    metrics = write_report(options.out, None, timed_out=not complete, plots=plots)
    metrics["reached_seqs"] = reached
    metrics["out"] = str(options.out)
    return metrics
