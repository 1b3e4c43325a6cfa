"""``rover-ctl sim``: run a mission against the emulator, end to end, and write a report.

Three processes, as in the field: ``rover-sitl`` (the rover), ``rover-ctl run`` (the daemon) and
this one, which plays the ground station. ``SimRun`` starts the emulator with ``sitl.launch`` (it
returns once the emulator's ``ready`` line came), then the daemon (``sys.executable -m rover_ctl
run --log-run OUT``), uploads the mission over the GCS link with the mission client, arms, starts
AUTO and watches the GCS link until the mission completes or the sim-time budget runs out.
Progress comes from message fields only: MISSION_CURRENT (``seq``, ``total``, ``mission_state``:
COMPLETE ends the run), MISSION_ITEM_REACHED, HEARTBEAT, the position; collisions come from the
emulator's truth log (``collision`` records, read as it grows). A second emulator endpoint (sysid
254, never allowed to drive) sets the emulator's SIM_* fault parameters (tests use it).

Our GCS heartbeat goes out every ``GCS_HEARTBEAT_PERIOD_S`` of wall time, as a ground station
sends it; lockstep runs faster than that clock, and the daemon calls a heartbeat late only when it
is late in both vehicle and wall time.

Ports are chosen free on 127.0.0.1: the vehicle link is TCP (the daemon connects to the
emulator's ``tcpin``), the GCS link UDP with the daemon listening (``udpin``: it serves each
ground station that has spoken, up to ``gcs.max_peers``, so a second one such as MAVProxy can
attach to a running sim), the watcher UDP.

``SimOptions.out`` is this run's folder: the daemon writes its logs into it as they are (the
``rover-ctl sim`` command line makes it a new numbered run folder under ``--out``), and the report
(``rover_ctl.app.report``) is written there beside both tlogs, the control CSV, the event log, the
emulator's truth log and the processes' logs.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mav  # noqa: E402

from rover_ctl.autopilot.executor import NAV_COMMANDS  # noqa: E402
from rover_ctl.config import GcsParams, load_config  # noqa: E402
from rover_ctl.estimation.frame import LocalFrame  # noqa: E402
from rover_ctl.mavlink.mission_client import MissionClient, MissionClientError  # noqa: E402
from rover_ctl.mavlink.signing import KeyStore  # noqa: E402
from rover_ctl.mavlink.telemetry import StatusTextAssembler  # noqa: E402
from rover_ctl.mission.files import load_mission  # noqa: E402
from rover_ctl.mission.model import Mission  # noqa: E402
from rover_ctl.mission.summary import nominal_duration_s  # noqa: E402
from rover_ctl.vocabulary import ARM_FORCE_MAGIC, MissionState, RoverMode  # noqa: E402
from sitl.launch import SitlError, SitlProcess, free_port, signals_held, stop_process  # noqa: E402
from sitl.launch import start as start_sitl  # noqa: E402
from sitl.world import Home as EmulatorHome  # noqa: E402
from sitl.world import WorldError, load_world  # noqa: E402

ROVER_CTL = [sys.executable, "-m", "rover_ctl"]
"""The ``rover-ctl`` command of this interpreter."""
WATCHER_SYSID = 254
"""Our id on the emulator's second endpoint: not SYSID_MYGCS, so it can never drive the rover."""
SITL_READY_TIMEOUT_S = 30.0
"""Wall seconds for the emulator to print its ready line."""
GCS_CONNECT_TIMEOUT_S = 30.0
"""Wall seconds for the daemon's first heartbeat on the GCS link."""
CONNECT_POLL_S = 1.0
"""Each wait for that heartbeat, between which the children are checked: a daemon that exited
at start is reported within about this long."""
DAEMON_START_ATTEMPTS = 3
"""Starts of the daemon when it exits 69 (EX_UNAVAILABLE: a link could not be opened) before it
answers: the GCS port is picked free, then bound by the daemon, and a process beside this one
(a second simulation, a test) can take it in between."""
STALL_TIMEOUT_S = 20.0
"""Wall seconds without any message from the daemon before the run is declared stuck."""
ARM_RETRY_S = 0.2
"""Wall seconds between arming attempts the daemon refused."""
POSITION_TIMEOUT_S = 30.0
"""Wall seconds for the daemon's first position (GPS fix, pose), for the clock to reach
``arm_at_s``, and for arming."""
ARM_AT_S = 30.0
"""``simulate`` in lockstep arms the rover at this sim time, the emulator's clock held there until
it is armed (``rover-sitl --hold-at-s``): every run of a seed then arms at the same frame and
runs the same (the daemon's pre-arm checks pass within about 6 s of boot; by 30 s the pose
filter has settled)."""
STOP_TIMEOUT_S = 10.0
"""Wall seconds a child gets to exit after SIGINT/SIGTERM before it is killed."""
GCS_HEARTBEAT_PERIOD_S = 1.0
"""Our GCS heartbeat period in wall time, as ground stations send it."""


