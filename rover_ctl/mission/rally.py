"""MAVProxy's legacy rally file: one ``RALLY lat lon alt break_alt land_dir flags`` line per point.

Read only. Each point becomes a NAV_RALLY_POINT (5100) item in frame GLOBAL_RELATIVE_ALT with
autocontinue 0, exactly as MAVProxy converts these files for the mission protocol; break_alt,
land_dir and flags are fixed-wing landing settings with no place in MISSION_ITEM_INT, so they are
dropped (as MAVProxy drops them). A rally list is saved as a WPL file of 5100 items, which is what
MAVProxy's ``rally save`` writes today.
"""

from __future__ import annotations

import math

from rover_ctl.mission.model import FRAME_GLOBAL_RELATIVE_ALT, Cmd, MissionItem, MissionType
from rover_ctl.mission.parsing import Parsed

KEYWORD = "RALLY"
FIELDS = ("latitude", "longitude", "altitude", "break_alt", "land_dir", "flags")


def is_rally_text(text: str) -> bool:
    """Whether the first line that is not blank or a comment starts with ``RALLY``."""
    for line in text.splitlines():
        stripped = line.strip()
        if stripped and not stripped.startswith("#"):
            return stripped.split()[0].upper() == KEYWORD
    return False


def parse_rally(text: str, source: str) -> Parsed:
    parsed = Parsed()
    for lineno, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        where = f"{source}:{lineno}"
        fields = stripped.split()
        if fields[0].upper() != KEYWORD:
            parsed.errors.append(f"{where}: expected a line 'RALLY lat lon alt break_alt land_dir flags', got {fields[0]!r}")
            continue
        if len(fields) != 1 + len(FIELDS):
            parsed.errors.append(f"{where}: expected {1 + len(FIELDS)} columns (RALLY {' '.join(FIELDS)}), got {len(fields)}")
            continue
        values = []
        for name, text_value in zip(FIELDS, fields[1:]):
            try:
                value = float(text_value)
            except ValueError:
                parsed.errors.append(f"{where}: {name} is not a number: {text_value!r}")
                continue
            if not math.isfinite(value):
                parsed.errors.append(f"{where}: {name} is not finite: {text_value!r}")
                continue
            values.append(value)
        if len(values) != len(FIELDS):
            continue
        parsed.labels[(MissionType.RALLY, len(parsed.mission.rally))] = where
        parsed.mission.rally.append(
            MissionItem(
                command=Cmd.NAV_RALLY_POINT, frame=FRAME_GLOBAL_RELATIVE_ALT,
                x=values[0], y=values[1], z=values[2], autocontinue=False,
            )  # fmt: skip
        )
    if not parsed.mission.rally and not parsed.errors:
        parsed.errors.append(f"{source}:1: no RALLY lines")
    return parsed
