"""Short-term obstacle memory from the rangefinders, after ArduPilot's AP_OADatabase and the
sectors of AP_Proximity.

A rangefinder is a narrow beam. As the rover turns, an obstacle it saw a moment ago falls into the
gap between beams (a 15 degree front beam covers +-7.5 deg; the 45 degree beams start at 37.5) and
a memoryless navigator, seeing "nothing in range", drives on into it. So every echo is kept as a
point in the local ENU frame for ``memory_s``, and the range handed to the navigator for each
sensor is the nearer of its latest reading and the nearest remembered point inside that sensor's
sector (``sector_half_deg`` either side of its axis), measured from the sensor.

Sensor positions are taken on the footprint's edge (front/back at half the length, sides at half
the width, diagonals at the corners), which is where small rovers mount them.

**Edges** (``edge_sectors``). The front and back sensors answer for their whole edge, the way the
rover meets an obstacle: a remembered point counts for the front when it lies ahead of the front
edge and within ``sector_half_deg`` of the edge's nearer end, i.e. in the cone from the sensor
widened by the footprint's width; a point inside the sensor's own cone keeps its distance from the
sensor, one in the widened part gets its distance from the edge (``hypot(ahead, beyond the
edge's end)``). The widened sector's sides run from the corners at ``sector_half_deg``, where the
diagonal sensors' sectors begin, so with the default 22.5 degrees the front, the diagonals and the
sides still tile the circle. Without it, an echo 0.15 m ahead of the bumper and 0.1 m to one side
lies in no sector at all (the front cone is +-0.06 m wide there): SITL scattered world 17, where
a rover that had stopped for such an echo turned 9 degrees, read every sector clear and drove into
the obstacle. The sides keep their cones: what brushes a flank is the side guard's
(``rover_ctl.navigation.side_guard``).

**Prediction** (``horizon_s`` > 0). Every echo then also goes to the obstacle tracker
(``rover_ctl.navigation.tracks``). For each confirmed *moving* track the remembered echoes of
that track (its trail: where it was) are dropped and its predicted path ``p + v tau`` for
``tau`` in ``[0, horizon_s]``, sampled every ``prediction_step_s``, stands in for it. A sensor's
range is then the closest approach of that path inside its sector: the nearest the obstacle will
come within the horizon, measured from where the rover is now. Only the obstacle's own motion is
predicted, not the rover's: the rule base was tuned for the rover's motion among static obstacles,
and a static world (no moving track) gives exactly the ranges it gave without prediction. So a
pedestrian about to cross ahead reads as an obstacle ahead before it gets there (the rover yields),
one walking away or clear of the rover's sectors reads no nearer than its echo, and the rover may
pass behind a crossing obstacle, where its trail would otherwise still read as blocked.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from rover_ctl.config import ProximityParams
from rover_ctl.navigation.tracks import ObstacleTracker

ORIENTATION_RAD = {o: -math.radians(45.0 * o) for o in range(8)}
"""MAV_SENSOR_ORIENTATION yaw steps (45 deg clockwise each) as body angles (counter-clockwise positive)."""
_EDGE = {o: (float(np.sign(round(math.cos(b), 6))), float(np.sign(round(math.sin(b), 6)))) for o, b in ORIENTATION_RAD.items()}
"""Per orientation, which edge of the footprint the sensor sits on: (forward, left) signs."""


class ObstacleMemory:
    """Echoes remembered in ENU; ``ranges`` folds them into per-sensor ranges."""

    def __init__(
        self,
        params: ProximityParams,
        footprint_length_m: float | Callable[[], float],
        footprint_width_m: float | Callable[[], float],
        tracking: Callable[[], bool] = lambda: False,
    ) -> None:
        """``params`` is read at every call; the footprint may be functions giving the value in force.
        Echoes go to the tracker while prediction is on or ``tracking()`` says another user needs
        the tracks (yielding, ``rover_ctl.navigation.yielding``)."""
        self.params = params
        self._length_m = footprint_length_m if callable(footprint_length_m) else (lambda: footprint_length_m)
        self._width_m = footprint_width_m if callable(footprint_width_m) else (lambda: footprint_width_m)
        self._points = np.empty((0, 4))  # rows: time_s, east_m, north_m, track ident
        self._added: list[tuple[float, float, float, int]] = []  # rows for _points, joined once per ``ranges``
        self.tracker = ObstacleTracker(params)
        self._tracking = tracking

    def _sensor_poses(self, orientations, east_m: float, north_m: float, heading_rad: float) -> list[tuple[float, float, float]]:
        """(east_m, north_m, axis_rad) in ENU of each sensor, on the footprint's edge."""
        half_length, half_width = self._length_m() / 2.0, self._width_m() / 2.0
        c, s = math.cos(heading_rad), math.sin(heading_rad)
        poses = []
        for orientation in orientations:
            forward_sign, left_sign = _EDGE[orientation % 8]
            forward, left = half_length * forward_sign, half_width * left_sign
            poses.append((east_m + forward * c - left * s, north_m + forward * s + left * c, heading_rad + ORIENTATION_RAD[orientation % 8]))
        return poses

    def sensor_pose(self, orientation: int, east_m: float, north_m: float, heading_rad: float) -> tuple[float, float, float]:
        """(east_m, north_m, axis_rad) in ENU of the sensor of ``orientation`` on a rover at this pose."""
        return self._sensor_poses((orientation,), east_m, north_m, heading_rad)[0]

    def add(self, time_s: float, east_m: float, north_m: float, heading_rad: float, orientation: int, range_m: float) -> int:
        """Remember the echo of one reading taken with the rover at this pose (inf: no echo);
        returns the ident of the track the echo joined (0: none, or not tracking)."""
        if not math.isfinite(range_m) or range_m < 0.0:
            return 0
        e, n, axis = self.sensor_pose(orientation, east_m, north_m, heading_rad)
        east, north = e + range_m * math.cos(axis), n + range_m * math.sin(axis)
        tracked = self.params.horizon_s > 0.0 or self._tracking()
        ident = self.tracker.add(time_s, east, north, axis, range_m) if tracked else 0  # no cost when off
        self._added.append((time_s, east, north, ident))
        return ident

    def ranges(self, time_s: float, east_m: float, north_m: float, heading_rad: float, latest_m: dict[int, float],
               speed_mps: float = 0.0) -> dict[int, float]:  # fmt: skip
        """``latest_m`` with each sensor's range shortened to the nearest remembered echo in its
        sector (and predicted path, see the module docstring; ``speed_mps`` is the rover's
        forward speed, which tells echoes sliding along a surface beside it from moving obstacles)."""
        if self._added:
            self._points = np.vstack((self._points, self._added))
            self._added = []
        self._points = self._points.compress(self._points[:, 0] > time_s - self.params.memory_s, axis=0)
        points = self._points[:, 1:3]
        if self.params.horizon_s > 0.0:
            points = self._predicted(time_s, (speed_mps * math.cos(heading_rad), speed_mps * math.sin(heading_rad)))
        if not len(points) or not latest_m:
            return dict(latest_m)
        # Every sensor at once, a row each: numpy's cost is per call, and the points are few.
        p = self.params
        half_rad = math.radians(p.sector_half_deg)
        edge_m = self._width_m() / 2.0 if p.edge_sectors and half_rad < math.pi / 2.0 else 0.0
        # math's cos and sin: numpy's vectorised ones may round differently. A half edge for the
        # sensors on the front and back edges (no sideways offset), 0 for the others.
        sensors = [(e, n, math.cos(axis), math.sin(axis), edge_m if _EDGE[orientation % 8][1] == 0.0 else 0.0)
                   for orientation, (e, n, axis) in zip(latest_m, self._sensor_poses(latest_m, east_m, north_m, heading_rad))]  # fmt: skip
        e, n, cos_axis, sin_axis, half_edge = np.array(sensors).T[:, :, None]
        d_east, d_north = points[:, 0] - e, points[:, 1] - n
        distance = np.hypot(d_east, d_north)
        along = d_east * cos_axis + d_north * sin_axis
        inside = along >= math.cos(half_rad) * distance  # within sector_half_deg of the axis
        seen_m = np.where(inside, distance, math.inf)
        if edge_m > 0.0:  # the front and back edges' whole width (module docstring)
            beside = np.abs(d_north * cos_axis - d_east * sin_axis) - half_edge  # across the axis, beyond the edge's end
            ahead = (along > 0.0) & (beside <= along * math.tan(half_rad))
            seen_m = np.where(inside, seen_m, np.where(ahead, np.hypot(along, np.maximum(beside, 0.0)), math.inf))
        nearest = seen_m.min(axis=1).tolist()
        out = {}
        for (orientation, range_m), nearest_m in zip(latest_m.items(), nearest):
            out[orientation] = min(range_m, nearest_m) if range_m is not None and not math.isnan(range_m) else range_m
        return out

    def _predicted(self, time_s: float, rover_velocity_en: tuple[float, float]) -> np.ndarray:
        """(east, north) rows: remembered echoes, those of moving tracks replaced by their
        predicted paths over the horizon (see the module docstring)."""
        moving = self.tracker.moving(time_s, rover_velocity_en)
        if not moving:
            return self._points[:, 1:3]
        p = self.params
        keep = ~np.isin(self._points[:, 3], [t.ident for t in moving])
        tau = np.arange(0.0, p.horizon_s + 1e-9, p.prediction_step_s)
        paths = [np.column_stack((e + t.v_east_mps * tau, n + t.v_north_mps * tau))
                 for t in moving for e, n in [t.position_at(time_s)]]  # fmt: skip
        return np.vstack([self._points[keep, 1:3], *paths])
