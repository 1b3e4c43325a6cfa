"""Semantic checks of a mission, fence and rally list: what would make the rover misbehave.

Errors refuse the mission: coordinates out of range, a value MISSION_ITEM_INT cannot carry
(command or frame beyond its field, an infinite or float32-overflowing param, an x/y beyond int32),
a frame MAVLink does not define, a DO_JUMP to an item that does not exist, a malformed fence
(vertex count that does not match its run, fewer than 3 vertices, a self-intersecting polygon,
radius <= 0), a fence too complex for the planner (more than ``MAX_PLANNER_NODES`` graph nodes,
``planner_nodes``). Warnings load it: commands this rover does not carry out (skipped by the executor)
and speeds above the rover's top speed (the executor clamps them). Pure: the caller decides what to
do. The same rules serve ``rover-ctl mission check`` and an upload over the mission protocol; each
error is a ``Problem`` (a str) that also names the item field it is about, from which the protocol
picks its MAV_MISSION_RESULT.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Mapping, Sequence

from shapely.geometry import Polygon

from rover_ctl.config import PlannerParams
from rover_ctl.mission.model import (
    FENCE_CIRCLE_COMMANDS,
    FENCE_COMMANDS,
    LOCAL_FRAMES,
    MAX_COMMAND,
    MAX_FRAME,
    NAV_POSITION_COMMANDS,
    SUPPORTED_COMMANDS,
    Cmd,
    Mission,
    MissionItem,
    MissionType,
    polygon_runs,
    xy_scale,
)
from rover_ctl.mission.parsing import HOME_INDEX
from rover_ctl.vocabulary import mav

MAX_LAT_DEG = 90.0
MAX_LON_DEG = 180.0
MIN_POLYGON_VERTICES = 3
SPEED_PARAM_UNCHANGED = -1.0
"""DO_CHANGE_SPEED param2 of -1 (or any value <= 0) leaves the speed unchanged."""
JUMP_FOREVER = -1
"""DO_JUMP param2 (repeat count) of -1 repeats forever."""

# What the rover does with a command it does not carry out (beyond "skipped"), by command.
INSTEAD = {
    Cmd.NAV_LOITER_UNLIM: "its position is not visited; use NAV_WAYPOINT (16) or NAV_LOITER_TIME (19)",
    Cmd.NAV_LOITER_TURNS: "its position is not visited; use NAV_LOITER_TIME (19)",
    Cmd.NAV_LAND: "its position is not visited; a rover has nothing to land, use NAV_WAYPOINT (16)",
    Cmd.DO_SET_HOME: "home stays where it is",
}
DEFAULT_INSTEAD = "the rover goes on with the next item"
FLOAT32_MAX = 3.4028234663852886e38
"""Largest finite float32: MISSION_ITEM_INT's param1-4 and z are float32."""
FLOAT32_TINY = 1.401298464324817e-45
"""The smallest positive float32: a positive value below half of it is sent as 0."""
INT32_MAX = 2**31 - 1
"""MISSION_ITEM_INT's x and y are int32 (scaled by the frame: 1e7 global, 1e4 local, else raw)."""
KNOWN_FRAMES = frozenset(mav.enums["MAV_FRAME"])
PARAM_FIELDS = ("param1", "param2", "param3", "param4", "z")

MAX_PLANNER_NODES = 800
"""Most graph nodes the planner (``rover_ctl.navigation.planner``) builds its visibility graph
over, as ``planner_nodes`` counts them (50 exclusion circles at the default 16 vertices, 12 at
PLN_CIRCLE_SEGS 64). The build is quadratic in the nodes and runs in the control step (40 ms at
25 Hz): 800 nodes took 46 ms on the 2-core x86-64 machine this was written on (exclusion circles,
every vertex a node; 30 ms at 640, 67 ms at 960, 110-140 ms at 1120), and a Raspberry Pi is
several times slower (not measured). A fence above it is refused (an upload with
MAV_MISSION_NO_SPACE, ``rover-ctl mission check`` with an error); the planner never builds a
graph above it, whatever made it so: it says "too complex to plan" instead (docs/missions.md)."""
FENCE_CIRCLE_SEGMENTS = PlannerParams.circle_segments
"""The planner's vertices per circle (PLN_CIRCLE_SEGS) a fence is counted with unless the caller
says otherwise: the default, as neither ``mission check`` nor an upload knows the live value."""


