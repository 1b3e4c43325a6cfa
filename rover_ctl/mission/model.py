"""The one typed mission model every format and the MAVLink protocol convert to and from.

It is the wire form: a mission, a fence and a rally list are each a sequence of
``MissionItem`` exactly as MISSION_ITEM_INT carries them (command, frame, param1-4, x, y, z),
so the protocol is lossless by construction and the file formats are translations of it.
For global frames ``x``/``y`` are latitude/longitude in degrees (floats; the wire uses 1e7
integers) and ``z`` is altitude in metres; for other frames they are the raw param5-7.

Fences keep the wire encoding too (MAV_CMD 5000-5004: a polygon is a run of vertex items whose
param1 is the vertex count; a circle's param1 is its radius); ``Mission.fence_polygons()``,
``fence_circles()`` and ``fence_return_point`` are the typed views the planner uses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from rover_ctl.vocabulary import Cmd, MissionType


SUPPORTED_COMMANDS = frozenset(
    {
        Cmd.NAV_WAYPOINT,
        Cmd.NAV_LOITER_TIME,
        Cmd.NAV_RETURN_TO_LAUNCH,
        Cmd.CONDITION_DELAY,
        Cmd.DO_JUMP,
        Cmd.DO_CHANGE_SPEED,
    }
)
"""Mission commands the rover's executor carries out; any other mission command is skipped."""
NAV_POSITION_COMMANDS = frozenset({Cmd.NAV_WAYPOINT, Cmd.NAV_LOITER_TIME})
"""Supported commands that drive the rover to the item's latitude/longitude."""
FENCE_POLYGON_COMMANDS = frozenset({Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION, Cmd.NAV_FENCE_POLYGON_VERTEX_EXCLUSION})
FENCE_CIRCLE_COMMANDS = frozenset({Cmd.NAV_FENCE_CIRCLE_INCLUSION, Cmd.NAV_FENCE_CIRCLE_EXCLUSION})
FENCE_COMMANDS = FENCE_POLYGON_COMMANDS | FENCE_CIRCLE_COMMANDS | {Cmd.NAV_FENCE_RETURN_POINT}
RALLY_COMMANDS = frozenset({Cmd.NAV_RALLY_POINT})

# MAV_FRAME values used by missions.
FRAME_GLOBAL = 0
FRAME_MISSION = 2
FRAME_GLOBAL_RELATIVE_ALT = 3
GLOBAL_FRAMES = frozenset({0, 3, 5, 6, 10, 11})  # GLOBAL, _RELATIVE_ALT, _INT variants, _TERRAIN_ALT
LOCAL_FRAMES = frozenset({1, 4, 7, 8, 9, 20, 21})
"""MAV_FRAME_LOCAL_NED/ENU and body/offset variants: x/y are metres * 1e4 in MISSION_ITEM_INT."""
GLOBAL_XY_SCALE = 1e7
"""MISSION_ITEM_INT x/y of a global frame: degrees * 1e7."""
LOCAL_XY_SCALE = 1e4
"""MISSION_ITEM_INT x/y of a local frame: metres * 1e4; any other frame carries them raw."""
MAX_COMMAND = 0xFFFF
"""MISSION_ITEM_INT.command is a uint16."""
MAX_FRAME = 0xFF
"""MISSION_ITEM_INT.frame is a uint8."""


def xy_scale(frame: int) -> float:
    """Model x/y -> MISSION_ITEM_INT x/y integer factor for ``frame`` (MISSION_ITEM_INT spec)."""
    return GLOBAL_XY_SCALE if frame in GLOBAL_FRAMES else LOCAL_XY_SCALE if frame in LOCAL_FRAMES else 1.0


@dataclass(frozen=True)
class MissionItem:
    """One mission/fence/rally item (seq is its index in its list)."""

    command: int
    frame: int = FRAME_GLOBAL_RELATIVE_ALT
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = 0.0
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    autocontinue: bool = True

    @property
    def is_global(self) -> bool:
        return self.frame in GLOBAL_FRAMES

    @property
    def lat_deg(self) -> float:
        return self.x

    @property
    def lon_deg(self) -> float:
        return self.y

    @property
    def alt_m(self) -> float:
        return self.z

    def same_as(self, other: "MissionItem", tol_deg: float = 1e-7, tol: float = 1e-4) -> bool:
        """Equal within wire precision (1e-7 deg for lat/lon, float32 for params; NaN == NaN)."""

        def close(a: float, b: float, t: float) -> bool:
            if math.isnan(a) or math.isnan(b):
                return math.isnan(a) and math.isnan(b)
            return abs(a - b) <= t * max(1.0, abs(a), abs(b))

        coord_tol = tol_deg if self.is_global else tol
        return (
            self.command == other.command
            and self.frame == other.frame
            and self.autocontinue == other.autocontinue
            and all(close(getattr(self, p), getattr(other, p), tol) for p in ("param1", "param2", "param3", "param4"))
            and close(self.x, other.x, coord_tol)
            and close(self.y, other.y, coord_tol)
            and close(self.z, other.z, tol)
        )


