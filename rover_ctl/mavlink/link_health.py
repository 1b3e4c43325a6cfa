"""What the vehicle link actually carries: each message's rate, the bytes, and what was lost.

Fed by ``VehicleLink`` with every frame from the vehicle (its name, size, sequence number and the
vehicle time at receipt) and every frame that failed (bad CRC, or bytes that are no MAVLink).
It measures, over the last ``window_s`` of vehicle time, the rate of each message and the bytes
per second; and over the whole run the frames lost, from gaps in the MAVLink ``seq`` counter of
each (system, component), and the frames dropped for a bad CRC. The daemon reports these in its
log, to the ground station (SYS_STATUS ``drop_rate_comm`` and ``errors_comm``, as ArduPilot fills
them) and to the failsafes (odometry rates).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

SEQ_MODULO = 256
DUPLICATE_WINDOW = 8
"""A frame up to this many numbers behind the last one is a duplicate or a late (reordered UDP)
frame: not counted, and the counter stays. Any other jump counts as that many lost (a dropout of
more than half the sequence space reads as its remainder modulo 256: the counter cannot tell)."""


@dataclass(frozen=True)
class LinkStats:
    rates_hz: dict[str, float]
    rx_bytes_per_s: float
    frames: int
    lost: int
    """Frames missing from the sequence (sent by the vehicle, never decoded here: lost on the way
    or dropped for a bad CRC)."""
    crc_errors: int
    garbage: int
    """Frames or bytes that were not MAVLink at all (no frame start, unknown message)."""
    loss_pct: float

    def describe(self, names: tuple[str, ...] = ()) -> str:
        shown = names or tuple(sorted(self.rates_hz))
        rates = ", ".join(f"{n} {self.rates_hz.get(n, 0.0):.1f} Hz" for n in shown)
        return (f"{self.rx_bytes_per_s:.0f} B/s in; {rates}; lost {self.lost} ({self.loss_pct:.2f}%), "
                f"bad CRC {self.crc_errors}, garbage {self.garbage}")  # fmt: skip


class LinkHealth:
    """Counters and sliding-window rates of one link (see the module doc)."""

    def __init__(self, window_s: float | Callable[[], float]) -> None:
        self._window = window_s if callable(window_s) else (lambda: window_s)
        self._times: dict[str, deque[float]] = {}
        self._first_s: dict[str, float] = {}
        self._bytes: deque[tuple[float, int]] = deque()
        self._seq: dict[tuple[int, int], int] = {}
        self.size_sum: dict[str, int] = {}
        self.size_count: dict[str, int] = {}
        self.frames = 0
        self.lost = 0
        self.crc_errors = 0
        self.garbage = 0

    def frame(self, t_s: float, name: str, source: tuple[int, int], seq: int, size_bytes: int) -> None:
        """A decoded frame from the vehicle at vehicle time ``t_s``."""
        self.frames += 1
        last = self._seq.get(source)
        if last is None or (last - seq) % SEQ_MODULO > DUPLICATE_WINDOW:
            self.lost += 0 if last is None else (seq - last - 1) % SEQ_MODULO
            self._seq[source] = seq
        times = self._times.get(name)
        if times is None:
            times = self._times[name] = deque()
            self._first_s[name] = t_s
        times.append(t_s)
        self._bytes.append((t_s, size_bytes))
        self.size_sum[name] = self.size_sum.get(name, 0) + size_bytes
        self.size_count[name] = self.size_count.get(name, 0) + 1

    @property
    def window_s(self) -> float:
        """Read on every use: a changed parameter applies at once."""
        return self._window()

    @property
    def loss_pct(self) -> float:
        """Frames lost of frames sent, from the sequence numbers (a frame dropped for its CRC left
        a gap too, so it is counted once, as lost)."""
        sent = self.frames + self.lost
        return 100.0 * self.lost / sent if sent else 0.0

    def bad_crc(self) -> None:
        self.crc_errors += 1

    def bad_bytes(self) -> None:
        self.garbage += 1

    def rate_hz(self, name: str, now_s: float) -> float | None:
        """Frames per second of ``name`` over the window ending at ``now_s``; None if never seen."""
        times = self._times.get(name)
        if times is None:
            return None
        start = now_s - self.window_s
        while times and times[0] <= start:
            times.popleft()
        span_s = min(self.window_s, max(now_s - self._first_s[name], 0.0))
        if span_s < self.window_s / 2.0:
            return None  # too soon after the first one to say
        return len(times) / span_s

    def mean_size(self, name: str) -> float | None:
        count = self.size_count.get(name, 0)
        return self.size_sum[name] / count if count else None

    def stats(self, now_s: float) -> LinkStats:
        start = now_s - self.window_s
        while self._bytes and self._bytes[0][0] <= start:
            self._bytes.popleft()
        rates = {name: r for name in self._times if (r := self.rate_hz(name, now_s)) is not None}
        rx = sum(n for _, n in self._bytes) / self.window_s
        return LinkStats(rates, rx, self.frames, self.lost, self.crc_errors, self.garbage, self.loss_pct)
