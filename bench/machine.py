"""The machine a benchmark ran on: its CPU, and the time of a fixed reference workload.

This machine is a virtual machine on a shared host, and the host under it changes: on 2026-11-27
the tree of 2026-11-22 ran ``python -m bench sitl`` at 75x real time alone and 21x in lockstep,
where on 2026-11-22 it had run at 181x and 48x. A figure in CPU time or in real-time factor is
only comparable with another taken on as fast a machine. Each result's header gives the CPU time
of ``reference_workload`` (pure Python: arithmetic, calls, a dict, a list, as the daemon's own code
is), the best of its runs over ``MIN_CPU_S``, in a fresh interpreter, before and after the run. It
does not depend on the tree or on any library, so two results' ratio of it says roughly how much
of a difference between them is the machine's. Roughly: the host's speed moves within minutes too
(on 2026-11-27, idle, six readings a few seconds apart: 40-74 ms), so only differences well
beyond that spread mean anything.
"""

from __future__ import annotations

import math
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

MIN_CPU_S = 1.0
"""The reference runs the workload for at least this much CPU time (and 3 times) and keeps the best."""
LOOPS = 200_000


def reference_workload(loops: int = LOOPS) -> float:
    """A fixed amount of interpreter work; returns a value so that nothing is optimised away."""
    table: dict[int, float] = {}
    window: list[float] = []
    acc = 0.0
    for i in range(loops):
        x = i * 0.5
        acc += math.sqrt(x) if i & 1 else x / (i + 1)
        table[i & 255] = acc
        window.append(acc)
        if len(window) > 16:
            window.pop(0)
    return acc + sum(window) + len(table)


def reference_ms(min_cpu_s: float = MIN_CPU_S) -> float:
    """Best CPU time of the reference workload (ms) over runs of at least ``min_cpu_s`` in all (and
    at least 3), in this process."""
    best, spent, runs = math.inf, 0.0, 0
    while spent < min_cpu_s or runs < 3:
        started = time.process_time()
        reference_workload()
        took = time.process_time() - started
        best, spent, runs = min(best, took), spent + took, runs + 1
    return round(best * 1e3, 1)


def cpu_model() -> str:
    """The CPU's model name (/proc/cpuinfo), else what ``platform`` knows."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def fresh_reference_ms() -> float:
    """``reference_ms`` in a new interpreter (none of the caller's objects, threads or state)."""
    code = "from bench.machine import reference_ms; print(reference_ms())"
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True, cwd=Path(__file__).parent.parent)
    return float(out.stdout)


def describe(before_ms: float, after_ms: float) -> str:
    """One line for a result's header: architecture, CPU, cores, Python, the reference times."""
    return (f"{platform.machine()}, {cpu_model()} x{os.cpu_count()}, python {platform.python_version()}, "
            f"reference {before_ms:g} / {after_ms:g} ms before / after")  # fmt: skip
