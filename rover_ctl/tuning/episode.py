"""The in-process episode runner: one mission in one seeded world, emulator and autopilot stepped
in one process, no sockets, no MAVLink, no files.

It is the lockstep SITL run (``rover-ctl sim --lockstep``, docs/architecture.md "Lockstep
handshake") with the wire taken out, built from the same modules:

- the vehicle: ``sitl.vehicle.SimRover`` (physics, world, sensors, faults, collisions) behind
  ``sitl.mavlink_vehicle.MavlinkVehicle`` (sensor sampling at each sensor's rate, arming, the
  RC overrides and ArduPilot's skid-steer mixer);
- the controller: the daemon's ``Autopilot`` (failsafes, executor, planner, obstacle memory,
  fuzzy navigator, wheel PI) fed what ``rover_ctl.app.daemon.Daemon`` feeds it: wheel and
  attitude readings as they come, the newest range per orientation, the estimator's pose, a step
  at each ``daemon.control_rate_hz`` tick of vehicle time; its overrides reach the mixer at the
  frame they were computed for, as the lockstep answer guarantees.

Each frame of ``FRAME_S``: the rover advances to t_k, the sensors due at t_k are read, their
readings go to the estimator and the autopilot in the order the emulator sends them (GPS,
ATTITUDE, DISTANCE_SENSOR, WHEEL_DISTANCE), the control step runs if a tick is due, its command
drives the motors from t_k on. Readings carry the wire's quantisation (ms and us stamps, cm
ranges, 1e-7 degree fixes), so the estimator and the navigator see the numbers the daemon sees.

What differs from the SITL run, and why it does not change the outcome beyond the tolerance the
test (tests/tune/test_episode.py) states:
- streams are sent when each sensor is sampled (the emulator sends the newest sample on a stream
  grid that starts when the daemon asks for its rates: the same readings, up to one frame later);
- the ground station is this loop: it arms as soon as the autopilot's and the vehicle's pre-arm
  checks pass (asking again at each step) and starts the mission at once (``rover-ctl sim``
  retries arming every 0.2 wall seconds, which in lockstep is a variable number of sim seconds);
  an arming the vehicle accepts reaches the autopilot at once (the daemon takes the vehicle's
  ACCEPTED as armed), and from then on the armed flag with each 1 Hz heartbeat, as over the wire;
- measured link rates are the stream rates (the daemon measures them); ATTITUDE and WHEEL_DISTANCE
  come on a grid at ``daemon.sensor_rate_hz`` from t = 0, the newest sample each (the emulator's
  grid starts when the daemon asks).

``start_s``: the ground station arms and starts the mission no earlier than this sim time (a
comparison with a SITL run starts when that run did: moving obstacles move on sim time).
``stop_on_collision``: end at the first collision (search needs no more of a failed episode).
``estimator="truth"`` replaces the pose filter with the true pose (a documented stand-in for
search when the filter's cost matters; the default is the real ``PoseEstimator``).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from rover_ctl.autopilot.autopilot import RELEASE, Autopilot, Readings
from rover_ctl.autopilot.events import ArmRequest, MissionComplete, ModeChanged
from rover_ctl.autopilot.loop_rate import ControlTicks
from rover_ctl.config import Config, load_config
from rover_ctl.estimation.estimator import Pose, PoseEstimator
from rover_ctl.estimation.frame import LocalFrame
from rover_ctl.estimation.readings import Attitude, GpsFix, RangeReading, WheelDistance
from rover_ctl.fuzzy import RuleBase
from rover_ctl.mission.model import GLOBAL_XY_SCALE, Home, Mission, MissionItem
from rover_ctl.tuning import scenarios as scenario_defs
from rover_ctl.vocabulary import RoverMode, mav
from sitl.mavlink_vehicle import STEERING_CHANNEL, THROTTLE_CHANNEL, LinkParams, MavlinkVehicle, next_slot
from sitl.params import RANGEFINDER_SETS, SitlParams
from sitl.vehicle import SimRover
from sitl.world import Home as SitlHome
from sitl.world import parse_world, scatter_obstacles

FRAME_S = 0.02
"""The emulator's lockstep frame (``rover-sitl --frame-s`` default)."""
HEARTBEAT_PERIOD_S = 1.0
"""The vehicle's HEARTBEAT period: how soon the autopilot learns the vehicle armed."""
TRUTH_PERIOD_S = 0.1
"""Path length is measured on the truth at this period, as the report reads the 10 Hz truth log."""
TIME_BUDGET_S = 240.0
"""Sim seconds from the start of AUTO before an episode counts as timed out (the navigation
benchmark's budget)."""
ACCEPTANCE_RADIUS_M = 0.5
"""Waypoint acceptance radius of the episodes (the navigation benchmark's)."""
ARMING_GIVE_UP_S = 60.0
"""Sim seconds after boot without the autopilot accepting to arm: the episode ends as failed."""
ESTIMATORS = ("ekf", "truth")


