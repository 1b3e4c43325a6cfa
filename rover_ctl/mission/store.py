"""Persistence of the vehicle's current mission, fence and rally points.

The store is one JSON file holding the model losslessly (floats as JSON numbers; NaN params as
Python's json writes them). ``save`` is atomic: write a temporary file in the same directory,
fsync it, rename it over the store, fsync the directory; a crash leaves either the old or the new
file, never a torn one. ``load`` of a missing file is an empty mission; a file that cannot be read
raises ``StoreError`` naming the file and the problem, and ``quarantine`` moves it aside
(``<name>.corrupt``, ``<name>.corrupt.1``, ...) so it is never silently overwritten. ``load`` checks
types only: a readable store whose plan breaks the mission rules (written by an older version)
still loads, and the planner and executor leave its invalid parts out.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Any

from rover_ctl.mission.model import Home, Mission, MissionItem

FORMAT = "rover_ctl-mission-store"
VERSION = 1


NUMBER_FIELDS = ("command", "frame", "param1", "param2", "param3", "param4", "x", "y", "z")
INT_FIELDS = ("command", "frame")


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


class StoreError(ValueError):
    """The store file is unreadable or not a mission store; the message names it."""


def to_json(mission: Mission) -> dict[str, Any]:
    return {
        "format": FORMAT,
        "version": VERSION,
        "home": dataclasses.asdict(mission.home) if mission.home else None,
        "items": [dataclasses.asdict(i) for i in mission.items],
        "fence": [dataclasses.asdict(i) for i in mission.fence],
        "rally": [dataclasses.asdict(i) for i in mission.rally],
    }


def from_json(data: Any, where: str) -> Mission:
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise StoreError(f"{where}: not a rover_ctl mission store (no \"format\": \"{FORMAT}\")")
    if data.get("version") != VERSION:
        raise StoreError(f"{where}: unsupported store version {data.get('version')!r} (expected {VERSION})")

    def items(key: str) -> list[MissionItem]:
        rows = data.get(key)
        if not isinstance(rows, list):
            raise StoreError(f"{where}: \"{key}\" must be a list")
        out = []
        for index, row in enumerate(rows):
            try:
                item = MissionItem(**row)
            except TypeError as exc:
                raise StoreError(f"{where}: {key}[{index}]: {exc}") from None
            bad = [name for name in NUMBER_FIELDS if not _is_number(getattr(item, name))]
            bad += [name for name in INT_FIELDS if name not in bad and not isinstance(getattr(item, name), int)]
            if bad or not isinstance(item.autocontinue, bool):
                raise StoreError(f"{where}: {key}[{index}]: {', '.join(bad) or 'autocontinue'} has the wrong type")
            out.append(item)
        return out

    home = data.get("home")
    try:
        home = Home(**home) if home is not None else None
    except TypeError as exc:
        raise StoreError(f"{where}: home: {exc}") from None
    if home is not None and not all(_is_number(v) for v in (home.lat_deg, home.lon_deg, home.alt_m)):
        raise StoreError(f"{where}: home: coordinates must be numbers")
    return Mission(items=items("items"), home=home, fence=items("fence"), rally=items("rally"))


def write_atomically(path: Path, text: str) -> None:
    """Replace ``path`` with ``text`` so that a crash leaves the old file or the new one, never a
    mix: a temporary file beside it, fsync, rename, fsync of the directory. OSError if it cannot."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    dir_fd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)


def mission_digest(mission: Mission) -> str:
    """A short fingerprint of the mission's items: progress belongs to one mission."""
    text = json.dumps(to_json(mission)["items"], sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


class MissionStore:
    """The store file at ``path`` (``~`` expanded; parent directories created on save)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path).expanduser()

    def load(self) -> Mission:
        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return Mission()
        except (OSError, UnicodeDecodeError) as exc:
            raise StoreError(f"{self.path}: cannot read mission store: {exc}") from None
        try:
            data = json.loads(text)
        except (ValueError, RecursionError) as exc:  # JSONDecodeError, a 5000-digit number, nesting
            raise StoreError(f"{self.path}: corrupt mission store: {str(exc).splitlines()[0] or type(exc).__name__}") from None
        return from_json(data, str(self.path))

    def save(self, mission: Mission) -> None:
        """Atomically replace the store with ``mission`` (raises OSError if it cannot)."""
        write_atomically(self.path, json.dumps(to_json(mission), indent=1))

    @property
    def progress_path(self) -> Path:
        return self.path.with_name(self.path.name + ".progress")

    def save_progress(self, mission: Mission, seq: int) -> None:
        """Remember that ``mission`` is at item ``seq`` (atomic; raises OSError if it cannot)."""
        write_atomically(self.progress_path, json.dumps({"mission": mission_digest(mission), "seq": int(seq)}))

    def load_progress(self, mission: Mission) -> int | None:
        """The item ``mission`` was at when last saved; None if unknown or saved for another mission."""
        try:
            data = json.loads(self.progress_path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError, RecursionError):
            return None
        if not isinstance(data, dict) or data.get("mission") != mission_digest(mission):
            return None
        seq = data.get("seq")
        return seq if isinstance(seq, int) and not isinstance(seq, bool) and seq >= 1 else None

    def quarantine(self) -> Path | None:
        """Move an unreadable store file aside and return where it went (None: no such file)."""
        if not self.path.is_file():
            return None
        target = self.path.with_name(self.path.name + ".corrupt")
        n = 0
        while target.exists():
            n += 1
            target = self.path.with_name(f"{self.path.name}.corrupt.{n}")
        os.replace(self.path, target)
        return target
