"""Run logs: numbered run folders, a MAVLink telemetry log (.tlog) per link, the control CSV,
and pymavlink's console chatter kept out of the way.

Run folders, as ArduPilot numbers its logs: each start of the daemon writes into a new folder
``LOG_DIR/00000012/`` (one more than the highest there), ``LOG_DIR/latest`` is a symlink to it,
and the oldest run folders are removed while all of them together exceed a size budget (never
the new one). An earlier run is never overwritten. During the run the tlogs stop writing, with
one warning, once the run's own folder exceeds that budget (``LogBudget``): a flood of frames on
the GCS link cannot fill the disk.

The .tlog is pymavlink's format, read by ``mavlogdump.py``, MAVExplorer and
``mavutil.mavlink_connection("run.tlog")``: each record is an 8-byte big-endian timestamp in
microseconds followed by the raw MAVLink frame. Both directions are logged: received frames
through the connection's message hook (the GCS link runs it only for frames that passed its
signature check and gate), sent frames through the MAVLink object's send callback.
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
MEASURE_EVERY_BYTES = 1_000_000
"""``LogBudget`` measures the run folder again after the tlogs wrote this much (the control CSV
and the event log grow meanwhile too); a measurement is a few ``lstat`` calls."""

log = logging.getLogger(__name__)


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


class LogBudget:
    """``daemon.log_max_total_mb`` during a run: once the run's folder holds more than that, the
    tlogs sharing this budget stop writing (``full``), with one warning and one call of
    ``on_full(size_bytes)`` (the daemon writes a ``log_budget`` event). 0: no limit. The size is
    what the tlogs wrote, counted as they write it, plus the rest of the folder (the control CSV,
    the event log) as measured at the start and after every ``MEASURE_EVERY_BYTES`` of tlog."""

    def __init__(self, folder: str | Path, max_total_mb: float, on_full: Callable[[int], Any] | None = None,
                 measure_every_bytes: int = MEASURE_EVERY_BYTES) -> None:  # fmt: skip
        self.folder = Path(folder)
        self.max_total_mb = max_total_mb
        self.on_full = on_full
        self.measure_every_bytes = measure_every_bytes
        self.full = False
        self._tlogs: list[Path] = []
        self._tlog_bytes = 0
        """What the tlogs wrote (in their files' buffers or on disk)."""
        self._others = 0
        """The rest of the folder when last measured."""
        self._unmeasured = 0
        """Tlog bytes since that measurement."""
        self._measure()

    def track(self, path: str | Path) -> None:
        """A tlog (a new, empty file in the folder) whose writes this budget counts."""
        self._tlogs.append(Path(path))

    @property
    def size_bytes(self) -> int:
        return self._others + self._tlog_bytes

    def _measure(self) -> None:
        if self.max_total_mb <= 0:
            return
        on_disk = 0
        for path in self._tlogs:
            with contextlib.suppress(OSError):
                on_disk += os.lstat(path).st_size
        self._others = max(folder_size_bytes(self.folder) - on_disk, 0)
        self._unmeasured = 0

    def allow(self, n_bytes: int) -> bool:
        """Whether a tlog may write ``n_bytes`` more (counted as written if so)."""
        if self.full:
            return False
        if self.max_total_mb <= 0:
            return True
        self._unmeasured += n_bytes
        if self._unmeasured >= self.measure_every_bytes:
            self._measure()
        if self.size_bytes + n_bytes <= self.max_total_mb * 1e6:
            self._tlog_bytes += n_bytes
            return True
        self.full = True
        log.warning("logs: %s holds more than the log budget (daemon.log_max_total_mb, LOG_MAX_MB: %g MB): "
                    "the tlogs stop here for this run", self.folder, self.max_total_mb)  # fmt: skip
        if self.on_full is not None:
            self.on_full(self.size_bytes + n_bytes)
        return False


class TlogWriter:
    """Appends every frame seen on one or more pymavlink connections to a .tlog file, while the
    run's ``LogBudget`` allows; a write that fails (a full disk) stops it, with one warning."""

    def __init__(self, path: str | Path, clock: Callable[[], float] = time.time, budget: LogBudget | None = None):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb")
        self._clock = clock
        self.budget = budget
        if budget is not None:
            budget.track(self.path)
        self.frames = 0
        self.unwritten = 0
        """Frames not written: over the budget, or after a failed write."""
        self.failed: str | None = None

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
        if self.failed is not None or (self.budget is not None and not self.budget.allow(TLOG_STAMP.size + len(buf))):
            self.unwritten += 1
            return
        try:
            # pymavlink's readers expect the low two bits clear (they mark other record kinds).
            self._file.write(TLOG_STAMP.pack(int(self._clock() * 1e6) & ~3) + buf)
        except OSError as exc:  # the disk is full: the link goes on without its tlog
            self.failed = str(exc)
            self.unwritten += 1
            log.warning("logs: %s: %s; not written from here on", self.path, exc)
            return
        self.frames += 1

    def close(self) -> None:
        _close_quietly(self._file, self.path)


def _close_quietly(handle, path: Path) -> None:
    """Close a log file; a flush that fails now (a full disk) loses the tail, not the shutdown."""
    if handle.closed:
        return
    try:
        handle.close()
    except OSError as exc:
        log.warning("logs: %s: %s on closing; its last lines are lost", path, exc)


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
        self.failed: str | None = None
        """Why writing stopped (a full disk): the control loop goes on without its CSV."""

    def write(self, row: dict[str, Any]) -> None:
        """One row; a missing column is empty, an unknown one a ValueError (as DictWriter's "raise")."""
        if not row.keys() <= self._names:
            raise ValueError(f"dict contains fields not in fieldnames: {', '.join(map(repr, row.keys() - self._names))}")
        if self.failed is not None:
            return
        digits = self._digits
        try:
            self._writer.writerow([round(v, digits) if isinstance(v, float) else v for v in map(row.get, self.columns, repeat(""))])
        except OSError as exc:
            self._fail(exc)
            return
        self.rows += 1

    def flush(self) -> None:
        if self.failed is None:
            try:
                self._file.flush()
            except OSError as exc:
                self._fail(exc)

    def _fail(self, exc: OSError) -> None:
        self.failed = str(exc)
        log.warning("logs: %s: %s; not written from here on", self.path, exc)

    def close(self) -> None:
        _close_quietly(self._file, self.path)


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
