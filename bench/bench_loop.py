"""The control loop on a companion computer: CPU per control step by part, CPU share, memory,
start-up.

* Real time: ``missions/cmac_loop.waypoints`` against rover-sitl at speed-up 1 (six rangefinders)
  and against ArduPilot's firmware at speed-up 1 (layout "six"), a ground station attached (this
  process, ``SimRun``/``FirmwareRun``), ``SAMPLES`` times each, alternating; the table shows each
  vehicle's median run, and every run is listed. The daemon runs as ``python -m bench.loop_probe``, i.e.
  ``rover-ctl run`` with its methods timed from outside (the daemon keeps no profiling code). The
  window is the first ``WINDOW_S`` wall seconds after MISSION_START: CPU seconds per part divided by
  the control steps in it, process CPU / wall, peak RSS (VmHWM) at its end.
* Start-up: ``rover-ctl --help`` wall time, and ``import rover_ctl.app.daemon`` time and RSS in a
  fresh interpreter, with which heavy packages it loaded.

The timing itself costs CPU: the probe's calls per step times one timed call's cost (measured here)
is shown beside the figures.
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

    def _daemon_command(self) -> list[str]:
        cmd = super()._daemon_command()  # type: ignore[misc]
        assert cmd[: len(ROVER_CTL)] == ROVER_CTL
        return [sys.executable, "-m", "bench.loop_probe", str(self.probe_out), *cmd[len(ROVER_CTL):]]


class _ProbedSim(_Probed, SimRun):
    pass


class _ProbedFirmware(_Probed, FirmwareRun):
    pass


def _drive(run_class: type, options: SimOptions, window_s: float) -> dict:
    probe_out = Path(options.out) / "probe.json"
    run_class.probe_out = probe_out
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


def _timed_call_cost_s(n: int = 200_000) -> float:
    """CPU seconds one probe-timed call adds (measured on an empty method)."""

    class Empty:
        def f(self) -> None:
            pass

    probe = loop_probe.Probe(Path(os.devnull))
    plain = Empty()
    started = time.process_time()
    for _ in range(n):
        plain.f()
    base = time.process_time() - started
    probe.wrap(Empty, "f", "loop_overhead")
    probe.stack.append("loop_overhead")
    started = time.process_time()
    for _ in range(n):
        plain.f()
    return max(0.0, (time.process_time() - started - base) / n)


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


def _summary(record: dict, call_cost_s: float) -> dict:
    steps = max(record["steps"], 1)
    per_step_ms = {k: 1e3 * v / steps for k, v in record["cpu_s"].items()}
    return {
        "steps": record["steps"], "wall_s": record["wall_s"], "steps_per_s": record["steps"] / record["wall_s"],
        "cpu_share_pct": 100 * record["process_cpu_s"] / record["wall_s"],
        "cpu_per_step_ms": 1e3 * record["process_cpu_s"] / steps, "parts_ms": per_step_ms,
        "probe_cost_per_step_ms": 1e3 * call_cost_s * sum(record["calls"].values()) / steps,
        "turns_per_step": record["calls"]["loop_overhead"] / steps,
        "peak_rss_mb": record["max_rss_kb"] / 1024, "waypoints_reached": record["waypoints_reached"],
    }  # fmt: skip


def _table(runs: dict[str, dict], startup: dict) -> str:
    labels = list(runs)
    lines = ["| per control step (CPU ms) | " + " | ".join(labels) + " |", "|---|" + "---|" * len(labels)]
    for part in loop_probe.CATEGORIES:
        lines.append(f"| {part.replace('_', ' ')} | " + " | ".join(f"{runs[k]['parts_ms'][part]:.3f}" for k in labels) + " |")
    rows = [("**whole process, per step**", "cpu_per_step_ms", "**{:.3f}**"), ("of which the probe's own timing (estimate)", "probe_cost_per_step_ms", "{:.3f}"),
            ("**CPU share of one core**", "cpu_share_pct", "**{:.2f}%**"), ("**peak RSS**", "peak_rss_mb", "**{:.0f} MB**"),
            ("control steps per wall second", "steps_per_s", "{:.1f}"), ("loop turns per control step", "turns_per_step", "{:.2f}"), ("control steps in the window", "steps", "{}"),
            ("waypoints reached in the window", "waypoints_reached", "{}")]  # fmt: skip
    for label, key, fmt in rows:
        lines.append(f"| {label} | " + " | ".join(fmt.format(runs[k][key]) for k in labels) + " |")
    lines += [
        "",
        "| start-up | figure |",
        "|---|---|",
        f"| `rover-ctl --help` wall (median of {STARTUP_REPEATS}) | {startup['help_s']:.3f} s (min {startup['help_min_s']:.3f} s) |",
        *([f"| `rover-ctl --help` CPU, user + system (median; the wall time waits for a shared core) | {startup['help_cpu_s']:.3f} s |"]
          if "help_cpu_s" in startup else []),
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
             f"on {before.get('date')} ({before.get('window_s'):g} s window), after is the table above.", "",
             "| figure | before | after |", "|---|---|---|"]  # fmt: skip
    for label in runs:
        old = before["runs"].get(label)
        if old is None:
            continue
        for name, key, fmt in (("CPU per control step", "cpu_per_step_ms", "{:.2f} ms"), ("estimator per step", None, "{:.3f} ms"),
                               ("CPU share of one core", "cpu_share_pct", "{:.1f}%"), ("peak RSS", "peak_rss_mb", "{:.0f} MB")):  # fmt: skip
            a, b = (old["parts_ms"]["estimator"], runs[label]["parts_ms"]["estimator"]) if key is None else (old[key], runs[label][key])
            lines.append(f"| {label}: {name} | {fmt.format(a)} | {fmt.format(b)} |")
    old = before["startup"]
    lines += [f"| `rover-ctl --help` (median) | {old['help_s']:.3f} s | {startup['help_s']:.3f} s |",
              f"| `import rover_ctl.app.daemon` (median) | {old['import_s']:.3f} s | {startup['import_s']:.3f} s |",
              f"| RSS after that import | {old['import_rss_mb']:.0f} MB | {startup['import_rss_mb']:.0f} MB |",
              f"| modules it loads | {old['modules']} | {startup['modules']} |"]  # fmt: skip
    return "\n".join(lines)


def run(quick: bool) -> dict:
    window_s = 15.0 if quick else WINDOW_S
    call_cost_s = _timed_call_cost_s()
    samples: dict[str, list[dict]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for index in range(1 if quick else SAMPLES):
            load = os.getloadavg()[0]
            sim = SimOptions(mission=MISSION, out=Path(tmp) / f"sitl{index}", lockstep=False, speedup=1, timeout_s=400)
            run_ = _summary(_drive(_ProbedSim, sim, window_s), call_cost_s)
            samples.setdefault("rover-sitl 1x", []).append(run_ | {"load_average": load})
            if firmware_path() is not None:
                load = os.getloadavg()[0]
                fw = FirmwareOptions(mission=MISSION, out=Path(tmp) / f"fw{index}", lockstep=False, speedup=1, timeout_s=400,
                                     rangefinders="six", config_overrides=list(WHEELS))  # fmt: skip
                run_ = _summary(_drive(_ProbedFirmware, fw, window_s), call_cost_s)
                samples.setdefault("ArduPilot firmware 1x", []).append(run_ | {"load_average": load})
    runs = {label: sorted(runs_, key=lambda r: r["cpu_per_step_ms"])[(len(runs_) - 1) // 2] for label, runs_ in samples.items()}
    result = {"title": "Control loop on a companion computer: CPU per step, share, memory, start-up", "window_s": window_s,
              "timed_call_cost_us": call_cost_s * 1e6, "runs": runs, "samples": samples, "startup": _startup()}  # fmt: skip
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
        "`rover-ctl run` under `bench/loop_probe.py`, which times its methods from outside: each part is the process "
        "CPU time spent in it (nested parts subtracted), divided by the control steps (25 Hz target). *receive decode*: "
        "the vehicle link's poll (socket read, MAVLink parse, typed readings); *autopilot*: the decision step "
        "(modes, failsafes, planner, fuzzy navigator, wheel control); *rc override*: commands to the vehicle; "
        "*gcs link*: ground-station requests, heartbeat, MISSION_CURRENT; *telemetry*: position, attitude, GPS, "
        "SYS_STATUS; *logging*: both tlogs, control.csv, events.jsonl; *loop overhead*: the rest of the turn. "
        "CPU share is process CPU over wall seconds in the window (the machine's 2 cores are shared with the "
        "emulator or firmware, this ground station and other work, so repeated runs differ by some tens of percent).",
        "",
        _table(runs, startup),
        "",
        f"Each column is the median of {max(len(v) for v in result.get('samples', {'': [0]}).values())} runs by CPU per step "
        "(rover-sitl and firmware alternating); every run's CPU per step, share of one core and the machine's "
        "1-minute load average when it started:",
        "",
        _samples(result.get("samples", {})),
        "",
        _goals(runs, startup),
        "",
        _compare(runs, startup),
    ])  # fmt: skip
