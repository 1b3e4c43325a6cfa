"""Real-time factor of rover-sitl (simulated seconds per wall second), standard sensor set.

- alone: ``--speedup inf`` free running for ``duration`` sim seconds, telemetry sent to a UDP port
  nobody reads; timed from the emulator's ready line to its stopped line (no start-up cost).
- lockstep: ``--lockstep`` with ``sitl.client.LockstepClient`` as the controller (arms, sends an RC
  override every frame, answers every TIMESYNC marker); timed by the client over the run.

Both on the cmac_loop world (six obstacles for the rangefinders to ray-cast), 0.02 s frames.
Goals (issue 2): >= 50x alone, >= 20x with a controller in lockstep, on 2 cores.
"""

from __future__ import annotations

import statistics
from pathlib import Path

from sitl.client import LockstepClient
from sitl.launch import free_port, rover_sitl

ROOT = Path(__file__).resolve().parent.parent
WORLD = ROOT / "missions" / "worlds" / "cmac_loop.geojson"
GOAL_ALONE = 50.0
GOAL_LOCKSTEP = 20.0


def _world_flags() -> list[str]:
    return ["--world", str(WORLD)] if WORLD.exists() else []


def alone_rtf(duration_s: float) -> float:
    sink = free_port()
    flags = ["--speedup", "inf", "--duration-s", str(duration_s), *_world_flags()]
    with rover_sitl(*flags, endpoints=[f"udpout:127.0.0.1:{sink}"]) as sitl:
        status = sitl.wait(timeout_s=max(60.0, duration_s))
        stopped_at = sitl.line_time("rover-sitl: stopped")
    if status != 0 or stopped_at is None:
        raise RuntimeError(f"rover-sitl failed (exit {status}): {sitl.last_error()}")
    return duration_s / (stopped_at - sitl.ready_at)


def lockstep_rtf(duration_s: float) -> tuple[float, int]:
    with rover_sitl("--lockstep", *_world_flags()) as sitl:
        client = LockstepClient(sitl.url)
        client.arm()
        stats = client.run(duration_s, lambda t_s, msgs: (1650, 1500))
        client.close()
    return stats.realtime_factor, stats.messages


def run(quick: bool) -> dict:
    duration_s = 20.0 if quick else 120.0
    repeats = 1 if quick else 3
    alone = [alone_rtf(duration_s) for _ in range(repeats)]
    lockstep = [lockstep_rtf(duration_s) for _ in range(repeats)]
    alone_x = statistics.median(alone)
    lockstep_x = statistics.median(r for r, _ in lockstep)
    messages_per_sim_s = lockstep[0][1] / duration_s
    rows = [
        ("alone (--speedup inf)", alone_x, GOAL_ALONE),
        ("lockstep with pymavlink controller", lockstep_x, GOAL_LOCKSTEP),
    ]
    markdown = "\n".join([
        f"{duration_s:g} sim s per run, median of {repeats}, cmac_loop world, 6 rangefinders, frame 0.02 s; "
        f"{messages_per_sim_s:.0f} telemetry messages per sim second.\n",
        "| mode | real-time factor | goal | met |",
        "|---|---:|---:|---|",
        *(f"| {name} | {x:.0f}x | {goal:.0f}x | {'yes' if x >= goal else 'NO'} |" for name, x, goal in rows),
    ])
    return {
        "title": "SITL real-time factor",
        "markdown": markdown,
        "duration_sim_s": duration_s,
        "repeats": repeats,
        "alone_rtf": alone_x,
        "alone_rtf_runs": alone,
        "lockstep_rtf": lockstep_x,
        "lockstep_rtf_runs": [r for r, _ in lockstep],
        "messages_per_sim_s": messages_per_sim_s,
        "goal_alone_rtf": GOAL_ALONE,
        "goal_lockstep_rtf": GOAL_LOCKSTEP,
    }
