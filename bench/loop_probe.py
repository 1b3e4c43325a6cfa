"""``python -m bench.loop_probe OUT.json [--bare] run ...``: ``rover-ctl run ...`` with the control loop's
CPU time split by what it is spent on, for ``bench/bench_loop.py``.

The daemon itself carries no profiling code: this wrapper replaces a few methods on their classes
before the command line builds the daemon, each by a timed call charging the process CPU time
(``time.process_time``) spent inside it, less what nested timed calls took, to one category.
``Daemon.turn``'s own remainder is the loop's overhead. SIGUSR1 zeroes the counters (the bench sends
it when the mission starts); SIGUSR2 writes OUT.json: CPU seconds per category, control steps,
timed calls per category (``loop_overhead``'s are loop turns), the window's wall and process CPU seconds, and the peak resident memory so far
(``peak_rss_kb``).

The timing costs CPU itself (two clock reads and a few list operations per timed call).
``--bare`` wraps nothing: the same window, steps, process CPU and peak memory,
with no category split, for the whole process's figures as it runs unobserved.
"""

from __future__ import annotations

import functools
import json
import signal
import sys
import time
from pathlib import Path

from bench.rss import peak_rss_kb
from rover_ctl.app.daemon import Daemon, EventLog
from rover_ctl.app.logs import CsvLog, TlogWriter
from rover_ctl.autopilot.autopilot import Autopilot
from rover_ctl.estimation.estimator import PoseEstimator
from rover_ctl.mavlink.gcs import GcsLink
from rover_ctl.mavlink.vehicle import VehicleLink

CATEGORIES = {
    "receive_decode": [(VehicleLink, "poll"), (VehicleLink, "tick")],
    "estimator": [(PoseEstimator, "on_wheels"), (PoseEstimator, "on_attitude"), (PoseEstimator, "on_gps"), (PoseEstimator, "pose")],
    "autopilot": [(Autopilot, "step"), (Autopilot, "on_wheels"), (Autopilot, "on_attitude"), (Autopilot, "on_vehicle")],
    "rc_override": [(VehicleLink, "send_override"), (VehicleLink, "release_override"), (VehicleLink, "answer_marker")],
    "gcs_link": [(GcsLink, "poll")],
    "telemetry": [(Daemon, "_send_telemetry")],
    "logging": [(TlogWriter, "write"), (CsvLog, "write"), (CsvLog, "flush"), (EventLog, "write")],
    "loop_overhead": [(Daemon, "turn")],
}
"""Category -> the methods whose exclusive CPU time it gets."""


class Probe:
    def __init__(self, out: Path) -> None:
        self.out = out
        self.stack: list[str] = []
        self.last = time.process_time()
        self.daemon: Daemon | None = None
        self.reset()

    def reset(self, *_args) -> None:
        self.cpu_s = dict.fromkeys(CATEGORIES, 0.0)
        self.calls = dict.fromkeys(CATEGORIES, 0)
        self.steps_at_start = self.daemon.steps if self.daemon else 0
        self.window_wall = time.monotonic()
        self.window_cpu = time.process_time()

    def _charge(self) -> None:
        now = time.process_time()
        if self.stack:
            self.cpu_s[self.stack[-1]] += now - self.last
        self.last = now

    def wrap(self, owner: type, name: str, category: str) -> None:
        original = getattr(owner, name)

        @functools.wraps(original)
        def timed(*args, **kwargs):
            self._charge()
            self.stack.append(category)
            self.calls[category] += 1
            try:
                return original(*args, **kwargs)
            finally:
                self._charge()
                self.stack.pop()

        setattr(owner, name, timed)

    def write(self, *_args) -> None:
        wall_s = time.monotonic() - self.window_wall
        cpu_s = time.process_time() - self.window_cpu
        steps = (self.daemon.steps if self.daemon else 0) - self.steps_at_start
        record = {"cpu_s": self.cpu_s, "steps": steps, "calls": self.calls, "wall_s": wall_s, "process_cpu_s": cpu_s,
                  "max_rss_kb": peak_rss_kb()}  # fmt: skip
        tmp = self.out.with_suffix(".tmp")
        tmp.write_text(json.dumps(record))
        tmp.replace(self.out)


def main(argv: list[str]) -> int:
    probe = Probe(Path(argv[0]))
    bare = argv[1:2] == ["--bare"]
    if not bare:
        for category, methods in CATEGORIES.items():
            for owner, name in methods:
                probe.wrap(owner, name, category)
    original_init = Daemon.__init__

    def init(daemon, *args, **kwargs):
        original_init(daemon, *args, **kwargs)
        probe.daemon = daemon

    Daemon.__init__ = init
    signal.signal(signal.SIGUSR1, probe.reset)
    signal.signal(signal.SIGUSR2, probe.write)
    from rover_ctl.cli import main as cli_main

    return cli_main(argv[2:] if bare else argv[1:])


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