class Problem(str):
    """One validation error: its one-line text, and ``field``, the MissionItem attribute it is
    about ("command", "frame", "param1".."param4", "x", "y", "z"), "item" for the whole item, or
    "size" when the list as a whole is too big for the rover (the planner's node budget)."""

    field: str

    def __new__(cls, text: str, field: str = "item") -> "Problem":
        problem = super().__new__(cls, text)
        problem.field = field
        return problem


@functools.cache
def command_name(command: int) -> str:
    """MAV_CMD name without its prefix (e.g. ``DO_SET_SERVO``), or ``command N`` if unknown."""
    entry = mav.enums["MAV_CMD"].get(command)
    return entry.name.removeprefix("MAV_CMD_") if entry is not None else f"command {command}"


def describe(command: int) -> str:
    """``DO_SET_SERVO (183)``, or ``command 4242`` for a number MAVLink does not define."""
    name = command_name(command)
    return name if name.startswith("command ") else f"{name} ({command})"


def _label(labels: Mapping[tuple[MissionType, int], str] | None, kind: MissionType, index: int) -> str:
    if labels is not None and (kind, index) in labels:
        return labels[(kind, index)]
    if kind == MissionType.MISSION and index == HOME_INDEX:
        return "home"
    if kind == MissionType.MISSION:
        return f"mission item {index + 1}"  # wire seq: home is 0
    return f"{kind.name.lower()} item {index}"


def _whole(value: float) -> bool:
    return isinstance(value, int) or (math.isfinite(value) and value == int(value))


def _check_latlon(lat_deg: float, lon_deg: float, where: str, errors: list[str], required: bool) -> None:
    """Latitude/longitude in range; NaN allowed only where no position is ``required``."""
    for name, field, value, limit in (("latitude", "x", lat_deg, MAX_LAT_DEG), ("longitude", "y", lon_deg, MAX_LON_DEG)):
        if math.isnan(value):
            if required:
                errors.append(Problem(f"{where}: {name} is missing (NaN)", field))
        elif not -limit <= value <= limit:
            errors.append(Problem(f"{where}: {name} {value:.10g} out of range [-{limit:g}, {limit:g}]", field))


def _check_position(item: MissionItem, where: str, errors: list[str], required: bool) -> None:
    """A global item's coordinates; a ``required`` position also needs a global frame."""
    if item.is_global:
        _check_latlon(item.x, item.y, where, errors, required)
    elif required:
        errors.append(Problem(f"{where}: {command_name(item.command)} needs a global frame for its position, got frame {item.frame}", "frame"))


def _check_wire(item: MissionItem, where: str, errors: list[str]) -> bool:
    """What MISSION_ITEM_INT can carry: False (after the errors) if the item cannot be sent."""
    before = len(errors)
    if not (_whole(item.command) and 0 <= item.command <= MAX_COMMAND):
        errors.append(Problem(f"{where}: command {item.command} is not a MAVLink command (0-{MAX_COMMAND})", "command"))
    if not (_whole(item.frame) and 0 <= item.frame <= MAX_FRAME) or item.frame not in KNOWN_FRAMES:
        errors.append(Problem(f"{where}: frame {item.frame} is not a MAV_FRAME", "frame"))
    for name in PARAM_FIELDS:
        value = getattr(item, name)
        if math.isinf(value) or abs(value) > FLOAT32_MAX:
            errors.append(Problem(f"{where}: {name} {value:g} is not a finite float32", name))
    if not item.is_global:  # global x/y are latitude/longitude, range-checked by _check_position
        scale = xy_scale(item.frame)
        for name in ("x", "y"):
            value = getattr(item, name)
            if not math.isnan(value) and not abs(value * scale) <= INT32_MAX:
                unit = " m" if item.frame in LOCAL_FRAMES else ""
                errors.append(Problem(f"{where}: {name} {value:g}{unit} does not fit MISSION_ITEM_INT", name))
    return len(errors) == before


