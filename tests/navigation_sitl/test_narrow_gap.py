"""A 1.5x-width gap driven through (issue 12), end to end: emulator and daemon as processes in
lockstep, the bench's ``narrow_gap`` world, narrow passages on (``passage.enabled``)."""

from __future__ import annotations

import csv
import itertools
import json
from pathlib import Path

import pytest

from rover_ctl.app.report import read_jsonl
from rover_ctl.app.sim import SimOptions, simulate
from rover_ctl.mission.files import save_mission
from rover_ctl.tuning import scenarios

pytestmark = pytest.mark.sitl

WALL_N = 15.0
"""narrow_gap: the wall's centre line (0.3 m thick) across the leg."""


def opening(seed: int) -> tuple[float, float]:
    """(west, east) edges of the seed's opening, from the world's two wall pieces."""
    west, east = scenarios.scenarios(seed)["narrow_gap"].polygons
    return max(p[0] for p in west), min(p[0] for p in east)


def crossing_east_m(states: list[dict]) -> float:
    """Where the rover's true centre crossed the wall's line northwards."""
    for a, b in itertools.pairwise(states):
        if a["north_m"] < WALL_N <= b["north_m"]:
            return a["east_m"] + (b["east_m"] - a["east_m"]) * (WALL_N - a["north_m"]) / (b["north_m"] - a["north_m"])
    raise AssertionError("the rover never crossed the wall's line")


SEEDS = (5, 8, 9, 14)
"""Worlds whose opening lies on the side the default rule base follows the wall (east of the leg,
0.9-1.9 m off it). The pose (GPS noise) at the wall depends on when arming happened, which in
lockstep varies with wall-clock retries (rover_ctl/tuning/episode.py), so runs differ. Before
the front beam's scan and the guard (docs/perception.md), 3 runs of 40 touched the opening's
edge (the line-up 0.12 m off the centre line) and 37 went through; after, 0 of 80 and 80 of 80.
A sweep the passage cannot prove wide enough, a gap not square to the wall or a guard that trips
hands the rover back to the rule base, which goes round."""


def drive(tmp_path: Path, seed: int) -> tuple[dict, Path]:
    scenario = scenarios.scenarios(seed)["narrow_gap"]
    save_mission(scenarios.mission(scenario), tmp_path / f"leg{seed}.waypoints")
    (tmp_path / f"world{seed}.geojson").write_text(json.dumps(scenarios.world_doc(scenario)))
    out = tmp_path / f"run{seed}"
    metrics = simulate(SimOptions(mission=tmp_path / f"leg{seed}.waypoints", out=out, world=tmp_path / f"world{seed}.geojson",
                                  seed=seed, config_overrides=["passage.enabled=true", "executor.acceptance_radius_m=0.5"]),
                       plots=False)  # fmt: skip
    return metrics, out


def test_a_one_and_a_half_width_gap_is_driven_through(tmp_path: Path):
    """The daemon is told nothing of the wall: its left rangefinder sweeps the opening as the rule
    base follows the wall, the passage lines up, looks through and drives through. Every run ends
    at the waypoint without contact; the rover's true path crosses the wall's line inside the
    0.6 m opening in at least one of the worlds (and then passed through every manoeuvre state)."""
    through = []
    for seed in SEEDS:
        metrics, out = drive(tmp_path, seed)
        assert metrics["success"] and metrics["collisions"] == 0, (seed, metrics)
        states = [r for r in read_jsonl(out / "truth.jsonl") if r["type"] == "state"]
        west, east = opening(seed)
        if west < crossing_east_m(states) < east:
            passage = {r["passage"] for r in csv.DictReader((out / "control.csv").open())}
            assert {"line_up", "look", "pass"} <= passage, seed
            through.append(seed)
    assert through, "no world was driven through its opening"
