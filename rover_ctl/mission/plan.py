"""QGroundControl ``.plan`` JSON (fileType "Plan", version 1; mission version 2).

Layout::

    {"fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
     "mission": {"version": 2, "firmwareType": 3, "vehicleType": 10, "cruiseSpeed": .., "hoverSpeed": ..,
                 "plannedHomePosition": [lat, lon, alt],
                 "items": [{"type": "SimpleItem", "command": 16, "frame": 3, "autoContinue": true,
                            "doJumpId": 1, "params": [p1, p2, p3, p4, lat, lon, alt], ...}, ...]},
     "geoFence": {"version": 2, "polygons": [{"polygon": [[lat, lon], ...], "inclusion": true, "version": 1}],
                  "circles": [{"circle": {"center": [lat, lon], "radius": r}, "inclusion": false, "version": 1}],
                  "breachReturn": [lat, lon, alt]},
     "rallyPoints": {"version": 2, "points": [[lat, lon, alt], ...]}}

``null`` params are NaN (QGC writes NaN as null). A DO_JUMP's param1 in a .plan is the ``doJumpId``
of its target, which QGC turns into the target's sequence number on upload; the model holds the
sequence number (wire form), and items are written with ``doJumpId`` = sequence number (home is 0).
Complex items (surveys, corridor scans, structure scans) are refused with an error naming them:
they are QGC's to expand into waypoints. Fence items get frame GLOBAL and autocontinue 0, rally
points frame GLOBAL_RELATIVE_ALT and autocontinue 0, as MAVProxy and ArduPilot hand them out.
"""

from __future__ import annotations

import json
import math
from typing import Any

from rover_ctl.mission.model import (
    FRAME_GLOBAL,
    FRAME_GLOBAL_RELATIVE_ALT,
    Cmd,
    Home,
    Mission,
    MissionItem,
    MissionType,
)
from rover_ctl.mission.parsing import HOME_INDEX, Parsed

FILE_TYPE = "Plan"
PLAN_VERSION = 1
MISSION_VERSION = 2
GEOFENCE_VERSION = 2
POLYGON_VERSION = 1
CIRCLE_VERSION = 1
RALLY_VERSION = 2
GROUND_STATION = "rover_ctl"
FIRMWARE_TYPE = 3
"""MAV_AUTOPILOT_ARDUPILOTMEGA: the daemon presents itself to ground stations as ArduPilot."""
VEHICLE_TYPE = 10
"""MAV_TYPE_GROUND_ROVER."""
CRUISE_SPEED_MPS = 1.0
"""What QGC uses for its time estimates when we write a plan (QGC's own setting, not uploaded)."""
HOVER_SPEED_MPS = 1.0
"""Required by QGC's reader; meaningless for a rover."""
PARAM_COUNT = 7

# QGC's altitude modes (QGroundControlQmlGlobal::AltMode) by MAV_FRAME, for the "AltitudeMode" key.
ALTITUDE_MODE_RELATIVE = 1
ALTITUDE_MODE_ABSOLUTE = 2
ALTITUDE_MODE_TERRAIN_FRAME = 4
ALTITUDE_MODE_BY_FRAME = {0: ALTITUDE_MODE_ABSOLUTE, 5: ALTITUDE_MODE_ABSOLUTE, 3: ALTITUDE_MODE_RELATIVE,
                          6: ALTITUDE_MODE_RELATIVE, 10: ALTITUDE_MODE_TERRAIN_FRAME, 11: ALTITUDE_MODE_TERRAIN_FRAME}  # fmt: skip


class _Refused(Exception):
    """A structural problem after which the rest of the file cannot be read."""


def _number(value: Any, where: str, errors: list[str], allow_null: bool = False) -> float:
    if value is None and allow_null:
        return math.nan
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        errors.append(f"{where}: expected a number, got {json.dumps(value)[:40]}")
        return math.nan
    try:
        return float(value)
    except OverflowError:  # an integer beyond any float
        errors.append(f"{where}: number out of range ({len(str(abs(value)))} digits)")
        return math.nan


def _whole(value: Any, where: str, errors: list[str]) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        if isinstance(value, float) and math.isfinite(value) and value == int(value):
            return int(value)
        errors.append(f"{where}: expected a whole number, got {json.dumps(value)[:40]}")
        return 0
    return value