def check_item(item: MissionItem, kind: MissionType, where: str) -> list[Problem]:
    """The rules one item of list ``kind`` must meet on its own (what an upload checks as each item
    arrives); the rules between items (jump targets, polygon runs) are ``validate``'s."""
    errors: list[Problem] = []
    if not _check_wire(item, where, errors):
        return errors
    command = item.command
    if kind == MissionType.MISSION:
        _check_position(item, where, errors, required=command in NAV_POSITION_COMMANDS)
        if command == Cmd.DO_JUMP:
            if not _whole(item.param2) or item.param2 < JUMP_FOREVER:
                errors.append(Problem(f"{where}: DO_JUMP repeat count {item.param2:g} is not a whole number >= -1", "param2"))
        elif command in (Cmd.CONDITION_DELAY, Cmd.NAV_LOITER_TIME):
            if not (math.isfinite(item.param1) and item.param1 >= 0.0):
                errors.append(Problem(f"{where}: {command_name(command)} time {item.param1:g} s must be >= 0", "param1"))
    elif kind == MissionType.FENCE:
        _check_position(item, where, errors, required=True)
        if command not in FENCE_COMMANDS:
            errors.append(Problem(f"{where}: {describe(command)} is not a fence item", "command"))
        elif command in FENCE_CIRCLE_COMMANDS and not circle_radius_ok(item.param1):
            errors.append(Problem(f"{where}: fence circle radius {item.param1:g} m must be > 0 (as the float32 sent)", "param1"))
    else:
        if command != Cmd.NAV_RALLY_POINT:
            errors.append(Problem(f"{where}: {describe(command)} is not a rally point", "command"))
        _check_position(item, where, errors, required=True)
    return errors


def _check_mission(mission: Mission, max_speed_mps: float, label, errors: list[str], warnings: list[str]) -> None:
    count = len(mission.items)
    for index, item in enumerate(mission.items):
        where = label(MissionType.MISSION, index)
        own = check_item(item, MissionType.MISSION, where)
        errors.extend(own)
        if any(problem.field in ("command", "frame") for problem in own):
            continue
        command = item.command
        if command == Cmd.DO_JUMP:
            target = item.param1
            if not _whole(target) or not 1 <= target <= count:
                errors.append(Problem(f"{where}: DO_JUMP to item {target:g}, which does not exist (items are 1-{count})", "param1"))
            elif int(target) == index + 1:
                errors.append(Problem(f"{where}: DO_JUMP to itself", "param1"))
        elif command == Cmd.DO_CHANGE_SPEED:
            speed_mps = item.param2
            if math.isfinite(speed_mps) and speed_mps > max_speed_mps:
                warnings.append(
                    f"{where}: DO_CHANGE_SPEED to {speed_mps:g} m/s is above the rover's maximum "
                    f"{max_speed_mps:.2f} m/s: clamped to {max_speed_mps:.2f} m/s"
                )
        elif command not in SUPPORTED_COMMANDS:
            instead = INSTEAD.get(command, DEFAULT_INSTEAD)
            warnings.append(f"{where}: {describe(command)} is not supported by this rover: skipped, {instead}")


def circle_radius_ok(radius_m: float) -> bool:
    """Positive as the float32 that MISSION_ITEM_INT's param1 carries (1e-300 is 0 there)."""
    return math.isfinite(radius_m) and FLOAT32_TINY <= radius_m <= FLOAT32_MAX


