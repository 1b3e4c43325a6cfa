"""Persistence of the parameters a ground station set, as ArduPilot keeps its parameters in EEPROM.

One ``.parm`` file (MAVProxy / Mission Planner format: ``NAME VALUE`` per line, ``#`` comments) in
the state directory, next to the mission store: ``params.parm`` beside ``gcs.mission_store_path``
(default ``~/.local/state/rover-ctl/``; no persistence when the mission store is off). It holds
only the parameters that were set, not the whole table, so a new default in a later release still
applies to the parameters nobody changed.

``save`` is atomic (temporary file in the same directory, fsync, rename, fsync of the directory):
a crash leaves the old or the new file, never a torn one. ``load`` of a missing file is empty; a
file with any bad line raises ``ParamStoreError`` and ``quarantine`` moves it aside
(``params.parm.corrupt``, ``.corrupt.1``, ...), so it is never silently overwritten.
"""

from __future__ import annotations

import os
from pathlib import Path

from rover_ctl.config import Config
from rover_ctl.mission.store import write_atomically
from rover_ctl.parameters import ParamError, format_parm, parse_parm

FILE_NAME = "params.parm"
HEADER = "rover-ctl parameters set from a ground station (rover-ctl params shows them all)"


class ParamStoreError(ValueError):
    """The store file cannot be used; the message names it and the bad line."""


def store_path(config: Config) -> Path | None:
    """Where the daemon persists parameters: beside the mission store, or None when that is off."""
    mission_store = config.gcs.mission_store_path
    return Path(mission_store).expanduser().with_name(FILE_NAME) if mission_store else None


class ParamStore:
    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)

    def load(self) -> dict[str, float]:
        """Stored name -> value (checked against the table); {} when there is no file yet."""
        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return {}
        except (OSError, UnicodeDecodeError) as exc:
            raise ParamStoreError(f"{self.path}: cannot read: {exc}") from None
        try:
            parsed = parse_parm(text, str(self.path))
        except ParamError as exc:
            raise ParamStoreError(str(exc)) from None
        return {name: param.encode(value) for name, (param, value) in parsed.items()}

    def save(self, values: dict[str, float]) -> None:
        """Replace the file with ``values`` atomically; OSError if it cannot be written."""
        write_atomically(self.path, format_parm(values, HEADER))

    def quarantine(self) -> Path | None:
        """Move the file aside to the first free ``.corrupt[.N]`` name; None if that failed."""
        for n in range(1000):
            aside = self.path.with_name(self.path.name + (".corrupt" if n == 0 else f".corrupt.{n}"))
            if aside.exists():
                continue
            try:
                os.replace(self.path, aside)
            except OSError:
                return None
            return aside
        return None
