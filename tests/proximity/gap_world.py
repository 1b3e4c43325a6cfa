"""A kinematic rover beside a wall with a narrow opening, for the passage's pure tests.

The wall runs along x at ``wall_y`` (0.3 m thick, from x = -6 to 6) with an opening of
``gap_m`` centred on ``gap_x``. Rangefinders are cones of 5 rays over 15 degrees, as the
emulator's (sitl/params.py), reporting the nearest hit up to 4 m. Until the passage drives, a
stand-in for the rule base drives along the wall at ``cruise_mps``; once through, it heads for
the goal. The passage gets what the autopilot gives it: wheel distances, the gyro's yaw rate
(NED), readings, and the pose (here the truth, or the truth plus a drifting offset). With
``yaw_lag_s`` the rover turns at its commanded yaw rate only after a first-order lag, so that it
coasts on after a turn in place is stopped, as the emulator's skid-steer rover does. With
``blocking`` a step that would bring the footprint into contact with a wall, or deeper into it,
does not happen (the rover and its wheels stay put, as the emulator puts a colliding rover back
and stops its wheels); each new contact counts in ``Run.contacts``."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np
from shapely.geometry import Point, Polygon, box

from rover_ctl.config import PassageParams, RobotParams
from rover_ctl.navigation.gaps import Passage

LENGTH, WIDTH, TRACK = (
    RobotParams.footprint_length_m,
    RobotParams.footprint_width_m,
    RobotParams.track_m,
)
SENSORS = {0: (LENGTH / 2, 0.0, 0.0), 1: (LENGTH / 2, -WIDTH / 2, -math.pi / 4), 2: (0.0, -WIDTH / 2, -math.pi / 2),
           6: (0.0, WIDTH / 2, math.pi / 2), 7: (LENGTH / 2, WIDTH / 2, math.pi / 4)}  # fmt: skip
"""orientation: (forward, left, body angle) as on the default rover."""
RAYS = np.radians(np.linspace(-7.5, 7.5, 5))
MAX_M = 4.0


@dataclass
class Run:
    path: list[tuple[float, float, float]] = field(default_factory=list)
    trace: list[tuple] = field(default_factory=list)
    events: list[str] = field(default_factory=list)
    min_clearance_m: float = math.inf
    """Least distance from the footprint to an obstacle while the passage drove."""
    contacts: int = 0
    """Steps the passage drove into contact that began one (``blocking``)."""
    blocked_steps: int = 0
    """Steps the passage drove into a wall (``blocking``): pushing against it."""

    def crossing_x(self, wall_y: float) -> float | None:
        """Where the rover's centre crossed the wall's near face."""
        for (x0, y0, _), (x1, y1, _) in itertools.pairwise(self.path):
            if y0 < wall_y <= y1:
                return x0 + (x1 - x0) * (wall_y - y0) / (y1 - y0)
        return None


def _walls(gap_x: float, gap_m: float, wall_y: float, behind_m: float | None) -> list[tuple[float, float, float, float]]:
    boxes = [
        (-6.0, wall_y, gap_x - gap_m / 2, wall_y + 0.3),
        (gap_x + gap_m / 2, wall_y, 6.0, wall_y + 0.3),
    ]
    if behind_m is not None:  # something beyond the opening, on its centre line
        boxes.append((gap_x - 0.3, wall_y + behind_m, gap_x + 0.3, wall_y + behind_m + 0.3))
    return boxes


def _ray(ox: float, oy: float, angle: float, boxes) -> float:
    dx, dy = math.cos(angle), math.sin(angle)
    best = MAX_M + 1.0
    for x0, y0, x1, y1 in boxes:
        lo, hi = 0.0, best
        for o, d, a, b in ((ox, dx, x0, x1), (oy, dy, y0, y1)):
            if abs(d) < 1e-12:
                if not a <= o <= b:
                    lo, hi = 1.0, 0.0
                continue
            t0, t1 = sorted(((a - o) / d, (b - o) / d))
            lo, hi = max(lo, t0), min(hi, t1)
        if lo <= hi:
            best = lo
    return best


def _footprint(x: float, y: float, h: float) -> Polygon:
    c, s = math.cos(h), math.sin(h)
    return Polygon([(x + a * c - b * s, y + a * s + b * c) for a, b in ((LENGTH / 2, WIDTH / 2), (LENGTH / 2, -WIDTH / 2),
                                                                         (-LENGTH / 2, -WIDTH / 2), (-LENGTH / 2, WIDTH / 2))])  # fmt: skip


def drive_past_gap(params: PassageParams, *, gap_x: float = 1.0, gap_m: float = 0.6, wall_y: float = 3.0,
                   start: tuple[float, float, float] = (-2.0, 1.9, 0.0), cruise_mps: float = 0.5, t0_s: float = 0.0,
                   duration_s: float = 40.0, behind_m: float | None = None, passage: Passage | None = None,
                   pose_drift_mps: float = 0.0, seed: int = 0, yaw_lag_s: float = 0.0,
                   blocking: bool = False, side_lead_m: float = 0.0, goal: tuple[float, float] | None = None,
                   map_holds_walls: bool | None = None) -> tuple[Run, Passage]:  # fmt: skip
    """Drive the scene; ``pose_drift_mps``: the pose given as 'fused' drifts from the truth this
    fast; ``side_lead_m``: the side rangefinders read from this far ahead of where they are (as
    if the pose they are placed with lagged the reading), so that the gap a sweep finds is off
    its true place along the wall by about as much; ``goal``: 10 m beyond the opening unless given;
    ``map_holds_walls``: the persistent-obstacle map the passage is given holds the walls (True),
    nothing (False), or there is none (None)."""
    rng, drift_rng = np.random.default_rng(seed), np.random.default_rng(seed + 1)
    passage = passage or Passage(params, lambda: LENGTH, lambda: WIDTH)
    boxes = _walls(gap_x, gap_m, wall_y, behind_m)
    shapes = [box(*b) for b in boxes]
    x, y, h = start
    mapped = None
    if map_holds_walls is not None:  # the odometry's frame starts at the start pose
        def mapped(east_m, north_m, distance_m):
            c, s_ = math.cos(start[2]), math.sin(start[2])
            world = Point(start[0] + c * east_m - s_ * north_m, start[1] + s_ * east_m + c * north_m)
            return map_holds_walls and any(shape.distance(world) <= distance_m for shape in shapes)
    left = right = 0.0
    goal = goal or (gap_x, wall_y + 10.0)
    run, dt, through = Run(), 0.04, False
    drift = np.zeros(2)
    yaw_rate = 0.0
    touching = False
    for k in range(int(duration_s / dt)):
        t = t0_s + k * dt
        passage.odometry.on_wheels(left, right)
        for o, (fwd, lat, body) in SENSORS.items():
            fwd = fwd + (side_lead_m if o in (2, 6) else 0.0)
            sx, sy = (
                x + fwd * math.cos(h) - lat * math.sin(h),
                y + fwd * math.sin(h) + lat * math.cos(h),
            )
            r = min(_ray(sx, sy, h + body + a, boxes) for a in RAYS) + rng.normal(0.0, 0.01)
            passage.on_range(t, o, round(r, 2) if r <= MAX_M else math.inf)
        drift += drift_rng.normal(0.0, 1.0, 2) * pose_drift_mps * dt * 5
        drive = passage.step(t, (x + drift[0], y + drift[1]), h, (goal[0] + 0.0, goal[1]), (), mapped)
        if drive is None:
            through = through or any("through" in e for e in passage.events)
            target = math.atan2(goal[1] - y, goal[0] - x) if through else 0.0
            v, w = (
                cruise_mps,
                max(-1.0, min(1.0, 2.0 * math.remainder(target - h, math.tau))),
            )
        else:
            v, w = drive.speed_mps, drive.yaw_rate_radps
            run.trace.append((drive.state, round(v, 3), round(w, 3), len(run.path)))  # the path's index after this step
        run.events += passage.events
        passage.events.clear()
        yaw_rate = w if yaw_lag_s <= 0.0 else yaw_rate + (w - yaw_rate) * min(1.0, dt / yaw_lag_s)
        w = yaw_rate
        nx, ny, nh = x + v * math.cos(h) * dt, y + v * math.sin(h) * dt, h + w * dt
        if blocking and drive is not None and any(_footprint(nx, ny, nh).intersection(w_).area > _footprint(x, y, h).intersection(w_).area + 1e-12
                                                  or _footprint(nx, ny, nh).distance(w_) < 1e-9 < _footprint(x, y, h).distance(w_) for w_ in shapes):  # fmt: skip
            run.contacts += not touching
            run.blocked_steps += 1
            touching = True
            passage.odometry.on_gyro(t, 0.0)
            run.path.append((x, y, h))
            continue
        touching = False
        passage.odometry.on_gyro(t, -w)
        x, y, h = nx, ny, nh
        left, right = left + (v - w * TRACK / 2) * dt, right + (v + w * TRACK / 2) * dt
        run.path.append((x, y, h))
        if drive is not None:  # the stand-in driver's own contacts are not the passage's
            body_shape = _footprint(x, y, h)
            run.min_clearance_m = min(run.min_clearance_m, *(body_shape.distance(w_) for w_ in shapes))
        if y > wall_y + 3.0:
            break
    return run, passage
