"""Time of the emulator: integer frame ticks, wall-clock pacing, and the lockstep marker.

Sim time advances in frames of ``frame_s``; it is kept as an integer count of nanoseconds so that
two runs agree to the bit and TIMESYNC markers carry it exactly (``ts1 = t_k`` in ns).
"""

from __future__ import annotations

import math
import time

NS_PER_S = 1_000_000_000
MARKER_RESEND_S = 0.2
"""An unanswered lockstep marker is sent again after this many wall seconds (UDP may drop it, a
byte error on a serial line may hide it): well under the daemon's vehicle-link timeout (0.4 s of
silence), so a lost marker is not taken for a silent vehicle."""
HOLD_TIMEOUT_S = 10.0
"""``--hold-at-s``: wall seconds the clock waits at the hold for the vehicle to be armed before it
goes on anyway (the controller's pre-arm checks may refuse the arming there: it is then retried
in running time, as without a hold)."""
MIN_SPEEDUP = 0.01
"""100 wall seconds per sim second; slower is a stalled emulator (1e-300 overflowed select's timeout)."""


class FrameClock:
    """Sim time t_k = k * frame_s, in integer nanoseconds."""

    def __init__(self, frame_s: float) -> None:
        self.frame_ns = int(round(frame_s * NS_PER_S))
        if self.frame_ns <= 0:
            raise ValueError(f"frame_s must be positive, got {frame_s!r}")
        self.frame_s = self.frame_ns / NS_PER_S
        self.k = 0

    @property
    def t_ns(self) -> int:
        return self.k * self.frame_ns

    @property
    def t_s(self) -> float:
        return self.t_ns / NS_PER_S

    def advance(self) -> None:
        self.k += 1


class Pacer:
    """Maps sim time to wall-clock deadlines at ``speedup`` x real time (math.inf: free running)."""

    def __init__(self, speedup: float, now=time.monotonic) -> None:
        if not speedup > 0:
            raise ValueError(f"speedup must be positive, got {speedup!r}")
        self.speedup = speedup
        self.now = now
        self.wall0 = now()

    def wait_s(self, t_s: float) -> float:
        """Wall seconds from now until sim time ``t_s`` is due (0 if already late or free running)."""
        if math.isinf(self.speedup):
            return 0.0
        return max(0.0, self.wall0 + t_s / self.speedup - self.now())


class LockstepMarker:
    """The outstanding end-of-frame TIMESYNC marker and when it was last sent (wall clock)."""

    def __init__(self, now=time.monotonic) -> None:
        self.now = now
        self.ts1_ns: int | None = None
        self.sent_wall = 0.0

    def sent(self, ts1_ns: int) -> None:
        self.ts1_ns = ts1_ns
        self.sent_wall = self.now()

    def resend_in_s(self) -> float:
        """Wall seconds until the marker is due to be repeated (<= 0: now)."""
        return self.sent_wall + MARKER_RESEND_S - self.now()

    def is_answer(self, msg) -> bool:
        """A TIMESYNC reply for the outstanding marker: tc1 != 0 (a reply) and ts1 = our t_k."""
        return msg.get_type() == "TIMESYNC" and msg.tc1 != 0 and msg.ts1 == self.ts1_ns
