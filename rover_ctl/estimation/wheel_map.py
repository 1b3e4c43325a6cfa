"""Is the wheel map right? The turn rate the wheels report against the gyro's, while turning.

Pure. ``WheelMapCheck`` takes WheelDistance and Attitude readings (``rover_ctl.estimation.readings``)
and, once the rover has turned enough, says whether the wheels' turn rate ((right - left) / track,
counter-clockwise) agrees with the gyro's (ATTITUDE yaw rate, clockwise, so negated). Left and
right swapped (ArduPilot's simulated encoder instance 0 is the RIGHT wheel) or both signs flipped
give the opposite turn: ``verdict`` is then "reversed" and the daemon refuses to drive on it (the
wheel-speed loop would steer the wrong way). One sign flipped reads the turn as speed and shows
up as "inconclusive" at worst.
"""

from __future__ import annotations

import math

from rover_ctl.estimation.readings import Attitude, WheelDistance

MIN_TURN_RADPS = 0.3
"""Gyro turn rates below this say nothing about the map (noise, straight driving)."""
EVIDENCE_RAD = 1.0
"""Turned this much (summed over turning samples) before a verdict."""
AGREEMENT = 0.5
"""Verdict when the wheel turn agrees with the gyro's by more than this fraction either way."""


class WheelMapCheck:
    def __init__(self, track_m: float) -> None:
        self.track_m = track_m
        self._last: WheelDistance | None = None
        self._gyro_ccw_radps: float | None = None
        self._turned_rad = 0.0  # sum of |gyro| * dt while turning
        self._agree_rad = 0.0  # sum of sign-agreement-weighted wheel turn
        self.verdict: str | None = None
        """None while undecided, then "ok" or "reversed" (or "inconclusive")."""

    def on_attitude(self, reading: Attitude) -> None:
        self._gyro_ccw_radps = -reading.yaw_rate_radps

    def on_wheels(self, reading: WheelDistance) -> None:
        last, self._last = self._last, reading
        gyro = self._gyro_ccw_radps
        if self.verdict is not None or last is None or gyro is None or abs(gyro) < MIN_TURN_RADPS:
            return
        dt_s = reading.time_s - last.time_s
        if not 0.0 < dt_s < 1.0:
            return
        wheel_turn_rad = ((reading.right_m - last.right_m) - (reading.left_m - last.left_m)) / self.track_m
        self._turned_rad += abs(gyro) * dt_s
        self._agree_rad += wheel_turn_rad * math.copysign(1.0, gyro)
        if self._turned_rad >= EVIDENCE_RAD:
            ratio = self._agree_rad / self._turned_rad
            self.verdict = "ok" if ratio > AGREEMENT else "reversed" if ratio < -AGREEMENT else "inconclusive"