def latlon_ok(lat_deg: float, lon_deg: float) -> bool:
    return -MAX_LAT_DEG <= lat_deg <= MAX_LAT_DEG and -MAX_LON_DEG <= lon_deg <= MAX_LON_DEG


def polygon_crosses_itself(vertices: list[MissionItem]) -> bool:
    """Whether the ring of these vertices (each in range; others are reported per item) crosses
    itself, in degrees: a fence spans far less than the curvature that would change the answer."""
    points = [(item.x, item.y) for item in vertices]
    if len(points) < MIN_POLYGON_VERTICES or not all(latlon_ok(lat, lon) for lat, lon in points):
        return False
    return not Polygon(points).is_valid


def _check_fence(mission: Mission, label, errors: list[str], circle_segments: int | None) -> None:
    fence = mission.fence
    for start, stop in polygon_runs(fence):
        where = label(MissionType.FENCE, start)
        count = fence[start].param1
        kind = "inclusion" if fence[start].command == Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION else "exclusion"
        if not _whole(count) or count < MIN_POLYGON_VERTICES:
            errors.append(Problem(f"{where}: {kind} polygon vertex count {count:g} must be a whole number >= {MIN_POLYGON_VERTICES}", "param1"))
        elif stop - start != int(count):
            errors.append(Problem(f"{where}: {kind} polygon declares {int(count)} vertices but has {stop - start}", "param1"))
        elif polygon_crosses_itself(fence[start:stop]):
            errors.append(Problem(f"{where}: {kind} polygon of {stop - start} vertices intersects itself"))
        for index in range(start + 1, stop):
            if fence[index].param1 != count:
                errors.append(Problem(f"{label(MissionType.FENCE, index)}: vertex count {fence[index].param1:g} differs from its polygon's {count:g}", "param1"))
    for index, item in enumerate(fence):
        errors.extend(check_item(item, MissionType.FENCE, label(MissionType.FENCE, index)))
    returns = sum(item.command == Cmd.NAV_FENCE_RETURN_POINT for item in fence)
    if returns > 1:
        errors.append(Problem(f"{label(MissionType.FENCE, 0)}: the fence has {returns} return points (at most 1)"))
    if circle_segments is not None:
        nodes = fence_nodes(fence, circle_segments)
        if nodes > MAX_PLANNER_NODES:
            circles = sum(item.command in FENCE_CIRCLE_COMMANDS for item in fence)
            errors.append(Problem(
                f"{label(MissionType.FENCE, 0)}: the fence is too complex for the planner: {nodes} nodes, max {MAX_PLANNER_NODES} "
                f"({circles} circles x {circle_segments} vertices, polygons {nodes - circles * circle_segments})",
                "size",
            ))  # fmt: skip


def planner_nodes(circles: int, rings: Iterable[tuple[Sequence[tuple[float, float]], bool]], segments: int) -> int:
    """The planner's graph nodes for ``circles`` circles and polygon ``rings`` (``(vertices,
    grown)``), at ``segments`` vertices per circle (PLN_CIRCLE_SEGS): the vertices of the shapes
    it inflates them into, an upper bound of its nodes (only the free space's reflex vertices are
    nodes: an inclusion circle, for one, makes none)."""
    return circles * segments + sum(ring_vertices(vertices, grown, segments) for vertices, grown in rings)


