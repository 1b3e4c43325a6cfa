"""The autopilot: every decision of the rover's controller, pure.

No sockets, no clock, no files, no logging: time comes in as ``t_s`` (vehicle time), readings
come in as values, and what to do goes out as a command and typed events
(``rover_ctl.autopilot.events``). The daemon (``rover_ctl.app.daemon``) is the loop around it.

Inputs, from the shell:
    set_home(home, frame)        the first GPS fix: the local frame the mission is placed in
    on_vehicle(armed)            the vehicle's HEARTBEAT armed flag (the truth about arming), and its
                                 ACCEPTED answer to an arming or disarming the moment it comes
    on_wheels(WheelDistance)     every wheel reading (the wheel-speed meter of the PI loop, the
                                 wheel-map check)
    on_attitude(Attitude)        every ATTITUDE (the wheel-map check's gyro)
    step(t_s, pose, Readings)    at each control tick -> StepOutput(command, events, log_row)
Ground-station requests (each decides at once and returns a ``Reply``: MAV_RESULT and reason;
its events, the refusal STATUSTEXT among them, are collected with ``drain()``):
    arm(arm, force), set_mode(custom_mode), mission_start(), return_to_launch(),
    set_current(seq), mission_changed(mission, mission_type), guided_target(lat, lon, change_mode)
State for the heartbeat and MISSION_CURRENT: ``state()``.

Sensors as data: which rangefinders the rover has is configured (``link.rangefinders``) or learnt
from the orientations reported in the first ``link.rangefinder_discovery_s`` of sensor data; the
plan (``rover_ctl.navigation.sensors``) sets what the navigator reads and what the rangefinder
failsafe requires, and arming waits for it. A rule base the rover cannot serve, or a wheel map the
gyro contradicts (``rover_ctl.estimation.wheel_map``), refuses arming and stops a driving mode.

One step: failsafes (``Failsafes``, on the failsafe clock: vehicle time, never going back) ->
mode -> goal (AUTO/RTL: the mission executor; GUIDED: the guided target; LOITER: the station)
-> path follower (planner, carrot) -> obstacle memory and fuzzy navigator -> wheel-speed PI.
Its command is a ``WheelCommand``, or ``RELEASE`` (MANUAL: the radio drives). HOLD and
failsafe holds brake to a stop, then send neutral; disarmed, neutral at once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

from rover_ctl.autopilot import modes, prearm
from rover_ctl.autopilot.events import (
    ArmRequest, Event, FailsafeChanged, ItemReached, MissionComplete, MissionCurrent, MissionLoaded,
    ModeChanged, PlanMade, StatusText,
)  # fmt: skip
from rover_ctl.autopilot.executor import NAV_COMMANDS, EventKind, MissionExecutor
from rover_ctl.autopilot.executor import Mode as ExecutorMode
from rover_ctl.autopilot.failsafe import Action, FailsafeDecision, FailsafeInputs, Failsafes
from rover_ctl.autopilot.loop_rate import LoopRate, LoopRateState
from rover_ctl.config import Config
from rover_ctl.estimation.estimator import Pose
from rover_ctl.estimation.frame import LocalFrame
from rover_ctl.estimation.readings import Attitude, RangeReading, WheelDistance
from rover_ctl.estimation.wheel_map import WheelMapCheck
from rover_ctl.fuzzy import RuleBase
from rover_ctl.mission.model import Home, Mission
from rover_ctl.navigation.gaps import Passage
from rover_ctl.navigation.navigator import Navigator
from rover_ctl.navigation.evasion import Evader
from rover_ctl.navigation.obstacle_map import ObstacleMap
from rover_ctl.navigation.odometry import FrameLink, Odometry
from rover_ctl.navigation.pivot import Pivot
from rover_ctl.navigation.planner import Fence, PathFollower, Planner
from rover_ctl.navigation.proximity import ObstacleMemory
from rover_ctl.navigation.side_guard import AHEAD, against_guard_removed, pass_speed_mps, rear_mover_side, side_turn_radps, way_ahead_clear
from rover_ctl.navigation.yielding import Yielder, keep_line
from rover_ctl.navigation.sensors import BACK, RangefinderPlan, SensorSetupError, plan_rangefinders
from rover_ctl.navigation.tracks import Track
from rover_ctl.navigation.wheel_control import WheelCommand, WheelController
from rover_ctl.vocabulary import MissionState, RoverMode, Severity, mav

EN = tuple[float, float]

LOG_COLUMNS = (
    "t_s", "mode", "armed", "failsafe", "est_east_m", "est_north_m", "est_heading_rad", "est_speed_mps",
    "est_healthy", "gps_ok", "goal_seq", "goal_east_m", "goal_north_m", "target_east_m", "target_north_m",
    "cross_track_m", "speed_limit_mps", "target_distance_m", "target_direction_rad",
    "range_front_m", "range_front_right_m", "range_right_m", "range_back_m", "range_left_m", "range_front_left_m",
    "left_set_rpm", "right_set_rpm", "left_meas_rpm", "right_meas_rpm", "steering_us", "throttle_us", "loop_rate_hz", "yield_track", "passage", "latency_ms",
    "map_obstacles", "evade_track", "side_turn_radps", "side_pass_mps", "side_rear", "pivot_radps",
)  # fmt: skip
"""Columns of the control log, one row per step (``latency_ms`` is the shell's to fill)."""
_EMPTY_ROW = dict.fromkeys(LOG_COLUMNS, "")
"""A step's row before it is filled (copied each step: cheaper than building it)."""
RANGE_COLUMNS = {0: "range_front_m", 1: "range_front_right_m", 2: "range_right_m", 4: "range_back_m",
                 6: "range_left_m", 7: "range_front_left_m"}  # fmt: skip
STATION_SEQ = 0
"""goal_seq of a path that is not to a mission item (GUIDED target, LOITER station)."""


class ReleaseRc:
    """The command "hand the RC channels back to the vehicle's radio" (MANUAL)."""

    def __repr__(self) -> str:
        return "RELEASE"


RELEASE = ReleaseRc()
Command = WheelCommand | ReleaseRc


@dataclass(frozen=True)
class Readings:
    """What the shell measured for one step (ages in vehicle time)."""

    ranges: Mapping[int, RangeReading] = field(default_factory=dict)
    """The latest DISTANCE_SENSOR per orientation."""
    vehicle_age_s: float = 0.0
    """Since the last message of any kind from the vehicle."""
    gcs_age_s: float = math.inf
    """Since the last ground-station HEARTBEAT (inf: none yet)."""
    gps_age_s: float = math.inf
    """Since the last GPS fix (fix_type >= 2; inf: none yet)."""
    sensor_rates_hz: Mapping[str, float] = field(default_factory=dict)
    """Measured on the vehicle link: ATTITUDE and WHEEL_DISTANCE, each once it has arrived."""
    odometry_planned_hz: float | None = None
    """The odometry rate the link budget asked for (what the loop can expect before a measurement)."""


@dataclass(frozen=True)
class StepOutput:
    command: Command
    events: tuple[Event, ...]
    log_row: dict[str, Any]


@dataclass(frozen=True)
class Reply:
    """The answer to a ground-station request: a MAV_RESULT and, when refused, why."""

    result: int
    reason: str = ""

    @property
    def accepted(self) -> bool:
        return self.result == mav.MAV_RESULT_ACCEPTED


@dataclass(frozen=True)
class AutopilotState:
    armed: bool
    mode: RoverMode
    system_status: int
    """MAV_STATE: STANDBY disarmed, ACTIVE armed, CRITICAL while a failsafe holds or stops."""
    home: Home | None
    mission_state: MissionState
    current_seq: int
    failsafes: tuple[str, ...]


ACCEPTED = Reply(mav.MAV_RESULT_ACCEPTED)


class Autopilot:
    """The rover's autopilot (see the module docstring)."""

    def __init__(self, config: Config, rulebase: RuleBase) -> None:
        self.config = config
        robot = config.robot  # read through functions: a parameter changed by the GCS applies at once
        self.wheels = WheelController(lambda: robot.wheel_radius_m, config.wheel_control)
        self.navigator = Navigator(rulebase, config.navigator, lambda: robot.max_wheel_rpm, lambda: robot.wheel_radius_m)
        self.failsafes = Failsafes(config.failsafe)
        self.loop_rate = LoopRate(config.daemon)
        self._loop: LoopRateState | None = None
        self.proximity = ObstacleMemory(config.proximity, lambda: robot.footprint_length_m, lambda: robot.footprint_width_m,
                                        tracking=lambda: config.yielding.enabled or config.evasion.enabled)  # fmt: skip
        self.yielder = Yielder(config.yielding, lambda: math.hypot(robot.footprint_length_m, robot.footprint_width_m) / 2.0)
        self.evader = Evader(config.evasion, lambda: robot.footprint_width_m / 2.0)
        self.pivot = Pivot(config.pivot)
        self._evaded_s = -math.inf
        """The last step a manoeuvre of the evader drove (``evasion.rejoin_s`` after it, the rover rejoins its path)."""
        self.obstacle_map = ObstacleMap(config.obstacle_map)
        self._map_updated_s = self._map_handed_s = -math.inf
        self._map_obstacles: tuple = ()  # the persistent obstacles handed to the planner
        self._map_moving: set[int] = set()  # tracks yielded to since the last map update
        self.odometry = Odometry()  # the frame of the obstacle map and the narrow passages
        self._map_link: FrameLink | None = None  # this step's odometry frame laid onto the pose (None: the map is in the pose's)
        self._map_in_odometry = False  # the frame the map's contents were placed in
        self.passage = Passage(config.passage, lambda: robot.footprint_length_m, lambda: robot.footprint_width_m, self.odometry)
        self.mode = RoverMode.HOLD
        self.armed = False
        self.home: Home | None = None
        self.frame: LocalFrame | None = None
        self.mission = Mission()
        self.fence = Fence()
        self.fence_error: str | None = None
        self.vehicle_params: dict[str, float] = {}
        """What the vehicle's autopilot answered for the parameters the daemon reads at connect."""
        self.planner: Planner | None = None
        self.follower: PathFollower | None = None
        self.executor: MissionExecutor | None = None
        """Built once home gives the frame, rebuilt on every new mission."""
        self.decision: FailsafeDecision | None = None
        self._outbox: list[Event] = []
        self._clock_s = -math.inf
        self._last_step_s: float | None = None
        self._commanded_speed_mps = 0.0
        self._wants_progress = False
        self._pose: Pose | None = None
        self._ranges: Mapping[int, RangeReading] = {}
        self._sensor_rates_hz: Mapping[str, float] = {}
        self._remembered_s: dict[int, float] = {}  # time of the last reading put into the memory
        self._last_said: str | None = None
        self._mission_started = False
        self._reported_state: tuple[int, MissionState] | None = None
        self._station_en: EN | None = None  # LOITER / GUIDED: the point held
        self._guided_target_en: EN | None = None  # GUIDED: still driving to it
        self._returning = False  # station keeping: driving back to the station
        self._resume_seq: int | None = None  # the stored mission's item before a restart (MIS_RESTART 0)
        self.rangefinder_plan: RangefinderPlan | None = None
        self.sensor_error: str | None = None
        """Why the rover cannot be driven (rule base vs rangefinders, reversed wheel map)."""
        self.wheel_map = WheelMapCheck(robot.track_m)
        self._sensors_since_s: float | None = None  # vehicle time of the first sensor reading
        if config.link.rangefinders != [-1]:
            self._plan_rangefinders(set(config.link.rangefinders))

    # ---- inputs from the shell -------------------------------------------------------------------

    def set_home(self, home: Home, frame: LocalFrame) -> None:
        """Home and the local frame (the first GPS fix); the mission is placed against it."""
        self.home, self.frame = home, frame
        self._load_mission()

    def on_vehicle(self, armed: bool) -> None:
        self.armed = armed

    def on_vehicle_param(self, name: str, value: float) -> None:
        """A parameter of the vehicle's own autopilot (``rover_ctl.mavlink.vehicle.VEHICLE_PARAMS``),
        for the pre-arm checks; a wrong one is said at once, not only when arming is refused."""
        known = self.vehicle_params.get(name)
        self.vehicle_params[name] = value
        reason = prearm.vehicle_param_problem(name, value)
        if reason is not None and known != value:
            self._say(f"Vehicle {reason}", Severity.CRITICAL)

    def on_wheels(self, reading: WheelDistance) -> None:
        self._sensor_seen(reading.time_s)
        self.wheels.on_wheels(reading)
        self.odometry.on_wheels(reading.left_m, reading.right_m)
        if self.wheel_map.verdict is None:
            self.wheel_map.on_wheels(reading)
            if self.wheel_map.verdict == "reversed":
                self.sensor_error = "wheel map reversed: check link.wheel_*_index"
                self._say(self.sensor_error, Severity.CRITICAL)
                if self.mode in modes.DRIVING_MODES:
                    self._enter(RoverMode.HOLD, "wheel map")

    def on_attitude(self, reading: Attitude) -> None:
        self._sensor_seen(reading.time_s)
        self.wheel_map.on_attitude(reading)
        self.odometry.on_gyro(reading.time_s, reading.yaw_rate_radps)

    def _sensor_seen(self, t_s: float) -> None:
        if self._sensors_since_s is None:
            self._sensors_since_s = t_s

    def resume_from(self, seq: int) -> None:
        """The stored mission was at item ``seq`` when the daemon stopped: with MIS_RESTART 0,
        AUTO resumes there (the rover stays stopped until a ground station asks for AUTO)."""
        if self.config.autopilot.mission_restart == 0:
            self._resume_seq = seq
            self._apply_resume()

    def _apply_resume(self) -> None:
        if self._resume_seq is None or self.executor is None:
            return
        seq, self._resume_seq = self._resume_seq, None
        try:
            self._executor_events(self.executor.set_current(seq))
        except ValueError:
            return  # the stored item no longer exists: start from the first
        self._say(f"Mission resumes at item {seq}")

    def drain(self) -> list[Event]:
        """Events of the requests since the last step or drain, in order."""
        self._report_mission_state()
        events, self._outbox = self._outbox, []
        return events

    # ---- ground-station requests -----------------------------------------------------------------

    def arm(self, arm: bool, force: bool = False) -> Reply:
        if arm and self.armed and self.sensor_error is None:
            return ACCEPTED
        if arm and (refusal := self._arming_refusal(force)) is not None:
            result, texts = refusal
            for text in texts:
                self._say(f"PreArm: {text}", Severity.CRITICAL)
            return Reply(result, texts[0])
        self._outbox.append(ArmRequest(arm, force))
        return ACCEPTED

    def ready_to_arm(self) -> bool:
        """Whether an arming request now would pass the daemon's own checks (armed: True), the
        ground station's "ready" light (SYS_STATUS's MAV_SYS_STATUS_PREARM_CHECK, as ArduPilot
        reports it). The vehicle's own checks come on top, when it is asked."""
        return self.armed or self._arming_refusal() is None

    def _arming_refusal(self, force: bool = False) -> tuple[int, list[str]] | None:
        """(MAV_RESULT, reasons) of the daemon's checks refusing an arming, or None. A sensor the
        rover cannot be driven without refuses even a forced one."""
        if self.sensor_error is not None:
            return mav.MAV_RESULT_DENIED, [self.sensor_error]
        if force:
            return None
        if self.rangefinder_plan is None:
            return mav.MAV_RESULT_TEMPORARILY_REJECTED, ["rangefinders not known yet"]
        failed = prearm.failures(self._arming_inputs())
        return (mav.MAV_RESULT_FAILED, failed) if failed else None

    def set_mode(self, custom_mode: int, reason: str = "gcs") -> Reply:
        why = modes.unsupported(custom_mode)
        if why:
            self._say(f"Mode change refused: {why}", Severity.WARNING)
            return Reply(mav.MAV_RESULT_DENIED, why)
        mode = RoverMode(custom_mode)
        why = modes.refusal(mode, self._mode_context())
        if why:
            self._say(f"Mode change refused: {why}", Severity.WARNING)
            return Reply(mav.MAV_RESULT_FAILED, why)
        self._enter(mode, reason)
        return ACCEPTED

    def mission_start(self) -> Reply:
        """MAV_CMD_MISSION_START: AUTO from the first item, jump counts cleared."""
        why = modes.refusal(RoverMode.AUTO, self._mode_context())
        if why:
            self._say(f"Mission start refused: {why}", Severity.WARNING)
            return Reply(mav.MAV_RESULT_FAILED, why)
        self._executor_events(self.executor.restart())
        self._enter(RoverMode.AUTO, "gcs", resume=False)
        return ACCEPTED

    def return_to_launch(self) -> Reply:
        return self.set_mode(RoverMode.RTL)

    def set_current(self, seq: int) -> bool:
        """MISSION_SET_CURRENT / DO_SET_MISSION_CURRENT (wire seq)."""
        if self.executor is None:
            self._say("Mission seq cannot be set: no position yet", Severity.WARNING)
            return False
        try:
            self._executor_events(self.executor.set_current(seq))
        except ValueError as exc:
            self._say(str(exc), Severity.WARNING)
            return False
        return True

    def mission_changed(self, mission: Mission, mission_type: int) -> None:
        """A new mission, fence or rally list was stored: AUTO stops (HOLD), RTL goes on."""
        self.mission = mission
        self._mission_started = False
        self._resume_seq = None
        if self.mode == RoverMode.AUTO:
            self._enter(RoverMode.HOLD, "mission changed")
        self._load_mission()
        if self.mode == RoverMode.RTL and self.executor is not None:
            self._executor_events(self.executor.rtl())

    def guided_target(self, lat_deg: float, lon_deg: float, change_mode: bool = False) -> Reply:
        """Drive to (lat, lon) in GUIDED (SET_POSITION_TARGET_GLOBAL_INT, DO_REPOSITION, a
        MISSION_ITEM with current=2). ``change_mode``: switch to GUIDED first (DO_REPOSITION's
        CHANGE_MODE flag); otherwise the rover must already be in GUIDED."""
        why = self._guided_refusal(lat_deg, lon_deg, change_mode)
        if why:
            self._say(f"Guided target refused: {why}", Severity.WARNING)
            return Reply(mav.MAV_RESULT_DENIED, why)
        if self.mode != RoverMode.GUIDED:
            reply = self.set_mode(RoverMode.GUIDED, "guided target")
            if not reply.accepted:
                return reply
        self._guided_target_en = tuple(map(float, self.frame.to_enu(lat_deg, lon_deg)))
        self._station_en = self._guided_target_en
        self._returning = False
        if self.follower is not None:
            self.follower.reset()
        self._say(f"Guided to {lat_deg:.7f} {lon_deg:.7f}")
        return ACCEPTED

    def _guided_refusal(self, lat_deg: float, lon_deg: float, change_mode: bool) -> str | None:
        if not (math.isfinite(lat_deg) and math.isfinite(lon_deg)) or abs(lat_deg) > 90 or abs(lon_deg) > 180:
            return "invalid location"
        if lat_deg == 0 and lon_deg == 0:
            return "invalid location"
        if self.mode != RoverMode.GUIDED and not change_mode:
            return "not in GUIDED mode"
        if self.frame is None:
            return "no position yet"
        where = prearm.fence_violation(self.fence, self.frame.to_enu(lat_deg, lon_deg))
        return f"target {where}" if where else None

    # ---- state ---------------------------------------------------------------------------------

    def state(self) -> AutopilotState:
        status = mav.MAV_STATE_ACTIVE if self.armed else mav.MAV_STATE_STANDBY
        if self.decision is not None and self.decision.action >= Action.HOLD:
            status = mav.MAV_STATE_CRITICAL
        reasons = self.decision.reasons if self.decision else ()
        return AutopilotState(self.armed, self.mode, status, self.home, self.mission_state(), self._current_seq(), reasons)

    def mission_state(self) -> MissionState:
        """MISSION_CURRENT.mission_state, as ArduPilot reports it."""
        if not self.mission.items:
            return MissionState.NO_MISSION
        if self.executor is None or not self._mission_started:
            return MissionState.NOT_STARTED
        if self.executor.complete:
            return MissionState.COMPLETE
        if self.mode == RoverMode.AUTO and self.executor.mode is ExecutorMode.AUTO:
            return MissionState.ACTIVE
        return MissionState.PAUSED

    def _current_seq(self) -> int:
        if not self.mission.items:
            return 0
        return self.executor.current_seq if self.executor is not None else 1

    # ---- the step ------------------------------------------------------------------------------

    def step(self, t_s: float, pose: Pose | None, readings: Readings) -> StepOutput:
        """One control step at vehicle time ``t_s``; ``pose`` None until the estimator has one."""
        dt_s = 1.0 / self.config.daemon.control_rate_hz
        if self._last_step_s is not None:
            dt_s = max(t_s - self._last_step_s, 1e-3)
        self._last_step_s = t_s
        self._pose, self._ranges = pose, readings.ranges
        self._sensor_rates_hz = readings.sensor_rates_hz
        odometry_hz = max(readings.sensor_rates_hz.values(), default=readings.odometry_planned_hz)
        self._loop = loop = self.loop_rate.step(t_s, odometry_hz)
        if loop.changed:
            self._say(loop.text(self.config.daemon.max_step_travel_m), Severity.WARNING if loop.slow else Severity.INFO)
        if self._sensors_since_s is None and readings.ranges:
            self._sensor_seen(min(r.time_s for r in readings.ranges.values()))
        since = self._sensors_since_s
        if self.rangefinder_plan is None and self.sensor_error is None and since is not None \
                and t_s >= since + self.config.link.rangefinder_discovery_s:  # fmt: skip
            self._plan_rangefinders(set(readings.ranges))
        decision = self._failsafe(t_s, pose, readings)
        row: dict[str, Any] = _EMPTY_ROW.copy()
        row.update(t_s=t_s, mode=int(self.mode), armed=int(self.armed), failsafe="+".join(decision.reasons))
        if loop.rate_hz is not None:
            row.update(loop_rate_hz=round(loop.rate_hz, 2))
        if pose is not None:
            row.update(est_east_m=pose.east_m, est_north_m=pose.north_m, est_heading_rad=pose.heading_rad,
                       est_speed_mps=pose.speed_mps, est_healthy=int(pose.healthy), gps_ok=int(pose.gps_ok))  # fmt: skip
        for orientation, column in RANGE_COLUMNS.items():
            if orientation in readings.ranges:
                row[column] = readings.ranges[orientation].range_m
        command = self._decide(t_s, dt_s, pose, decision, row)
        if isinstance(command, WheelCommand):
            row.update(steering_us=command.steering_us, throttle_us=command.throttle_us)
        row.update(left_meas_rpm=self.wheels.meter.left_rpm, right_meas_rpm=self.wheels.meter.right_rpm)
        return StepOutput(command, tuple(self.drain()), row)

    def _failsafe(self, t_s: float, pose: Pose | None, readings: Readings) -> FailsafeDecision:
        """Ask the failsafes, report what changed, apply a failsafe RTL and a stuck re-plan."""
        p = self.config.failsafe
        self._clock_s = max(self._clock_s, t_s)
        position = (pose.east_m, pose.north_m) if pose is not None else None
        # A vehicle that does not answer is not being driven: not a stuck rover.
        commanded = 0.0 if readings.vehicle_age_s > p.vehicle_timeout_s else self._commanded_speed_mps
        inputs = FailsafeInputs(
            vehicle_age_s=readings.vehicle_age_s,
            gcs_age_s=readings.gcs_age_s,
            gps_age_s=readings.gps_age_s,
            range_ages_s={o: max(0.0, t_s - r.time_s) for o, r in readings.ranges.items()},
            range_times_s={o: r.time_s for o, r in readings.ranges.items()},
            estimator_healthy=pose is not None and pose.healthy,
            inside_fence=position is None or self.planner is None or self.planner.is_inside_fence(position),
            driving=self.armed and self.mode in modes.DRIVING_MODES,
            commanded_speed_mps=commanded,
            wants_progress=self._wants_progress and readings.vehicle_age_s <= p.vehicle_timeout_s,
            position_en=position,
            sensor_rates_hz=readings.sensor_rates_hz,
        )
        decision = self.failsafes.update(self._clock_s, inputs)
        previous = self.decision.reasons if self.decision else ()
        self.decision = decision
        for event in decision.events:
            self._say(event.text, event.severity)
        if decision.reasons != previous:
            self._outbox.append(FailsafeChanged(decision.reasons, decision.action.name))
        if decision.action == Action.RTL and self.mode in modes.FAILSAFE_RTL_MODES and self.executor is not None:
            self._enter(RoverMode.RTL, "failsafe")
        if decision.replan and self.follower is not None and pose is not None:
            # Backed off after being stuck: mark the spot ahead as blocked and plan around it; each
            # further try in the same episode blocks a wider circle (the first detour was too tight).
            radius_m = self.config.planner.blocked_radius_m * max(1, decision.stuck_tries)
            ahead_m = radius_m + self.config.robot.footprint_length_m
            self.follower.block(t_s, (pose.east_m + ahead_m * math.cos(pose.heading_rad),
                                      pose.north_m + ahead_m * math.sin(pose.heading_rad)), radius_m)  # fmt: skip
        return decision

    def _decide(self, t_s: float, dt_s: float, pose: Pose | None, decision: FailsafeDecision, row: dict[str, Any]) -> Command:
        self._commanded_speed_mps = 0.0
        self._wants_progress = False
        if decision.action == Action.NEUTRAL:
            return self.wheels.neutral()
        if self.mode == RoverMode.MANUAL:
            return RELEASE
        if not self.armed or self.executor is None or pose is None:
            return self.wheels.neutral()
        if self.mode == RoverMode.HOLD or decision.action == Action.HOLD:
            return self._hold(t_s, dt_s, pose)
        position = (pose.east_m, pose.north_m)
        if self.mode in (RoverMode.AUTO, RoverMode.RTL):
            out = self.executor.update(t_s, position)
            self._executor_events(out.events)
            row.update(goal_seq=out.current_seq, speed_limit_mps=out.speed_limit_mps)
            if self.executor.complete and self.mode == RoverMode.AUTO:
                self._enter(RoverMode.HOLD, "mission complete")
                return self._hold(t_s, dt_s, pose)
            if out.hold or out.target_en is None:
                return self._hold(t_s, dt_s, pose)
            goal, speed, goal_seq = out.target_en, out.speed_limit_mps, out.current_seq
        else:
            goal = self._station_goal(position)
            if goal is None:
                return self._hold(t_s, dt_s, pose)
            speed = min(self.config.executor.cruise_speed_mps, self.config.robot.max_speed_mps)
            goal_seq = STATION_SEQ
            row.update(goal_seq=goal_seq, speed_limit_mps=speed)
        return self._drive(t_s, dt_s, pose, goal, speed, goal_seq, decision, row)

    def _station_goal(self, position: EN) -> EN | None:
        """GUIDED and LOITER: where to drive now, None to hold still."""
        if self._guided_target_en is not None:
            if math.dist(position, self._guided_target_en) > self.config.executor.acceptance_radius_m:
                return self._guided_target_en
            self._guided_target_en = None  # arrived: keep station here
            self._say("Reached destination")
            return None
        if self._station_en is None:
            self._station_en = position
        radius_m = self.config.autopilot.loiter_radius_m
        distance_m = math.dist(position, self._station_en)
        if self._returning and distance_m <= radius_m / 2.0:
            self._returning = False
        elif not self._returning and distance_m > radius_m:
            self._returning = True
        return self._station_en if self._returning else None

    def _movers(self, t_s: float, pose: Pose) -> list[Track]:
        """The moving obstacle tracks, less those within ``obstacle_map.track_on_wall_m`` of a
        persistent obstacle (with the map on): a wall's face swept by a turning rover's beam."""
        rover_velocity = (pose.speed_mps * math.cos(pose.heading_rad), pose.speed_mps * math.sin(pose.heading_rad))
        tracks = self.proximity.tracker.moving(t_s, rover_velocity)
        if self.config.obstacle_map.enabled:
            on_wall_m = self.config.obstacle_map.track_on_wall_m
            tracks = [t for t in tracks if not self.obstacle_map.near_persistent(*self._to_map((t.east_m, t.north_m)), on_wall_m)]
        return tracks

    def _drive(self, t_s: float, dt_s: float, pose: Pose, goal: EN, speed_mps: float, goal_seq: int,
               decision: FailsafeDecision, row: dict[str, Any]) -> WheelCommand:  # fmt: skip
        """Planner -> carrot -> obstacle memory -> fuzzy navigator -> wheel PI, towards ``goal``."""
        row.update(goal_east_m=goal[0], goal_north_m=goal[1])
        if decision.action == Action.BACK_OFF:
            back = self._ranges.get(BACK)
            fs = self.config.failsafe
            rpm = 0.0 if back is not None and back.range_m <= fs.back_off_clear_m else -self._speed_to_rpm(fs.back_off_speed_mps)
            row.update(left_set_rpm=rpm, right_set_rpm=rpm)
            return self.wheels.step(t_s, dt_s, rpm, rpm)
        self._update_obstacle_map(t_s, pose, row)
        evasion = self.config.evasion
        rejoining = t_s - self._evaded_s < evasion.rejoin_s  # back to the path with the front beam down it
        guidance = self.follower.update(t_s, (pose.east_m, pose.north_m), goal, evasion.rejoin_lookahead_m if rejoining else None)
        if guidance.replanned and guidance.path is not None and guidance.path.ok:
            self._outbox.append(PlanMade(goal_seq, guidance.path.length_m, tuple(guidance.path.points)))
        if guidance.target_en is None:
            self._say_once(f"No path: {guidance.error}")
            return self._hold(t_s, dt_s, pose)
        row.update(target_east_m=guidance.target_en[0], target_north_m=guidance.target_en[1], cross_track_m=guidance.cross_track_m)
        for orientation, reading in self._ranges.items():
            if reading.time_s > self._remembered_s.get(orientation, -math.inf):
                self._remembered_s[orientation] = reading.time_s
                ident = self.proximity.add(reading.time_s, pose.east_m, pose.north_m, pose.heading_rad, orientation, reading.range_m)
                if self.config.obstacle_map.enabled:
                    east, north, axis = self.proximity.sensor_pose(orientation, pose.east_m, pose.north_m, pose.heading_rad)
                    self._map_add(reading.time_s, (east, north), axis, reading.range_m, reading.max_range_m, ident)
                if self.config.passage.enabled:
                    self.passage.on_range(reading.time_s, orientation, reading.range_m)
        tracking = self.config.yielding.enabled or self.config.evasion.enabled
        if tracking:
            tracks = self._movers(t_s, pose)
        if self.config.passage.enabled:  # a narrow passage: the manoeuvre drives, the rule base waits
            # (it hands back when a mover comes near: the yielder and the evader need the tracks)
            # (the map in the odometry's frame, the passages' own: it says which walls are held)
            mapped = self.obstacle_map.near_persistent if self.config.obstacle_map.enabled and self._map_link is not None else None
            drive = self.passage.step(t_s, (pose.east_m, pose.north_m), pose.heading_rad, goal, tracks if tracking else (), mapped)
            for text in self.passage.events:
                self._say(text)
            self.passage.events.clear()
            if drive is not None:
                row.update(passage=drive.state)
                return self._speed_and_turn(t_s, dt_s, drive.speed_mps, drive.yaw_rate_radps, row)
        else:
            self.passage.reset()
        ranges = self.proximity.ranges(t_s, pose.east_m, pose.north_m, pose.heading_rad, {o: r.range_m for o, r in self._ranges.items()},
                                       pose.speed_mps)  # fmt: skip
        for orientation in decision.blocked_orientations:
            ranges.pop(orientation, None)  # a silent rangefinder: the navigator counts that side as blocked
        if decision.speed_limit_mps is not None:  # a blind side, or rangefinders slower than the speed needs
            speed_mps = min(speed_mps, decision.speed_limit_mps)
            row.update(speed_limit_mps=speed_mps)
        if self._loop is not None and self._loop.speed_limit_mps is not None:  # slow loop: bounded travel per step
            speed_mps = min(speed_mps, self._loop.speed_limit_mps)
            row.update(speed_limit_mps=speed_mps)
        course = math.atan2(guidance.target_en[1] - pose.north_m, guidance.target_en[0] - pose.east_m)
        yielding = False
        if self.config.yielding.enabled:  # crossing traffic: slow or stop on the path and let it pass
            alive = {track.ident for track in self.proximity.tracker.tracks}
            yielded = self.yielder.limit(pose.east_m, pose.north_m, course, speed_mps, tracks, t_s, alive, pose.heading_rad)
            yielding = yielded.speed_limit_mps is not None
        if self.config.evasion.enabled:  # oncoming traffic: step aside, the navigator waits
            evade = self.evader.step(t_s, pose.east_m, pose.north_m, pose.heading_rad, pose.speed_mps, course, speed_mps, tracks, ranges,
                                     may_start=not yielding)  # fmt: skip
            if evade is not None:
                self.yielder.evaded(t_s, evade.track_ident)
                self._evaded_s = t_s
                row.update(evade_track=evade.track_ident)
                return self._speed_and_turn(t_s, dt_s, evade.speed_mps, evade.yaw_rate_radps, row)
        else:
            self.evader.reset()
        if yielding:
            speed_mps = yielded.speed_limit_mps
            self._map_moving.add(yielded.track_ident)  # crossing traffic: never a persistent obstacle
            row.update(speed_limit_mps=speed_mps, yield_track=yielded.track_ident)
        piv = self.config.pivot
        direction = math.remainder(course - pose.heading_rad, math.tau)
        # (last: a wall the passages' search is measuring, on the side the pivot would turn to)
        held = (yielding or rejoining or abs(guidance.cross_track_m) > piv.max_cross_track_m
                or (tracking and any(math.hypot(t.east_m - pose.east_m, t.north_m - pose.north_m) <= piv.mover_m for t in tracks))
                or (self.config.passage.enabled and not self.pivot.active and abs(direction) > math.radians(piv.angle_deg)
                    and self.passage.wall_beside(direction, (pose.east_m, pose.north_m), pose.heading_rad, goal)))  # fmt: skip
        turn = self.pivot.step(t_s, direction, ranges, held, (pose.east_m, pose.north_m))
        if turn is not None:
            row.update(pivot_radps=turn)
            return self._speed_and_turn(t_s, dt_s, 0.0, turn, row)
        nav = self.navigator.step(pose.east_m, pose.north_m, pose.heading_rad, guidance.target_en[0], guidance.target_en[1],
                                  ranges, speed_mps, guidance.remaining_m)  # fmt: skip
        left, right = nav.left_rpm, nav.right_rpm
        if yielding:  # not turning the way the crosser walks
            left, right = keep_line(left, right, yielded)
        side_turn = side_turn_radps(ranges, self.config.side_guard)  # something at a flank: turn away from it
        if side_turn:
            if way_ahead_clear(ranges, self.config.side_guard):  # the rule base turns back towards its target only
                left, right = against_guard_removed(left, right, side_turn)
            floor_mps = None if yielding else pass_speed_mps(ranges, speed_mps, self.config.side_guard)
            if floor_mps is not None and (left + right) / 2.0 < (floor_rpm := self._speed_to_rpm(floor_mps)):
                left, right = self._raised_to(left, right, floor_rpm)  # draw ahead of it, the turn kept
                row.update(side_pass_mps=floor_mps)
            half_rpm = self._speed_to_rpm(side_turn * self.config.robot.track_m / 2.0)
            left, right = left - half_rpm, right + half_rpm
            row.update(side_turn_radps=side_turn)
        rear = rear_mover_side(tracks, t_s, pose.east_m, pose.north_m, pose.heading_rad, self.config.side_guard) if tracking and not yielding else 0.0
        # A walker where no beam looks: go on away from it, neither stopping nor turning into it.
        if rear and way_ahead_clear(ranges, self.config.side_guard):
            left, right = against_guard_removed(left, right, -rear)  # the guard's too, turning away from the other flank
            if self.config.side_guard.pass_speed_mps > 0.0:  # 0: no passing speed, here as beside a walker
                left, right = self._raised_to(left, right, self._speed_to_rpm(min(self.config.side_guard.pass_speed_mps, speed_mps)))
            row.update(side_rear=rear)
        self._commanded_speed_mps = (left + right) / 2.0 / self._speed_to_rpm(1.0)
        # Parked facing something, not crawling up to a target in the open (nor blind ahead).
        self._wants_progress = (not yielding and speed_mps > self.config.failsafe.stuck_min_command_mps
                                and any(ranges.get(o, math.inf) <= self.config.side_guard.front_clear_m for o in AHEAD))  # fmt: skip
        row.update(left_set_rpm=left, right_set_rpm=right,
                   target_distance_m=nav.inputs["target_distance_m"], target_direction_rad=nav.inputs["target_direction_rad"])  # fmt: skip
        return self.wheels.step(t_s, dt_s, left, right)

    def _update_obstacle_map(self, t_s: float, pose: Pose, row: dict[str, Any]) -> None:
        """Every ``update_period_s``: the queued readings into the persistent-obstacle map, and
        its obstacles to the planner when enough changed and the last rebuild is old enough."""
        p = self.config.obstacle_map
        if not p.enabled:
            if self._map_obstacles:  # switched off: the planner forgets them
                self._map_obstacles = ()
                self.follower.set_persistent(())
            return
        row.update(map_obstacles=len(self._map_obstacles))
        odometry = p.odometry_frame and self.odometry.live
        self._map_link = self.odometry.link((pose.east_m, pose.north_m), pose.heading_rad) if odometry else None
        if odometry != self._map_in_odometry:  # what the map holds was placed in the other frame
            self._map_in_odometry = odometry
            self.obstacle_map.clear()
        if t_s - self._map_updated_s < p.update_period_s:
            return
        self._map_updated_s = t_s
        robot = self.config.robot
        position = self._to_map((pose.east_m, pose.north_m))
        changed = self.obstacle_map.update(t_s, position, math.hypot(robot.footprint_length_m, robot.footprint_width_m) / 2.0,
                                           self._map_moving)  # fmt: skip
        self._map_moving = set()
        if changed >= p.min_change_cells and t_s - self._map_handed_s >= p.rebuild_min_interval_s:
            self._map_handed_s = t_s
            link = self._map_link
            shapes = self.obstacle_map.obstacles(position)
            self._map_obstacles = shapes if link is None else tuple(tuple(map(link.to_pose, ring)) for ring in shapes)
            self.follower.set_persistent(self._map_obstacles)
            row.update(map_obstacles=len(self._map_obstacles))

    def _map_add(self, time_s: float, sensor_en: EN, axis_rad: float, range_m: float, max_range_m: float, track_ident: int = 0) -> None:
        """One rangefinder reading (sensor and axis in the fused pose's frame) into the obstacle map."""
        link = self._map_link
        if link is not None:
            sensor_en, axis_rad = link.to_odometry(sensor_en), axis_rad + link.turn_rad
        self.obstacle_map.add(time_s, sensor_en[0], sensor_en[1], axis_rad, range_m, max_range_m, track_ident)

    def _to_map(self, point_en: EN) -> EN:
        """A point of the fused pose's frame in the obstacle map's: the odometry frame, where what
        the beams saw seconds apart stays where it was against the rover as GPS fixes move the
        pose (``rover_ctl.navigation.odometry``); the pose's own with ``obstacle_map.odometry_frame``
        off or no odometry heard."""
        return point_en if self._map_link is None else self._map_link.to_odometry(point_en)

    def _speed_and_turn(self, t_s: float, dt_s: float, speed_mps: float, yaw_rate_radps: float, row: dict[str, Any]) -> WheelCommand:
        """A manoeuvre's forward speed (m/s, negative: reverse) and yaw rate (rad/s, CCW) as wheel
        setpoints, the navigator bypassed (a narrow passage, stepping aside)."""
        self._commanded_speed_mps = abs(speed_mps)
        turn_mps = yaw_rate_radps * self.config.robot.track_m / 2.0
        left, right = self._speed_to_rpm(speed_mps - turn_mps), self._speed_to_rpm(speed_mps + turn_mps)
        row.update(left_set_rpm=left, right_set_rpm=right)
        return self.wheels.step(t_s, dt_s, left, right)

    @staticmethod
    def _raised_to(left_rpm: float, right_rpm: float, floor_rpm: float) -> tuple[float, float]:
        """Both wheels raised by the same amount so that their mean is at least ``floor_rpm`` (the turn kept)."""
        raise_rpm = floor_rpm - (left_rpm + right_rpm) / 2.0
        return (left_rpm + raise_rpm, right_rpm + raise_rpm) if raise_rpm > 0.0 else (left_rpm, right_rpm)

    def _speed_to_rpm(self, speed_mps: float) -> float:
        return speed_mps / (2.0 * math.pi * self.config.robot.wheel_radius_m) * 60.0

    def _hold(self, t_s: float, dt_s: float, pose: Pose | None) -> WheelCommand:
        """Stop: brake actively while moving, until the wheels are about to stand (the wheel
        controller's ``brake``), then neutral."""
        if pose is not None and abs(pose.speed_mps) > self.config.daemon.hold_speed_mps:
            command = self.wheels.brake(t_s, dt_s)
            if command is not None:
                return command
        return self.wheels.neutral()

    # ---- modes and the mission -----------------------------------------------------------------

    def _mode_context(self) -> modes.ModeContext:
        has_position = self.executor is not None and self._pose is not None
        return modes.ModeContext(has_position=has_position, has_mission=bool(self.mission.items))

    def _enter(self, mode: RoverMode, reason: str, resume: bool = True) -> None:
        previous, self.mode = self.mode, mode
        if self.executor is not None:
            if mode == RoverMode.AUTO and resume and self.config.autopilot.mission_restart == 1 and previous != mode:
                self._executor_events(self.executor.restart())  # MIS_RESTART 1: AUTO starts over
            elif mode == RoverMode.AUTO and resume:
                self._executor_events(self.executor.start())
            elif mode == RoverMode.RTL:
                self._executor_events(self.executor.rtl())
            elif mode != RoverMode.AUTO:
                self.executor.stop()
        if mode == RoverMode.AUTO:
            self._mission_started = True
        if mode in modes.STATION_MODES:
            pose = self._pose
            self._station_en = (pose.east_m, pose.north_m) if pose is not None else None
            self._guided_target_en = None
            self._returning = False
        if self.follower is not None:
            self.follower.reset()
        self.passage.reset()
        self.evader.reset()
        self.pivot.reset()
        self._evaded_s = -math.inf
        self.wheels.reset()
        if previous != mode:
            self._outbox.append(ModeChanged(mode, previous, reason))

    def _load_mission(self) -> None:
        """(Re)build the planner, path follower and executor for the current mission and home."""
        if self.frame is None:
            return  # done again once the first fix gives a frame
        cfg = self.config
        to_enu = self.frame.to_enu
        self.fence, self.fence_error = Fence(), None
        if self.mission.fence:
            # A stored fence with invalid parts (an older version's store) never stops the rover
            # starting: the valid parts are kept, and arming is refused while the fence is not whole.
            self.fence, ignored = Fence.checked(self.mission.fence, to_enu)
            if ignored:
                self.fence_error = ignored[0] + (f" (and {len(ignored) - 1} more)" if len(ignored) > 1 else "")
                self._say(f"Fence part ignored: {self.fence_error}", Severity.WARNING)
        self.planner = Planner(cfg.planner, cfg.robot, fence=self.fence, persistent_margin_m=lambda: cfg.obstacle_map.margin_m)
        self.follower = PathFollower(self.planner, cfg.planner)
        if self._map_obstacles:
            self.follower.set_persistent(self._map_obstacles)
        self.executor = MissionExecutor(self.mission.items, to_enu, cfg.executor, lambda: cfg.robot.max_speed_mps)
        waypoints = tuple(tuple(map(float, to_enu(i.x, i.y))) for i in self.mission.items
                          if i.command in NAV_COMMANDS and i.is_global and (i.x or i.y))  # fmt: skip
        total = sum(i.command in NAV_COMMANDS for i in self.mission.items)
        self._outbox.append(MissionLoaded(total, len(self.mission.items), waypoints))
        self._apply_resume()

    def _executor_events(self, events) -> None:
        for event in events:
            if event.kind is EventKind.ITEM_REACHED:
                self._outbox.append(ItemReached(event.seq))
            elif event.kind is EventKind.CURRENT:
                self._outbox.append(MissionCurrent(event.seq, self.mission_state()))
                self._reported_state = (event.seq, self.mission_state())
            elif event.kind is EventKind.COMPLETE:
                self._outbox.append(MissionComplete(event.seq))
            elif event.kind is EventKind.STATUSTEXT:
                self._say(event.text, event.severity)

    def _report_mission_state(self) -> None:
        """A MISSION_CURRENT whenever the mission state or current item changes (PAUSED on HOLD,
        COMPLETE at the end, NO_MISSION after a clear), not only at the periodic broadcast."""
        now = (self._current_seq(), self.mission_state())
        if now != self._reported_state:
            self._reported_state = now
            self._outbox.append(MissionCurrent(*now))

    def _arming_inputs(self) -> prearm.ArmingInputs:
        pose = self._pose
        position = (pose.east_m, pose.north_m) if pose is not None and self.frame is not None else None
        last = self._last_step_s if self._last_step_s is not None else -math.inf
        first = next((i for i in self.mission.items if i.command in NAV_COMMANDS and i.is_global and (i.x or i.y)), None)
        return prearm.ArmingInputs(
            position_en=position,
            estimator_healthy=pose is not None and pose.healthy,
            gps_ok=pose is not None and pose.gps_ok,
            range_ages_s={o: max(0.0, last - r.time_s) for o, r in self._ranges.items()},
            needed_orientations=sorted(self.rangefinder_plan.required) if self.rangefinder_plan else self.navigator.orientations,
            rangefinder_timeout_s=self.config.failsafe.rangefinder_timeout_s,
            fence=self.fence,
            fence_error=self.fence_error,
            first_waypoint_en=self.frame.to_enu(first.x, first.y) if first is not None and self.frame is not None else None,
            max_distance_m=self.config.autopilot.arming_max_distance_m,
            sensor_rates_hz=self._sensor_rates_hz,
            min_sensor_rate_hz=self.config.failsafe.min_sensor_rate_hz,
            planner_nodes=self.planner.node_count(fixed_only=True) if self.planner is not None else 0,
            vehicle_params=dict(self.vehicle_params),
        )

    def _plan_rangefinders(self, present: set[int]) -> None:
        """What the navigator reads and the failsafe requires, from the rangefinders ``present``."""
        try:
            plan = plan_rangefinders(self.navigator.orientations, present)
        except SensorSetupError as exc:
            self.sensor_error = f"rangefinders: {exc}"
            self._say(self.sensor_error, Severity.CRITICAL)
            return
        self.rangefinder_plan = self.navigator.rangefinders = plan
        self.failsafes.used_rangefinders = plan.required
        self._say(plan.describe(), Severity.INFO if plan.avoidance else Severity.WARNING)

    # ---- STATUSTEXT ----------------------------------------------------------------------------

    def _say(self, text: str, severity: Severity = Severity.INFO) -> None:
        self._outbox.append(StatusText(text, Severity(severity)))

    def _say_once(self, text: str) -> None:
        if text != self._last_said:
            self._last_said = text
            self._say(text, Severity.WARNING)
