"""Mission files on disk: load (detect the format, parse, validate) and save (atomically).

Formats, detected from the content first and the extension second:
- QGC WPL 110 text (``.waypoints``, ``.txt``): a mission, or a fence (MAV_CMD 5000-5004), or a
  rally list (5100) -- ``rover_ctl.mission.wpl``;
- QGroundControl ``.plan`` JSON: mission, geofence and rally points -- ``rover_ctl.mission.plan``;
- MAVProxy's legacy ``RALLY`` lines (read only) -- ``rover_ctl.mission.rally``.

A file loads whole or not at all: any syntax or validation error raises ``MissionFileError``
listing every problem found. Saving writes a temporary file beside the target, fsyncs it and
renames it over the target, so a crash leaves either the old file or the new one.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from rover_ctl import inputfile
from rover_ctl.config import RobotParams
from rover_ctl.mission import plan, rally, wpl
from rover_ctl.mission.model import Mission, MissionType
from rover_ctl.mission.parsing import MissionFileError, Parsed
from rover_ctl.mission.summary import MissionSummary, summarize
from rover_ctl.mission.validate import validate

__all__ = ["LoadedMission", "MissionFileError", "MissionSummary", "load_mission", "save_mission", "summarize", "validate"]

WPL_SUFFIXES = frozenset({".waypoints", ".txt"})
PLAN_SUFFIX = ".plan"


@dataclass
class LoadedMission:
    """A loaded mission and its warnings (one line each, "file:line: what")."""

    mission: Mission
    warnings: list[str] = field(default_factory=list)
    format: str = "wpl"
    """Which format it was read from: "wpl", "plan" or "rally"."""


def parse_text(text: str, source: str, suffix: str = "") -> tuple[str, Parsed]:
    """Detect the format of ``text`` (content first, then ``suffix``) and parse it."""
    head = text.lstrip("\ufeff \t\r\n")
    if head.startswith("{") or (suffix == PLAN_SUFFIX and not head.startswith("QGC WPL")):
        return "plan", plan.parse_plan(text, source)
    if rally.is_rally_text(text):
        return "rally", rally.parse_rally(text, source)
    if head.startswith("QGC WPL") or suffix in WPL_SUFFIXES:
        return "wpl", wpl.parse_wpl(text, source)
    first = head.splitlines()[0][:40] if head else ""
    raise MissionFileError(
        [f"{source}:1: unknown mission file format (starts with {first!r}): expected 'QGC WPL 110', "
         "a QGroundControl .plan (JSON) or MAVProxy RALLY lines"]
    )  # fmt: skip


def load_mission(path: str | os.PathLike, max_speed_mps: float | None = None) -> LoadedMission:
    """Read, parse and validate a mission file; raise ``MissionFileError`` if anything is wrong.

    ``max_speed_mps`` (default: the rover's ``RobotParams().max_speed_mps``) is the speed above
    which DO_CHANGE_SPEED is warned as clamped.
    """
    path = Path(path)
    source = str(path)
    try:
        data = inputfile.read_bytes(path)
    except FileNotFoundError:
        raise MissionFileError([f"{source}: no such file"]) from None
    except IsADirectoryError:
        raise MissionFileError([f"{source}: is a directory, not a mission file"]) from None
    except OSError as exc:
        raise MissionFileError([f"{source}: cannot read: {exc.strerror}"]) from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise MissionFileError([f"{source}:{line}: not a text file (invalid UTF-8 at byte {exc.start})"]) from None
    if not text.strip():
        raise MissionFileError([f"{source}:1: empty file"])

    kind, parsed = parse_text(text, source, path.suffix.lower())
    if parsed.errors:
        raise MissionFileError(parsed.errors)
    if max_speed_mps is None:
        max_speed_mps = RobotParams().max_speed_mps
    errors, warnings = validate(parsed.mission, max_speed_mps, parsed.labels)
    if errors:
        raise MissionFileError(errors)
    return LoadedMission(parsed.mission, parsed.warnings + warnings, kind)


def format_for(mission: Mission, path: Path) -> str:
    """The text ``save_mission`` writes for ``path`` (format by extension)."""
    suffix = path.suffix.lower()
    if suffix == PLAN_SUFFIX:
        return plan.format_plan(mission)
    if suffix not in WPL_SUFFIXES:
        raise MissionFileError([f"{path}: unknown extension {suffix!r}: use .plan, .waypoints or .txt"])
    # Home belongs to the mission list, but a fence or rally alone is written without it.
    parts = [t for t in MissionType if mission.of_type(t)]
    if len(parts) > 1:
        sizes = ", ".join(f"{len(mission.of_type(t))} {t.name.lower()}" for t in parts)
        raise MissionFileError(
            [f"{path}: a WPL file holds one list but this mission has {sizes} items: save it as .plan, "
             "or save the mission, fence and rally lists to separate WPL files"]
        )  # fmt: skip
    kind = parts[0] if parts else MissionType.MISSION
    return wpl.format_wpl(mission.of_type(kind), kind, mission.home)


def save_mission(mission: Mission, path: str | os.PathLike) -> None:
    """Write ``mission`` to ``path``: ``.plan`` as QGC plan JSON, ``.waypoints``/``.txt`` as WPL 110
    (a mission with its home row; a mission with only fence or only rally items as a fence or
    rally WPL, without home). A WPL file holds one list: a mission with items in more than one
    list is refused for WPL rather than written in part.

    Atomic: temp file in the same directory, fsync, rename, fsync the directory.
    """
    path = Path(path)
    text = format_for(mission, path)
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise MissionFileError([f"{path}: directory {directory} does not exist"])
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as handle:
            handle.write(text)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp_name, path)
    except BaseException:
        Path(tmp_name).unlink(missing_ok=True)
        raise
    dir_fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)
