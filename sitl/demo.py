"""``python -m sitl.demo``: the emulator under a scripted drive, printing what a controller sees.

Starts ``rover-sitl --lockstep`` as a separate process (``sitl.launch``) on the cmac_loop world
when the checkout has it, connects as a minimal pymavlink controller (``sitl.client``), arms, and
drives a fixed pattern with RC overrides: straight, a right arc, a pivot, straight again, stop.
Once per sim second it prints time, GPS, heading, wheel distances and the ranges; then a summary.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from sitl.client import LockstepClient
from sitl.launch import rover_sitl

ROOT = Path(__file__).resolve().parent.parent
WORLD = ROOT / "missions" / "worlds" / "cmac_loop.geojson"
PATTERN = [  # (until sim s, throttle us, steering us, what)
    (18.0, 1800, 1500, "straight"),  # north towards cmac_loop's barrel, 20 m ahead
    (22.0, 1750, 1560, "right arc"),
    (25.0, 1500, 1430, "pivot left"),
    (31.0, 1850, 1500, "straight"),
    (33.0, 1500, 1500, "stop"),
]
ORIENTATION_NAMES = {0: "F", 1: "FR", 2: "R", 4: "B", 6: "L", 7: "FL"}


def command_at(t_s: float) -> tuple[int, int, str]:
    for until_s, throttle_us, steering_us, what in PATTERN:
        if t_s < until_s:
            return throttle_us, steering_us, what
    return 1500, 1500, "stop"


class Watch:
    """The latest of each message, printed once per sim second."""

    def __init__(self, console: Console) -> None:
        self.console = console
        self.latest: dict[str, object] = {}
        self.ranges: dict[int, object] = {}
        self.events: list[str] = []
        self.next_print_s = 0.0

    def __call__(self, t_s: float, msgs: list) -> tuple[int, int]:
        for msg in msgs:
            kind = msg.get_type()
            if kind == "DISTANCE_SENSOR":
                self.ranges[msg.orientation] = msg
            elif kind == "STATUSTEXT":
                self.events.append(f"{t_s:6.2f} s  {msg.text}")
                self.console.print(f"[bold yellow]{t_s:6.2f} s  STATUSTEXT {msg.text}")
            self.latest[kind] = msg
        throttle_us, steering_us, what = command_at(t_s)
        if t_s >= self.next_print_s and "GPS_RAW_INT" in self.latest and "ATTITUDE" in self.latest:
            self.next_print_s += 1.0
            self.console.print(self.line(t_s, what), soft_wrap=True)
        return throttle_us, steering_us

    def line(self, t_s: float, what: str) -> str:
        gps, att, wheels = self.latest["GPS_RAW_INT"], self.latest["ATTITUDE"], self.latest.get("WHEEL_DISTANCE")
        heading_deg = math.degrees(att.yaw) % 360.0
        left_m, right_m = (wheels.distance[0], wheels.distance[1]) if wheels else (0.0, 0.0)
        ranges = " ".join(
            f"{ORIENTATION_NAMES.get(o, o)}={'-' if r.current_distance > r.max_distance else f'{r.current_distance / 100:.1f}'}"
            for o, r in sorted(self.ranges.items()))
        return (f"{t_s:5.1f} s {what:<10} GPS {gps.lat / 1e7:.6f},{gps.lon / 1e7:.6f} fix {gps.fix_type} "
                f"hdg {heading_deg:5.1f} wheels {left_m:5.2f}/{right_m:5.2f} m ranges {ranges}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m sitl.demo", description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)
    console = Console(highlight=False)
    flags = ["--seed", str(args.seed)] + (["--world", str(WORLD)] if WORLD.exists() else [])
    console.print(f"[bold]rover-sitl demo[/] world: {WORLD.name if WORLD.exists() else 'empty'}; scripted drive "
                  + ", ".join(f"{what} until {until:g} s" for until, _t, _s, what in PATTERN))
    with rover_sitl("--lockstep", *flags) as sitl:
        client = LockstepClient(sitl.url)
        client.arm()
        console.print("armed (MANUAL); driving with RC overrides, lockstep")
        watch = Watch(console)
        started = time.perf_counter()
        stats = client.run(PATTERN[-1][0], watch)
        wall_s = time.perf_counter() - started
        client.close()
    sim = watch.latest.get("SIMSTATE")
    wheels = watch.latest.get("WHEEL_DISTANCE")
    table = Table(title="summary")
    table.add_column("figure")
    table.add_column("value", justify="right")
    table.add_row("sim time", f"{stats.sim_s:.1f} s in {wall_s:.2f} s wall ({stats.sim_s / wall_s:.0f}x real time)")
    table.add_row("messages received", str(stats.messages))
    if wheels:
        table.add_row("wheel distance L / R", f"{wheels.distance[0]:.2f} / {wheels.distance[1]:.2f} m")
    if sim:
        table.add_row("true final position", f"{sim.lat / 1e7:.6f}, {sim.lng / 1e7:.6f}, heading {math.degrees(sim.yaw) % 360:.0f} deg")
    table.add_row("events", "\n".join(watch.events) or "none")
    console.print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
