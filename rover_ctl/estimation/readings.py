"""Typed sensor readings: what the vehicle link decodes from MAVLink and the estimator and
navigator consume. Plain frozen dataclasses, SI units in the names, no I/O.

Angle conventions: readings keep MAVLink's (yaw 0 = north, positive clockwise, as ATTITUDE and
GPS course); the pose (``rover_ctl.estimation.estimator.Pose``) is in the local ENU frame (heading 0 = east,
positive counter-clockwise). ``time_s`` is always vehicle time (time_boot_ms or time_usec), never
the wall clock, so a run is the same at any speed-up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class GpsFix:
    """GPS_RAW_INT, decoded. Unknown fields (65535 / UINT16_MAX) become NaN."""

    time_s: float
    lat_deg: float
    lon_deg: float
    alt_m: float
    fix_type: int
    """GPS_FIX_TYPE: 0-1 no fix, 2 2D, 3 3D, ..."""
    eph_m: float
    """Horizontal dilution x ~1 m as ArduPilot reports it (eph/100); used as the fix's 1-sigma."""
    speed_mps: float
    course_deg: float
    satellites: int

    @property
    def has_fix(self) -> bool:
        return self.fix_type >= 2 and not (math.isnan(self.lat_deg) or math.isnan(self.lon_deg))


@dataclass(frozen=True)
class Attitude:
    """ATTITUDE: compass yaw and gyro yaw rate (NED: 0 north, clockwise positive)."""

    time_s: float
    yaw_rad: float
    yaw_rate_radps: float


@dataclass(frozen=True)
class WheelDistance:
    """WHEEL_DISTANCE with count 2: cumulative distance rolled by each wheel, metres."""

    time_s: float
    left_m: float
    right_m: float


@dataclass(frozen=True)
class RangeReading:
    """DISTANCE_SENSOR, decoded. ``range_m`` is +inf when nothing is in range (a reading above
    max_distance, the capped 65535, or 0 while starting), as ArduPilot's rangefinders report it."""

    time_s: float
    sensor_id: int
    orientation: int
    """MAV_SENSOR_ORIENTATION: 0 front, 1 front-right (45), 2 right, 4 back, 6 left, 7 front-left."""
    range_m: float
    min_range_m: float
    max_range_m: float
