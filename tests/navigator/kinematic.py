"""A pure, fast closed-loop kinematic rover for navigator tests and the quick navigation bench.

Unicycle (differential drive) with wheel-speed limits and a first-order lag on each wheel, circle
and polygon obstacles, rangefinders ray-cast from the footprint edges like the emulator's
(front, back, left, right, front-left, front-right; 4 m max, 0.2 m min, 15 degree beam of 3 rays).
No noise: it tests the rule base's geometry, not the estimator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

HALF_LENGTH_M, HALF_WIDTH_M = 0.225, 0.20
"""Footprint of the paper's robot (as RobotParams)."""
BODY_RADIUS_M = 0.25
"""Collision disc around the axle midpoint (the footprint's inscribed-ish circle plus margin)."""
TRACK_M, WHEEL_RADIUS_M = 0.32, 0.07
WHEEL_LAG_S = 0.15
"""First-order time constant of each wheel's speed (motor + PI loop)."""
RANGE_MAX_M, RANGE_MIN_M = 4.0, 0.2
BEAM_HALF_RAD = math.radians(7.5)
MOUNTS = {  # orientation: (forward_m, left_m, beam bearing CCW from the nose)
    0: (HALF_LENGTH_M, 0.0, 0.0),
    4: (-HALF_LENGTH_M, 0.0, math.pi),
    6: (0.0, HALF_WIDTH_M, math.pi / 2),
    2: (0.0, -HALF_WIDTH_M, -math.pi / 2),
    7: (HALF_LENGTH_M, HALF_WIDTH_M, math.pi / 4),
    1: (HALF_LENGTH_M, -HALF_WIDTH_M, -math.pi / 4),
}
PAPER_ORIENTATIONS = (0, 2, 4, 6)


@dataclass(frozen=True)
class Circle:
    east_m: float
    north_m: float
    radius_m: float

    def ray(self, ox: float, oy: float, dx: float, dy: float) -> float:
        fx, fy = ox - self.east_m, oy - self.north_m
        b = fx * dx + fy * dy
        c = fx * fx + fy * fy - self.radius_m**2
        disc = b * b - c
        if disc < 0.0:
            return math.inf
        root = math.sqrt(disc)
        for t in (-b - root, -b + root):
            if t >= 0.0:
                return t
        return math.inf

    def clearance(self, x: float, y: float) -> float:
        return math.hypot(x - self.east_m, y - self.north_m) - self.radius_m


@dataclass(frozen=True)
class Polygon:
    vertices: tuple[tuple[float, float], ...]

    def _edges(self):
        v = self.vertices
        return zip(v, v[1:] + v[:1])

    def ray(self, ox: float, oy: float, dx: float, dy: float) -> float:
        best = math.inf
        for (ax, ay), (bx, by) in self._edges():
            ex, ey = bx - ax, by - ay
            denom = dx * ey - dy * ex
            if abs(denom) < 1e-12:
                continue
            t = ((ax - ox) * ey - (ay - oy) * ex) / denom
            u = ((ax - ox) * dy - (ay - oy) * dx) / denom
            if t >= 0.0 and 0.0 <= u <= 1.0:
                best = min(best, t)
        return best

    def clearance(self, x: float, y: float) -> float:
        inside, best = False, math.inf
        for (ax, ay), (bx, by) in self._edges():
            ex, ey = bx - ax, by - ay
            t = max(0.0, min(1.0, ((x - ax) * ex + (y - ay) * ey) / (ex * ex + ey * ey)))
            best = min(best, math.hypot(x - ax - t * ex, y - ay - t * ey))
            if (ay > y) != (by > y) and x < ax + (y - ay) * ex / ey:
                inside = not inside
        return -best if inside else best


def box(east_min: float, north_min: float, east_max: float, north_max: float) -> Polygon:
    return Polygon(((east_min, north_min), (east_max, north_min), (east_max, north_max), (east_min, north_max)))


@dataclass
class Run:
    """A closed-loop run: the trace and how it ended."""

    path: list[tuple[float, float]] = field(default_factory=list)
    headings_rad: list[float] = field(default_factory=list)
    turn_rpm: list[float] = field(default_factory=list)
    """right minus left wheel setpoint per step (positive = turning left)."""
    reached: bool = False
    collided: bool = False
    time_s: float = 0.0
    min_clearance_m: float = math.inf

    @property
    def length_m(self) -> float:
        return sum(math.dist(p, q) for p, q in zip(self.path, self.path[1:]))


def ranges(obstacles, x: float, y: float, heading: float, orientations) -> dict[int, float]:
    """Range per orientation as the emulator reports it (inf = no echo within RANGE_MAX_M)."""
    c, s = math.cos(heading), math.sin(heading)
    result = {}
    for orientation in orientations:
        forward, left, bearing = MOUNTS[orientation]
        ox, oy = x + c * forward - s * left, y + s * forward + c * left
        nearest = math.inf
        for offset in (-BEAM_HALF_RAD, 0.0, BEAM_HALF_RAD):
            angle = heading + bearing + offset
            dx, dy = math.cos(angle), math.sin(angle)
            for obstacle in obstacles:
                nearest = min(nearest, obstacle.ray(ox, oy, dx, dy))
        result[orientation] = max(nearest, RANGE_MIN_M) if nearest <= RANGE_MAX_M else math.inf
    return result


def drive(
    navigator,
    target: tuple[float, float],
    obstacles=(),
    start: tuple[float, float, float] = (0.0, 0.0, 0.0),
    orientations=tuple(MOUNTS),
    max_wheel_rpm: float = 200.0,
    accept_m: float = 1.0,
    time_limit_s: float = 60.0,
    dt_s: float = 0.05,
) -> Run:
    """Drive until within ``accept_m`` of the target, a collision, or the time limit."""
    x, y, heading = start
    wheel_left = wheel_right = 0.0  # rad/s
    alpha = dt_s / (WHEEL_LAG_S + dt_s)
    limit = max_wheel_rpm * math.tau / 60.0
    run = Run()
    steps = int(time_limit_s / dt_s)
    for step in range(steps):
        run.path.append((x, y))
        run.headings_rad.append(heading)
        clearance = min((o.clearance(x, y) for o in obstacles), default=math.inf) - BODY_RADIUS_M
        run.min_clearance_m = min(run.min_clearance_m, clearance)
        if clearance < 0.0:
            run.collided = True
            break
        if math.dist((x, y), target) <= accept_m:
            run.reached = True
            break
        out = navigator.step(x, y, heading, target[0], target[1], ranges(obstacles, x, y, heading, orientations), None)
        run.turn_rpm.append(out.right_rpm - out.left_rpm)
        set_left = max(-limit, min(limit, out.left_rpm * math.tau / 60.0))
        set_right = max(-limit, min(limit, out.right_rpm * math.tau / 60.0))
        wheel_left += alpha * (set_left - wheel_left)
        wheel_right += alpha * (set_right - wheel_right)
        speed = WHEEL_RADIUS_M * (wheel_left + wheel_right) / 2.0
        yaw_rate = WHEEL_RADIUS_M * (wheel_right - wheel_left) / TRACK_M
        x += speed * math.cos(heading + yaw_rate * dt_s / 2.0) * dt_s
        y += speed * math.sin(heading + yaw_rate * dt_s / 2.0) * dt_s
        heading = math.remainder(heading + yaw_rate * dt_s, math.tau)
        run.time_s = (step + 1) * dt_s
    return run
