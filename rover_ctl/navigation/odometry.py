"""Dead reckoning in a frame of its own, and the rigid transform between it and the fused pose's.

Why a second frame. The fused pose (``rover_ctl.estimation``) is where the rover is on the Earth,
and it moves against the ground as GPS fixes come in: 0.1-0.2 m (median, p95 0.4 m) over 5 s in
the emulator, more as the receiver's bias wanders. What the rangefinders saw a few seconds ago,
placed with that pose, is therefore misplaced against what they see now: a wall seen along its
length smears across cells, and a gap found by one beam is not where the rover aims later. The
wheels and the gyro drift slowly instead (1 cm per metre of slip in the emulator) and never jump,
so what the rover saw lately agrees with where it is now to centimetres in this frame, as ROS's
``odom`` frame serves a local costmap while ``map`` carries the global pose.

``Odometry``: distance from the mean of the two wheels' travel, heading from the gyro's yaw rate
(ATTITUDE's yawspeed, NED clockwise), integrated from zero at start-up.

``FrameLink``: the transform that puts the odometry's pose onto the fused pose at one instant,

    p_odometry = o + R(psi_o - psi) (p - x)        p = x + R(psi - psi_o) (p_odometry - o)

with ``x, psi`` the fused position and heading, ``o, psi_o`` the odometry's, ``R(a)`` the
rotation by ``a`` counter-clockwise. Taken afresh at each control step, it carries things kept in
the odometry frame to where the fused pose says they are now: their places relative to the rover
are the odometry's, their place on the Earth the pose filter's.

Pure: no clock, no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

EN = tuple[float, float]


class Odometry:
    """Dead reckoning from the wheels and the gyro (module docstring)."""

    def __init__(self) -> None:
        self.east_m = self.north_m = self.heading_rad = 0.0
        self.yaw_rate_radps = 0.0
        """The latest gyro reading (counter-clockwise)."""
        self._wheels: tuple[float, float] | None = None
        self._gyro_s: float | None = None

    def on_wheels(self, left_m: float, right_m: float) -> None:
        if self._wheels is not None:
            step = ((left_m - self._wheels[0]) + (right_m - self._wheels[1])) / 2.0
            if math.isfinite(step):
                self.east_m += step * math.cos(self.heading_rad)
                self.north_m += step * math.sin(self.heading_rad)
        self._wheels = (left_m, right_m)

    def on_gyro(self, time_s: float, yaw_rate_ned_radps: float) -> None:
        if self._gyro_s is not None and 0.0 < time_s - self._gyro_s <= 0.5 and math.isfinite(yaw_rate_ned_radps):
            self.heading_rad = math.remainder(self.heading_rad - yaw_rate_ned_radps * (time_s - self._gyro_s), math.tau)
        if math.isfinite(yaw_rate_ned_radps):
            self.yaw_rate_radps = -yaw_rate_ned_radps
        self._gyro_s = time_s

    @property
    def live(self) -> bool:
        """Both the wheels and the gyro have been heard (without them the frame stands still)."""
        return self._wheels is not None and self._gyro_s is not None

    @property
    def position_en(self) -> EN:
        return (self.east_m, self.north_m)

    def link(self, pose_en: EN, pose_heading_rad: float) -> FrameLink:
        """The transform between this frame and the fused pose's, now (module docstring)."""
        return FrameLink(pose_en, pose_heading_rad, self.position_en, self.heading_rad)


@dataclass(frozen=True)
class FrameLink:
    """The odometry frame laid onto the fused pose's at one instant (module docstring)."""

    pose_en: EN
    pose_heading_rad: float
    odometry_en: EN
    odometry_heading_rad: float

    @property
    def turn_rad(self) -> float:
        """Angle from the fused pose's frame to the odometry's (counter-clockwise)."""
        return self.odometry_heading_rad - self.pose_heading_rad

    def to_odometry(self, point_en: EN) -> EN:
        """A point given in the fused pose's frame, in the odometry's."""
        c, s = math.cos(self.turn_rad), math.sin(self.turn_rad)
        de, dn = point_en[0] - self.pose_en[0], point_en[1] - self.pose_en[1]
        return (self.odometry_en[0] + c * de - s * dn, self.odometry_en[1] + s * de + c * dn)

    def to_pose(self, point_en: EN) -> EN:
        """A point given in the odometry frame, in the fused pose's."""
        c, s = math.cos(self.turn_rad), -math.sin(self.turn_rad)
        de, dn = point_en[0] - self.odometry_en[0], point_en[1] - self.odometry_en[1]
        return (self.pose_en[0] + c * de - s * dn, self.pose_en[1] + s * de + c * dn)
