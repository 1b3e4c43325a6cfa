"""Peak resident memory of this process (stdlib only: importing it adds nothing to what it measures)."""

from __future__ import annotations

import resource


def peak_rss_kb() -> int:
    """This process's peak resident set: /proc's VmHWM. Not ``getrusage``'s ``ru_maxrss``: Linux
    carries that across exec, so a child of a big process (this bench) reports its parent's size."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            return next(int(line.split()[1]) for line in status if line.startswith("VmHWM:"))
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