@dataclass(frozen=True)
class Home:
    lat_deg: float
    lon_deg: float
    alt_m: float = 0.0

    def same_as(self, other: "Home | None", tol_deg: float = 1e-7, tol_m: float = 1e-3) -> bool:
        """Equal within wire precision (1e-7 deg, 1 mm)."""
        return (
            other is not None
            and abs(self.lat_deg - other.lat_deg) <= tol_deg
            and abs(self.lon_deg - other.lon_deg) <= tol_deg
            and abs(self.alt_m - other.alt_m) <= tol_m
        )


@dataclass(frozen=True)
class FencePolygon:
    """A fence polygon: vertices as (lat, lon) degrees, in order, not closed (last != first)."""

    vertices_latlon: tuple[tuple[float, float], ...]
    inclusion: bool


@dataclass(frozen=True)
class FenceCircle:
    center_latlon: tuple[float, float]
    radius_m: float
    inclusion: bool


def polygon_runs(fence: list[MissionItem]) -> list[tuple[int, int]]:
    """``(start, stop)`` index ranges of the polygons in a fence list.

    A polygon starts at a vertex item and spans ``param1`` (its vertex count) items, cut short
    where the command changes; validation reports runs whose length differs from their count.
    """
    runs = []
    i = 0
    while i < len(fence):
        command = fence[i].command
        if command not in FENCE_POLYGON_COMMANDS:
            i += 1
            continue
        count = fence[i].param1
        wanted = int(count) if math.isfinite(count) and count >= 1 else 1
        stop = i + 1
        while stop < len(fence) and stop - i < wanted and fence[stop].command == command:
            stop += 1
        runs.append((i, stop))
        i = stop
    return runs


@dataclass
class Mission:
    """A mission with its fence and rally points.

    ``items`` excludes home: ``items[0]`` is the first navigation or DO item (wire seq 1 in
    ArduPilot's numbering, where seq 0 is home). ``fence`` and ``rally`` hold the items of
    mission_type FENCE (MAV_CMD 5000-5004) and RALLY (MAV_CMD 5100).
    """

    items: list[MissionItem] = field(default_factory=list)
    home: Home | None = None
    fence: list[MissionItem] = field(default_factory=list)
    rally: list[MissionItem] = field(default_factory=list)

    def fence_polygons(self) -> list[FencePolygon]:
        return [
            FencePolygon(
                tuple((item.lat_deg, item.lon_deg) for item in self.fence[start:stop]),
                self.fence[start].command == Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION,
            )
            for start, stop in polygon_runs(self.fence)
        ]

    def fence_circles(self) -> list[FenceCircle]:
        return [
            FenceCircle((item.lat_deg, item.lon_deg), item.param1, item.command == Cmd.NAV_FENCE_CIRCLE_INCLUSION)
            for item in self.fence
            if item.command in FENCE_CIRCLE_COMMANDS
        ]

    @property
    def fence_return_point(self) -> tuple[float, float, float] | None:
        """(lat, lon, alt) of the fence breach return point, if the fence has one."""
        for item in self.fence:
            if item.command == Cmd.NAV_FENCE_RETURN_POINT:
                return (item.lat_deg, item.lon_deg, item.alt_m)
        return None

    def same_as(self, other: "Mission") -> bool:
        """Equal within wire precision: home, and every item of the mission, fence and rally."""

        def same_items(a: list[MissionItem], b: list[MissionItem]) -> bool:
            return len(a) == len(b) and all(x.same_as(y) for x, y in zip(a, b))

        same_home = other.home is None if self.home is None else self.home.same_as(other.home)
        return (
            same_home
            and same_items(self.items, other.items)
            and same_items(self.fence, other.fence)
            and same_items(self.rally, other.rally)
        )

    def of_type(self, mission_type: MissionType) -> list[MissionItem]:
        return {MissionType.MISSION: self.items, MissionType.FENCE: self.fence, MissionType.RALLY: self.rally}[
            MissionType(mission_type)
        ]
