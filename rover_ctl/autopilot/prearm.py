"""Pre-arm checks: every reason the rover must not arm now, as ArduPilot's "PreArm: ..." lines.

Pure: the autopilot gathers ``ArmingInputs`` from what it knows (the last pose, rangefinder ages,
the fence, the mission) and ``failures`` returns one short text per failed check, in a fixed
order, or an empty list. Force-arming (ARM_FORCE_MAGIC) skips them all, as in ArduPilot.

The checks:
- no position: no GPS home yet, or the estimator has not initialised;
- estimator unhealthy (position or heading uncertainty beyond its health limits);
- no GPS fix fused within the estimator's ``gps_timeout_s`` (a dropout or a glitch it rejects):
  armed now, the rover would start on dead reckoning;
- a stored fence the planner cannot use (invalid geometry), or one too complex for it at the
  current PLN_CIRCLE_SEGS (more graph nodes than ``MAX_PLANNER_NODES``: uploads are checked at
  the default, and a raised parameter would leave the rover holding with no path);
- a rangefinder the rule base reads has not reported within ``rangefinder_timeout_s``;
- the rover is outside an inclusion fence or inside an exclusion zone;
- the mission's first waypoint, or the fence's nearest edge, is farther from home than
  ``AutopilotParams.arming_max_distance_m``: a plan made for another place;
- the vehicle's autopilot is configured against the daemon's RC overrides: an ArduPilot
  PILOT_STEER_TYPE other than 3 reverses the steering whenever its throttle output is negative
  (``rover_ctl.vocabulary.PILOT_STEER_TYPE``). Checked once the vehicle has answered (only an
  ArduPilot vehicle is asked).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

from shapely.geometry import LinearRing, Point, Polygon

from rover_ctl.mission.validate import MAX_PLANNER_NODES
from rover_ctl.navigation.planner import Fence
from rover_ctl.vocabulary import PILOT_STEER_TYPE, STEER_TWO_PADDLES, STEER_UNCHANGED_WHEN_REVERSING

EN = tuple[float, float]

ORIENTATION_NAMES = {0: "front", 1: "front-right", 2: "right", 3: "back-right", 4: "back", 5: "back-left", 6: "left", 7: "front-left"}
"""MAV_SENSOR_ORIENTATION yaw values -> names for the refusal texts."""


@dataclass(frozen=True)
class ArmingInputs:
    position_en: EN | None
    """The estimated position, None before the estimator has one."""
    estimator_healthy: bool
    gps_ok: bool = True
    """The estimator fused a GPS fix within its ``gps_timeout_s``."""
    range_ages_s: Mapping[int, float] = field(default_factory=dict)
    """Age of the last reading per rangefinder orientation (absent: never heard)."""
    needed_orientations: Sequence[int] = ()
    """Orientations the rule base reads."""
    rangefinder_timeout_s: float = 0.5
    fence: Fence = field(default_factory=Fence)
    fence_error: str | None = None
    """Why the stored fence could not be used, if it could not."""
    first_waypoint_en: EN | None = None
    max_distance_m: float = math.inf
    sensor_rates_hz: Mapping[str, float] = field(default_factory=dict)
    """Odometry messages measured on the vehicle link (ATTITUDE, WHEEL_DISTANCE)."""
    min_sensor_rate_hz: float = 0.0
    vehicle_params: Mapping[str, float] = field(default_factory=dict)
    """The vehicle autopilot's parameters read at connect (absent: not answered, not checked)."""
    planner_nodes: int = 0
    """Graph nodes the fence and known obstacles make for the planner (``Planner.node_count``)."""
    max_planner_nodes: int = MAX_PLANNER_NODES


def failures(inputs: ArmingInputs) -> list[str]:
    """The failed checks (texts without the "PreArm: " prefix), empty when the rover may arm."""
    found: list[str] = []
    if inputs.position_en is None:
        found.append("no position (waiting for GPS)")
    elif not inputs.estimator_healthy:
        found.append("estimator unhealthy")
    if inputs.position_en is not None and not inputs.gps_ok:
        found.append("no recent GPS fix")
    if inputs.fence_error:
        found.append(f"fence unusable: {inputs.fence_error}")
    if inputs.planner_nodes > inputs.max_planner_nodes:
        found.append(f"fence too complex to plan: {inputs.planner_nodes} nodes, max {inputs.max_planner_nodes} (PLN_CIRCLE_SEGS)")
    silent = [o for o in inputs.needed_orientations if inputs.range_ages_s.get(o, math.inf) > inputs.rangefinder_timeout_s]
    if silent:
        found.append("rangefinder missing: " + ", ".join(ORIENTATION_NAMES.get(o, str(o)) for o in silent))
    slow = [f"{name} {hz:.1f} Hz" for name, hz in sorted(inputs.sensor_rates_hz.items()) if hz < inputs.min_sensor_rate_hz]
    if slow:
        found.append(f"link too slow: {', '.join(slow)} < {inputs.min_sensor_rate_hz:g} Hz")
    if inputs.position_en is not None:
        where = fence_violation(inputs.fence, inputs.position_en)
        if where:
            found.append(where)
    if inputs.first_waypoint_en is not None:
        distance = math.hypot(*inputs.first_waypoint_en)
        if distance > inputs.max_distance_m:
            found.append(f"first waypoint {distance:.0f} m from home")
    distance = fence_distance_m(inputs.fence, (0.0, 0.0))
    if distance is not None and distance > inputs.max_distance_m:
        found.append(f"fence {distance:.0f} m from home")
    for name, value in sorted(inputs.vehicle_params.items()):
        problem = vehicle_param_problem(name, value)
        if problem is not None:
            found.append(f"vehicle {problem}")
    return found


def vehicle_param_problem(name: str, value: float) -> str | None:
    """Why the vehicle's parameter ``name`` at ``value`` keeps the daemon from driving it, or None."""
    if name == PILOT_STEER_TYPE and value != STEER_UNCHANGED_WHEN_REVERSING:
        how = "reads steering and throttle as two paddles" if value == STEER_TWO_PADDLES else "reverses steering in reverse"
        return f"{name} {value:g} {how}: set {STEER_UNCHANGED_WHEN_REVERSING}"
    return None


def fence_violation(fence: Fence, point_en: EN) -> str | None:
    """Why ``point_en`` breaches the fence (outside an inclusion, inside an exclusion), or None."""
    p = Point(point_en)
    if not all(Polygon(poly).covers(p) for poly in fence.inclusion_polygons) or not all(
        math.dist(point_en, c.center_en) <= c.radius_m for c in fence.inclusion_circles
    ):
        return "outside the inclusion fence"
    if any(Polygon(poly).contains(p) for poly in fence.exclusion_polygons) or any(
        math.dist(point_en, c.center_en) < c.radius_m for c in fence.exclusion_circles
    ):
        return "inside a fence exclusion zone"
    return None


def fence_distance_m(fence: Fence, point_en: EN) -> float | None:
    """Distance from ``point_en`` to the nearest fence boundary; None without a fence."""
    p = Point(point_en)
    distances = [LinearRing(poly).distance(p) for poly in (*fence.inclusion_polygons, *fence.exclusion_polygons)]
    distances += [abs(math.dist(point_en, c.center_en) - c.radius_m) for c in (*fence.inclusion_circles, *fence.exclusion_circles)]
    return min(distances) if distances else None
