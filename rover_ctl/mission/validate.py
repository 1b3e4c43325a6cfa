"""Semantic checks of a mission, fence and rally list: what would make the rover misbehave.

Errors refuse the mission: coordinates out of range, a DO_JUMP to an item that does not exist,
a malformed fence (vertex count that does not match its run, fewer than 3 vertices, radius <= 0).
Warnings load it: commands this rover does not carry out (skipped by the executor) and speeds
above the rover's top speed (the executor clamps them). Pure: the caller decides what to do.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping

from rover_ctl.mission.model import (
    FENCE_CIRCLE_COMMANDS,
    FENCE_COMMANDS,
    NAV_POSITION_COMMANDS,
    SUPPORTED_COMMANDS,
    Cmd,
    Mission,
    MissionItem,
    MissionType,
    polygon_runs,
)
from rover_ctl.mission.parsing import HOME_INDEX

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


@functools.cache
def command_name(command: int) -> str:
    """MAV_CMD name without its prefix (e.g. ``DO_SET_SERVO``), or ``command N`` if unknown."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    entry = mavlink.enums["MAV_CMD"].get(command)
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
    return math.isfinite(value) and value == int(value)


def _check_latlon(lat_deg: float, lon_deg: float, where: str, errors: list[str], required: bool) -> None:
    """Latitude/longitude in range; NaN allowed only where no position is ``required``."""
    for name, value, limit in (("latitude", lat_deg, MAX_LAT_DEG), ("longitude", lon_deg, MAX_LON_DEG)):
        if math.isnan(value):
            if required:
                errors.append(f"{where}: {name} is missing (NaN)")
        elif not -limit <= value <= limit:
            errors.append(f"{where}: {name} {value:.10g} out of range [-{limit:g}, {limit:g}]")


def _check_position(item: MissionItem, where: str, errors: list[str], required: bool) -> None:
    """A global item's coordinates; a ``required`` position also needs a global frame."""
    if item.is_global:
        _check_latlon(item.x, item.y, where, errors, required)
    elif required:
        errors.append(f"{where}: {command_name(item.command)} needs a global frame for its position, got frame {item.frame}")


def _check_mission(mission: Mission, max_speed_mps: float, label, errors: list[str], warnings: list[str]) -> None:
    count = len(mission.items)
    for index, item in enumerate(mission.items):
        where = label(MissionType.MISSION, index)
        command = item.command
        _check_position(item, where, errors, required=command in NAV_POSITION_COMMANDS)
        if command == Cmd.DO_JUMP:
            target, repeat = item.param1, item.param2
            if not _whole(target) or not 1 <= target <= count:
                errors.append(f"{where}: DO_JUMP to item {target:g}, which does not exist (items are 1-{count})")
            elif int(target) == index + 1:
                errors.append(f"{where}: DO_JUMP to itself")
            if not _whole(repeat) or repeat < JUMP_FOREVER:
                errors.append(f"{where}: DO_JUMP repeat count {repeat:g} is not a whole number >= -1")
        elif command == Cmd.DO_CHANGE_SPEED:
            speed_mps = item.param2
            if math.isfinite(speed_mps) and speed_mps > max_speed_mps:
                warnings.append(
                    f"{where}: DO_CHANGE_SPEED to {speed_mps:g} m/s is above the rover's maximum "
                    f"{max_speed_mps:.2f} m/s: clamped to {max_speed_mps:.2f} m/s"
                )
        elif command in (Cmd.CONDITION_DELAY, Cmd.NAV_LOITER_TIME):
            if not (math.isfinite(item.param1) and item.param1 >= 0.0):
                errors.append(f"{where}: {command_name(command)} time {item.param1:g} s must be >= 0")
        elif command not in SUPPORTED_COMMANDS:
            instead = INSTEAD.get(command, DEFAULT_INSTEAD)
            warnings.append(f"{where}: {describe(command)} is not supported by this rover: skipped, {instead}")


def _check_fence(mission: Mission, label, errors: list[str]) -> None:
    fence = mission.fence
    for start, stop in polygon_runs(fence):
        where = label(MissionType.FENCE, start)
        count = fence[start].param1
        kind = "inclusion" if fence[start].command == Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION else "exclusion"
        if not _whole(count) or count < MIN_POLYGON_VERTICES:
            errors.append(f"{where}: {kind} polygon vertex count {count:g} must be a whole number >= {MIN_POLYGON_VERTICES}")
        elif stop - start != int(count):
            errors.append(f"{where}: {kind} polygon declares {int(count)} vertices but has {stop - start}")
        for index in range(start + 1, stop):
            if fence[index].param1 != count:
                errors.append(f"{label(MissionType.FENCE, index)}: vertex count {fence[index].param1:g} differs from its polygon's {count:g}")
    for index, item in enumerate(fence):
        where = label(MissionType.FENCE, index)
        _check_position(item, where, errors, required=True)
        if item.command not in FENCE_COMMANDS:
            errors.append(f"{where}: {describe(item.command)} is not a fence item")
        elif item.command in FENCE_CIRCLE_COMMANDS and not (math.isfinite(item.param1) and item.param1 > 0.0):
            errors.append(f"{where}: fence circle radius {item.param1:g} m must be > 0")
    returns = sum(item.command == Cmd.NAV_FENCE_RETURN_POINT for item in fence)
    if returns > 1:
        errors.append(f"{label(MissionType.FENCE, 0)}: the fence has {returns} return points (at most 1)")


def _check_rally(mission: Mission, label, errors: list[str]) -> None:
    for index, item in enumerate(mission.rally):
        where = label(MissionType.RALLY, index)
        if item.command != Cmd.NAV_RALLY_POINT:
            errors.append(f"{where}: {describe(item.command)} is not a rally point")
        _check_position(item, where, errors, required=True)


def validate(
    mission: Mission,
    max_speed_mps: float,
    labels: Mapping[tuple[MissionType, int], str] | None = None,
) -> tuple[list[str], list[str]]:
    """``(errors, warnings)``, one line each, prefixed with ``labels[(type, index)]`` when given
    (file:line) or else with the item's place ("mission item 3" in wire seq, "fence item 0")."""
    errors: list[str] = []
    warnings: list[str] = []

    def label(kind: MissionType, index: int) -> str:
        return _label(labels, kind, index)

    if mission.home is not None:
        _check_latlon(mission.home.lat_deg, mission.home.lon_deg, label(MissionType.MISSION, HOME_INDEX), errors, required=True)
    _check_mission(mission, max_speed_mps, label, errors, warnings)
    _check_fence(mission, label, errors)
    _check_rally(mission, label, errors)
    return errors, warnings