@dataclass(frozen=True)
class Outcome:
    """What one episode gave: the figures ``rover-ctl sim``'s report computes."""

    scenario: str
    seed: int
    success: bool
    """Mission complete, no collision, within the budget."""
    complete: bool
    timed_out: bool
    collisions: int
    path_length_m: float
    """Truth path from the start of AUTO to the end (10 Hz samples)."""
    duration_s: float
    """Sim seconds from the start of AUTO to mission complete (or to the end of the episode)."""
    sim_s: float
    """Sim seconds simulated in all (boot and arming included)."""

    def to_dict(self) -> dict:
        return asdict(self)


def episode_config(overrides: list[str] | tuple[str, ...] = ()) -> Config:
    """The daemon configuration of an episode: defaults, the benchmark's acceptance radius, overrides."""
    return load_config(None, [f"executor.acceptance_radius_m={ACCEPTANCE_RADIUS_M}", *overrides])


def build_world(scenario: scenario_defs.Scenario, seed: int, mission: Mission):
    """The emulator's world for a scenario and seed: its file, plus the obstacles ``rover-sitl
    --scatter N --along HOME;WAYPOINTS --seed S`` draws (as ``rover-ctl sim --obstacles N`` asks)."""
    world = parse_world(scenario_defs.world_doc(scenario), scenario.name)
    if scenario.scatter:
        legs = [(mission.home.lat_deg, mission.home.lon_deg)] + [(i.x, i.y) for i in mission.items]
        world.obstacles.extend(scatter_obstacles(legs, scenario.scatter, seed).obstacles)
    return world


def _on_wire(mission: Mission) -> Mission:
    """The mission as the daemon stores it after an upload: lat/lon in whole 1e-7 degrees."""
    items = [MissionItem(i.command, i.frame, i.param1, i.param2, i.param3, i.param4, round(i.x * GLOBAL_XY_SCALE) / GLOBAL_XY_SCALE,
                         round(i.y * GLOBAL_XY_SCALE) / GLOBAL_XY_SCALE, i.z, i.autocontinue) for i in mission.items]  # fmt: skip
    return Mission(items=items, home=mission.home)


