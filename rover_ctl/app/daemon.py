"""The controller daemon: one single-threaded loop wiring the links to the pure core.

Each turn of the loop

1. reads the vehicle link and feeds every reading to the estimator (wheel distances also to the
   wheel-speed meter; the latest range per orientation is kept; SIMSTATE truth only goes to the tlog);
2. runs a control step when the vehicle (sensor) clock has reached the next tick of
   ``daemon.control_rate_hz``; in lockstep (the vehicle sends TIMESYNC frame markers) the step
   runs at the frame's marker and the marker is answered only after the step's override went out;
3. polls the GCS link (``rover_ctl.mavlink.gcs.GcsLink``), for which the daemon is the ``AutopilotHandlers``;
4. sends telemetry to the GCS and blocks on both sockets for at most ``daemon.idle_wait_s``.

The control step: failsafes -> mode -> (AUTO/RTL) mission executor -> path follower (global
planner, carrot) -> fuzzy navigator -> wheel-speed PI -> RC override. MANUAL hands the RC channels
back to the vehicle's radio; HOLD, disarmed and failsafe holds send neutral. The vehicle itself is
kept in MANUAL mode: every autonomous behaviour is the daemon's.

Time: every decision uses vehicle time (message timestamps) so a run is the same at any speed-up.
The wall clock serves link housekeeping and one failsafe: a silent vehicle link cannot advance
vehicle time, so its silence is measured on the wall clock.
"""

from __future__ import annotations

import json
import logging
import math
import select
import time
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mav

from rover_ctl.config import Config
from rover_ctl.estimation.estimator import PoseEstimator
from rover_ctl.autopilot.executor import NAV_COMMANDS, EventKind, MissionExecutor
from rover_ctl.autopilot.failsafe import Action, FailsafeDecision, FailsafeInputs, Failsafes
from rover_ctl.fuzzy import load_rulebase
from rover_ctl.mavlink.gcs import ConfigParams, GcsLink, VehicleState
from rover_ctl.estimation.frame import LocalFrame, enu_to_compass_rad
from rover_ctl.vocabulary import ARM_FORCE_MAGIC, RoverMode
from rover_ctl.mavlink.vehicle import Battery, FrameMarker, LinkError, StatusText, VehicleLink, VehicleStatus
from rover_ctl.mission.model import Home, Mission
from rover_ctl.mission.store import MissionStore
from rover_ctl.navigation.navigator import Navigator
from rover_ctl.navigation.planner import Fence, PathFollower, Planner
from rover_ctl.navigation.proximity import ObstacleMemory
from rover_ctl.estimation.readings import Attitude, GpsFix, RangeReading, WheelDistance
from rover_ctl.app.logs import CsvLog, TlogWriter
from rover_ctl.navigation.wheel_control import WheelCommand, WheelController

log = logging.getLogger("rover_ctl.app.daemon")

# Exit codes (sysexits.h), so that a service manager can tell a bad setup from a crash.
EXIT_OK = 0
EXIT_SOFTWARE = 70
EXIT_UNAVAILABLE = 69
"""The vehicle never answered."""
EXIT_CONFIG = 78

CSV_COLUMNS = (
    "t_s", "mode", "armed", "failsafe", "est_east_m", "est_north_m", "est_heading_rad", "est_speed_mps",
    "est_healthy", "gps_ok", "goal_seq", "goal_east_m", "goal_north_m", "target_east_m", "target_north_m",
    "cross_track_m", "speed_limit_mps", "target_distance_m", "target_direction_rad",
    "range_front_m", "range_front_right_m", "range_right_m", "range_back_m", "range_left_m", "range_front_left_m",
    "left_set_rpm", "right_set_rpm", "left_meas_rpm", "right_meas_rpm", "steering_us", "throttle_us", "latency_ms",
)  # fmt: skip
SENSORS_PRESENT = (mav.MAV_SYS_STATUS_SENSOR_GPS | mav.MAV_SYS_STATUS_SENSOR_3D_GYRO | mav.MAV_SYS_STATUS_SENSOR_3D_MAG
                   | mav.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS)  # fmt: skip
