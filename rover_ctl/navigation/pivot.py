"""Pivot turns: a skid-steer rover whose target lies far off its heading turns in place to face it
before the rule base drives on, as ArduPilot Rover's ``AR_PivotTurn`` (WP_PIVOT_ANGLE) does.

Why. The rule base trades the target's direction against the obstacles it sees: with the target
behind and a wall's end in a front diagonal it turns away from the wall, the long way round, and
once turned, the wall in the diagonal on the target's side keeps it from turning back. In the
``walls`` benchmark the rover came to the opening in the second wall with the planner's path
through it and drove 6 m along the wall away from it, its front-left beam on the wall beside the
opening (docs/perception.md). A turn in place moves no part of the rover farther out than the
circle through its corners, which the rangefinders (on the footprint's edge) watch.

Pure: no clock, no I/O. ``step`` is given the direction of the target (``bearing - heading``,
ENU, radians, positive = left), the obstacle memory's ranges by MAV_SENSOR_ORIENTATION and whether
something else holds the rover; it returns a yaw rate (rad/s, CCW) while pivoting, else None.

- Starts when ``|direction| > angle_deg``, every range is beyond ``clear_m`` and the ranges of the
  beams within ``open_half_deg`` of the target's direction are beyond ``open_m`` (pivoting to face
  a wall would hand the rule base a rover that turns away again), nothing holds the rover.
- Turns at ``omega = clip(heading_gain * direction, +-rate_dps)``, the way it started while the
  target is more than ``LOCK_RELEASE_DEG`` off (the shorter way flips near 180 degrees as the
  heading estimate wobbles; ArduPilot locks the direction the same way).
- Ends within ``accuracy_deg`` of the target's direction (ArduPilot: 5 degrees), when a range
  falls to ``clear_m``, when something holds the rover, or after ``timeout_s``; the next may start
  ``rest_s`` later (the rule base drives meanwhile: no flapping between the two). After a timeout
  (a rover that cannot turn: stuck against something) the next waits until the rover has moved
  ``retry_after_m``: meanwhile the rule base drives and the stuck failsafe, which a turn in place
  never trips (it asks for no speed), sees it stuck.
"""

from __future__ import annotations

import math

from rover_ctl.config import PivotParams
from rover_ctl.navigation.proximity import ORIENTATION_RAD

LOCK_RELEASE_DEG = 160.0
"""Beyond this the turn keeps the direction it started in (ArduPilot's AR_PIVOT_DIRECTION_RELEASE_DEG)."""


class Pivot:
    """Turn in place towards a target far off the heading (module docstring)."""

    def __init__(self, params: PivotParams) -> None:
        self.params = params
        self.active = False
        self._sign = 0.0
        self._since_s = 0.0
        self._rest_until_s = -math.inf
        self._stuck_at: tuple[float, float] | None = None

    def reset(self) -> None:
        self.active = False
        self._rest_until_s = -math.inf
        self._stuck_at = None

    def step(self, t_s: float, direction_rad: float, ranges: dict[int, float], held: bool,
             position_en: tuple[float, float]) -> float | None:  # fmt: skip
        """Yaw rate (rad/s, CCW) while pivoting towards ``direction_rad``; None: the rule base
        drives. ``position_en`` (m): where the rover is, for ``retry_after_m``."""
        p = self.params
        off_deg = abs(math.degrees(direction_rad))
        near = any(r <= p.clear_m for r in ranges.values() if r is not None and not math.isnan(r))
        if self.active:
            timed_out = t_s - self._since_s > p.timeout_s
            if held or near or off_deg <= p.accuracy_deg or timed_out:
                self.active, self._rest_until_s = False, t_s + p.rest_s
                self._stuck_at = position_en if timed_out else None
        if not self.active:
            if self._stuck_at is not None and math.dist(position_en, self._stuck_at) >= p.retry_after_m:
                self._stuck_at = None
            if (p.angle_deg <= p.accuracy_deg or held or near or off_deg <= p.angle_deg or t_s < self._rest_until_s
                    or self._stuck_at is not None or not self._open(direction_rad, ranges)):  # fmt: skip
                return None
            self.active, self._sign, self._since_s = True, math.copysign(1.0, direction_rad), t_s
        error = direction_rad
        if off_deg > LOCK_RELEASE_DEG and error * self._sign < 0.0:
            error = self._sign * (math.tau - abs(error))  # the way it started
        rate = math.radians(p.rate_dps)
        return max(-rate, min(rate, p.heading_gain * error))

    def _open(self, direction_rad: float, ranges: dict[int, float]) -> bool:
        """Every beam within ``open_half_deg`` of the target's direction reads beyond ``open_m``."""
        p = self.params
        for orientation, range_m in ranges.items():
            axis = ORIENTATION_RAD.get(orientation % 8)
            if axis is None or range_m is None or math.isnan(range_m) or range_m > p.open_m:
                continue
            if abs(math.degrees(math.remainder(direction_rad - axis, math.tau))) <= p.open_half_deg:
                return False
        return True
