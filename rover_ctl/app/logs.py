"""Run logs: numbered run folders, a MAVLink telemetry log (.tlog) per link, the control CSV,
and pymavlink's console chatter kept out of the way.

Run folders, as ArduPilot numbers its logs: each start of the daemon writes into a new folder
``LOG_DIR/00000012/`` (one more than the highest there), ``LOG_DIR/latest`` is a symlink to it,
and the oldest run folders are removed while all of them together exceed a size budget (never
the new one). An earlier run is never overwritten.

The .tlog is pymavlink's format, read by ``mavlogdump.py``, MAVExplorer and
``mavutil.mavlink_connection("run.tlog")``: each record is an 8-byte big-endian timestamp in
microseconds followed by the raw MAVLink frame. Both directions are logged: received frames
through the connection's message hook, sent frames through the MAVLink object's send callback.
pymavlink's own ``mavfile.setup_logfile`` does not fit: it stamps the wall clock and logs only
what ``recv_msg`` returns (the vehicle link parses whole buffers, and sent frames are missed).
The timestamps come from a ``LogClock``: vehicle time in a lockstep run, so a log replays with the
mission's real duration.
"""

from __future__ import annotations

import contextlib
import csv
import logging
import os
import re
import shutil
import struct
import time
from pathlib import Path
from itertools import repeat
from typing import Any, Callable, Iterable

RUN_NAME = re.compile(r"^\d{8}$")
"""A run folder's name: eight digits, as ArduPilot's 00000012.BIN."""
LATEST = "latest"
"""The symlink to the newest run folder."""
TLOG_STAMP = struct.Struct(">Q")
"""A .tlog record's timestamp: microseconds, big-endian, before the frame."""


class LogDirError(RuntimeError):
    """The log directory cannot be written; one line."""


def run_folders(root: Path) -> list[Path]:
    """The run folders under ``root``, oldest (lowest number) first."""
    if not root.is_dir():
        return []
    return sorted((p for p in root.iterdir() if RUN_NAME.match(p.name) and p.is_dir() and not p.is_symlink()), key=lambda p: int(p.name))


def folder_size_bytes(folder: Path) -> int:
    total = 0
    for dirpath, _dirs, files in os.walk(folder):
        for name in files:
            try:
                total += os.lstat(os.path.join(dirpath, name)).st_size
            except OSError:
                pass  # removed meanwhile
    return total


def _why(exc: OSError) -> str:
    """A folder that cannot be made, said plainly ("File exists" was all mkdir said of a file)."""
    if isinstance(exc, (FileExistsError, NotADirectoryError)):
        return "a file is in the way: it, or a folder above it, is a file, not a folder"
    return exc.strerror or str(exc)


def new_run_folder(root: str | Path, max_total_mb: float) -> Path:
    """Create the next numbered run folder under ``root``, point ``root/latest`` at it and prune
    the oldest ones while the run folders together exceed ``max_total_mb`` (0: no limit).
    Raises LogDirError when ``root`` cannot be written."""
    root = Path(root).expanduser()
    latest = root / LATEST
    run = pointer = None
    try:
        if latest.exists() and not latest.is_symlink():  # checked first: nothing is made for a run that cannot start
            raise LogDirError(f"log dir {root}: {latest} is not the link this program keeps there; move it away")
        root.mkdir(parents=True, exist_ok=True)
        existing = run_folders(root)
        number = int(existing[-1].name) + 1 if existing else 1
        while True:
            run = root / f"{number:08d}"
            try:
                run.mkdir()  # atomic: two daemons sharing a log dir never get the same folder
                break
            except FileExistsError:
                number += 1
        pointer = root / f".{LATEST}.{os.getpid()}"
        pointer.unlink(missing_ok=True)
        pointer.symlink_to(run.name)
        os.replace(pointer, latest)  # atomic: readers see the old or the new run, never none
    except OSError as exc:
        for leftover in (pointer, run):  # nothing half-made stays behind
            with contextlib.suppress(OSError):
                if leftover is not None and leftover.is_symlink():
                    leftover.unlink()
                elif leftover is not None:
                    leftover.rmdir()  # only if still empty
        raise LogDirError(f"log dir {root}: {_why(exc)}") from None
    prune_runs(root, max_total_mb, keep=run)
    return run


def given_run_folder(folder: str | Path) -> Path:
    """A folder named by the caller as this run's own (``rover-ctl sim`` numbers its runs
    itself): created if needed, checked writable. Raises LogDirError."""
    folder = Path(folder).expanduser()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / f".write-test.{os.getpid()}"
        probe.touch()
        probe.unlink()
    except OSError as exc:
        raise LogDirError(f"log folder {folder}: {_why(exc)}") from None
    return folder


