"""The one typed mission model every format and the MAVLink protocol convert to and from.

It is the wire form: a mission, a fence and a rally list are each a sequence of
``MissionItem`` exactly as MISSION_ITEM_INT carries them (command, frame, param1-4, x, y, z),
so the protocol is lossless by construction and the file formats are translations of it.
For global frames ``x``/``y`` are latitude/longitude in degrees (floats; the wire uses 1e7
integers) and ``z`` is altitude in metres; for other frames they are the raw param5-7.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field


class MissionType(enum.IntEnum):
    """MAV_MISSION_TYPE."""

    MISSION = 0
    FENCE = 1
    RALLY = 2


# MAV_FRAME values used by missions.
FRAME_GLOBAL = 0
FRAME_MISSION = 2
FRAME_GLOBAL_RELATIVE_ALT = 3
GLOBAL_FRAMES = frozenset({0, 3, 5, 6, 10, 11})  # GLOBAL, _RELATIVE_ALT, _INT variants, _TERRAIN_ALT


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

    def of_type(self, mission_type: MissionType) -> list[MissionItem]:
        return {MissionType.MISSION: self.items, MissionType.FENCE: self.fence, MissionType.RALLY: self.rally}[
            MissionType(mission_type)
        ]