def _member(obj: dict, key: str, kind: type | tuple, where: str, required: bool = True) -> Any:
    if key not in obj:
        if required:
            raise _Refused(f"{where}: missing {key!r}")
        return None
    value = obj[key]
    if not isinstance(value, kind):
        names = kind.__name__ if isinstance(kind, type) else " or ".join(k.__name__ for k in kind)
        # "file.plan: mission.items" inside the file, "file.plan: geoFence" at its top
        path = f"{where}.{key}" if ": " in where else f"{where}: {key}"
        raise _Refused(f"{path}: expected {_JSON_NAMES.get(names, names)}, got {json.dumps(value)[:40]}")
    return value


_JSON_NAMES = {"dict": "an object", "list": "an array", "str": "a string", "bool": "true/false"}


def _latlon(value: Any, where: str, errors: list[str], length: int = 2) -> tuple[float, ...]:
    if not isinstance(value, list) or len(value) != length:
        errors.append(f"{where}: expected [{', '.join(('lat', 'lon', 'alt')[:length])}], got {json.dumps(value)[:60]}")
        return (math.nan,) * length
    return tuple(_number(v, f"{where}[{i}]", errors) for i, v in enumerate(value))


def _parse_items(mission_obj: dict, source: str, parsed: Parsed) -> None:
    items = _member(mission_obj, "items", list, f"{source}: mission")
    jump_ids: dict[int, int] = {}
    jumps: list[tuple[int, int, str]] = []  # (index, target doJumpId, where)
    for index, raw in enumerate(items):
        where = f"{source}: mission.items[{index}]"
        if not isinstance(raw, dict):
            parsed.errors.append(f"{where}: expected an object, got {json.dumps(raw)[:40]}")
            continue
        kind = raw.get("type")
        if kind == "ComplexItem":
            name = raw.get("complexItemType", "unknown")
            parsed.errors.append(
                f"{where}: complex item {name!r} is not supported: expand it into waypoints in QGroundControl first"
            )
            continue
        if kind != "SimpleItem":
            parsed.errors.append(f"{where}: unknown item type {json.dumps(kind)} (expected \"SimpleItem\")")
            continue
        count_before = len(parsed.errors)
        command = _whole(raw.get("command"), f"{where}.command", parsed.errors)
        frame = _whole(raw.get("frame"), f"{where}.frame", parsed.errors)
        params = raw.get("params")
        if not isinstance(params, list) or len(params) != PARAM_COUNT:
            parsed.errors.append(f"{where}.params: expected an array of {PARAM_COUNT} numbers or nulls")
            continue
        values = [_number(v, f"{where}.params[{i}]", parsed.errors, allow_null=True) for i, v in enumerate(params)]
        autocontinue = raw.get("autoContinue", True)
        if not isinstance(autocontinue, bool):
            parsed.errors.append(f"{where}.autoContinue: expected true/false, got {json.dumps(autocontinue)}")
        if "doJumpId" in raw:
            jump_id = _whole(raw["doJumpId"], f"{where}.doJumpId", parsed.errors)
            if jump_id in jump_ids:
                parsed.errors.append(f"{where}.doJumpId: {jump_id} already used by mission.items[{jump_ids[jump_id] - 1}]")
            jump_ids[jump_id] = len(parsed.mission.items) + 1
        if len(parsed.errors) > count_before:
            continue
        if command == Cmd.DO_JUMP and math.isfinite(values[0]):
            jumps.append((len(parsed.mission.items), int(values[0]), where))
        parsed.labels[(MissionType.MISSION, len(parsed.mission.items))] = where
        parsed.mission.items.append(
            MissionItem(command, frame, *values[:4], x=values[4], y=values[5], z=values[6], autocontinue=autocontinue)
        )
    # QGC numbers DO_JUMP targets by doJumpId; without any doJumpId the number is the sequence.
    if jump_ids:
        for item_index, target_id, where in jumps:
            if target_id not in jump_ids:
                parsed.errors.append(f"{where}: DO_JUMP to doJumpId {target_id}, which no item has")
                continue
            old = parsed.mission.items[item_index]
            parsed.mission.items[item_index] = MissionItem(
                old.command, old.frame, float(jump_ids[target_id]), old.param2, old.param3, old.param4,
                old.x, old.y, old.z, old.autocontinue,
            )  # fmt: skip


def _fence_item(command: int, lat: float, lon: float, param1: float) -> MissionItem:
    return MissionItem(command, FRAME_GLOBAL, param1=param1, x=lat, y=lon, autocontinue=False)