def prune_runs(root: Path, max_total_mb: float, keep: Path) -> list[Path]:
    """Remove the oldest run folders (never ``keep``) until the rest fit in ``max_total_mb``."""
    if max_total_mb <= 0:
        return []
    runs = run_folders(root)
    sizes = {run: folder_size_bytes(run) for run in runs}
    total = sum(sizes.values())
    removed = []
    for run in runs:
        if total <= max_total_mb * 1e6:
            break
        if run == keep:
            continue
        shutil.rmtree(run, ignore_errors=True)
        total -= sizes[run]
        removed.append(run)
    return removed


class LogClock:
    """Timestamps for the tlogs: the wall clock (as MAVProxy stamps its logs) until
    ``vehicle_time_s()`` gives a time, i.e. the vehicle drives time in lockstep; from then on
    vehicle time, placed at the wall time of the switch so the log stays continuous. A lockstep
    run at 20x real time then replays in MAVExplorer with its sim duration, not its wall one."""

    def __init__(self, vehicle_time_s: Callable[[], float | None], wall: Callable[[], float] = time.time):
        self._vehicle_time_s = vehicle_time_s
        self._wall = wall
        self._offset_s: float | None = None
        self._last_s = 0.0

    def __call__(self) -> float:
        vehicle_s = self._vehicle_time_s()
        if vehicle_s is None:
            now = self._wall() if self._offset_s is None else self._last_s
        else:
            if self._offset_s is None:
                self._offset_s = self._wall() - vehicle_s
            now = self._offset_s + vehicle_s
        self._last_s = max(self._last_s, now)  # a rebooted vehicle must not make the log go back
        return self._last_s


class TlogWriter:
    """Appends every frame seen on one or more pymavlink connections to a .tlog file."""

    def __init__(self, path: str | Path, clock: Callable[[], float] = time.time):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb")
        self._clock = clock
        self.frames = 0

    def attach(self, conn: Any) -> None:
        """Log what ``conn`` (a ``mavutil.mavfile``) receives and sends from now on."""
        conn.message_hooks.append(lambda _conn, msg: self.write(msg))
        conn.mav.set_send_callback(self.write)

    def write(self, msg: Any) -> None:
        if self._file.closed or msg.get_type() == "BAD_DATA":
            return
        buf = msg.get_msgbuf()
        if not buf:
            return
        # pymavlink's readers expect the low two bits clear (they mark other record kinds).
        self._file.write(TLOG_STAMP.pack(int(self._clock() * 1e6) & ~3) + buf)
        self.frames += 1

    def close(self) -> None:
        if not self._file.closed:
            self._file.close()


class CsvLog:
    """The control loop's CSV: one row per control step, fixed columns, floats rounded."""

    def __init__(self, path: str | Path, columns: Iterable[str], digits: int = 4):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.columns = list(columns)
        self._digits = digits
        self._file = open(self.path, "w", newline="", encoding="utf-8")
        self._names = frozenset(self.columns)
        # csv.DictWriter's output, one list per row: it rebuilt a dict and a set for every row.
        self._writer = csv.writer(self._file)
        self._writer.writerow(self.columns)
        self.rows = 0

    def write(self, row: dict[str, Any]) -> None:
        """One row; a missing column is empty, an unknown one a ValueError (as DictWriter's "raise")."""
        if not row.keys() <= self._names:
            raise ValueError(f"dict contains fields not in fieldnames: {', '.join(map(repr, row.keys() - self._names))}")
        digits = self._digits
        self._writer.writerow([round(v, digits) if isinstance(v, float) else v for v in map(row.get, self.columns, repeat(""))])
        self.rows += 1

    def flush(self) -> None:
        self._file.flush()

    def close(self) -> None:
        if not self._file.closed:
            self._file.close()


class Chatter:
    """A ``print`` for pymavlink's module: its connection messages ("Connection reset or closed by
    peer on TCP socket", "[Errno 111] Connection refused sleeping", printed on every reconnect
    attempt) go to ``logger``, each distinct line at most once per ``interval_s`` with a count
    of the repeats held back, so a vehicle that is away for an hour does not flood the log."""

    def __init__(self, logger: logging.Logger, interval_s: float, clock: Callable[[], float] = time.monotonic):
        self.logger = logger
        self.interval_s = interval_s
        self._clock = clock
        self._last: dict[str, tuple[float, int]] = {}
        """line -> (when it was last logged, repeats held back since)."""

    def __call__(self, *args: Any, sep: str | None = " ", **_ignored: Any) -> None:
        line = (" " if sep is None else sep).join(str(a) for a in args).strip()
        if not line:
            return
        now = self._clock()
        last = self._last.get(line)
        if last is not None and now - last[0] < self.interval_s:
            self._last[line] = (last[0], last[1] + 1)
            return
        held = last[1] if last is not None else 0
        self._last[line] = (now, 0)
        self.logger.warning("%s%s", line, f" (and {held} times more in {now - last[0]:.0f} s)" if held else "")


def quiet_pymavlink(logger: logging.Logger, interval_s: float) -> Chatter:
    """Route pymavlink's prints through a ``Chatter`` (a module global shadows the builtin)."""
    from pymavlink import mavutil

    chatter = Chatter(logger, interval_s)
    mavutil.print = chatter
    return chatter