class Episode:
    """One scenario, seed and rule base; ``run()`` steps it to the end and returns the ``Outcome``."""

    def __init__(self, rulebase: RuleBase, scenario: str, seed: int, config: Config | None = None, *,
                 estimator: str = "ekf", time_budget_s: float = TIME_BUDGET_S, stop_on_collision: bool = False,
                 start_s: float = 0.0) -> None:  # fmt: skip
        if estimator not in ESTIMATORS:
            raise ValueError(f"estimator must be one of {', '.join(ESTIMATORS)}, got {estimator!r}")
        defs = scenario_defs.scenarios(seed)
        if scenario not in defs:
            raise ValueError(f"unknown scenario {scenario!r} (known: {', '.join(defs)})")
        self.scenario, self.seed = scenario, seed
        self.config = config or episode_config()
        self.time_budget_s = time_budget_s
        self.stop_on_collision = stop_on_collision
        self.start_s = start_s
        self.use_truth = estimator == "truth"
        mission = scenario_defs.mission(defs[scenario])
        home = mission.home
        params = SitlParams()
        params.rangefinder.sensors = RANGEFINDER_SETS["default"]()
        self.rover = SimRover(params, build_world(defs[scenario], seed, mission), SitlHome(home.lat_deg, home.lon_deg, home.alt_m, 0.0), seed)
        self.vehicle = MavlinkVehicle(self.rover, LinkParams())
        self.autopilot = Autopilot(self.config, rulebase)
        self.autopilot.mission_changed(_on_wire(mission), mav.MAV_MISSION_TYPE_ALL)
        self.estimator: PoseEstimator | None = None
        self.frame: LocalFrame | None = None
        self.ranges: dict[int, RangeReading] = {}
        self.last_fix_s: float | None = None
        odometry_hz = self.config.daemon.sensor_rate_hz
        self.odometry_period_s = 1.0 / odometry_hz if odometry_hz > 0 else None
        """ATTITUDE and WHEEL_DISTANCE come at the rate the daemon asks for, the newest sample each."""
        self._next_odometry_s = 0.0
        self.rates_hz = {"ATTITUDE": min(params.imu.rate_hz, odometry_hz), "WHEEL_DISTANCE": min(params.encoder.rate_hz, odometry_hz)}
        self.period_s = 1.0 / self.config.daemon.control_rate_hz
        self.ticks = ControlTicks(lambda: self.period_s)
        self.arm_sent = False
        self.vehicle_armed_seen = False
        self.auto_start_s: float | None = None
        self.complete_s: float | None = None
        self.collisions = 0
        self.path_m = 0.0
        self._last_truth: tuple[float, float] | None = None
        self._next_truth_s = 0.0
        self._next_heartbeat_s = 0.0

    # ---- the loop ------------------------------------------------------------------------------

    def run(self) -> Outcome:
        k = 0
        while True:
            t_s = k * FRAME_S
            if k > 0:
                for event in self.rover.step(FRAME_S):
                    if event.kind == "collision":
                        self.collisions += 1
            self._truth(t_s)
            self._sense(t_s)
            self._maybe_step(t_s)
            self.vehicle.apply_outputs(t_s)
            if self._done(t_s):
                break
            k += 1
        return self._outcome(t_s)

    def _done(self, t_s: float) -> bool:
        if self.complete_s is not None:
            return True
        if self.stop_on_collision and self.collisions:
            return True
        if self.auto_start_s is None:
            return t_s >= self.start_s + ARMING_GIVE_UP_S
        return t_s - self.auto_start_s >= self.time_budget_s

    def _outcome(self, t_s: float) -> Outcome:
        complete = self.complete_s is not None
        timed_out = not complete and not (self.stop_on_collision and self.collisions)
        start = self.auto_start_s if self.auto_start_s is not None else t_s
        end = self.complete_s if complete else t_s
        return Outcome(self.scenario, self.seed, complete and not self.collisions and not timed_out, complete, timed_out,
                       self.collisions, round(self.path_m, 2), round(end - start, 2), round(t_s, 2))  # fmt: skip

    def _truth(self, t_s: float) -> None:
        """Path length over the truth, sampled as the truth log is, inside the AUTO window."""
        if t_s + 1e-9 < self._next_truth_s:
            return
        self._next_truth_s += TRUTH_PERIOD_S
        here = (self.rover.drive.east_m, self.rover.drive.north_m)
        if self.auto_start_s is not None and self.complete_s is None and self._last_truth is not None:
            self.path_m += math.dist(here, self._last_truth)
        self._last_truth = here

    # ---- the vehicle's side: sensors as the wire carries them -----------------------------------

    def _sense(self, t_s: float) -> None:
        """Sample what is due at ``t_s`` and hand it over in the emulator's message order."""
        v = self.vehicle
        if v.armed:  # world motions that start at arming (as sitl.main's frame loop)
            self.rover.world.armed(t_s)
        before = (v.gps, v.ranges)
        v.sample_sensors(t_s)
        odometry = self.odometry_period_s is not None and t_s + 1e-9 >= self._next_odometry_s
        if odometry:
            self._next_odometry_s = next_slot(self._next_odometry_s, self.odometry_period_s, t_s)
        if t_s + 1e-9 >= self._next_heartbeat_s:
            self._next_heartbeat_s += HEARTBEAT_PERIOD_S
            self.autopilot.on_vehicle(v.armed)
        if v.gps is not before[0]:
            self._on_gps(v.gps, t_s)
        if odometry and v.attitude is not None:
            a = v.attitude
            reading = Attitude(int(t_s * 1000) / 1000.0, math.remainder(a.yaw_rad, math.tau), a.yaw_rate_radps)
            self.autopilot.on_attitude(reading)
            if self.estimator:
                self.estimator.on_attitude(reading)
        if v.ranges is not before[1]:
            for s in v.ranges:
                max_cm = int(round(s.max_m * 100))
                current_cm = max_cm + 1 if s.range_m is None else int(round(s.range_m * 100))
                self.ranges[s.orientation] = RangeReading(int(t_s * 1000) / 1000.0, s.sensor_id, s.orientation,
                                                          math.inf if current_cm > max_cm else current_cm / 100.0,
                                                          int(round(s.min_m * 100)) / 100.0, max_cm / 100.0)  # fmt: skip
        if odometry and v.wheels is not None:
            reading = WheelDistance(round(t_s * 1e6) / 1e6, v.wheels.left_m, v.wheels.right_m)
            self.autopilot.on_wheels(reading)
            if self.estimator:
                self.estimator.on_wheels(reading)

    def _on_gps(self, sample, t_s: float) -> None:
        if sample is None:
            return  # a dropped fix: GPS_RAW_INT says no fix, which the daemon ignores
        fix = GpsFix(round(t_s * 1e6) / 1e6, round(sample.lat_deg * 1e7) / 1e7, round(sample.lon_deg * 1e7) / 1e7,
                     round(sample.alt_m * 1000) / 1000.0, sample.fix_type, min(round(sample.eph_m * 100), 65535) / 100.0,
                     round(sample.speed_mps * 100) / 100.0, (round((sample.course_deg % 360.0) * 100) % 36000) / 100.0,
                     sample.satellites)  # fmt: skip
        if not fix.has_fix:
            return
        self.last_fix_s = fix.time_s
        if self.frame is None:
            self.frame = LocalFrame(fix.lat_deg, fix.lon_deg, fix.alt_m)
            self.estimator = PoseEstimator(self.frame, self.config.estimator, lambda: self.config.robot.track_m)
            self.autopilot.set_home(Home(fix.lat_deg, fix.lon_deg, fix.alt_m), self.frame)
            self.autopilot.drain()
        self.estimator.on_gps(fix)

    # ---- the daemon's side -------------------------------------------------------------------

    def _pose(self, t_s: float) -> Pose | None:
        if self.use_truth:
            return self._true_pose(t_s)
        return self.estimator.pose(t_s) if self.estimator and self.estimator.initialised else None

    def _true_pose(self, t_s: float) -> Pose | None:
        if self.frame is None:
            return None
        d = self.rover.drive
        # The truth in the daemon's frame (home = its first fix, not the emulator's origin).
        lat, lon = self.rover.frame.to_latlon(d.east_m, d.north_m)
        east, north = self.frame.to_enu(lat, lon)
        return Pose(t_s, east, north, math.remainder(d.yaw_rad, math.tau), d.speed_mps, d.yaw_rate_radps, np.zeros((3, 3)),
                    True, True, 0.0, 0.0)  # fmt: skip

    def _maybe_step(self, t_s: float) -> None:
        """``Daemon._maybe_step`` and ``control_step``: a step when vehicle time reaches the tick."""
        if not self.ticks.due(t_s):
            return
        readings = Readings(ranges=dict(self.ranges), vehicle_age_s=0.0, gcs_age_s=0.0,
                            gps_age_s=math.inf if self.last_fix_s is None else max(0.0, t_s - self.last_fix_s),
                            sensor_rates_hz=self.rates_hz, odometry_planned_hz=self.rates_hz["WHEEL_DISTANCE"])  # fmt: skip
        pose = self._pose(t_s)
        out = self.autopilot.step(t_s, pose, readings)
        self._command(out.command, t_s)
        self._events(out.events, t_s)
        self._ground_station(t_s, pose)

    def _command(self, command, t_s: float) -> None:
        """The override as the emulator applies it (``MavlinkVehicle`` keeps (pwm, time set) per channel)."""
        overrides = self.vehicle.overrides
        if command is RELEASE:
            overrides.pop(STEERING_CHANNEL, None)
            overrides.pop(THROTTLE_CHANNEL, None)
            return
        overrides[STEERING_CHANNEL] = (command.steering_us, t_s)
        overrides[THROTTLE_CHANNEL] = (command.throttle_us, t_s)

    def _events(self, events, t_s: float) -> None:
        for event in events:
            if isinstance(event, ArmRequest):
                self.vehicle.handle(mav.MAVLink_command_long_message(1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, float(event.arm),
                                                                     0.0, 0, 0, 0, 0, 0), t_s)  # fmt: skip
                if self.vehicle.armed == event.arm:  # ACCEPTED: the daemon takes it at once
                    self.autopilot.on_vehicle(event.arm)
            elif isinstance(event, ModeChanged) and event.mode == RoverMode.AUTO and self.auto_start_s is None:
                self.auto_start_s = t_s
            elif isinstance(event, MissionComplete) and self.complete_s is None:
                self.complete_s = t_s

    def _ground_station(self, t_s: float, pose: Pose | None) -> None:
        """Arm once the pre-arm checks pass, then start the mission (as ``rover-ctl sim`` does)."""
        ap = self.autopilot
        if pose is None or self.auto_start_s is not None or t_s + 1e-9 < self.start_s:
            return
        if not self.arm_sent:
            accepted = ap.arm(True).accepted
            self._events(ap.drain(), t_s)
            # The vehicle answers at once here; a refusal (no 3D fix for GPS_TIMEOUT_S) is asked
            # again at the next step, as rover-ctl sim asks again on a refused COMMAND_ACK.
            self.arm_sent = accepted and self.vehicle.armed
            if not self.arm_sent:
                return
        if ap.mission_start().accepted:
            self._events(ap.drain(), t_s)


def run_episode(rulebase: RuleBase, scenario: str, seed: int, config: Config | None = None, **options) -> Outcome:
    """One episode to its end (``Episode`` documents the options)."""
    return Episode(rulebase, scenario, seed, config, **options).run()