"""SYS_STATUS sensors the daemon reports on the GCS link (through the vehicle)."""
SENSOR_FAILSAFES = {"GPS lost": mav.MAV_SYS_STATUS_SENSOR_GPS, "fence breach": mav.MAV_SYS_STATUS_GEOFENCE,
                    "vehicle link": mav.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS}  # fmt: skip
"""Active failsafe -> the SYS_STATUS health bit it clears."""
RANGE_COLUMNS = {0: "range_front_m", 1: "range_front_right_m", 2: "range_right_m", 4: "range_back_m",
                 6: "range_left_m", 7: "range_front_left_m"}  # fmt: skip


class EventLog:
    """events.jsonl: what happened when (vehicle time), for the report."""

    def __init__(self, path: Path | None):
        self._file = open(path, "w", encoding="utf-8") if path else None

    def write(self, t_s: float, kind: str, **fields: Any) -> None:
        if self._file:
            self._file.write(json.dumps({"t_s": round(t_s, 3), "type": kind, **fields}) + "\n")
            self._file.flush()

    def close(self) -> None:
        if self._file:
            self._file.close()


class Daemon:
    """The controller. ``run()`` returns an exit code; ``stop()`` (signal-safe) ends the loop."""

    def __init__(self, config: Config, rulebase: str = "default", log_dir: str | Path | None = None):
        self.config = config
        self.rulebase = load_rulebase(rulebase)
        self.log_dir = Path(log_dir) if log_dir else (Path(config.daemon.log_dir) if config.daemon.log_dir else None)
        self.settings = config.daemon
        self._stop = False
        # Vehicle-side state.
        self.link: VehicleLink | None = None
        self.gcs: GcsLink | None = None
        self.vehicle: VehicleStatus | None = None
        self.home: Home | None = None
        self.frame: LocalFrame | None = None
        self.estimator: PoseEstimator | None = None
        robot = config.robot  # read through functions: a parameter changed by the GCS applies at once
        self.wheels = WheelController(lambda: robot.wheel_radius_m, config.wheel_control)
        self.navigator = Navigator(self.rulebase, config.navigator, lambda: robot.max_wheel_rpm, lambda: robot.wheel_radius_m)
        self.failsafes = Failsafes(config.failsafe)
        self.decision: FailsafeDecision | None = None
        self.clock_s = 0.0
        """Failsafe clock: vehicle time, carried on by the wall clock while the vehicle is silent."""
        self.last_fix_s: float | None = None
        self.commanded_speed_mps = 0.0
        self._silent_neutral_wall_s = 0.0
        self._marker_wall_s = 0.0
        self.ranges: dict[int, RangeReading] = {}
        self.proximity = ObstacleMemory(config.proximity, lambda: robot.footprint_length_m, lambda: robot.footprint_width_m)
        self._remembered_s: dict[int, float] = {}  # time of the last reading put into the memory, per orientation
        self._last_said: str | None = None
        self.battery: Battery | None = None
        # Autopilot state the GCS sees.
        self.mode = int(RoverMode.HOLD)
        self.mission = Mission()
        self.lockstep = False
        self.next_tick_s: float | None = None
        self.last_step_s: float | None = None
        self._released = False
        self._rx_perf: float | None = None
        self.steps = 0
        self.table = ConfigParams.persistent(config)
        self.events = EventLog(None)
        self.csv: CsvLog | None = None
        self.tlogs: list[TlogWriter] = []
        # Built once a GPS fix gives the local frame, rebuilt on every new mission.
        self.planner: Planner | None = None
        self.follower: PathFollower | None = None
        self.executor: MissionExecutor | None = None

    @property
    def period_s(self) -> float:
        return 1.0 / self.settings.control_rate_hz

    # ---- lifecycle -----------------------------------------------------------------------------

    def stop(self) -> None:
        self._stop = True

    def open(self) -> bool:
        """Connect both links and open the logs. False if stopped while waiting for the vehicle;
        raises LinkError when the vehicle is absent."""
        cfg = self.config
        if self.log_dir:
            self.log_dir.mkdir(parents=True, exist_ok=True)
            self.events = EventLog(self.log_dir / "events.jsonl")
            self.csv = CsvLog(self.log_dir / "control.csv", CSV_COLUMNS)
        self.link = VehicleLink(
            cfg.link.vehicle_url,
            cfg.link,
            command_timeout_s=self.settings.command_timeout_s,
            command_retries=self.settings.command_retries,
        )
        if self.log_dir:
            self.tlogs.append(TlogWriter(self.log_dir / "vehicle.tlog"))
            self.tlogs[-1].attach(self.link.conn)
        log.info("vehicle link %s: waiting for a heartbeat", cfg.link.vehicle_url)
        self.vehicle = self.link.wait_vehicle(self.settings.vehicle_wait_s, cancelled=lambda: self._stop)
        if self.vehicle is None:
            return False
        log.info("vehicle sysid %d found (mode %d, armed %s)", self.link.target_system, self.vehicle.custom_mode, self.vehicle.armed)
        self._request_streams()
        result = self.link.command(mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, RoverMode.MANUAL)
        if not result.accepted:
            log.warning("vehicle refused MANUAL mode (result %d): overrides may be ignored", result.result)
        store_path = cfg.gcs.mission_store_path
        store = MissionStore(Path(store_path).expanduser()) if store_path else None
        self.gcs = GcsLink(cfg.link.gcs_url, cfg.gcs, handlers=self, store=store)
        if self.log_dir:
            self.tlogs.append(TlogWriter(self.log_dir / "gcs.tlog"))
            self.tlogs[-1].attach(self.gcs.conn)
        log.info("GCS link %s ready", cfg.link.gcs_url)
        return True

    def _request_streams(self) -> None:
        p = self.settings
        self.link.request_streams(
            {"ATTITUDE": p.sensor_rate_hz, "GPS_RAW_INT": p.gps_rate_hz, "DISTANCE_SENSOR": p.rangefinder_rate_hz,
             "SIMSTATE": p.truth_rate_hz},
            extra1_hz=p.sensor_rate_hz,
        )  # fmt: skip
        self._streams_requested_wall_s = time.monotonic()

    def run(self) -> int:
        """Open, loop until stopped, close. Returns a process exit code."""
        try:
            if not self.open():
                self.close()
                return EXIT_OK
        except LinkError as exc:
            log.error("%s", exc)
            self.close()
            return EXIT_UNAVAILABLE
        try:
            while not self._stop:
                self.turn()
        except Exception:
            log.exception("control loop failed")
            self.shutdown()
            return EXIT_SOFTWARE
        self.shutdown()
        return EXIT_OK

    def shutdown(self) -> None:
        """Motors neutral first, then disarm, then close links and logs."""
        if self.link:
            self.link.send_override(self.config.wheel_control.rc_trim_us, self.config.wheel_control.rc_trim_us)
            self.link.arm_async(False)
            log.info("stopped: motors neutral, disarm sent")
        self.close()

    def close(self) -> None:
        for closeable in (self.gcs, self.link, self.csv, self.events, *self.tlogs):
            if closeable is not None:
                closeable.close()

    # ---- one loop turn -------------------------------------------------------------------------

    def turn(self) -> None:
        link = self.link
        link.tick()
        items = link.poll()
        marker: FrameMarker | None = None
        for item in items:
            if isinstance(item, FrameMarker):
                marker = item
            else:
                self._on_item(item)
        if marker is not None:
            self.lockstep = True
            self._marker_wall_s = time.monotonic()
            self._maybe_step(marker.time_s)
            link.answer_marker(marker)
        elif not self.lockstep and items:
            self._maybe_step(link.vehicle_time_s)
        self._check_silence()
        self.gcs.poll(time.monotonic())
        self._send_telemetry()
        if not items:
            fds = [fd for fd in (link.fileno(), getattr(self.gcs.conn, "fd", None)) if fd is not None]
            select.select(fds, [], [], self.settings.idle_wait_s)

    def _on_item(self, item: Any) -> None:
        if isinstance(item, WheelDistance):
            self._rx_perf = time.perf_counter()
            self.wheels.on_wheels(item)
            if self.estimator:
                self.estimator.on_wheels(item)
        elif isinstance(item, Attitude):
            self._rx_perf = time.perf_counter()
            if self.estimator:
                self.estimator.on_attitude(item)
        elif isinstance(item, RangeReading):
            self._rx_perf = time.perf_counter()
            self.ranges[item.orientation] = item
        elif isinstance(item, GpsFix):
            self._rx_perf = time.perf_counter()
            if item.has_fix:
                self.last_fix_s = item.time_s
            if self.home is None and item.has_fix:
                self._set_home(item)
            if self.estimator:
                self.estimator.on_gps(item)
        elif isinstance(item, VehicleStatus):
            self.vehicle = item
        elif isinstance(item, Battery):
            self.battery = item
        elif isinstance(item, StatusText):
            log.info("vehicle: %s", item.text)
            self.events.write(item.time_s, "statustext", text=item.text, severity=item.severity)

    def _set_home(self, fix: GpsFix) -> None:
        self.home = Home(fix.lat_deg, fix.lon_deg, fix.alt_m)
        self.frame = LocalFrame(fix.lat_deg, fix.lon_deg, fix.alt_m)
        self.estimator = PoseEstimator(self.frame, self.config.estimator, lambda: self.config.robot.track_m)
        self.events.write(fix.time_s, "frame", lat_deg=fix.lat_deg, lon_deg=fix.lon_deg, alt_m=fix.alt_m)
        log.info("home set at %.7f %.7f", fix.lat_deg, fix.lon_deg)
        self._load_mission_into_core()

    # ---- mission ---------------------------------------------------------------------------------

    def _load_mission_into_core(self) -> None:
        """(Re)build the planner, path follower and executor for the current mission and home."""
        if self.frame is None:
            return  # done again once the first fix gives a frame
        cfg = self.config

        def to_enu(lat_deg: float, lon_deg: float) -> tuple[float, float]:
            return self.frame.to_enu(lat_deg, lon_deg)

        fence = Fence.from_items(self.mission.fence, to_enu) if self.mission.fence else Fence()
        self.planner = Planner(cfg.planner, cfg.robot, fence=fence)
        self.follower = PathFollower(self.planner, cfg.planner)
        self.executor = MissionExecutor(self.mission.items, to_enu, cfg.executor, lambda: cfg.robot.max_speed_mps)
        waypoints = [to_enu(i.x, i.y) for i in self.mission.items if i.command in NAV_COMMANDS and i.is_global and (i.x or i.y)]
        self.events.write(self._now(), "mission", waypoints_total=sum(i.command in NAV_COMMANDS for i in self.mission.items),
                          items=len(self.mission.items), waypoints_en=[list(map(float, w)) for w in waypoints])  # fmt: skip
        self._goal_seen: tuple[float, float] | None = None

    def _now(self) -> float:
        return self.link.vehicle_time_s if self.link else 0.0

    # ---- AutopilotHandlers (the GCS link calls these) ---------------------------------------------

    def state(self) -> VehicleState:
        armed = bool(self.vehicle and self.vehicle.armed)
        status = mav.MAV_STATE_ACTIVE if armed else mav.MAV_STATE_STANDBY
        if self.decision is not None and self.decision.action >= Action.HOLD:
            status = mav.MAV_STATE_CRITICAL
        return VehicleState(armed, self.mode, status, self.home)

    def arm(self, arm: bool, force: bool) -> int:
        if arm and self.home is None and not force:
            self._say("PreArm: no GPS fix yet", mav.MAV_SEVERITY_CRITICAL)
            return mav.MAV_RESULT_DENIED
        if not arm:
            self.wheels.neutral()
        params = (1.0 if arm else 0.0, float(ARM_FORCE_MAGIC) if force else 0.0)
        self.link.command_async(mav.MAV_CMD_COMPONENT_ARM_DISARM, *params, on_result=self._on_arm_result)
        return mav.MAV_RESULT_ACCEPTED

    def _on_arm_result(self, result) -> None:
        if not result.accepted:
            self._say(f"Vehicle refused arming/disarming (result {result.result})", mav.MAV_SEVERITY_WARNING)

    def set_mode(self, custom_mode: int) -> int:
        if custom_mode not in (RoverMode.MANUAL, RoverMode.HOLD, RoverMode.AUTO, RoverMode.RTL):
            return mav.MAV_RESULT_DENIED
        if custom_mode in (RoverMode.AUTO, RoverMode.RTL) and self.executor is None:
            self._say("Mode change refused: no GPS home yet", mav.MAV_SEVERITY_WARNING)
            return mav.MAV_RESULT_FAILED
        if custom_mode == RoverMode.AUTO and not self.mission.items:
            self._say("Mode change refused: no mission", mav.MAV_SEVERITY_WARNING)
            return mav.MAV_RESULT_FAILED
        self._enter_mode(int(custom_mode))
        return mav.MAV_RESULT_ACCEPTED

    def mission_start(self) -> int:
        if self.executor is None or not self.mission.items:
            return mav.MAV_RESULT_FAILED
        self._report(self.executor.restart())
        self._enter_mode(int(RoverMode.AUTO), resume=False)
        return mav.MAV_RESULT_ACCEPTED

    def return_to_launch(self) -> int:
        return self.set_mode(int(RoverMode.RTL))

    def set_current(self, seq: int) -> bool:
        if self.executor is None:
            return False
        try:
            self._report(self.executor.set_current(seq))
        except ValueError as exc:
            self._say(str(exc), mav.MAV_SEVERITY_WARNING)
            return False
        return True

    def mission_changed(self, mission: Mission, mission_type: int) -> None:
        self.mission = mission
        if self.mode in (RoverMode.AUTO, RoverMode.RTL):
            self._enter_mode(int(RoverMode.HOLD))
        self._load_mission_into_core()

    def params(self) -> dict[str, float]:
        return self.table.params()

    def set_param(self, name: str, value: float) -> tuple[bool, str]:
        return self.table.set_param(name, value)

    # ---- modes and events ------------------------------------------------------------------------

    def _enter_mode(self, mode: int, resume: bool = True) -> None:
        previous, self.mode = self.mode, mode
        now = self._now()
        if mode == RoverMode.AUTO and resume:
            self._report(self.executor.start())
        elif mode == RoverMode.RTL:
            self._report(self.executor.rtl())
        elif self.executor is not None and mode in (RoverMode.HOLD, RoverMode.MANUAL):
            self.executor.stop()
        if self.follower is not None:
            self.follower.reset()
        self.wheels.reset()
        self._released = False
        if previous != mode:
            log.info("mode %s -> %s", RoverMode(previous).name, RoverMode(mode).name)
            self.events.write(now, "mode", mode=mode, name=RoverMode(mode).name)

    def _report(self, events: list) -> None:
        """Executor events -> GCS messages and the event log."""
        now = self._now()
        for event in events:
            if event.kind is EventKind.ITEM_REACHED:
                self.gcs.send_mission_item_reached(event.seq)
                self.events.write(now, "reached", seq=event.seq)
            elif event.kind is EventKind.CURRENT:
                self.gcs.send_mission_current(event.seq)
                self.events.write(now, "current", seq=event.seq)
            elif event.kind is EventKind.COMPLETE:
                self.events.write(now, "complete", seq=event.seq)
                log.info("mission complete at t=%.2f s", now)
            elif event.kind is EventKind.STATUSTEXT:
                self._say(event.text, int(event.severity))

    def _say(self, text: str, severity: int = mav.MAV_SEVERITY_INFO) -> None:
        log.log(logging.WARNING if severity <= mav.MAV_SEVERITY_WARNING else logging.INFO, "%s", text)
        self.events.write(self._now(), "statustext", text=text, severity=severity)
        if self.gcs is not None:
            self.gcs.send_statustext(text, severity)

    # ---- the control step ------------------------------------------------------------------------

    def _maybe_step(self, t_s: float) -> None:
        """Run the control step if vehicle time ``t_s`` reached the next tick."""
        if self.next_tick_s is None:
            self.next_tick_s = t_s
        if t_s + 1e-9 < self.next_tick_s:
            return
        dt_s = self.period_s if self.last_step_s is None else max(t_s - self.last_step_s, 1e-3)
        self.last_step_s = t_s
        self.next_tick_s += self.period_s
        if self.next_tick_s <= t_s:  # fell behind (a gap in the data): do not replay missed ticks
            self.next_tick_s = t_s + self.period_s
        self.control_step(t_s, dt_s)

    def control_step(self, t_s: float, dt_s: float) -> None:
        row: dict[str, Any] = dict.fromkeys(CSV_COLUMNS, "")
        pose = self.estimator.pose() if self.estimator and self.estimator.initialised else None
        last = self.link.last_rx_vehicle_s
        decision = self._failsafe(t_s, pose, vehicle_age_s=0.0 if last is None else max(0.0, t_s - last))
        row.update(t_s=t_s, mode=self.mode, armed=int(self._armed()), failsafe="+".join(decision.reasons))
        if pose is not None:
            row.update(est_east_m=pose.east_m, est_north_m=pose.north_m, est_heading_rad=pose.heading_rad,
                       est_speed_mps=pose.speed_mps, est_healthy=int(pose.healthy), gps_ok=int(pose.gps_ok))  # fmt: skip
        for orientation, column in RANGE_COLUMNS.items():
            if orientation in self.ranges:
                row[column] = self.ranges[orientation].range_m
        command = self._decide(t_s, dt_s, pose, decision, row)
        if command is None:
            if not self._released:
                self.link.release_override()
                self._released = True
        else:
            self.link.send_override(command.steering_us, command.throttle_us)
            row.update(steering_us=command.steering_us, throttle_us=command.throttle_us)
        if self._rx_perf is not None:
            row["latency_ms"] = (time.perf_counter() - self._rx_perf) * 1e3
        row.update(left_meas_rpm=self.wheels.meter.left_rpm, right_meas_rpm=self.wheels.meter.right_rpm)
        self.steps += 1
        if self.csv:
            self.csv.write(row)
            if self.steps % 50 == 0:
                self.csv.flush()

    def _armed(self) -> bool:
        return bool(self.vehicle and self.vehicle.armed)

    def _driving(self) -> bool:
        return self._armed() and self.mode in (RoverMode.AUTO, RoverMode.RTL)

    def _failsafe(self, t_s: float, pose, vehicle_age_s: float) -> FailsafeDecision:
        """Measure the ages, ask ``rover_ctl.autopilot.failsafe``, report its events, apply a mode change."""
        self.clock_s = max(self.clock_s, t_s)
        now = self.clock_s
        gcs_seen = self.gcs.last_gcs_heartbeat_s if self.gcs else None
        position = (pose.east_m, pose.north_m) if pose is not None else None
        inputs = FailsafeInputs(
            vehicle_age_s=vehicle_age_s,
            gcs_age_s=math.inf if gcs_seen is None else time.monotonic() - gcs_seen,
            gps_age_s=math.inf if self.last_fix_s is None else max(0.0, t_s - self.last_fix_s),
            range_ages_s={o: max(0.0, t_s - r.time_s) for o, r in self.ranges.items()},
            estimator_healthy=pose is not None and pose.healthy,
            inside_fence=position is None or self.planner is None or self.planner.is_inside_fence(position),
            driving=self._driving(),
            commanded_speed_mps=self.commanded_speed_mps,
            position_en=position,
        )
        decision = self.failsafes.update(now, inputs)
        previous = self.decision.reasons if self.decision else ()
        self.decision = decision
        for event in decision.events:
            self._say(event.text, int(event.severity))
        if decision.reasons != previous:
            self.events.write(t_s, "failsafe", reasons=list(decision.reasons), action=decision.action.name)
        if decision.action == Action.RTL and self.mode == RoverMode.AUTO and self.executor is not None:
            self._enter_mode(int(RoverMode.RTL))
        if decision.replan and self.follower is not None and pose is not None:
            # Backed off after being stuck: mark the spot ahead as blocked and plan around it; each
            # further try in the same episode blocks a wider circle (the first detour was too tight).
            radius_m = self.config.planner.blocked_radius_m * max(1, decision.stuck_tries)
            ahead_m = radius_m + self.config.robot.footprint_length_m
            self.follower.block(t_s, (pose.east_m + ahead_m * math.cos(pose.heading_rad),
                                      pose.north_m + ahead_m * math.sin(pose.heading_rad)), radius_m)  # fmt: skip
        return decision

    def _check_silence(self) -> None:
        """Nothing at all from the vehicle (not even lockstep markers, which would drive the
        control step and its failsafe in vehicle time): run the failsafe on the wall clock and
        send neutral."""
        link = self.link
        if link.last_rx_wall_s is None:
            return
        age_s = time.monotonic() - max(link.last_rx_wall_s, self._marker_wall_s)
        if age_s <= self.config.failsafe.vehicle_timeout_s:
            return
        pose = self.estimator.pose() if self.estimator and self.estimator.initialised else None
        self.commanded_speed_mps = 0.0  # nothing is being driven: not a stuck rover
        decision = self._failsafe(link.vehicle_time_s + age_s, pose, vehicle_age_s=age_s)
        if decision.action == Action.NEUTRAL and time.monotonic() >= self._silent_neutral_wall_s:
            self._silent_neutral_wall_s = time.monotonic() + self.period_s
            neutral = self.wheels.neutral()
            link.send_override(neutral.steering_us, neutral.throttle_us)
        if age_s > self.settings.stream_rerequest_s and time.monotonic() - self._streams_requested_wall_s > self.settings.stream_rerequest_s:
            self._request_streams()  # the vehicle may have rebooted and forgotten our rates

    def _decide(self, t_s: float, dt_s: float, pose, decision: FailsafeDecision, row: dict[str, Any]) -> WheelCommand | None:
        """The wheel command for this step; None = hand the channels back (MANUAL)."""
        self.commanded_speed_mps = 0.0
        if decision.action == Action.NEUTRAL:
            return self.wheels.neutral()
        if self.mode == RoverMode.MANUAL:
            return None
        if not self._armed() or self.executor is None or pose is None:
            return self.wheels.neutral()
        if self.mode == RoverMode.HOLD or decision.action == Action.HOLD:
            return self._hold(t_s, dt_s, pose)
        out = self.executor.update(t_s, (pose.east_m, pose.north_m))
        self._report(out.events)
        row.update(goal_seq=out.current_seq, speed_limit_mps=out.speed_limit_mps)
        if self.executor.complete and self.mode == RoverMode.AUTO:
            self._enter_mode(int(RoverMode.HOLD))
            return self._hold(t_s, dt_s, pose)
        if out.hold or out.target_en is None:
            return self._hold(t_s, dt_s, pose)
        row.update(goal_east_m=out.target_en[0], goal_north_m=out.target_en[1])
        if decision.action == Action.BACK_OFF:
            rpm = -self._speed_to_rpm(self.config.failsafe.back_off_speed_mps)
            row.update(left_set_rpm=rpm, right_set_rpm=rpm)
            return self.wheels.step(t_s, dt_s, rpm, rpm)
        guidance = self.follower.update(t_s, (pose.east_m, pose.north_m), out.target_en)
        if guidance.replanned and guidance.path is not None and guidance.path.ok:
            self.events.write(t_s, "plan", goal_seq=out.current_seq, length_m=round(guidance.path.length_m, 3),
                              path_en=[[round(e, 3), round(n, 3)] for e, n in guidance.path.points])  # fmt: skip
        if guidance.target_en is None:
            self._say_once(f"No path: {guidance.error}")
            return self._hold(t_s, dt_s, pose)
        row.update(target_east_m=guidance.target_en[0], target_north_m=guidance.target_en[1], cross_track_m=guidance.cross_track_m)
        for orientation, reading in self.ranges.items():
            if reading.time_s > self._remembered_s.get(orientation, -math.inf):
                self._remembered_s[orientation] = reading.time_s
                self.proximity.add(reading.time_s, pose.east_m, pose.north_m, pose.heading_rad, orientation, reading.range_m)
        ranges = self.proximity.ranges(t_s, pose.east_m, pose.north_m, pose.heading_rad, {o: r.range_m for o, r in self.ranges.items()})
        for orientation in decision.blocked_orientations:
            ranges.pop(orientation, None)  # a silent rangefinder: the navigator counts that side as blocked
        nav = self.navigator.step(pose.east_m, pose.north_m, pose.heading_rad, guidance.target_en[0], guidance.target_en[1],
                                  ranges, out.speed_limit_mps, guidance.remaining_m)  # fmt: skip
        self.commanded_speed_mps = (nav.left_rpm + nav.right_rpm) / 2.0 / self._speed_to_rpm(1.0)
        row.update(left_set_rpm=nav.left_rpm, right_set_rpm=nav.right_rpm,
                   target_distance_m=nav.inputs["target_distance_m"], target_direction_rad=nav.inputs["target_direction_rad"])  # fmt: skip
        return self.wheels.step(t_s, dt_s, nav.left_rpm, nav.right_rpm)

    def _hold(self, t_s: float, dt_s: float, pose) -> WheelCommand:
        """Stop: brake actively (zero wheel-speed setpoints) while moving, then neutral."""
        if pose is not None and abs(pose.speed_mps) > self.settings.hold_speed_mps:
            return self.wheels.step(t_s, dt_s, 0.0, 0.0)
        return self.wheels.neutral()

    def _speed_to_rpm(self, speed_mps: float) -> float:
        return speed_mps / (2.0 * math.pi * self.config.robot.wheel_radius_m) * 60.0

    def _say_once(self, text: str) -> None:
        if text != self._last_said:
            self._last_said = text
            self._say(text, mav.MAV_SEVERITY_WARNING)

    # ---- telemetry to the GCS ------------------------------------------------------------------

    def _send_telemetry(self) -> None:
        now = time.monotonic()
        if self.link.last_gps_msg is not None:
            self.gcs.send_gps_raw_int(now, self.link.last_gps_msg)
        if self.battery is not None:
            present = SENSORS_PRESENT | (mav.MAV_SYS_STATUS_GEOFENCE if self.mission.fence else 0)
            reasons = self.decision.reasons if self.decision else ()
            failed = sum(bit for reason, bit in SENSOR_FAILSAFES.items() if reason in reasons)
            self.gcs.send_sys_status(now, self.battery.voltage_v, self.battery.remaining_pct, present=present, failed=failed)
        if self.estimator is None or not self.estimator.initialised or not self.gcs.pose_due(now):
            return
        pose = self.estimator.pose()
        lat, lon = self.frame.to_geodetic(pose.east_m, pose.north_m)
        time_boot_ms = int(pose.time_s * 1000)
        compass_rad = enu_to_compass_rad(pose.heading_rad)
        self.gcs.send_global_position_int(
            now, lat, lon, self.home.alt_m, 0.0, pose.speed_mps * math.cos(pose.heading_rad),
            pose.speed_mps * math.sin(pose.heading_rad), math.degrees(compass_rad), time_boot_ms,
        )  # fmt: skip
        self.gcs.send_attitude(now, compass_rad, -pose.yaw_rate_radps, time_boot_ms)
