"""Persistent obstacles end to end (issue 12): emulator and daemon as processes, lockstep. In the
benchmark's cul-de-sac (a U of walls open towards the rover on its leg) the rover, once its
rangefinders have seen the U, has the walls in its planner's map and is planned out of the U and
around it, instead of feeling its way along the walls (the map is on by default; the test
sets it all the same, so that it tests the map whatever the default)."""

from __future__ import annotations

import bisect
import csv
import json

import pytest
from shapely.affinity import translate
from shapely.geometry import LineString, Polygon

from bench.bench_navigation import ACCEPTANCE_RADIUS_M, write_inputs
from rover_ctl.app.report import read_jsonl
from rover_ctl.app.sim import SimOptions, simulate
from rover_ctl.tuning.scenarios import scenarios

pytestmark = pytest.mark.sitl


def test_in_the_cul_de_sac_the_rover_replans_around_the_walls_it_has_seen(tmp_path):
    scenario = scenarios(1)["cul_de_sac"]
    mission, world = write_inputs(scenario, tmp_path)
    out = tmp_path / "run"
    metrics = simulate(SimOptions(mission=mission, out=out, world=world, seed=1, timeout_s=240.0,
                                  config_overrides=[f"executor.acceptance_radius_m={ACCEPTANCE_RADIUS_M}",
                                                    "obstacle_map.enabled=1"]), plots=False)  # fmt: skip
    assert metrics["success"] and metrics["collisions"] == 0, metrics

    rows = list(csv.DictReader((out / "control.csv").open()))
    assert max(int(r["map_obstacles"] or 0) for r in rows) >= 1, "no persistent obstacle reached the planner"
    # A plan made with the rover inside the U (between its side walls, short of its back wall)
    # leads out of it: it does not go through the back wall, which the first plan did. Through:
    # across the wall's centre line (a rover pushed against the wall may start its plan inside
    # the 0.3 m thick wall's outline, as the planner's clearance band allows). Plans are in the
    # daemon's estimated frame, the walls in the world's: each plan is moved by the estimator's
    # error when it was made (about 0.7 m here; in the estimated frame a plan out of the U can
    # clip the back wall's true corner).
    u = Polygon([(-2.5, 12.0), (-2.5, 17.0), (2.5, 17.0), (2.5, 12.0)])
    back_wall = LineString([(-2.5, 17.0), (2.5, 17.0)])
    states = [r for r in read_jsonl(out / "truth.jsonl") if r["type"] == "state"]
    state_t = [s["t_s"] for s in states]
    row_t = [float(r["t_s"]) for r in rows]

    def true_path(plan):
        state = states[min(bisect.bisect_left(state_t, plan["t_s"]), len(states) - 1)]
        row = rows[min(bisect.bisect_left(row_t, plan["t_s"]), len(rows) - 1)]
        error_e = state["east_m"] - float(row["est_east_m"])
        error_n = state["north_m"] - float(row["est_north_m"])
        return translate(LineString(plan["path_en"]), error_e, error_n)

    plans = [true_path(e) for e in read_jsonl(out / "events.jsonl") if e.get("type") == "plan"]
    assert plans[0].intersects(back_wall)
    inside = [p for p in plans[1:] if u.contains(p.interpolate(0.0))]
    assert inside, [p.wkt for p in plans]
    assert not inside[-1].intersects(back_wall), inside[-1].wkt
