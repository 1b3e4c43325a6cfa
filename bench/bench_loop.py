"""The control loop on a companion computer: CPU per control step by part, CPU share, memory,
start-up.

* Real time: ``missions/cmac_loop.waypoints`` against rover-sitl at speed-up 1 (six rangefinders)
  and against ArduPilot's firmware at speed-up 1 (layout "six"), a ground station attached (this
  process, ``SimRun``/``FirmwareRun``). The daemon runs as ``python -m bench.loop_probe``, i.e.
  ``rover-ctl run`` under a wrapper (the daemon keeps no profiling code). The window is the first
  ``WINDOW_S`` wall seconds after MISSION_START.
  - The whole process: ``SAMPLES`` runs per vehicle, alternating, with nothing timed
    (``--bare``): process CPU / wall, CPU per control step, peak RSS (VmHWM) at the window's end;
    the table shows each vehicle's median run, and every run is listed.
  - By part: one more run per vehicle with the daemon's methods timed from outside, CPU seconds
    per part divided by the control steps. The timing costs CPU of its own (two clock reads per
    timed call), which this run's total includes; it is shown beside the untimed runs'.
* Start-up: ``rover-ctl --help`` wall time, and ``import rover_ctl.app.daemon`` time and RSS in a
  fresh interpreter, with which heavy packages it loaded.
"""

from __future__ import annotations

import json
import os
import resource
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench import loop_probe
from rover_ctl.app.firmware import FirmwareOptions, FirmwareRun, firmware_path
from rover_ctl.app.sim import ROVER_CTL, SimOptions, SimRun

ROOT = Path(__file__).resolve().parent.parent
MISSION = ROOT / "missions" / "cmac_loop.waypoints"
WINDOW_S = 60.0
"""Wall seconds measured from MISSION_START (the whole mission takes about 150 s)."""
WHEELS = ["link.wheel_left_index=1", "link.wheel_right_index=0"]
HEAVY = ("scipy", "scipy.stats", "scipy.optimize", "scipy.ndimage", "scipy.linalg", "scipy.integrate", "filterpy",
         "networkx", "shapely", "pyproj", "matplotlib", "rich", "bench")  # fmt: skip
"""Packages whose presence after the daemon's import is reported."""
SAMPLES = 3
"""Real-time runs per vehicle, rover-sitl and firmware alternating (the machine is shared: a single
run can be off by tens of percent); each column of the table is the run with the median CPU per
step, and every run's figure is listed beside it."""
STARTUP_REPEATS = 5
BASELINE = Path(__file__).resolve().parent / "baselines" / "loop_before.json"
"""This benchmark's result on the tree before issue 17's changes (BASELINE_COMMIT with this bench's
files copied in), run just before or after the current figures; shown beside them."""
BASELINE_COMMIT = "8293069"


class _Probed:
    """A SimRun whose daemon runs under ``bench.loop_probe``."""

    probe_out: Path
    bare: bool

    def _daemon_command(self) -> list[str]:
        cmd = super()._daemon_command()  # type: ignore[misc]
        assert cmd[: len(ROVER_CTL)] == ROVER_CTL
        flags = ["--bare"] if self.bare else []
        return [sys.executable, "-m", "bench.loop_probe", str(self.probe_out), *flags, *cmd[len(ROVER_CTL):]]


class _ProbedSim(_Probed, SimRun):
    pass


class _ProbedFirmware(_Probed, FirmwareRun):
    pass


def _drive(run_class: type, options: SimOptions, window_s: float, bare: bool) -> dict:
    probe_out = Path(options.out) / "probe.json"
    run_class.probe_out, run_class.bare = probe_out, bare
    with run_class(options) as run:
        run.arm()
        run.start_mission()
        run.progress.started_sim_s = run.progress.sim_time_s
        os.kill(run.daemon.pid, signal.SIGUSR1)
        run.wait_for(lambda p: p.complete, wall_timeout_s=window_s)
        os.kill(run.daemon.pid, signal.SIGUSR2)
        run.wait_for(lambda p: probe_out.exists(), wall_timeout_s=10.0)
        reached = len(run.progress.reached)
    record = json.loads(probe_out.read_text())
    record["waypoints_reached"] = reached
    return record


