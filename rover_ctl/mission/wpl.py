"""QGC WPL 110: the text waypoint format of QGroundControl, Mission Planner and MAVProxy.

A header line ``QGC WPL 110`` then one item per line, 12 columns separated by tabs or spaces::

    seq  current  frame  command  param1  param2  param3  param4  x(lat)  y(lon)  z(alt)  autocontinue

A mission file's row 0 is home, as ArduPilot writes it (NAV_WAYPOINT in frame GLOBAL; lat = lon = 0
means no home; Mission Planner writes command 0 there, read as 16). Fence files (MAV_CMD 5000-5004)
and rally files (5100, what MAVProxy's ``fence save``/``rally save`` write) have no home row: all
their rows are items. Lines starting with ``#`` are comments (MAVProxy writes them). Parsing and
formatting are pure text <-> model; ``files`` does the I/O.
"""

from __future__ import annotations

import math

from rover_ctl.mission.model import (
    FENCE_COMMANDS,
    FRAME_GLOBAL,
    RALLY_COMMANDS,
    Cmd,
    MAX_COMMAND,
    MAX_FRAME,
    Home,
    MissionItem,
    MissionType,
)
from rover_ctl.mission.parsing import HOME_INDEX, Parsed

HEADER = "QGC WPL 110"
COLUMNS = ("seq", "current", "frame", "command", "param1", "param2", "param3", "param4",
           "latitude/x", "longitude/y", "altitude/z", "autocontinue")  # fmt: skip
INT_COLUMNS = frozenset({0, 1, 2, 3, 11})
FLAG_COLUMNS = frozenset({1, 11})
MAX_SEQ = 0xFFFF
"""MISSION_ITEM_INT.seq is a uint16."""
INT_COLUMN_MAX = {0: MAX_SEQ, 1: 1, 2: MAX_FRAME, 3: MAX_COMMAND, 11: 1}
"""Largest value of each integer column: the width of its MISSION_ITEM_INT field (flags are 0/1)."""
MISSION_PLANNER_HOME_COMMAND = 0
"""Mission Planner writes home as command 0; ArduPilot and MAVProxy read it as NAV_WAYPOINT."""
MIN_DECIMALS = 6
"""Numbers are written with MAVProxy's ``%f`` (6 decimals) when that is exact, else with more."""
MAX_DECIMALS = 10


def _kind_of(command: int) -> MissionType:
    if command in FENCE_COMMANDS:
        return MissionType.FENCE
    if command in RALLY_COMMANDS:
        return MissionType.RALLY
    return MissionType.MISSION


def _parse_row(fields: list[str], where: str, errors: list[str]) -> list[float] | None:
    """The 12 numbers of a row, or None after appending one error per bad column."""
    values: list[float] = []
    ok = True
    for col, text in enumerate(fields):
        name = f"column {col + 1} ({COLUMNS[col]})"
        if col in INT_COLUMNS:
            try:
                number = int(text)
            except ValueError:  # also a number of more digits than Python converts
                errors.append(f"{where}: {name} is not a whole number: {text[:40]!r}")
                ok = False
                continue
            if not 0 <= number <= INT_COLUMN_MAX[col]:
                limits = "0 or 1" if col in FLAG_COLUMNS else f"0-{INT_COLUMN_MAX[col]}"
                errors.append(f"{where}: {name} must be {limits}, got {text[:40]}")
                ok = False
                continue
            value = float(number)
        else:
            try:
                value = float(text)
            except ValueError:
                errors.append(f"{where}: {name} is not a number: {text[:40]!r}")
                ok = False
                continue
            if math.isinf(value):
                errors.append(f"{where}: {name} is infinite")
                ok = False
        values.append(value)
    return values if ok else None


