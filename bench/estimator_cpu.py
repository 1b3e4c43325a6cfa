"""``python -m bench.estimator_cpu [--runs N] [--save FILE.npz | --compare FILE.npz] [--profile]``:
CPU per call of the pose estimator, replayed in-process.

Not one of ``python -m bench``'s sections (it writes nothing to docs/BENCHMARKS.md): a
micro-benchmark for work on the estimator's cost. It replays a synthetic drive
(tests/estimator/synthetic.py: 60 s at 1.5 m/s with a slow weave, 0.5 m white GPS with a 1 m bias,
mis-sized tyres, a 4 s 39 m glitch and a 5 s outage) at the daemon's cadence: ATTITUDE and
WHEEL_DISTANCE at 50 Hz, GPS at 5 Hz, a ``pose()`` at each 25 Hz control step (every second wheel
reading). Each call is timed with ``time.perf_counter_ns`` (the timer's own cost, ~0.1 us, is
included); the figure per method is its mean over the replay, the best of ``--runs`` replays. A
control step is 2 wheel + 2 attitude readings, a fifth of a fix and one pose.

``--save`` writes every pose of the replay; ``--compare`` reads such a file and prints the largest
differences, so that a change to the filter can be checked against the code before it.
``--profile`` prints cProfile's top entries for one replay.

``--episode SCENARIO:SEED[,...]`` times the estimator inside the in-process episode runner
(``rover_ctl.tuning.episode.run_episode`` with the default rule base) instead: the same methods,
wrapped with the same timer, interleaved with the emulator, the autopilot and the navigator as in
the daemon (so with the caches those leave), per control step of the run (``duration_s`` x
``daemon.control_rate_hz``).
"""

from __future__ import annotations

import argparse
import cProfile
import math
import pstats
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from estimator.synthetic import CMAC, TRACK_M, Sensors, simulate  # noqa: E402
from rover_ctl.config import EstimatorParams  # noqa: E402
from rover_ctl.estimation.estimator import PoseEstimator  # noqa: E402
from rover_ctl.estimation.readings import Attitude, GpsFix  # noqa: E402

METHODS = ("on_wheels", "on_attitude", "on_gps", "pose")
PER_STEP = {"on_wheels": 2.0, "on_attitude": 2.0, "on_gps": 0.2, "pose": 1.0}


def readings() -> list:
    sensors = Sensors(gps_white_m=0.5, gps_bias_m=1.0, wheel_scale=1.05, outages=[(40.0, 45.0)],
                      glitches=[(25.0, 29.0, 39.0, 0.0)])
    run = simulate(60.0, lambda t: 1.5, lambda t: 0.15 * math.sin(t / 5.0), seed=21, sensors=sensors)
    return run.readings


def replay(items: list, record: list | None = None) -> dict[str, tuple[int, int]]:
    """Feed every reading; returns {method: (total ns, calls)}."""
    est = PoseEstimator(CMAC, EstimatorParams(), TRACK_M)
    clock = time.perf_counter_ns
    totals = dict.fromkeys(METHODS, 0)
    calls = dict.fromkeys(METHODS, 0)
    wheels = 0
    for r in items:
        if isinstance(r, GpsFix):
            name, call = "on_gps", est.on_gps
        elif isinstance(r, Attitude):
            name, call = "on_attitude", est.on_attitude
        else:
            name, call = "on_wheels", est.on_wheels
        t0 = clock()
        call(r)
        totals[name] += clock() - t0
        calls[name] += 1
        if name == "on_wheels":
            wheels += 1
            if wheels % 2 == 0:
                t0 = clock()
                pose = est.pose()
                totals["pose"] += clock() - t0
                calls["pose"] += 1
                if record is not None:
                    record.append([pose.time_s, pose.east_m, pose.north_m, pose.heading_rad, pose.speed_mps,
                                   pose.yaw_rate_radps, pose.position_sigma_m, pose.heading_sigma_rad,
                                   float(pose.healthy), float(pose.gps_ok), *pose.cov.ravel()])
    return {m: (totals[m], calls[m]) for m in METHODS}


def episode_cost(specs: list[str]) -> None:
    """Estimator CPU inside ``run_episode`` for each ``SCENARIO:SEED``."""
    import functools

    from rover_ctl.config import load_config
    from rover_ctl.fuzzy import load_rulebase
    from rover_ctl.tuning.episode import run_episode

    totals = dict.fromkeys(METHODS, 0)
    calls = dict.fromkeys(METHODS, 0)
    clock = time.perf_counter_ns

    def timed(name, original):
        @functools.wraps(original)
        def wrapper(*args, **kwargs):
            t0 = clock()
            try:
                return original(*args, **kwargs)
            finally:
                totals[name] += clock() - t0
                calls[name] += 1

        return wrapper

    for name in METHODS:
        setattr(PoseEstimator, name, timed(name, getattr(PoseEstimator, name)))
    rate_hz = load_config(None).daemon.control_rate_hz
    rulebase = load_rulebase("default")
    for spec in specs:
        scenario, seed = spec.split(":")
        for m in METHODS:
            totals[m] = calls[m] = 0
        outcome = run_episode(rulebase, scenario, int(seed))
        steps = outcome.duration_s * rate_hz
        per_step = sum(totals.values()) / 1000.0 / steps
        detail = ", ".join(f"{m} {totals[m] / 1000.0 / max(calls[m], 1):.1f} us x {calls[m] / steps:.2f}" for m in METHODS)
        print(f"{spec}: estimator {per_step:.1f} us per control step ({steps:.0f} steps; per call: {detail})")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.estimator_cpu", description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--save", metavar="FILE.npz")
    parser.add_argument("--compare", metavar="FILE.npz")
    parser.add_argument("--profile", action="store_true")
    parser.add_argument("--episode", metavar="SCENARIO:SEED,...")
    args = parser.parse_args(argv)
    if args.episode:
        episode_cost(args.episode.split(","))
        return 0
    items = readings()
    record: list = []
    replay(items, record)  # warm-up, and the poses
    poses = np.array(record)
    if args.save:
        np.savez(args.save, poses=poses)
    if args.compare:
        ref = np.load(args.compare)["poses"]
        if ref.shape != poses.shape:
            print(f"compare: shapes differ {ref.shape} vs {poses.shape}")
        else:
            both_nan = np.isnan(ref) & np.isnan(poses)
            diff = np.where(both_nan, 0.0, np.abs(ref - poses))
            names = ["time", "east", "north", "heading", "speed", "yaw_rate", "pos_sigma", "head_sigma", "healthy",
                     "gps_ok"] + [f"cov{i}{j}" for i in range(3) for j in range(3)]
            print("compare: largest absolute difference per field over", len(poses), "poses")
            print("  " + ", ".join(f"{n} {d:.2e}" for n, d in zip(names, diff.max(axis=0))))
    best = {m: math.inf for m in METHODS}
    calls = {}
    for _ in range(args.runs):
        for m, (ns, n) in replay(items).items():
            best[m] = min(best[m], ns / n / 1000.0)
            calls[m] = n
    print(f"{len(items)} readings, best of {args.runs} replays, mean CPU per call:")
    for m in METHODS:
        print(f"  {m:12s} {best[m]:7.1f} us  ({calls[m]} calls)")
    step = sum(best[m] * PER_STEP[m] for m in METHODS)
    print(f"  per 25 Hz control step (2 wheels, 2 attitude, 0.2 GPS, 1 pose): {step:.1f} us")
    if args.profile:
        profiler = cProfile.Profile()
        profiler.runcall(replay, items)
        pstats.Stats(profiler).sort_stats("tottime").print_stats(25)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