BUDGET_MARGIN = 2.0
"""The default time budget is this many times the mission's nominal duration (its route at the
mission's speeds plus its holds): detours around obstacles, turns at waypoints, slowing for each
waypoint and yielding take time the straight route does not count. The bench's default rule base
drives its obstacle scenarios in at most 1.4x the shortest path, at less than cruise speed."""
BUDGET_FLOOR_S = 300.0
"""...and at least this many sim seconds: a short mission still gets time to find its way
around a cul-de-sac or wait for a crossing obstacle."""


def time_budget_s(nominal_s: float) -> float:
    """Sim seconds a mission of ``nominal_s`` nominal duration
    (``rover_ctl.mission.summary.nominal_duration_s``) may take before the run counts as failed."""
    return max(BUDGET_FLOOR_S, BUDGET_MARGIN * nominal_s)


class TruthTail:
    """The records appended to the emulator's truth log since the last ``read`` (whole lines only)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._offset = 0
        self._partial = b""

    def read(self) -> list[dict]:
        try:
            with open(self.path, "rb") as handle:
                handle.seek(self._offset)
                data = handle.read()
        except FileNotFoundError:
            return []
        self._offset += len(data)
        *lines, self._partial = (self._partial + data).split(b"\n")
        records = []
        for line in lines:
            try:
                records.append(json.loads(line))
            except ValueError:
                continue  # a line cut by a crash
        return records


def boot_altitude_m(mission: Mission) -> float:
    """The altitude the emulator boots at for this mission's home: its own, or 0 when that is NaN
    (MAVLink's "unset", which ``mission check`` accepts); WorldError when the emulator would
    refuse it (its ``--home`` check)."""
    if mission.home is None:
        return 0.0
    alt_m = mission.home.alt_m if math.isfinite(mission.home.alt_m) else 0.0
    EmulatorHome(mission.home.lat_deg, mission.home.lon_deg, alt_m)
    return alt_m


class SimError(RuntimeError):
    """The run could not be set up or a child process failed; one line."""


@dataclass
class SimOptions:
    mission: Path
    out: Path
    """This run's folder (logs, report); made if missing."""
    world: Path | None = None
    obstacles: int | None = None
    seed: int = 1
    rulebase: str = "default"
    lockstep: bool = True
    speedup: float = 1.0
    timeout_s: float | None = None
    """Budget in sim seconds from the start of AUTO; None: ``time_budget_s`` of the mission."""
    config_overrides: list[str] = field(default_factory=list)
    sitl_params: list[str] = field(default_factory=list)
    """NAME=VALUE for the emulator's --param (e.g. SIM_GPS_GLITCH_X=5)."""
    mission_store: Path | None = None
    """Where the daemon persists the mission (and its progress); None: not persisted."""
    signing_key: bytes | None = None
    """MAVLink 2 signing key of the GCS link, for the daemon (a key file in a private temporary
    folder, removed at the end) and this ground station. None: the daemon runs without signing
    (never with the user's own key)."""
    line_baud: int | None = None
    """The vehicle link over a serial line of this many baud (docs/sitl.md, "Serial line"):
    rover-sitl's ``--pty --baud``, the firmware behind ``sitl.line_relay``; the daemon opens the
    pty as ``DEVICE,BAUD``. The line's counters are written to ``line.json`` in the run folder.
    None: a TCP (rover-sitl) or UDP (firmware) socket on loopback."""
    line_byte_error: float = 0.0
    """With ``line_baud``: the probability that a byte on the line arrives changed."""
    arm_at_s: float | None = None
    """Lockstep: ``run_mission`` arms at this sim time, the emulator's clock held there until the
    rover is armed (``simulate`` sets ``ARM_AT_S``). None: as soon as it can, which in lockstep
    is whenever the ground station's commands happen to land."""


@dataclass
class Progress:
    """What the ground station sees, for the live display."""

    sim_time_s: float = 0.0
    started_sim_s: float | None = None
    wall_started: float = field(default_factory=time.monotonic)
    current_seq: int = 0
    waypoints_total: int = 0
    """Navigation items in the mission file."""
    items_total: int = 0
    """MISSION_CURRENT.total: the daemon's mission items (home excluded)."""
    mission_state: MissionState = MissionState.UNKNOWN
    """MISSION_CURRENT.mission_state."""
    reached: set[int] = field(default_factory=set)
    distance_left_m: float = math.nan
    collisions: int = 0
    mode: int = RoverMode.HOLD
    armed: bool = False
    system_status: int = 0
    """MAV_STATE of the daemon's heartbeat (CRITICAL while a failsafe holds)."""
    held_at_s: float | None = None
    """Lockstep: the sim time of a frame whose end marker came twice (the emulator's clock held
    there, the daemon done with the frame; or a marker not answered in 0.2 wall s)."""
    ready_to_arm: bool | None = None
    """SYS_STATUS's pre-arm health bit (MAV_SYS_STATUS_PREARM_CHECK); None until reported."""
    last_text: str = ""
    texts: list[str] = field(default_factory=list)
    """Every STATUSTEXT from the daemon, in order."""
    position_en: tuple[float, float] | None = None
    gcs_url: str = ""
    """Where another ground station can attach to the daemon."""

    @property
    def complete(self) -> bool:
        return self.mission_state == MissionState.COMPLETE

    @property
    def elapsed_sim_s(self) -> float:
        return 0.0 if self.started_sim_s is None else self.sim_time_s - self.started_sim_s

    @property
    def elapsed_wall_s(self) -> float:
        return time.monotonic() - self.wall_started


class SimRun:
    """The emulator and the daemon as child processes plus our GCS and watcher connections."""

    cancelled = threading.Event()
    """Set, every run of this process gives up at its next check (SimError) and stops its
    children: how a program running several on threads (the navigation benchmark) stops them all
    on Ctrl-C or SIGTERM, which only its main thread receives."""

    def __init__(self, options: SimOptions):
        self.options = options
        self.out = Path(options.out)
        self.out.mkdir(parents=True, exist_ok=True)
        loaded = load_mission(options.mission)
        self.mission: Mission = loaded.mission
        self.warnings = loaded.warnings
        if not self.mission.items:
            raise SimError(f"{options.mission}: the mission has no items")
        self.home = self.mission.home
        try:  # the emulator's own checks: their one-line errors, before anything starts
            self.home_alt_m = boot_altitude_m(self.mission)
            self.world = load_world(options.world) if options.world is not None else None
        except WorldError as exc:
            raise SimError(str(exc)) from None
        self.frame = LocalFrame(self.home.lat_deg, self.home.lon_deg, self.home_alt_m) if self.home else None
        self.targets = {seq: (item.x, item.y) for seq, item in enumerate(self.mission.items, 1) if item.is_global and (item.x or item.y)}
        self.progress = Progress(waypoints_total=sum(i.command in NAV_COMMANDS for i in self.mission.items))
        self._texts = StatusTextAssembler()
        self.world_path: Path | None = options.world
        self.sitl: SitlProcess | None = None
        self.daemon: subprocess.Popen | None = None
        self.gcs: MissionClient | None = None
        self.watcher: Any = None
        self.vehicle_port = free_port(socket.SOCK_STREAM)
        self.gcs_port = free_port(socket.SOCK_DGRAM)
        self.gcs_url = f"udpout:127.0.0.1:{self.gcs_port}"
        """Where a ground station reaches the daemon (it listens; every peer that speaks is served,
        so MAVProxy can attach to a running sim with ``--master`` this URL)."""
        self.progress.gcs_url = self.gcs_url
        self.watch_port = free_port(socket.SOCK_DGRAM, avoid={self.gcs_port})
        self._key_dir: str | None = None
        """A private temporary folder for the daemon's key file (not the report folder, which is shared)."""
        self._logs: list[Any] = []
        self._last_rx_wall = time.monotonic()
        self._param_ack: dict[str, float] = {}
        self._last_marker_s: float | None = None
        """The watcher's last lockstep marker's time (``Progress.held_at_s``)."""
        self.send_heartbeats = True
        """Our GCS heartbeat at 1 Hz, as a ground station sends it (tests pause it for the GCS failsafe)."""
        self._next_heartbeat_wall = 0.0
        self._truth = TruthTail(self.out / "truth.jsonl")
        self.daemon_log_run = self.out
        self.daemon_output = self.out / "daemon.log"
        """The daemon's stdout and stderr (its log lines), quoted when it fails."""
        """The daemon's run folder (``restart_daemon`` gives the second daemon its own)."""

    # ---- processes -------------------------------------------------------------------------

    @property
    def signing_key_path(self) -> Path:
        return Path(self._key_dir or ".") / "signing.key"

    def _sitl_flags(self) -> list[str]:
        """The emulator's flags (``sitl.launch`` adds the endpoints)."""
        o = self.options
        cmd = ["--seed", str(o.seed), "--truth-log", str(self.out / "truth.jsonl")]
        cmd += ["--lockstep"] if o.lockstep else ["--speedup", f"{o.speedup:g}"]
        if self._arm_at_s is not None:
            cmd += ["--hold-at-s", repr(self._arm_at_s)]
        heading = self.world.home.heading_deg if self.world is not None and self.world.home is not None else 0.0
        if o.world is not None:
            cmd += ["--world", str(o.world)]
        if self.home is not None:
            cmd += [f"--home={self.home.lat_deg},{self.home.lon_deg},{self.home_alt_m},{heading}"]
        if o.obstacles:
            legs = [(self.home.lat_deg, self.home.lon_deg)] if self.home else []
            legs += [self.targets[s] for s in sorted(self.targets)]
            self.world_path = self.out / "world.geojson"
            cmd += ["--scatter", str(o.obstacles), "--along=" + ";".join(f"{lat},{lon}" for lat, lon in legs),
                    "--write-world", str(self.world_path)]  # fmt: skip
        for item in o.sitl_params:
            cmd += ["--param", item]
        if o.line_baud:
            cmd += ["--pty", "--baud", str(o.line_baud), "--byte-error", repr(o.line_byte_error),
                    "--line-stats", str(self.line_stats_path)]  # fmt: skip
        return cmd

    @property
    def line_stats_path(self) -> Path:
        return self.out / "line.json"

    def _vehicle_url(self) -> str:
        """Where the daemon reaches the vehicle: the emulator's TCP port, or its pty at the line's baud."""
        if self.options.line_baud:
            return f"{self.sitl.pty_device},{self.options.line_baud}"
        return f"tcp:127.0.0.1:{self.vehicle_port}"

    def _daemon_command(self) -> list[str]:
        o = self.options
        cmd = [*ROVER_CTL, "run", "--vehicle", self._vehicle_url(),
               "--gcs", f"udpin:127.0.0.1:{self.gcs_port}", "--rulebase", o.rulebase, "--log-run", str(self.daemon_log_run),
               "--mission-store", str(o.mission_store or ""), "--signing-key-file", str(self.signing_key_path) if self._key_dir else ""]  # fmt: skip
        for item in o.config_overrides:
            cmd += ["--set", item]
        return cmd

    def start(self) -> None:
        """Start both children, connect the GCS and the watcher, upload the mission."""
        if self.options.signing_key is not None:
            self._key_dir = tempfile.mkdtemp(prefix="rover-ctl-sim-")
            KeyStore(self.signing_key_path).save_key(self.options.signing_key)
        self._start_sitl()
        self.watcher = mavutil.mavlink_connection(f"udpout:127.0.0.1:{self.watch_port}", source_system=WATCHER_SYSID,
                                                  source_component=mav.MAV_COMP_ID_MISSIONPLANNER, dialect="ardupilotmega")  # fmt: skip
        self.watcher.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        self._start_until_bound(self._start_daemon, self._new_gcs_port)
        self._upload_mission()

    def _upload_mission(self) -> None:
        """The mission to the daemon. Refused or unanswered: a SimError naming why (the daemon's
        exit first, when it has gone), not a traceback."""
        try:
            self.gcs.upload(self.mission)
        except MissionClientError as exc:
            self._check_children()
            raise SimError(f"{exc}; see {self.daemon_output}") from None

    def _start_until_bound(self, start: Callable[[], None], repick: Callable[[], None]) -> None:
        """``start()`` (which starts the daemon), then our GCS connection. A port picked free can
        be taken by another process before the daemon binds it: the daemon exits EX_UNAVAILABLE,
        ``repick()`` undoes the start on new ports and it goes again, DAEMON_START_ATTEMPTS in all."""
        for attempt in range(1, DAEMON_START_ATTEMPTS + 1):
            start()
            try:
                self._connect_gcs()
                return
            except SimError:
                if attempt == DAEMON_START_ATTEMPTS or self.daemon.poll() != os.EX_UNAVAILABLE:
                    raise
                repick()

    def _new_gcs_port(self) -> None:
        self.gcs.close()
        self.gcs_port = free_port(socket.SOCK_DGRAM, avoid={self.watch_port})
        self.gcs_url = self.progress.gcs_url = f"udpout:127.0.0.1:{self.gcs_port}"

    def _start_sitl(self) -> None:
        """The emulator, started again on new ports when one picked free was taken before it bound
        it (``sitl.launch.start``)."""
        try:
            self.sitl = start_sitl(*self._sitl_flags(), endpoints=self._sitl_endpoints(), repick=self._new_sitl_ports,
                                   stdout_path=self.out / "sitl.out", stderr_path=self.out / "sitl.log",
                                   start_timeout_s=SITL_READY_TIMEOUT_S)  # fmt: skip
        except SitlError as exc:
            raise SimError(str(exc)) from None

    def _sitl_endpoints(self) -> list[str]:
        endpoints = [f"udpin:127.0.0.1:{self.watch_port}"]
        if not self.options.line_baud:  # else the daemon's vehicle link is the emulator's pty
            endpoints.insert(0, f"tcpin:127.0.0.1:{self.vehicle_port}")
        return endpoints

    def _new_sitl_ports(self) -> list[str]:
        self.vehicle_port = free_port(socket.SOCK_STREAM)
        self.watch_port = free_port(socket.SOCK_DGRAM, avoid={self.gcs_port})
        return self._sitl_endpoints()

    def _start_daemon(self) -> None:
        daemon_log = open(self.daemon_output, "w")
        self._logs.append(daemon_log)
        with signals_held():  # stop() must know it whenever Ctrl-C or SIGTERM comes
            self.daemon = subprocess.Popen(self._daemon_command(), stdout=daemon_log, stderr=subprocess.STDOUT)

    def _connect_gcs(self) -> None:
        """Our GCS connection, once the daemon heartbeats on its GCS link."""
        self.gcs = MissionClient(self.gcs_url, replace(GcsParams(), client_connect_timeout_s=CONNECT_POLL_S), signing_key=self.options.signing_key)
        deadline = time.monotonic() + GCS_CONNECT_TIMEOUT_S
        while True:
            self._check_children()
            try:
                self.gcs.connect()
                return
            except Exception as exc:  # MissionClientError: not up yet
                if time.monotonic() > deadline:
                    raise SimError(f"daemon: no heartbeat on the GCS link within {GCS_CONNECT_TIMEOUT_S:g} s ({exc}); see {self.daemon_output}") from None

    def restart_daemon(self, log_run: Path) -> None:
        """Kill the daemon (SIGKILL: no clean shutdown, as a crash or a power cut) and start it
        again with the same options, logging into ``log_run``; the emulator runs on."""
        stop_process(self.daemon, signal.SIGKILL, STOP_TIMEOUT_S)
        self.daemon_log_run = log_run
        self.daemon_output = Path(log_run) / "daemon.log"
        self.daemon_output.parent.mkdir(parents=True, exist_ok=True)
        self.progress.position_en = None  # the old daemon's: the new one reports its own once it has one
        self._start_daemon()

    def _check_children(self) -> None:
        if SimRun.cancelled.is_set():
            raise SimError("cancelled")
        if self.sitl is not None and self.sitl.poll() is not None:
            raise SimError(f"rover-sitl exited with status {self.sitl.returncode}: {self.sitl.last_error()}")
        if self.daemon is not None and self.daemon.poll() is not None:
            text = self.daemon_output.read_text(errors="replace").strip().splitlines()
            raise SimError(f"rover-ctl run exited with status {self.daemon.returncode}: {text[-1] if text else 'no output'}")

    def stop(self) -> None:
        """Daemon first (SIGINT: it sets motors neutral), then the emulator; kill what does not exit."""
        if self.daemon is not None:
            stop_process(self.daemon, signal.SIGINT, STOP_TIMEOUT_S)
        if self.sitl is not None:
            self.sitl.stop(STOP_TIMEOUT_S)
        self.progress.collisions += sum(r.get("type") == "collision" for r in self._truth.read())  # flushed at exit
        for conn in (self.gcs, self.watcher):
            if conn is not None:
                conn.close()
        for handle in self._logs:
            handle.close()
        if self._key_dir is not None:
            shutil.rmtree(self._key_dir, ignore_errors=True)
            self._key_dir = None

    def __enter__(self) -> "SimRun":
        try:
            self.start()
        except BaseException:
            self.stop()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    # ---- ground-station actions ---------------------------------------------------------------

    def command(self, command: int, *params: float, timeout_s: float = 5.0) -> int:
        """COMMAND_LONG to the daemon; returns the MAV_RESULT (-1: no answer). Messages seen
        while waiting update the progress. Only an ACK addressed to this ground station answers
        (the daemon's GCS port sends every peer's ACKs to each peer: a CLI's, MAVProxy's)."""
        target = self.gcs.target
        me = (self.gcs.conn.source_system, self.gcs.conn.source_component)
        padded = tuple(params) + (0.0,) * (7 - len(params))
        deadline = time.monotonic() + timeout_s
        next_send = 0.0
        while time.monotonic() < deadline:
            self._heartbeat()  # a ground station waiting for an answer is still there
            if time.monotonic() >= next_send:
                self.gcs.conn.mav.command_long_send(target[0], target[1], command, 0, *padded)
                next_send = time.monotonic() + 1.0
            msg = self.gcs.conn.recv_match(blocking=True, timeout=0.1)
            if msg is None:
                self._check_children()
                continue
            self._observe(msg)
            if msg.get_type() == "COMMAND_ACK" and msg.command == command and (msg.target_system, msg.target_component) == me:
                return msg.result
        return -1

    @property
    def _arm_at_s(self) -> float | None:
        """``options.arm_at_s`` where the emulator can hold its clock for it: in lockstep, with the
        vehicle link on a socket (a serial line carries bytes in sim time, and a held clock would
        hold the arming command on the line too)."""
        o = self.options
        return o.arm_at_s if o.lockstep and not o.line_baud else None

    def wait_for_position(self, timeout_s: float = POSITION_TIMEOUT_S) -> None:
        """Until the daemon reports a position (AUTO and arming need one)."""
        if not self.wait_for(lambda p: p.position_en is not None, wall_timeout_s=timeout_s):
            raise SimError(f"no position from the daemon within {timeout_s:g} s: {self.progress.last_text}")

    def arm(self, timeout_s: float = POSITION_TIMEOUT_S, force: bool = False) -> None:
        """Arm as soon as the daemon's and the vehicle's pre-arm checks pass (``force``: skip the
        daemon's); a refusal is retried. Its ACK is the vehicle's answer, on which the daemon drives,
        so nothing waits here for the GCS heartbeat's flag (1 Hz of wall time is many seconds of
        lockstep sim time)."""
        self.wait_for_position(timeout_s)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1, ARM_FORCE_MAGIC if force else 0) == mav.MAV_RESULT_ACCEPTED:
                return
            self.wait_for(lambda p: False, wall_timeout_s=ARM_RETRY_S)
        raise SimError(f"the rover did not arm within {timeout_s:g} s: {self.progress.last_text}")

    def arming_answer(self, timeout_s: float = POSITION_TIMEOUT_S, force: bool = False) -> int:
        """The daemon's answer (MAV_RESULT) to an arming request once it has a position, asked
        again while it is TEMPORARILY_REJECTED (its rangefinders are counted for
        ``link.rangefinder_discovery_s`` after the first reading), as a ground station would."""
        self.wait_for_position(timeout_s)
        deadline = time.monotonic() + timeout_s
        while True:
            result = self.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1, ARM_FORCE_MAGIC if force else 0)
            if result != mav.MAV_RESULT_TEMPORARILY_REJECTED or time.monotonic() >= deadline:
                return result
            self.wait_for(lambda p: False, wall_timeout_s=ARM_RETRY_S)

    def set_mode(self, custom_mode: int) -> int:
        return self.command(mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom_mode)

    def start_mission(self) -> None:
        result = self.command(mav.MAV_CMD_MISSION_START, 0, 0)
        if result != mav.MAV_RESULT_ACCEPTED:
            raise SimError(f"MISSION_START refused (result {result}): {self.progress.last_text}")

    def sitl_param(self, name: str, value: float, timeout_s: float = 5.0, confirm: bool = True) -> None:
        """PARAM_SET on the emulator (fault injection), confirmed by its PARAM_VALUE unless
        ``confirm`` is false (a quiet link sends no confirmation)."""
        if not confirm:
            self.watcher.mav.param_set_send(1, 1, name.encode(), float(value), mav.MAV_PARAM_TYPE_REAL32)
            return
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            self.watcher.mav.param_set_send(1, 1, name.encode(), float(value), mav.MAV_PARAM_TYPE_REAL32)
            end = time.monotonic() + 0.5
            while time.monotonic() < end:
                self.poll(0.05)
                if self._param_ack.get(name) == float(value):
                    return
        raise SimError(f"rover-sitl did not confirm {name}={value:g}")

    # ---- watching ----------------------------------------------------------------------------

    def poll(self, wait_s: float = 0.05) -> None:
        """Read what both connections have (waiting up to ``wait_s`` for the GCS link)."""
        self._heartbeat()
        msg = self.gcs.conn.recv_match(blocking=True, timeout=wait_s)
        while msg is not None:
            self._observe(msg)
            self._heartbeat()
            msg = self.gcs.conn.recv_msg()
        while (msg := self.watcher.recv_msg()) is not None:
            if msg.get_type() == "PARAM_VALUE":
                self._param_ack[msg.param_id] = float(msg.param_value)
            elif msg.get_type() == "ATTITUDE":  # the emulator's own clock, at its sensor rate
                self.progress.sim_time_s = max(self.progress.sim_time_s, msg.time_boot_ms / 1000.0)
            elif msg.get_type() == "TIMESYNC" and msg.tc1 == 0 and self.options.lockstep:  # a lockstep frame's end: its exact time
                t_s = msg.ts1 / 1e9
                if t_s == self._last_marker_s:
                    self.progress.held_at_s = t_s
                self._last_marker_s = t_s
                self.progress.sim_time_s = max(self.progress.sim_time_s, t_s)
        self.progress.collisions += sum(r.get("type") == "collision" for r in self._truth.read())
        self._check_children()

    def _heartbeat(self) -> None:
        """Our GCS heartbeat, due every period of wall time."""
        if self.send_heartbeats and time.monotonic() >= self._next_heartbeat_wall:
            self._next_heartbeat_wall = time.monotonic() + GCS_HEARTBEAT_PERIOD_S
            self.gcs.conn.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)

    def _observe(self, msg: Any) -> None:
        p = self.progress
        kind = msg.get_type()
        if kind == "BAD_DATA":
            return
        self._last_rx_wall = time.monotonic()
        if kind == "HEARTBEAT":
            p.mode = msg.custom_mode
            p.armed = bool(msg.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)
            p.system_status = msg.system_status
        elif kind == "GLOBAL_POSITION_INT":
            p.sim_time_s = max(p.sim_time_s, msg.time_boot_ms / 1000.0)
            if self.frame is not None:
                p.position_en = self.frame.to_enu(msg.lat / 1e7, msg.lon / 1e7)
                target = self.targets.get(p.current_seq)
                if target is not None:
                    te, tn = self.frame.to_enu(*target)
                    p.distance_left_m = math.dist(p.position_en, (te, tn))
        elif kind == "ATTITUDE":
            p.sim_time_s = max(p.sim_time_s, msg.time_boot_ms / 1000.0)
        elif kind == "SYS_STATUS" and msg.onboard_control_sensors_present & mav.MAV_SYS_STATUS_PREARM_CHECK:
            p.ready_to_arm = bool(msg.onboard_control_sensors_health & mav.MAV_SYS_STATUS_PREARM_CHECK)
        elif kind == "MISSION_CURRENT":
            p.current_seq = msg.seq
            p.items_total = msg.total
            try:
                p.mission_state = MissionState(msg.mission_state)
            except ValueError:
                p.mission_state = MissionState.UNKNOWN
        elif kind == "MISSION_ITEM_REACHED":
            p.reached.add(msg.seq)
        elif kind == "STATUSTEXT":
            text = self._texts.add(msg)
            if text is not None:
                p.last_text = text
                p.texts.append(text)

    def wait_for(self, predicate: Callable[[Progress], bool], sim_timeout_s: float | None = None,
                 wall_timeout_s: float | None = None, on_tick: Callable[[Progress], None] | None = None) -> bool:  # fmt: skip
        """Watch until ``predicate(progress)``; False on a sim or wall timeout. Raises SimError if
        a child dies or the daemon goes silent."""
        sim_end = None if sim_timeout_s is None else self.progress.sim_time_s + sim_timeout_s
        wall_end = None if wall_timeout_s is None else time.monotonic() + wall_timeout_s
        while not predicate(self.progress):
            if sim_end is not None and self.progress.sim_time_s >= sim_end:
                return False
            if wall_end is not None and time.monotonic() >= wall_end:
                return False
            if time.monotonic() - self._last_rx_wall > STALL_TIMEOUT_S:
                raise SimError(f"no message from the daemon for {STALL_TIMEOUT_S:g} s; see {self.daemon_output}")
            self.poll()
            if on_tick:
                on_tick(self.progress)
        return True

    def run_mission(self, on_tick: Callable[[Progress], None] | None = None) -> bool:
        """Arm, MISSION_START, watch to the end. True if complete within the budget.

        With ``arm_at_s`` (lockstep): once the emulator's clock stands at it, MISSION_START and
        then the arming, so that the daemon drives AUTO from the frame at which the vehicle arms,
        in every run the same frame (docs/architecture.md, "Lockstep handshake")."""
        arm_at_s = self._arm_at_s
        if arm_at_s is None:
            self.arm()
            self.start_mission()
        else:
            self.wait_for_position()
            # The hold's marker twice: the daemon is done with that frame, so MISSION_START cannot
            # come before its step there in one run and after it in another.
            if not self.wait_for(lambda p: (p.held_at_s or 0.0) >= arm_at_s - 1e-9, wall_timeout_s=POSITION_TIMEOUT_S):
                raise SimError(f"the emulator's clock did not stop at {arm_at_s:g} s within {POSITION_TIMEOUT_S:g} s")
            self.start_mission()
            self.arm()
        self.progress.started_sim_s = self.progress.sim_time_s
        return self.wait_for(lambda p: p.complete, sim_timeout_s=self.budget_s, on_tick=on_tick)

    @property
    def budget_s(self) -> float:
        """``options.timeout_s``, else the budget scaled from the mission at the daemon's speeds."""
        if self.options.timeout_s is not None:
            return self.options.timeout_s
        config = load_config(None, self.options.config_overrides)
        return time_budget_s(nominal_duration_s(self.mission, config.executor.cruise_speed_mps, config.robot.max_speed_mps))


def simulate(options: SimOptions, on_tick: Callable[[Progress], None] | None = None, plots: bool = True) -> dict[str, Any]:
    """The whole ``rover-ctl sim``: run, stop, report. Returns the metrics."""
    from rover_ctl.app.report import write_report

    if options.lockstep and options.arm_at_s is None:
        options = replace(options, arm_at_s=ARM_AT_S)
    with SimRun(options) as run:
        complete = run.run_mission(on_tick)
    metrics = write_report(options.out, run.world_path, timed_out=not complete, plots=plots)
    metrics["out"] = str(options.out)
    return metrics