def _startup() -> dict:
    env = dict(os.environ)
    helps, help_cpu = [], []
    for _ in range(STARTUP_REPEATS):
        started, before = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run([*ROVER_CTL, "--help"], check=True, stdout=subprocess.DEVNULL, env=env)
        helps.append(time.perf_counter() - started)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        help_cpu.append(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)
    code = ("import sys, time; t = time.perf_counter(); import rover_ctl.app.daemon; "
            f"t = time.perf_counter() - t; n = len(sys.modules); heavy = [m for m in {HEAVY!r} if m in sys.modules]; "
            "import json; from bench.rss import peak_rss_kb; "
            "print(json.dumps({'import_s': t, 'max_rss_kb': peak_rss_kb(), 'modules': n, 'heavy': heavy}))")  # fmt: skip
    imports = [json.loads(subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True, env=env).stdout)
               for _ in range(STARTUP_REPEATS)]  # fmt: skip
    bare = [json.loads(subprocess.run([sys.executable, "-c", "from bench.rss import peak_rss_kb; print(peak_rss_kb())"],
                                      check=True, capture_output=True, text=True).stdout) for _ in range(2)]  # fmt: skip
    return {
        "help_s": statistics.median(helps), "help_min_s": min(helps), "help_cpu_s": statistics.median(help_cpu),
        "import_s": statistics.median(i["import_s"] for i in imports), "import_min_s": min(i["import_s"] for i in imports),
        "import_rss_mb": statistics.median(i["max_rss_kb"] for i in imports) / 1024,
        "bare_python_rss_mb": min(bare) / 1024,
        "modules": imports[0]["modules"], "heavy_loaded": imports[0]["heavy"],
    }  # fmt: skip


def _summary(record: dict) -> dict:
    """The whole process's figures, and the split by part when the run was timed (an untimed run's
    counters are all zero)."""
    steps = max(record["steps"], 1)
    summary = {
        "steps": record["steps"], "wall_s": record["wall_s"], "steps_per_s": record["steps"] / record["wall_s"],
        "cpu_share_pct": 100 * record["process_cpu_s"] / record["wall_s"],
        "cpu_per_step_ms": 1e3 * record["process_cpu_s"] / steps,
        "peak_rss_mb": record["max_rss_kb"] / 1024, "waypoints_reached": record["waypoints_reached"],
    }  # fmt: skip
    if record["calls"]["loop_overhead"]:
        summary["parts_ms"] = {k: 1e3 * v / steps for k, v in record["cpu_s"].items()}
        summary["turns_per_step"] = record["calls"]["loop_overhead"] / steps
    return summary


def _table(runs: dict[str, dict], startup: dict) -> str:
    labels = list(runs)
    lines = ["| per control step (CPU ms) | " + " | ".join(labels) + " |", "|---|" + "---|" * len(labels)]
    for part in loop_probe.CATEGORIES:
        lines.append(f"| {part.replace('_', ' ')} | " + " | ".join(f"{runs[k]['by_part']['parts_ms'][part]:.3f}" for k in labels) + " |")
    lines.append("| whole process, per step, in the timed run | " + " | ".join(f"{runs[k]['by_part']['cpu_per_step_ms']:.3f}" for k in labels) + " |")
    lines.append("| loop turns per control step (timed run) | " + " | ".join(f"{runs[k]['by_part']['turns_per_step']:.2f}" for k in labels) + " |")
    rows = [("**whole process, per step, untimed (median run)**", "cpu_per_step_ms", "**{:.3f}**"),
            ("**CPU share of one core**", "cpu_share_pct", "**{:.2f}%**"), ("**peak RSS**", "peak_rss_mb", "**{:.0f} MB**"),
            ("control steps per wall second", "steps_per_s", "{:.1f}"), ("control steps in the window", "steps", "{}"),
            ("waypoints reached in the window", "waypoints_reached", "{}")]  # fmt: skip
    for label, key, fmt in rows:
        lines.append(f"| {label} | " + " | ".join(fmt.format(runs[k][key]) for k in labels) + " |")
    lines += [
        "",
        "| start-up | figure |",
        "|---|---|",
        f"| `rover-ctl --help` wall (median of {STARTUP_REPEATS}) | {startup['help_s']:.3f} s (min {startup['help_min_s']:.3f} s) |",
        f"| `rover-ctl --help` CPU, user + system (median; the wall time waits for a shared core) | {startup['help_cpu_s']:.3f} s |",
        f"| `import rover_ctl.app.daemon` (median of {STARTUP_REPEATS}) | {startup['import_s']:.3f} s (min {startup['import_min_s']:.3f} s) |",
        f"| RSS after that import (bare interpreter: {startup['bare_python_rss_mb']:.0f} MB) | {startup['import_rss_mb']:.0f} MB |",
        f"| modules loaded by it | {startup['modules']} |",
        f"| heavy packages among them | {', '.join(startup['heavy_loaded']) or 'none'} |",
    ]
    return "\n".join(lines)