def _parse_fence(fence_obj: dict, source: str, parsed: Parsed) -> None:
    fence = parsed.mission.fence
    for index, poly in enumerate(_member(fence_obj, "polygons", list, f"{source}: geoFence", required=False) or []):
        where = f"{source}: geoFence.polygons[{index}]"
        if not isinstance(poly, dict) or not isinstance(poly.get("polygon"), list):
            parsed.errors.append(f"{where}: expected an object with a \"polygon\" array of [lat, lon]")
            continue
        inclusion = poly.get("inclusion", True)
        if not isinstance(inclusion, bool):
            parsed.errors.append(f"{where}.inclusion: expected true/false, got {json.dumps(inclusion)}")
            continue
        command = Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION if inclusion else Cmd.NAV_FENCE_POLYGON_VERTEX_EXCLUSION
        vertices = poly["polygon"]
        if not vertices:  # no items would carry it, and the fence would be gone without a word
            parsed.errors.append(f"{where}.polygon: no vertices (a polygon needs at least 3)")
            continue
        for k, vertex in enumerate(vertices):
            lat, lon = _latlon(vertex, f"{where}.polygon[{k}]", parsed.errors)
            parsed.labels[(MissionType.FENCE, len(fence))] = f"{where}.polygon[{k}]"
            fence.append(_fence_item(command, lat, lon, float(len(vertices))))
    for index, circ in enumerate(_member(fence_obj, "circles", list, f"{source}: geoFence", required=False) or []):
        where = f"{source}: geoFence.circles[{index}]"
        circle = circ.get("circle") if isinstance(circ, dict) else None
        if not isinstance(circle, dict):
            parsed.errors.append(f"{where}: expected an object with a \"circle\": {{\"center\": [lat, lon], \"radius\": r}}")
            continue
        inclusion = circ.get("inclusion", True)
        if not isinstance(inclusion, bool):
            parsed.errors.append(f"{where}.inclusion: expected true/false, got {json.dumps(inclusion)}")
            continue
        lat, lon = _latlon(circle.get("center"), f"{where}.circle.center", parsed.errors)
        radius_m = _number(circle.get("radius"), f"{where}.circle.radius", parsed.errors)
        command = Cmd.NAV_FENCE_CIRCLE_INCLUSION if inclusion else Cmd.NAV_FENCE_CIRCLE_EXCLUSION
        parsed.labels[(MissionType.FENCE, len(fence))] = where
        fence.append(_fence_item(command, lat, lon, radius_m))
    if "breachReturn" in fence_obj:
        where = f"{source}: geoFence.breachReturn"
        lat, lon, alt = _latlon(fence_obj["breachReturn"], where, parsed.errors, length=3)
        parsed.labels[(MissionType.FENCE, len(fence))] = where
        fence.append(
            MissionItem(Cmd.NAV_FENCE_RETURN_POINT, FRAME_GLOBAL_RELATIVE_ALT, x=lat, y=lon, z=alt, autocontinue=False)
        )


def _parse_rally(rally_obj: dict, source: str, parsed: Parsed) -> None:
    for index, point in enumerate(_member(rally_obj, "points", list, f"{source}: rallyPoints", required=False) or []):
        where = f"{source}: rallyPoints.points[{index}]"
        lat, lon, alt = _latlon(point, where, parsed.errors, length=3)
        parsed.labels[(MissionType.RALLY, len(parsed.mission.rally))] = where
        parsed.mission.rally.append(
            MissionItem(Cmd.NAV_RALLY_POINT, FRAME_GLOBAL_RELATIVE_ALT, x=lat, y=lon, z=alt, autocontinue=False)
        )


