"""The control loop's rate in vehicle time, and what a slow loop means for driving.

The daemon steps once per ``1 / SCHED_LOOP_RATE`` of vehicle time when it keeps up. Against a
simulator running many times faster than real time (or on a machine too slow for the loop), the
steps come further apart in vehicle time: the rover then moves further between two decisions.
``LoopRate`` measures the rate over a sliding window of vehicle time (steps per second with the
window's longest interval left out: one gap in the vehicle's data does not count as a slow loop,
the vehicle-link failsafe owns gaps, but frequent stalls do) and, while it is low:

- says so once (STATUSTEXT warning, and again when the rate recovers), and
- limits the speed so that the rover moves at most ``daemon.max_step_travel_m`` between two
  control steps: ``speed_limit_mps = max_step_travel_m * rate_hz``. At the nominal 25 Hz and the
  default 0.25 m that is 6.25 m/s, above any cruise speed, so a loop that keeps up is never limited.

The target is the control rate, or the odometry's measured rate where the line brings less (the
loop cannot step faster than new data comes; the link budget and its failsafes own that case).
Hysteresis: slow below ``slow_loop_fraction`` of the target rate, recovered above the midpoint
between that and the target, so a rate on the edge does not flap.
"""

from __future__ import annotations

import math

from collections import deque
from dataclasses import dataclass
from typing import Callable

from rover_ctl.config import DaemonParams


RATE_EVERY = 5
"""Steps between two computations of the rate (it moves slowly)."""


class ControlTicks:
    """The control step's schedule in vehicle time: a tick at every whole multiple of
    ``period_s()``; ticks missed in a gap of the vehicle's data are not replayed (the next one is
    the next multiple after the gap).

    Whole multiples, not a period after the first message: which message the daemon happens to
    see first depends on the wall clock (it connects while the emulator runs), and a lockstep run
    whose steps fell on odd 20 ms frames ran differently from one whose steps fell on even ones."""

    def __init__(self, period_s: Callable[[], float]) -> None:
        self._period_s = period_s
        self.next_s: float | None = None

    def due(self, t_s: float) -> bool:
        """Whether a step is due at vehicle time ``t_s``; if so the next tick is scheduled."""
        period_s = self._period_s()
        if self.next_s is None:
            self.next_s = math.ceil(t_s / period_s - 1e-9) * period_s
        if t_s + 1e-9 < self.next_s:
            return False
        self.next_s += period_s
        if self.next_s <= t_s + 1e-9:  # a gap: the next multiple after it
            self.next_s = (math.floor(t_s / period_s + 1e-9) + 1) * period_s
        return True


@dataclass(frozen=True)
class LoopRateState:
    rate_hz: float | None
    """Steps per second of vehicle time over the last window, its longest interval left out; None
    until a window is full."""
    slow: bool
    speed_limit_mps: float | None
    """The travel-per-step speed limit while slow, else None."""
    changed: bool
    """The slow flag changed at this step (say so)."""
    target_hz: float = 0.0
    """What the loop was measured against."""

    def text(self, max_step_travel_m: float) -> str:
        """What to tell the ground station when ``changed``. The limit follows the rate while the
        loop stays slow, so the text names the rule, not one figure that would go stale."""
        if self.slow:
            return (f"Control loop slow: {self.rate_hz:.1f} Hz of {self.target_hz:g} Hz, "
                    f"speed limited to {max_step_travel_m:g} m per step")  # fmt: skip
        return f"Control loop back to {self.rate_hz:.1f} Hz of {self.target_hz:g} Hz"


class LoopRate:
    """Control steps per second of vehicle time over ``daemon.loop_rate_window_s`` (parameters read live)."""

    def __init__(self, params: DaemonParams) -> None:
        self.params = params
        self._times: deque[float] = deque()
        self._steps = 0
        self._rate_hz: float | None = None
        self.slow = False

    def step(self, t_s: float, expected_hz: float | None = None) -> LoopRateState:
        """Record a control step at vehicle time ``t_s``. ``expected_hz``: the rate the loop can
        reach at best, when the vehicle's data comes slower than ``control_rate_hz`` (a slow
        line: there is no step without new odometry); default the control rate."""
        p = self.params
        target_hz = min(p.control_rate_hz, expected_hz) if expected_hz else p.control_rate_hz
        if self._times and t_s < self._times[-1]:
            self._times.clear()  # the vehicle's clock restarted: measure afresh
        self._times.append(t_s)
        while len(self._times) > 2 and t_s - self._times[1] >= p.loop_rate_window_s:
            self._times.popleft()
        self._steps += 1
        if t_s - self._times[0] < p.loop_rate_window_s:
            self._rate_hz = None
        elif self._rate_hz is None or self._steps % RATE_EVERY == 0:
            # The mean, not a quantile of the intervals: ArduPilot's 50 Hz stream skips about one
            # message in ten, so a loop that keeps up steps at 40, 40, 40, 60 and 20 ms (the 90th
            # percentile read 16.7 Hz). A stalling loop's mean falls all the same.
            times = list(self._times)
            longest_s = max(b - a for a, b in zip(times, times[1:]))
            span_s = times[-1] - times[0] - longest_s
            self._rate_hz = (len(times) - 2) / span_s if span_s > 0 else None
        rate_hz = self._rate_hz
        was = self.slow
        if rate_hz is not None:
            slow_hz = p.slow_loop_fraction * target_hz
            if rate_hz < slow_hz:
                self.slow = True
            elif rate_hz >= (slow_hz + target_hz) / 2.0:
                self.slow = False
        limit = p.max_step_travel_m * rate_hz if self.slow and rate_hz is not None else None
        return LoopRateState(rate_hz, self.slow, limit, self.slow != was, target_hz)
