"""A closed loop around the pure autopilot, no sockets: a kinematic skid-steer rover that obeys the
autopilot's RC command through ArduPilot's mixer, a perfect pose, fresh rangefinders.

    bench = Bench()                       # home at CMAC, rover at (0, 0) facing north
    bench.ready()                         # steps until the autopilot has a position, then arms
    bench.run(20.0)                       # 20 s of vehicle time at 25 Hz
    bench.events / bench.texts / bench.position_en
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rover_ctl.autopilot.autopilot import RELEASE, Autopilot, Readings, StepOutput
from rover_ctl.autopilot.events import ArmRequest, Event, StatusText
from rover_ctl.config import Config
from rover_ctl.estimation.estimator import Pose
from rover_ctl.estimation.frame import LocalFrame
from rover_ctl.estimation.readings import RangeReading, WheelDistance
from rover_ctl.fuzzy import load_rulebase
from rover_ctl.mission.model import FRAME_GLOBAL_RELATIVE_ALT, Home, Mission, MissionItem
from rover_ctl.navigation.wheel_control import WheelCommand, rc_to_motors
from rover_ctl.vocabulary import Cmd

HOME = Home(-35.363261, 149.165230, 584.0)
FRAME = LocalFrame(HOME.lat_deg, HOME.lon_deg, HOME.alt_m)
RULEBASE = load_rulebase("default")
ORIENTATIONS = (0, 1, 2, 4, 6, 7)


def latlon(east_m: float, north_m: float) -> tuple[float, float]:
    return FRAME.to_geodetic(east_m, north_m)


def waypoint(east_m: float, north_m: float, command: int = Cmd.NAV_WAYPOINT, **params: float) -> MissionItem:
    lat, lon = latlon(east_m, north_m)
    return MissionItem(command, FRAME_GLOBAL_RELATIVE_ALT, x=lat, y=lon, **params)


def mission(*points: tuple[float, float], fence: list[MissionItem] | None = None) -> Mission:
    return Mission(items=[waypoint(e, n) for e, n in points], home=HOME, fence=fence or [])


def pose(east_m: float = 0.0, north_m: float = 0.0, heading_rad: float = math.pi / 2, speed_mps: float = 0.0,
         t_s: float = 0.0, healthy: bool = True, gps_ok: bool = True) -> Pose:  # fmt: skip
    return Pose(t_s, east_m, north_m, heading_rad, speed_mps, 0.0, np.eye(3) * 0.01, healthy, gps_ok, 0.1, 0.05)


def rover_config() -> Config:
    """The default config on a rover whose rangefinders are configured (not learnt first)."""
    config = Config()
    config.link.rangefinders = list(ORIENTATIONS)
    return config


@dataclass
class Bench:
    config: Config = field(default_factory=rover_config)
    east_m: float = 0.0
    north_m: float = 0.0
    heading_rad: float = math.pi / 2
    t_s: float = 0.0
    healthy: bool = True
    gps_ok: bool = True
    """The estimator's pose says a fix was fused recently."""
    ranges_m: dict[int, float] = field(default_factory=lambda: dict.fromkeys(ORIENTATIONS, math.inf))
    """Range per orientation; delete a key to silence that rangefinder."""
    vehicle_age_s: float = 0.0
    gcs_age_s: float = math.inf
    gps_age_s: float = 0.0
    vehicle_armed: bool | None = None
    """None: the vehicle arms as asked (ArmRequest events); else fixed."""
    frozen: bool = False
    """The rover does not move whatever it is told (stuck against something)."""
    step_period_s: float | None = None
    """Vehicle time between two steps; None: the configured control rate (a loop that keeps up)."""
    events: list[Event] = field(default_factory=list)
    outputs: list[StepOutput] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.autopilot = Autopilot(self.config, RULEBASE)
        self.startup = self.autopilot.drain()
        """What the autopilot emitted when built; its texts (the rangefinder plan) are kept out of
        ``events`` so tests read the texts their own actions caused."""
        self.left_mps = self.right_mps = 0.0
        self.left_m = self.right_m = 0.0
        self.armed = False
        self._ranges: dict[int, RangeReading] = {}
        self.events.extend(e for e in self.startup if not isinstance(e, StatusText))

    # -- the world --------------------------------------------------------------------------

    @property
    def position_en(self) -> tuple[float, float]:
        return (self.east_m, self.north_m)

    @property
    def speed_mps(self) -> float:
        return (self.left_mps + self.right_mps) / 2.0

    def pose(self) -> Pose | None:
        return pose(self.east_m, self.north_m, self.heading_rad, self.speed_mps, self.t_s, self.healthy, self.gps_ok)

    def _move(self, command, dt_s: float) -> None:
        if isinstance(command, WheelCommand):
            left, right = rc_to_motors(command.steering_us, command.throttle_us, self.config.wheel_control)
        else:  # released or neutral: the rover coasts to a stop
            left = right = 0.0
        full_mps = self.config.wheel_control.full_output_rpm / 60.0 * 2.0 * math.pi * self.config.robot.wheel_radius_m
        alpha = min(1.0, dt_s / 0.15)
        self.left_mps += alpha * (left * full_mps - self.left_mps)
        self.right_mps += alpha * (right * full_mps - self.right_mps)
        self.left_m += self.left_mps * dt_s
        self.right_m += self.right_mps * dt_s
        if self.frozen:
            return
        speed = self.speed_mps
        self.heading_rad += (self.right_mps - self.left_mps) / self.config.robot.track_m * dt_s
        self.east_m += speed * math.cos(self.heading_rad) * dt_s
        self.north_m += speed * math.sin(self.heading_rad) * dt_s

    # -- driving the autopilot --------------------------------------------------------------

    def home(self, mission: Mission | None = None) -> None:
        if mission is not None:
            self.autopilot.mission_changed(mission, 0)
        self.autopilot.set_home(HOME, FRAME)
        self.collect(self.autopilot.drain())

    def collect(self, events) -> None:
        for event in events:
            self.events.append(event)
            if isinstance(event, ArmRequest) and self.vehicle_armed is None:
                self.armed = event.arm

    def step(self) -> StepOutput:
        dt_s = self.step_period_s or 1.0 / self.config.daemon.control_rate_hz
        self.autopilot.on_vehicle(self.armed if self.vehicle_armed is None else self.vehicle_armed)
        self.autopilot.on_wheels(WheelDistance(self.t_s, self.left_m, self.right_m))
        # A silent rangefinder's last reading stays, growing old (as the daemon keeps it).
        self._ranges.update({o: RangeReading(self.t_s, o, o, r, 0.2, 4.0) for o, r in self.ranges_m.items()})
        readings = Readings(dict(self._ranges), self.vehicle_age_s, self.gcs_age_s, self.gps_age_s)
        out = self.autopilot.step(self.t_s, self.pose(), readings)
        self.outputs.append(out)
        self.collect(out.events)
        self._move(out.command, dt_s)
        self.t_s += dt_s
        return out

    def run(self, seconds: float, until=None) -> bool:
        """Step for ``seconds`` of vehicle time or until ``until(bench)``; True if it came true."""
        end = self.t_s + seconds
        while self.t_s < end:
            self.step()
            if until is not None and until(self):
                return True
        return until is None

    def request(self, reply):
        """A ground-station request's reply, with its events collected."""
        self.collect(self.autopilot.drain())
        return reply

    def ready(self, mission: Mission | None = None) -> None:
        """Home (with the mission), one step for a position, armed."""
        self.home(mission)
        self.step()
        assert self.request(self.autopilot.arm(True)).accepted, self.texts
        self.step()

    @property
    def texts(self) -> list[str]:
        return [e.text for e in self.events if isinstance(e, StatusText)]

    def of_type(self, kind: type) -> list:
        return [e for e in self.events if isinstance(e, kind)]

    @property
    def released(self) -> bool:
        return self.outputs[-1].command is RELEASE

    @property
    def neutral(self) -> bool:
        command = self.outputs[-1].command
        trim = self.config.wheel_control.rc_trim_us
        return isinstance(command, WheelCommand) and (command.steering_us, command.throttle_us) == (trim, trim)
