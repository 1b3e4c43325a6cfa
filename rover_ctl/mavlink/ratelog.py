"""Log lines about what strangers send, rate-limited: a flood of frames must not flood the log.

``LogLimit(logger)`` is one call site's limiter: at most ``burst`` lines per ``LOG_INTERVAL_S``; the
lines held back meanwhile are counted and the next line that goes out says how many. It keeps no
keys, so nothing a frame carries can grow it.
"""

from __future__ import annotations

import logging
import time
from typing import Callable

LOG_INTERVAL_S = 1.0
"""The window of a limiter (a log line is disk work: a flood is 100 frames a loop turn)."""


class LogLimit:
    def __init__(self, logger: logging.Logger, burst: int = 1, interval_s: float = LOG_INTERVAL_S,
                 clock: Callable[[], float] = time.monotonic) -> None:  # fmt: skip
        self.logger = logger
        self.burst = burst
        self.interval_s = interval_s
        self.clock = clock
        self.held_back = 0
        """Lines not logged since the last one that was."""
        self._window_s: float | None = None
        self._in_window = 0

    def log(self, level: int, text: str, *args) -> bool:
        """Log ``text % args`` at ``level`` unless ``burst`` lines went out in the current window;
        True if it went out."""
        if not self.logger.isEnabledFor(level):
            return False
        now = self.clock()
        if self._window_s is None or now - self._window_s >= self.interval_s:
            self._window_s, self._in_window = now, 0
        if self._in_window >= self.burst:
            self.held_back += 1
            return False
        self._in_window += 1
        if self.held_back:
            text, args = text + " (and %d more like it not logged)", (*args, self.held_back)
            self.held_back = 0
        self.logger.log(level, text, *args)
        return True