GOALS = (("CPU share <= 2% of one core", "cpu_share_pct", 2.0), ("peak RSS <= 120 MB", "peak_rss_mb", 120.0))
"""Issue 17's targets for the daemon driving the bundled mission in real time."""
HELP_GOAL_S = 0.3


def _goals(runs: dict[str, dict], startup: dict) -> str:
    lines = ["| issue 17 goal | met |", "|---|---|"]
    for label, key, limit in GOALS:
        lines.append(f"| {label} | " + ", ".join(f"{k}: {'yes' if r[key] <= limit else 'no'} ({r[key]:.1f})" for k, r in runs.items()) + " |")
    lines.append(f"| `rover-ctl --help` < {HELP_GOAL_S:g} s | {'yes' if startup['help_s'] < HELP_GOAL_S else 'no'} ({startup['help_s']:.3f} s) |")
    return "\n".join(lines)


def _compare(runs: dict[str, dict], startup: dict) -> str:
    """Before (BASELINE) and now, side by side."""
    if not BASELINE.exists():
        return ""
    before = json.loads(BASELINE.read_text())
    lines = [f"Before and after issue 17's changes: before is commit {BASELINE_COMMIT} measured by this same benchmark "
             f"on {before.get('date')} ({before.get('window_s'):g} s window; it had only runs with the methods timed), "
             "after is this run's timed run, so that like is compared with like.", "",
             "| figure | before | after |", "|---|---|---|"]  # fmt: skip
    for label in runs:
        old = before["runs"].get(label)
        if old is None:
            continue
        for name, key, fmt in (("CPU per control step", "cpu_per_step_ms", "{:.2f} ms"), ("estimator per step", None, "{:.3f} ms"),
                               ("CPU share of one core", "cpu_share_pct", "{:.1f}%"), ("peak RSS", "peak_rss_mb", "{:.0f} MB")):  # fmt: skip
            timed = runs[label]["by_part"]
            a, b = (old["parts_ms"]["estimator"], timed["parts_ms"]["estimator"]) if key is None else (old[key], timed[key])
            lines.append(f"| {label}: {name} | {fmt.format(a)} | {fmt.format(b)} |")
    old = before["startup"]
    lines += [f"| `rover-ctl --help` (median) | {old['help_s']:.3f} s | {startup['help_s']:.3f} s |",
              f"| `import rover_ctl.app.daemon` (median) | {old['import_s']:.3f} s | {startup['import_s']:.3f} s |",
              f"| RSS after that import | {old['import_rss_mb']:.0f} MB | {startup['import_rss_mb']:.0f} MB |",
              f"| modules it loads | {old['modules']} | {startup['modules']} |"]  # fmt: skip
    return "\n".join(lines)


