"""The dynamic world end to end (issue 12): emulator and daemon as processes, lockstep, defaults."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from bench.bench_navigation import ACCEPTANCE_RADIUS_M, write_inputs
from rover_ctl.app.report import read_jsonl
from rover_ctl.app.sim import ARM_AT_S, SimOptions, simulate
from rover_ctl.estimation.frame import LocalFrame
from rover_ctl.mission.files import save_mission
from rover_ctl.mission.model import FRAME_GLOBAL_RELATIVE_ALT, Home, Mission, MissionItem
from rover_ctl.tuning.scenarios import CRUISE_MPS, START_LAG_S, scenarios  # the pedestrian is timed as the benchmark's traffic
from rover_ctl.vocabulary import Cmd

HOME = (-35.363261, 149.165230, 584.0)

pytestmark = pytest.mark.sitl


def mission_file(path: Path, waypoints_en: list[tuple[float, float]]) -> Path:
    frame = LocalFrame(*HOME)
    items = [MissionItem(Cmd.NAV_WAYPOINT, FRAME_GLOBAL_RELATIVE_ALT, x=lat, y=lon)
             for lat, lon in (frame.to_geodetic(e, n) for e, n in waypoints_en)]  # fmt: skip
    save_mission(Mission(items=items, home=Home(*HOME)), path)
    return path


def test_a_pedestrian_crossing_the_path_is_let_through(tmp_path):
    """A pedestrian (0.3 m) walks across the leg from the left at 0.8 m/s, timed to reach the
    rover's line 12 m out just as the rover does: the rover slows or stops, lets it pass and
    goes on behind it, without contact."""
    along_m, speed_mps = 12.0, 0.8
    arrive_s = START_LAG_S + along_m / CRUISE_MPS
    frame = LocalFrame(*HOME)
    lat, lon = frame.to_geodetic(-speed_mps * arrive_s, along_m)
    world = {"type": "FeatureCollection", "home": [HOME[1], HOME[0], HOME[2], 0.0], "features": [
        {"type": "Feature", "geometry": {"type": "Point", "coordinates": [lon, lat]},
         "properties": {"id": "pedestrian", "radius_m": 0.3,
                        "motion": {"type": "velocity", "velocity_mps": [speed_mps, 0.0], "start": "armed"}}}]}  # fmt: skip
    (tmp_path / "world.geojson").write_text(json.dumps(world))
    out = tmp_path / "run"
    metrics = simulate(SimOptions(mission=mission_file(tmp_path / "leg.waypoints", [(0.0, 25.0)]), out=out,
                                  world=tmp_path / "world.geojson"), plots=False)  # fmt: skip

    assert metrics["success"] and metrics["collisions"] == 0, metrics
    rows = list(csv.DictReader((out / "control.csv").open()))
    yielded = [r for r in rows if r["yield_track"]]
    assert yielded, "the rover never yielded to the pedestrian"
    assert min(float(r["speed_limit_mps"]) for r in yielded) < CRUISE_MPS
    # It went on behind the pedestrian: past the crossing point while the pedestrian was east of the line.
    states = [r for r in read_jsonl(out / "truth.jsonl") if r["type"] == "state"]
    crossed = next(s for s in states if s["north_m"] >= along_m)
    armed_s = next(float(r["t_s"]) for r in rows if r["armed"] == "1")
    pedestrian_east_m = -speed_mps * arrive_s + speed_mps * (crossed["t_s"] - armed_s)
    assert pedestrian_east_m > crossed["east_m"], (pedestrian_east_m, crossed)


@pytest.mark.parametrize("seed", [18, 34])
def test_walkers_coming_head_on_are_stepped_aside_from(tmp_path, seed):
    """The navigation benchmark's head_on worlds 18 and 34 (one or two walkers coming down the leg
    at the rover): with stepping aside off (``evasion.enabled=0``) the rover strikes a walker in
    each; with it (the default) it steps aside, without contact. (World 25, used before, was a near
    miss that went either way while a lockstep run's arming time followed the wall clock.)"""
    mission, world = write_inputs(scenarios(seed)["head_on"], tmp_path)
    out = tmp_path / "run"
    metrics = simulate(SimOptions(mission=mission, out=out, world=world, seed=seed,
                                  config_overrides=[f"executor.acceptance_radius_m={ACCEPTANCE_RADIUS_M}"]), plots=False)  # fmt: skip
    assert metrics["success"] and metrics["collisions"] == 0, metrics
    rows = list(csv.DictReader((out / "control.csv").open()))
    assert any(r["evade_track"] for r in rows), "the rover never stepped aside"


def test_an_830_m_mission_completes_under_sim_defaults(tmp_path):
    """83 legs of 10 m zigzagging north-east (830 m, nominally 692 s at cruise speed): no
    --timeout-s, the budget scales with the mission and the mission completes."""
    step_m = 10.0 / 2**0.5
    zigzag = [(step_m * (i % 2), step_m * i) for i in range(1, 84)]
    metrics = simulate(SimOptions(mission=mission_file(tmp_path / "zigzag.waypoints", zigzag), out=tmp_path / "run"), plots=False)
    assert metrics["success"], metrics
    assert metrics["waypoints_reached"] == metrics["waypoints_total"] == 83
    assert metrics["duration_s"] > 600.0  # longer than the old fixed budget allowed


def test_a_lockstep_run_of_a_seed_is_the_same_every_time(tmp_path):
    """Two ``rover-ctl sim`` runs of one world and seed drive the same, byte for byte in the
    emulator's truth log up to the mission's end, however long the ground station's commands took
    in wall time: the first frame waits for the daemon, the daemon steps every frame from the
    first, everything a frame sends the vehicle precedes the frame's answer, and the arming lands
    at the frame the clock is held at (ARM_AT_S; docs/architecture.md, "Lockstep handshake")."""
    runs = []
    for k in (1, 2):
        folder = tmp_path / str(k)
        folder.mkdir()
        mission, world = write_inputs(scenarios(18)["head_on"], folder)
        metrics = simulate(SimOptions(mission=mission, out=folder / "run", world=world, seed=18,
                                      config_overrides=[f"executor.acceptance_radius_m={ACCEPTANCE_RADIUS_M}"]), plots=False)  # fmt: skip
        end_s = ARM_AT_S + metrics["duration_s"]
        truth = [line for line in (folder / "run" / "truth.jsonl").read_text().splitlines() if json.loads(line)["t_s"] <= end_s]
        runs.append((metrics["duration_s"], metrics["path_length_m"], metrics["collisions"], truth))
    assert runs[0][:3] == runs[1][:3]
    assert runs[0][3] == runs[1][3]