def parse_plan(text: str, source: str) -> Parsed:
    """Parse a QGC .plan file's text; ``source`` names it in messages."""
    parsed = Parsed()
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        parsed.errors.append(f"{source}:{exc.lineno}: invalid JSON: {exc.msg} (column {exc.colno})")
        return parsed
    except ValueError as exc:  # an integer of more digits than Python converts
        parsed.errors.append(f"{source}: invalid JSON: {str(exc).splitlines()[0]}")
        return parsed
    except RecursionError:
        parsed.errors.append(f"{source}: invalid JSON: nested too deeply")
        return parsed
    try:
        if not isinstance(doc, dict):
            raise _Refused(f"{source}: expected a JSON object at the top, got {_JSON_NAMES.get(type(doc).__name__, type(doc).__name__)}")
        file_type = doc.get("fileType")
        if file_type != FILE_TYPE:
            raise _Refused(f"{source}: fileType is {json.dumps(file_type)}, expected \"{FILE_TYPE}\"")
        if isinstance(doc.get("version"), bool) or doc.get("version") != PLAN_VERSION:  # true == 1 in Python
            raise _Refused(f"{source}: plan version {json.dumps(doc.get('version'))} is not supported (expected {PLAN_VERSION})")
        mission_obj = _member(doc, "mission", dict, source)
        if isinstance(mission_obj.get("version"), bool) or mission_obj.get("version") != MISSION_VERSION:
            raise _Refused(
                f"{source}: mission version {json.dumps(mission_obj.get('version'))} is not supported "
                f"(expected {MISSION_VERSION}; re-save the plan with a current QGroundControl)"
            )
        home = _member(mission_obj, "plannedHomePosition", list, f"{source}: mission", required=False)
        if home is not None:
            lat, lon, alt = _latlon(home, f"{source}: mission.plannedHomePosition", parsed.errors, length=3)
            if not (lat == 0.0 and lon == 0.0):
                parsed.mission.home = Home(lat, lon, alt)
                parsed.labels[(MissionType.MISSION, HOME_INDEX)] = f"{source}: mission.plannedHomePosition"
        _parse_items(mission_obj, source, parsed)
        fence_obj = _member(doc, "geoFence", dict, source, required=False)
        if fence_obj is not None:
            _parse_fence(fence_obj, source, parsed)
        rally_obj = _member(doc, "rallyPoints", dict, source, required=False)
        if rally_obj is not None:
            _parse_rally(rally_obj, source, parsed)
    except _Refused as exc:
        parsed.errors.append(str(exc))
    return parsed


def _json_number(value: float) -> float | None:
    """NaN as null (as QGC writes it); a NaN coordinate then fails to load rather than to save."""
    return None if math.isnan(value) else value


def _item_json(seq: int, item: MissionItem) -> dict:
    params = [item.param1, item.param2, item.param3, item.param4, item.x, item.y, item.z]
    out: dict[str, Any] = {}
    if item.frame in ALTITUDE_MODE_BY_FRAME:
        out |= {"AMSLAltAboveTerrain": None, "Altitude": _json_number(item.z), "AltitudeMode": ALTITUDE_MODE_BY_FRAME[item.frame]}
    return out | {
        "autoContinue": item.autocontinue,
        "command": item.command,
        "doJumpId": seq,
        "frame": item.frame,
        "params": [_json_number(p) for p in params],
        "type": "SimpleItem",
    }


def format_plan(mission: Mission) -> str:
    """The QGC .plan JSON text of a mission with its fence and rally points."""
    polygons = [
        {"inclusion": p.inclusion, "polygon": [[_json_number(c) for c in v] for v in p.vertices_latlon], "version": POLYGON_VERSION}
        for p in mission.fence_polygons()
    ]
    circles = [
        {"circle": {"center": [_json_number(v) for v in c.center_latlon], "radius": _json_number(c.radius_m)}, "inclusion": c.inclusion, "version": CIRCLE_VERSION}
        for c in mission.fence_circles()
    ]
    geofence: dict[str, Any] = {"circles": circles, "polygons": polygons, "version": GEOFENCE_VERSION}
    if mission.fence_return_point is not None:
        geofence["breachReturn"] = [_json_number(v) for v in mission.fence_return_point]
    home = mission.home or Home(0.0, 0.0, 0.0)
    doc = {
        "fileType": FILE_TYPE,
        "geoFence": geofence,
        "groundStation": GROUND_STATION,
        "mission": {
            "cruiseSpeed": CRUISE_SPEED_MPS,
            "firmwareType": FIRMWARE_TYPE,
            "hoverSpeed": HOVER_SPEED_MPS,
            "items": [_item_json(seq, item) for seq, item in enumerate(mission.items, start=1)],
            "plannedHomePosition": [_json_number(v) for v in (home.lat_deg, home.lon_deg, home.alt_m)],
            "vehicleType": VEHICLE_TYPE,
            "version": MISSION_VERSION,
        },
        "rallyPoints": {
            "points": [[_json_number(v) for v in (p.lat_deg, p.lon_deg, p.alt_m)] for p in mission.rally],
            "version": RALLY_VERSION,
        },
        "version": PLAN_VERSION,
    }
    return json.dumps(doc, indent=4, allow_nan=False) + "\n"
