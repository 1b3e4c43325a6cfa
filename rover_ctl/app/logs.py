"""Run logs: a MAVLink telemetry log (.tlog) per link and a compact CSV of the control loop.

The .tlog is pymavlink's format, read by ``mavlogdump.py``, MAVExplorer and
``mavutil.mavlink_connection("run.tlog")``: each record is an 8-byte big-endian wall-clock
timestamp in microseconds followed by the raw MAVLink frame. Both directions are logged:
received frames through the connection's message hook, sent frames through the MAVLink
object's send callback.
"""

from __future__ import annotations

import csv
import struct
import time
from pathlib import Path
from typing import Any, Callable, Iterable


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
        usec = int(self._clock() * 1e6) & ~3
        self._file.write(struct.pack(">Q", usec) + bytes(buf))
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
        self._writer = csv.DictWriter(self._file, fieldnames=self.columns, extrasaction="raise")
        self._writer.writeheader()
        self.rows = 0

    def write(self, row: dict[str, Any]) -> None:
        self._writer.writerow({k: round(v, self._digits) if isinstance(v, float) else v for k, v in row.items()})
        self.rows += 1

    def flush(self) -> None:
        self._file.flush()

    def close(self) -> None:
        if not self._file.closed:
            self._file.close()