def ring_vertices(vertices: Sequence[tuple[float, float]], grown: bool, segments: int) -> int:
    """Vertices of a polygon ring (x, y in any frame that keeps angles) once the planner inflates
    it (``grown``: an exclusion zone or obstacle) or shrinks it (an inclusion fence) with round
    corners: one per corner, and at a corner that turns by an angle t away from the zone (convex
    when grown, concave when shrunk) at most t / (90 deg / (segments // 4)) + 1 more, the arc's
    (shapely's quad_segs; a turn of nearly 180 deg adds segments // 2 + 1). An upper bound: the
    buffer rounds each arc's chord count and drops vertices that come too close."""
    points = [p for k, p in enumerate(vertices) if p != vertices[k - 1]] if len(vertices) > 1 else list(vertices)
    n = len(points)
    if n < MIN_POLYGON_VERTICES:
        return n
    area2 = sum(x0 * y1 - x1 * y0 for (x0, y0), (x1, y1) in zip(points, points[1:] + points[:1]))
    away = 1.0 if (area2 > 0) == grown else -1.0  # the sign of a turn that makes an arc
    step = math.pi / 2 / max(1, segments // 4)
    total = 0.0
    for k in range(n):
        (ax, ay), (bx, by), (cx, cy) = points[k - 1], points[k], points[(k + 1) % n]
        ux, uy, vx, vy = bx - ax, by - ay, cx - bx, cy - by
        turn = math.atan2(ux * vy - uy * vx, ux * vx + uy * vy) * away
        total += 1.0 + (turn / step + 1.0 if turn > 0 else 0.0)
    return math.ceil(total)


def fence_nodes(fence: Sequence[MissionItem], segments: int = FENCE_CIRCLE_SEGMENTS) -> int:
    """``planner_nodes`` of a fence list: its circle items and its polygon runs, as they stand
    (longitude scaled by the cosine of the latitude, so that corner angles are the ground's)."""
    circles = sum(item.command in FENCE_CIRCLE_COMMANDS for item in fence)
    rings, unplaced = [], 0
    for start, stop in polygon_runs(list(fence)):
        run = fence[start:stop]
        if all(latlon_ok(item.x, item.y) for item in run):  # NaN is not
            scale = math.cos(math.radians(run[0].x))
            rings.append(([(item.y * scale, item.x) for item in run], run[0].command != Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION))
        else:  # reported per item; counted as if every corner turned fully
            unplaced += len(run) * (segments // 2 + 2)
    return planner_nodes(circles, rings, segments) + unplaced


def _check_rally(mission: Mission, label, errors: list[str]) -> None:
    for index, item in enumerate(mission.rally):
        errors.extend(check_item(item, MissionType.RALLY, label(MissionType.RALLY, index)))


def validate(
    mission: Mission,
    max_speed_mps: float,
    labels: Mapping[tuple[MissionType, int], str] | None = None,
    parts: Iterable[MissionType] = tuple(MissionType),
    circle_segments: int | None = FENCE_CIRCLE_SEGMENTS,
) -> tuple[list[str], list[str]]:
    """``(errors, warnings)``, one line each, prefixed with ``labels[(type, index)]`` when given
    (file:line) or else with the item's place ("mission item 3" in wire seq, "fence item 0").
    Errors are ``Problem``s. ``parts``: the lists to check (home goes with MISSION).
    ``circle_segments``: the PLN_CIRCLE_SEGS the fence's planner nodes are counted at (None: no
    node budget, for the planner, which counts its own)."""
    errors: list[str] = []
    warnings: list[str] = []

    def label(kind: MissionType, index: int) -> str:
        return _label(labels, kind, index)

    parts = frozenset(parts)
    if mission.home is not None and MissionType.MISSION in parts:
        where = label(MissionType.MISSION, HOME_INDEX)
        _check_latlon(mission.home.lat_deg, mission.home.lon_deg, where, errors, required=True)
        if math.isinf(mission.home.alt_m) or abs(mission.home.alt_m) > FLOAT32_MAX:
            errors.append(Problem(f"{where}: altitude {mission.home.alt_m:g} is not a finite float32", "z"))
    if MissionType.MISSION in parts:
        _check_mission(mission, max_speed_mps, label, errors, warnings)
    if MissionType.FENCE in parts:
        _check_fence(mission, label, errors, circle_segments)
    if MissionType.RALLY in parts:
        _check_rally(mission, label, errors)
    return errors, warnings
