"""A mission at a glance: what ``rover-ctl mission check`` prints.

The route is home, then each NAV_WAYPOINT / NAV_LOITER_TIME position in order, then home again
for NAV_RETURN_TO_LAUNCH; leg lengths are geodesic on the WGS84 ellipsoid (pyproj ``Geod``).
DO_JUMP repeats are not unrolled: the length is one pass through the list. A waypoint at
lat = lon = 0 means "where the rover is" to ArduPilot and adds no leg.

``nominal_duration_s`` is how long that one pass takes driven exactly: each leg at the speed in
force (cruise, or the last DO_CHANGE_SPEED, at most the robot's top speed, as the executor does)
plus the holds (NAV_WAYPOINT and NAV_LOITER_TIME param1, CONDITION_DELAY param1). It is the
lower bound a time budget is scaled from (``rover_ctl.app.sim.time_budget_s``).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

from pyproj import Geod

from rover_ctl.mission.model import NAV_POSITION_COMMANDS, Cmd, Mission
from rover_ctl.mission.validate import command_name

GEOD = Geod(ellps="WGS84")


@dataclass(frozen=True)
class MissionSummary:
    items: int
    nav_waypoints: int
    legs: int
    total_length_m: float
    fence_inclusion_polygons: int = 0
    fence_exclusion_polygons: int = 0
    fence_inclusion_circles: int = 0
    fence_exclusion_circles: int = 0
    fence_return_point: bool = False
    rally_points: int = 0
    commands: dict[str, int] = field(default_factory=dict)
    """Mission command name -> how many items use it."""
    has_home: bool = False

    def __str__(self) -> str:
        lines = [
            f"items: {self.items} ({self.nav_waypoints} navigation waypoints)",
            f"route: {self.legs} legs, {self.total_length_m:.1f} m" + ("" if self.has_home else " (no home: from the first waypoint)"),
            f"commands: {', '.join(f'{name} x{count}' for name, count in self.commands.items()) or 'none'}",
            (
                f"fence: {self.fence_inclusion_polygons} inclusion / {self.fence_exclusion_polygons} exclusion polygons, "
                f"{self.fence_inclusion_circles} inclusion / {self.fence_exclusion_circles} exclusion circles"
                + (", return point" if self.fence_return_point else "")
            ),
            f"rally points: {self.rally_points}",
        ]
        return "\n".join(lines)


def route_latlon(mission: Mission) -> list[tuple[float, float]]:
    """The (lat, lon) points the rover drives through, in order (one pass, see module doc)."""
    home = (mission.home.lat_deg, mission.home.lon_deg) if mission.home is not None else None
    points = [home] if home is not None else []
    for item in mission.items:
        if item.command in NAV_POSITION_COMMANDS and not (item.x == 0.0 and item.y == 0.0):
            points.append((item.lat_deg, item.lon_deg))
        elif item.command == Cmd.NAV_RETURN_TO_LAUNCH and home is not None:
            points.append(home)
    return points


def nominal_duration_s(mission: Mission, cruise_speed_mps: float, max_speed_mps: float) -> float:
    """Seconds to drive one pass of the route at the mission's speeds and hold where it says
    (see the module docstring); 0 for a mission that goes nowhere."""
    speed = min(cruise_speed_mps, max_speed_mps)
    home = (mission.home.lat_deg, mission.home.lon_deg) if mission.home is not None else None
    here = home
    total_s = 0.0
    for item in mission.items:
        hold_s = _finite(item.param1)
        target = None
        if item.command in NAV_POSITION_COMMANDS:
            if not (item.x == 0.0 and item.y == 0.0):
                target = (item.lat_deg, item.lon_deg)
            total_s += hold_s
        elif item.command == Cmd.NAV_RETURN_TO_LAUNCH:
            target = home
        elif item.command == Cmd.CONDITION_DELAY:
            total_s += hold_s
        elif item.command == Cmd.DO_CHANGE_SPEED and _finite(item.param2) > 0.0:
            speed = min(item.param2, max_speed_mps)
        if target is not None:
            if here is not None and speed > 0.0:
                total_s += GEOD.line_length([here[1], target[1]], [here[0], target[0]]) / speed
            here = target
    return total_s


def _finite(value: float) -> float:
    """A parameter as a duration or speed: NaN and negatives ("unused") count as 0."""
    return value if math.isfinite(value) and value > 0.0 else 0.0


def summarize(mission: Mission) -> MissionSummary:
    points = route_latlon(mission)
    length_m = 0.0
    if len(points) > 1:
        lats, lons = zip(*points)
        length_m = float(GEOD.line_length(lons, lats))
    polygons = mission.fence_polygons()
    circles = mission.fence_circles()
    return MissionSummary(
        items=len(mission.items),
        nav_waypoints=sum(item.command in NAV_POSITION_COMMANDS for item in mission.items),
        legs=max(0, len(points) - 1),
        total_length_m=length_m,
        fence_inclusion_polygons=sum(p.inclusion for p in polygons),
        fence_exclusion_polygons=sum(not p.inclusion for p in polygons),
        fence_inclusion_circles=sum(c.inclusion for c in circles),
        fence_exclusion_circles=sum(not c.inclusion for c in circles),
        fence_return_point=mission.fence_return_point is not None,
        rally_points=len(mission.rally),
        commands=dict(Counter(command_name(item.command) for item in mission.items)),
        has_home=mission.home is not None,
    )