def _vehicles(tmp: str, tag: str) -> list[tuple[str, type, SimOptions]]:
    out: list[tuple[str, type, SimOptions]] = [
        ("rover-sitl 1x", _ProbedSim, SimOptions(mission=MISSION, out=Path(tmp) / f"sitl{tag}", lockstep=False, speedup=1, timeout_s=400))]
    if firmware_path() is not None:
        out.append(("ArduPilot firmware 1x", _ProbedFirmware,
                    FirmwareOptions(mission=MISSION, out=Path(tmp) / f"fw{tag}", lockstep=False, speedup=1, timeout_s=400,
                                    rangefinders="six", config_overrides=list(WHEELS))))  # fmt: skip
    return out


def run(quick: bool) -> dict:
    window_s = 15.0 if quick else WINDOW_S
    samples: dict[str, list[dict]] = {}
    by_part: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for index in range(1 if quick else SAMPLES):
            for label, run_class, options in _vehicles(tmp, str(index)):
                load = os.getloadavg()[0]
                summary = _summary(_drive(run_class, options, window_s, bare=True))
                samples.setdefault(label, []).append(summary | {"load_average": load})
        for label, run_class, options in _vehicles(tmp, "timed"):
            by_part[label] = _summary(_drive(run_class, options, window_s, bare=False))
    runs = {label: sorted(runs_, key=lambda r: r["cpu_per_step_ms"])[(len(runs_) - 1) // 2] | {"by_part": by_part[label]}
            for label, runs_ in samples.items()}  # fmt: skip
    result = {"title": "Control loop on a companion computer: CPU per step, share, memory, start-up", "window_s": window_s,
              "runs": runs, "samples": samples, "startup": _startup()}  # fmt: skip
    result["markdown"] = markdown(result)
    return result


def _samples(samples: dict[str, list[dict]]) -> str:
    lines = []
    for label, runs in samples.items():
        figures = ", ".join(f"{r['cpu_per_step_ms']:.2f} ms ({r['cpu_share_pct']:.1f}%, load {r['load_average']:.1f})" for r in runs)
        cpu = [r["cpu_per_step_ms"] for r in runs]
        lines.append(f"- {label}: {figures}; spread {min(cpu):.2f}-{max(cpu):.2f} ms per step")
    return "\n".join(lines)


def markdown(result: dict) -> str:
    """The section of docs/BENCHMARKS.md for ``result`` (and the baseline, when there is one)."""
    window_s, runs, startup = result["window_s"], result["runs"], result["startup"]
    return "\n".join([
        f"`missions/cmac_loop.waypoints` in real time, six rangefinders, this process as the ground station; the first "
        f"{window_s:g} wall seconds after MISSION_START (the whole mission takes about 150 s). The daemon is "
        "`rover-ctl run` under `bench/loop_probe.py`. The bold rows are the whole process running untimed (`--bare`): "
        "process CPU per control step (25 Hz target), CPU share (process CPU over wall seconds), peak RSS. The parts "
        "come from one more run per vehicle with the daemon's methods timed from outside: each part is the process "
        "CPU time spent in it (nested parts subtracted), divided by the control steps; that run's total includes "
        "what the timing itself costs. *receive decode*: "
        "the vehicle link's poll (socket read, MAVLink parse, typed readings); *autopilot*: the decision step "
        "(modes, failsafes, planner, fuzzy navigator, wheel control); *rc override*: commands to the vehicle; "
        "*gcs link*: ground-station requests, heartbeat, MISSION_CURRENT; *telemetry*: position, attitude, GPS, "
        "SYS_STATUS; *logging*: both tlogs, control.csv, events.jsonl; *loop overhead*: the rest of the turn. "
        "The machine's 2 cores are shared with the emulator or firmware, this ground station and other work, so "
        "repeated runs differ by some tens of percent.",
        "",
        _table(runs, startup),
        "",
        f"The bold rows are each vehicle's median of {max(len(v) for v in result.get('samples', {'': [0]}).values())} "
        "untimed runs by CPU per step (rover-sitl and firmware alternating); every untimed run's CPU per step, share "
        "of one core and the machine's 1-minute load average when it started:",
        "",
        _samples(result.get("samples", {})),
        "",
        _goals(runs, startup),
        "",
        _compare(runs, startup),
    ])  # fmt: skip
