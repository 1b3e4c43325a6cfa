"""The fuzzy navigator: pose, path target and ranges -> fuzzy inputs -> left/right wheel rpm.

Pure: no clock, no I/O. Each ``step`` maps the geometry onto the rule base's inputs by name:

- ``target_distance``: metres from the pose to the target.
- ``target_direction``: degrees in ``[0, 360)``, the paper's "robot heading minus bearing to the
  target" measured clockwise (compass sense); in ENU (counter-clockwise) terms that is
  ``bearing - heading``, so 90 means the target lies 90 degrees to the LEFT, 270 to the right.
- ``obstacle_<side>``: the latest range of the rangefinder with that MAV_SENSOR_ORIENTATION
  (``front`` 0, ``front_right`` 1, ``right`` 2, ``back`` 4, ``left`` 6, ``front_left`` 7); ``inf``
  means nothing in range. Inputs in metres (unit ``m``) get metres; any other unit (the paper's
  0..20 range units) gets ``range_m * paper_range_units_per_m``.

**A rangefinder the rule base reads but the caller does not pass (or passes as NaN) is taken as
``NavigatorParams.missing_range_m`` (0 by default): that side counts as blocked.** The daemon's
rangefinder failsafe relies on this; a rule base that has no input for a side ignores it.

Which rangefinders the rover has is ``rangefinders`` (a ``rover_ctl.navigation.sensors.
RangefinderPlan``, set by the daemon once known): without rangefinders every obstacle input reads
clear (GPS-only navigation); a missing diagonal reads the nearer of its front and side
neighbours. Until it is set, the ranges are read as passed.

The outputs ``left_motor`` and ``right_motor`` are scaled so that the rule base's largest output
peak becomes ``max_wheel_rpm``; with a speed limit both wheels are scaled down together
(keeping the turn radius) so that neither exceeds the wheel rpm of that ground speed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

from rover_ctl.config import NavigatorParams, RobotParams
from rover_ctl.fuzzy import RuleBase, RuleBaseError, load_rulebase
from rover_ctl.navigation.sensors import RangefinderPlan

SIDES = {"front": 0, "front_right": 1, "right": 2, "back": 4, "left": 6, "front_left": 7}
"""Obstacle input suffix -> MAV_SENSOR_ORIENTATION of the rangefinder that feeds it."""
OUTPUTS = ("left_motor", "right_motor")


@dataclass(frozen=True)
class NavOutput:
    """One navigator step: wheel setpoints and what the rule base saw."""

    left_rpm: float
    right_rpm: float
    inputs: dict[str, float] = field(default_factory=dict)
    """The rule base's inputs by name, plus ``target_distance_m`` and ``target_direction_rad``
    (bearing minus heading in ENU, wrapped to (-pi, pi]: positive = target to the left)."""


class Navigator:
    """Steers towards a target among obstacles with a fuzzy rule base."""

    def __init__(
        self,
        rulebase: RuleBase | str,
        params: NavigatorParams,
        max_wheel_rpm: float | Callable[[], float],
        wheel_radius_m: float | Callable[[], float] = RobotParams.wheel_radius_m,
    ) -> None:
        """``params`` is read at every step; the robot's numbers may be functions giving the value
        in force, so that a changed parameter applies at the next step."""
        self.rulebase = load_rulebase(rulebase) if isinstance(rulebase, str) else rulebase
        self.params = params
        self._max_wheel_rpm = max_wheel_rpm if callable(max_wheel_rpm) else (lambda: max_wheel_rpm)
        self._wheel_radius_m = wheel_radius_m if callable(wheel_radius_m) else (lambda: wheel_radius_m)
        names = self.rulebase.input_names
        missing = [n for n in ("target_distance", "target_direction") if n not in names]
        missing += [n for n in OUTPUTS if n not in self.rulebase.output_names]
        unknown = [n for n in names if n not in ("target_distance", "target_direction") and n.removeprefix("obstacle_") not in SIDES]
        if missing or unknown:
            raise RuleBaseError(
                f"{self.rulebase.source}: not a navigation rule base "
                f"(missing {', '.join(missing) or '-'}; unknown inputs {', '.join(unknown) or '-'}; "
                f"inputs must be target_distance, target_direction, obstacle_<{'|'.join(SIDES)}>)"
            )
        self._obstacles = []  # (input name, orientation, whether the input is in metres)
        for variable in self.rulebase.inputs:
            if variable.name.startswith("obstacle_"):
                self._obstacles.append((variable.name, SIDES[variable.name.removeprefix("obstacle_")], variable.unit == "m"))
        self._orientations = tuple(orientation for _, orientation, _ in self._obstacles)
        self._full_scale = max(abs(s.peak) for name in OUTPUTS for s in self.rulebase.outputs[self.rulebase.output_names.index(name)].sets)
        if self._full_scale <= 0.0:  # every output set peaks at 0: the largest peak scales to max_wheel_rpm
            raise RuleBaseError(f"{self.rulebase.source}: every motor set peaks at 0: the rover could never move")
        self.rangefinders: RangefinderPlan | None = None
        """How the rover's rangefinders feed the obstacle inputs (None: as passed)."""

    @property
    def max_wheel_rpm(self) -> float:
        return self._max_wheel_rpm()

    @property
    def wheel_radius_m(self) -> float:
        return self._wheel_radius_m()

    @property
    def orientations(self) -> list[int]:
        """Rangefinder orientations this rule base reads."""
        return list(self._orientations)

    def step(
        self,
        pose_east_m: float,
        pose_north_m: float,
        heading_rad: float,
        target_east_m: float,
        target_north_m: float,
        ranges_m: dict[int, float],
        speed_limit_mps: float | None = None,
        target_distance_m: float | None = None,
    ) -> NavOutput:
        """``target_*`` is the point to steer to (the planner's carrot); ``target_distance_m``, when
        given, is how far the target really is (the path length left to the waypoint), which the
        rule base's distance input should see: the paper's controller slows down within 7.5 m of
        its target and would crawl if it saw only the carrot 3 m ahead. Default: the straight-line
        distance to the steering point."""
        d_east, d_north = target_east_m - pose_east_m, target_north_m - pose_north_m
        steer_m = math.hypot(d_east, d_north)
        relative_rad = math.remainder(math.atan2(d_north, d_east) - heading_rad, math.tau) if steer_m > 0.0 else 0.0
        distance_m = steer_m if target_distance_m is None else max(target_distance_m, 0.0)
        inputs = {"target_distance": distance_m, "target_direction": math.degrees(relative_rad) % 360.0}
        if self.rangefinders is not None:
            ranges_m = self.rangefinders.inputs(ranges_m, self._orientations)
        for name, orientation, in_metres in self._obstacles:
            range_m = ranges_m.get(orientation, math.nan)
            if range_m is None or math.isnan(range_m):
                range_m = self.params.missing_range_m
            inputs[name] = range_m * (1.0 if in_metres else self.params.paper_range_units_per_m)
        crisp = self.rulebase.evaluate_one(**inputs)
        rpm_per_output = self.max_wheel_rpm / self._full_scale
        left = crisp["left_motor"] * rpm_per_output
        right = crisp["right_motor"] * rpm_per_output
        if speed_limit_mps is not None:
            limit_rpm = max(speed_limit_mps, 0.0) / (math.tau * self.wheel_radius_m) * 60.0
            fastest = max(abs(left), abs(right))
            if fastest > limit_rpm:
                left, right = left * limit_rpm / fastest, right * limit_rpm / fastest
        inputs["target_distance_m"] = distance_m
        inputs["target_direction_rad"] = relative_rad
        return NavOutput(left, right, inputs)
