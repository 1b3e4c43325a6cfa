"""A serial line in one direction: a telemetry radio or a UART, as bytes in time (pure, no I/O).

8N1 framing (start bit, 8 data bits, stop bit): a byte takes 10 bit times, so the line carries
``baud / 10`` bytes per second. Bytes offered enter a bounded buffer (a SiK radio holds about 2 KB)
and leave it one after another at the line rate, in order; bytes that find the buffer full are
lost (tail drop, counted), as on a radio without flow control. Each byte leaving is corrupted with
probability ``byte_error`` (replaced by a different byte drawn at random; counted).

Time is whatever clock the caller passes, in seconds, never going back: sim time in the emulator
(``rover-sitl --pty --baud``), vehicle time (wall time x speed-up) in the relay to ArduPilot's
firmware (``sitl.line_relay``). Used by both, one instance per direction.
"""

from __future__ import annotations

import math
import random
from collections import deque
from dataclasses import asdict, dataclass

BITS_PER_BYTE = 10
"""8N1: a start bit, 8 data bits and a stop bit per byte."""
DEFAULT_BUFFER_BYTES = 2048
"""A SiK telemetry radio's serial buffer (its firmware's 2 KB transmit FIFO)."""
TIME_EPSILON_BYTES = 1e-9
"""Slack, in bytes, on ``elapsed x rate`` so float rounding never holds back a byte that is due."""


class LineError(ValueError):
    """A bad line parameter; the message is one line."""


@dataclass
class LineStats:
    """Counters of one direction of a line, in bytes. Always ``offered = delivered +
    dropped_overflow + buffered`` (corrupted bytes are delivered, changed)."""

    offered: int = 0
    delivered: int = 0
    dropped_overflow: int = 0
    corrupted: int = 0
    buffered: int = 0
    peak_buffer_bytes: int = 0

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


def check_line(baud: float, byte_error: float = 0.0, buffer_bytes: int = DEFAULT_BUFFER_BYTES) -> None:
    """Raise LineError unless baud > 0, 0 <= byte_error < 1 and buffer_bytes >= 1."""
    if not (math.isfinite(baud) and baud > 0):
        raise LineError(f"baud must be a positive number, got {baud!r}")
    if not 0.0 <= byte_error < 1.0:
        raise LineError(f"byte error probability must be in [0, 1), got {byte_error!r}")
    if buffer_bytes < 1:
        raise LineError(f"buffer must hold at least 1 byte, got {buffer_bytes!r}")


class SerialLine:
    """One direction of a serial line: ``offer`` bytes at a time, ``take`` what has left by a time."""

    def __init__(self, baud: float, byte_error: float = 0.0, buffer_bytes: int = DEFAULT_BUFFER_BYTES,
                 seed: int = 1) -> None:  # fmt: skip
        check_line(baud, byte_error, buffer_bytes)
        self.baud = baud
        self.byte_error = byte_error
        self.buffer_bytes = buffer_bytes
        self.bytes_per_s = baud / BITS_PER_BYTE
        self.stats = LineStats()
        self._queue = bytearray()
        """Bytes in the buffer, oldest first."""
        self._out = bytearray()
        """Bytes that have left the line and not yet been taken."""
        self._run_start_s = 0.0
        """When the current back-to-back run of bytes started leaving (the line is busy since)."""
        self._run_sent = 0
        """Bytes of the current run that have left."""
        self._now_s = -math.inf
        self._rng = random.Random(seed)
        self._clean_bytes = self._clean_run()
        """Bytes that will leave intact before the next corrupted one."""

    # ---- what callers use ------------------------------------------------------------------
    def offer(self, data: bytes, t_s: float, whole: bool = False) -> int:
        """Offer ``data`` at time ``t_s``; returns how many bytes the buffer took (the rest are
        dropped). ``whole``: all of it or nothing, as a sender that checks the room first (ArduPilot
        sends a MAVLink message only if its port has space for all of it)."""
        self._advance(t_s)
        if not self._queue:
            self._run_start_s, self._run_sent = self._now_s, 0  # idle line: the first byte starts now
        accepted = min(len(data), self.buffer_bytes - len(self._queue))
        if whole and accepted < len(data):
            accepted = 0
        self._queue += data[:accepted]
        self.stats.offered += len(data)
        self.stats.dropped_overflow += len(data) - accepted
        self.stats.buffered = len(self._queue)
        self.stats.peak_buffer_bytes = max(self.stats.peak_buffer_bytes, len(self._queue))
        return accepted

    def take(self, t_s: float) -> bytes:
        """Every byte that has left the line by ``t_s`` and was not taken yet, in order."""
        self._advance(t_s)
        out, self._out = bytes(self._out), bytearray()
        return out

    def next_departure_s(self) -> float | None:
        """When the next buffered byte will have left (None: the buffer is empty)."""
        if not self._queue:
            return None
        return self._run_start_s + (self._run_sent + 1) / self.bytes_per_s

    @property
    def buffered(self) -> int:
        return len(self._queue)

    # ---- the model ---------------------------------------------------------------------------
    def _advance(self, t_s: float) -> None:
        """Move the bytes whose last bit has gone by ``t_s`` from the buffer to the output."""
        self._now_s = max(self._now_s, t_s)
        if not self._queue:
            return
        gone = math.floor((self._now_s - self._run_start_s) * self.bytes_per_s + TIME_EPSILON_BYTES) - self._run_sent
        n = max(0, min(len(self._queue), gone))
        if n == 0:
            return
        chunk = self._queue[:n]
        del self._queue[:n]
        self._run_sent += n
        self._corrupt(chunk)
        self._out += chunk
        self.stats.delivered += n
        self.stats.buffered = len(self._queue)

    def _corrupt(self, chunk: bytearray) -> None:
        """Corrupt bytes of ``chunk`` in place: geometric gaps between errors, one draw per error."""
        pos = 0
        while self._clean_bytes < len(chunk) - pos:
            pos += self._clean_bytes
            chunk[pos] ^= self._rng.randrange(1, 256)  # uniform over the 255 other values
            self.stats.corrupted += 1
            pos += 1
            self._clean_bytes = self._clean_run()
        self._clean_bytes -= len(chunk) - pos

    def _clean_run(self) -> float:
        """Intact bytes before the next error: geometric with success probability ``byte_error``."""
        if self.byte_error == 0.0:
            return math.inf
        return math.floor(math.log(1.0 - self._rng.random()) / math.log(1.0 - self.byte_error))


class FrameGate:
    """Holds back the bytes of a partly delivered frame so a reader only ever gets whole frames.

    A SiK radio in its MAVLink framing mode sends whole frames in its air packets; the emulator
    also needs frame boundaries on the wire to slip its lockstep marker between two frames. It
    is told the size each offered frame had in the line's buffer (``accepted``; a frame cut by
    overflow counts as its kept head), and cuts the line's output at those sizes.
    """

    def __init__(self) -> None:
        self._sizes: deque[int] = deque()
        self._held = bytearray()

    def accepted(self, size: int) -> None:
        if size > 0:
            self._sizes.append(size)

    def release(self, data: bytes) -> bytes:
        """Add ``data`` from the line; return the whole frames now complete."""
        self._held += data
        whole = 0
        while self._sizes and self._sizes[0] <= len(self._held) - whole:
            whole += self._sizes.popleft()
        out = bytes(self._held[:whole])
        del self._held[:whole]
        return out
