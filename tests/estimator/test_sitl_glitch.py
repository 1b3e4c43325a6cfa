"""A 50 m GPS glitch held for 30 s while the daemon drives a mission, emulator in the loop (three
processes, lockstep): the fault is the emulator's SIM_GPS_GLITCH_X set over the wire mid-leg. The
rover must stay on its path (truth, beyond the GPS bias it follows), reach no waypoint it is not at, and the estimate must be back
to its normal error within 10 s of the glitch's end."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
from shapely.geometry import LineString, Point

from rover_ctl.app.report import read_jsonl
from rover_ctl.app.sim import SimOptions, SimRun
from rover_ctl.estimation.frame import LocalFrame
from rover_ctl.mission.files import load_mission

ROOT = Path(__file__).resolve().parents[2]
LOOP = ROOT / "missions" / "cmac_loop.waypoints"
GLITCH_NORTH_M = 50.0
GLITCH_S = 30.0
RECOVERY_S = 10.0
CROSS_TRACK_LIMIT_M = 2.0
RECOVERED_RATIO = 1.25
"""After recovery the error's maximum over 20 s is within this factor of its maximum over the
NORMAL_WINDOW_S before the glitch (both are maxima of a noisy series: equal levels differ by a few
per cent)."""
NORMAL_WINDOW_S = 60.0
"""What "normal" is sampled over. 20 s was too small a sample of the level: that window's maximum
was 1.12 m in one suite run (which then failed at 1.56 m after recovery) and 1.56-1.58 m in six
others, whose minute before the glitch reached 1.76 m and whose error 0-5 s after the glitch's end
was 0.83 m, rising to 1.4 m with the bias's wander, not falling from the glitch."""
ACCEPTANCE_M = 2.0
"""ExecutorParams.acceptance_radius_m."""

pytestmark = pytest.mark.sitl


def _control_rows(out: Path) -> list[dict]:
    with open(out / "control.csv", newline="") as handle:
        return [r for r in csv.DictReader(handle) if r["est_east_m"]]


def _series(times: list[float], values: list) -> callable:
    """Sample-and-hold lookup of a logged series at a time."""
    t, v = np.array(times), np.array(values, dtype=float)
    return lambda t_s: v[min(int(np.searchsorted(t, t_s)), len(t) - 1)]


def test_fifty_metre_glitch_for_thirty_seconds_keeps_the_rover_on_its_path(tmp_path):
    out = tmp_path / "run"
    mission = load_mission(LOOP).mission
    frame = LocalFrame(mission.home.lat_deg, mission.home.lon_deg)
    waypoints = [frame.to_enu(i.x, i.y) for i in mission.items if i.command == 16]
    with SimRun(SimOptions(mission=LOOP, out=out, timeout_s=300.0)) as run:
        run.arm()
        run.start_mission()
        assert run.wait_for(lambda p: 1 in p.reached, sim_timeout_s=60.0)
        run.sitl_param("SIM_GPS_GLITCH_X", GLITCH_NORTH_M)
        assert run.wait_for(lambda p: False, sim_timeout_s=GLITCH_S) is False
        run.sitl_param("SIM_GPS_GLITCH_X", 0.0)
        assert run.wait_for(lambda p: p.complete, sim_timeout_s=200.0), run.progress.texts
        texts = run.progress.texts

    truth = read_jsonl(out / "truth.jsonl")
    fixes = [r for r in truth if r["type"] == "gps" and not r["dropped"]]
    glitched = [r["t_s"] for r in fixes if r["err_glitch_n_m"]]
    start_s, end_s = glitched[0], glitched[-1]
    assert end_s - start_s >= GLITCH_S - 1.0
    states = [r for r in truth if r["type"] == "state"]
    truth_en = _series([s["t_s"] for s in states], [frame.to_enu(s["lat_deg"], s["lon_deg"]) for s in states])
    bias_en = _series([r["t_s"] for r in fixes], [(r["err_bias_e_m"], r["err_bias_n_m"]) for r in fixes])
    events = read_jsonl(out / "events.jsonl")

    # On its path: the truth's distance from the path the daemon was following (its last plan),
    # beyond the GPS bias at that moment, which the estimate follows and so the rover with it (the
    # false-reach check below allows it too). The bias wanders by a metre and more: with the
    # truth's bare distance the limit failed a run whose truth was 2.19 m off while the glitch was
    # rejected. A glitch let in would put the rover tens of metres off.
    plans = [(e["t_s"], LineString(e["path_en"])) for e in events if e["type"] == "plan"]
    window = [s for s in states if start_s <= s["t_s"] <= end_s + RECOVERY_S]
    off_path = [([line for t0, line in plans if t0 <= s["t_s"]][-1].distance(Point(truth_en(s["t_s"]))), float(np.hypot(*bias_en(s["t_s"]))))
                for s in window]  # fmt: skip
    truth_off_m = max(d for d, _ in off_path)
    cross_track_m = max(d - bias for d, bias in off_path)

    # No waypoint reached falsely: at each MISSION_ITEM_REACHED the truth is within the radius
    # (plus what the GPS bias, which the estimate follows, may add).
    reached = [(e["t_s"], e["seq"]) for e in events if e["type"] == "reached" and 1 <= e["seq"] <= len(waypoints)]
    assert {seq for _, seq in reached} == set(range(1, len(waypoints) + 1))
    false_reach = [(t_s, seq) for t_s, seq in reached
                   if math.dist(truth_en(t_s), waypoints[seq - 1]) > ACCEPTANCE_M + float(np.hypot(*bias_en(t_s))) + 0.5]  # fmt: skip

    # Recovery: the estimate's error apart from the GPS bias (which it follows, as any filter
    # without another absolute reference must) is back to its pre-glitch level within RECOVERY_S.
    error = []
    for r in _control_rows(out):
        t_s = float(r["t_s"])
        error.append((t_s, math.dist((float(r["est_east_m"]), float(r["est_north_m"])), truth_en(t_s) + bias_en(t_s))))
    normal_m = max(e for t, e in error if start_s - NORMAL_WINDOW_S <= t < start_s)
    during_m = max(e for t, e in error if start_s <= t <= end_s)
    after_m = max(e for t, e in error if end_s + RECOVERY_S <= t <= end_s + RECOVERY_S + 20.0)
    print(f"glitch {start_s:.1f}-{end_s:.1f} s: cross-track {truth_off_m:.2f} m, beyond the GPS bias {cross_track_m:.2f} m, error before {normal_m:.2f} m, "
          f"during {during_m:.2f} m, from +{RECOVERY_S:g} s {after_m:.2f} m; reached {reached}")  # fmt: skip
    assert cross_track_m < CROSS_TRACK_LIMIT_M
    assert not false_reach
    assert after_m <= RECOVERED_RATIO * max(normal_m, 1.0)
    assert not any(t.startswith("FS GPS") for t in texts), texts