def parse_wpl(text: str, source: str) -> Parsed:
    """Parse a QGC WPL 110 file's text; ``source`` names it in messages."""
    parsed = Parsed()
    lines = text.splitlines()
    header = lines[0].strip().lstrip("\ufeff") if lines else ""
    if header != HEADER:
        parsed.errors.append(f"{source}:1: bad header {header[:40]!r}: expected {HEADER!r}")
        return parsed

    rows: list[tuple[str, list[float]]] = []
    for lineno, line in enumerate(lines[1:], start=2):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        where = f"{source}:{lineno}"
        fields = stripped.split()
        if len(fields) != len(COLUMNS):
            parsed.errors.append(
                f"{where}: expected {len(COLUMNS)} columns (seq current frame command param1-4 lat lon alt "
                f"autocontinue), got {len(fields)}"
            )
            continue
        values = _parse_row(fields, where, parsed.errors)
        if values is None:
            continue
        if int(values[0]) != len(rows):
            parsed.errors.append(f"{where}: seq {int(values[0])} out of order (expected {len(rows)})")
        rows.append((where, values))
    if parsed.errors:
        return parsed
    if not rows:
        parsed.errors.append(f"{source}:2: no items after the header (a mission file needs at least the home row)")
        return parsed

    kind = _kind_of(int(rows[0][1][3]))
    if kind == MissionType.MISSION:
        where, home_row = rows[0]
        command = int(home_row[3])
        if command not in (Cmd.NAV_WAYPOINT, MISSION_PLANNER_HOME_COMMAND):
            parsed.errors.append(f"{where}: row 0 must be the home position (command 16), got command {command}")
        elif home_row[8] != 0.0 or home_row[9] != 0.0:
            parsed.labels[(MissionType.MISSION, HOME_INDEX)] = where
            parsed.mission.home = Home(home_row[8], home_row[9], home_row[10])
        rows = rows[1:]
    target = parsed.mission.of_type(kind)
    for where, v in rows:
        command = int(v[3])
        if _kind_of(command) != kind:
            parsed.errors.append(
                f"{where}: command {command} does not belong in a {kind.name.lower()} file "
                f"(missions, fences (5000-5004) and rally points (5100) are separate WPL files)"
            )
            continue
        parsed.labels[(kind, len(target))] = where
        target.append(
            MissionItem(
                command=command, frame=int(v[2]), param1=v[4], param2=v[5], param3=v[6], param4=v[7],
                x=v[8], y=v[9], z=v[10], autocontinue=bool(v[11]),
            )  # fmt: skip
        )
    return parsed


def format_number(value: float) -> str:
    """Shortest of ``%.6f`` .. ``%.10f`` that reads back exactly, else ``repr``; NaN as ``nan``."""
    if math.isnan(value):
        return "nan"
    for decimals in range(MIN_DECIMALS, MAX_DECIMALS + 1):
        text = f"{value:.{decimals}f}"
        if float(text) == value:
            return text
    return repr(value)


def _row(seq: int, item: MissionItem) -> str:
    numbers = (item.param1, item.param2, item.param3, item.param4, item.x, item.y, item.z)
    columns = [str(seq), "0", str(item.frame), str(item.command), *map(format_number, numbers)]
    return "\t".join([*columns, str(int(item.autocontinue))])


def format_wpl(mission_items: list[MissionItem], mission_type: MissionType, home: Home | None = None) -> str:
    """A WPL 110 file of one list: a mission (home row first), a fence or a rally list."""
    lines = [HEADER]
    if mission_type == MissionType.MISSION:
        home_item = MissionItem(command=Cmd.NAV_WAYPOINT, frame=FRAME_GLOBAL)
        if home is not None:
            home_item = MissionItem(
                command=Cmd.NAV_WAYPOINT, frame=FRAME_GLOBAL, x=home.lat_deg, y=home.lon_deg, z=home.alt_m
            )
        lines.append(_row(0, home_item))
        lines.extend(_row(seq, item) for seq, item in enumerate(mission_items, start=1))
    else:
        lines.extend(_row(seq, item) for seq, item in enumerate(mission_items))
    return "\n".join(lines) + "\n"
