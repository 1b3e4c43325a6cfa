"""Navigation benchmark: seeded worlds driven end to end (emulator + daemon in lockstep), per rule base.

Scenarios (all at ArduPilot's CMAC field; the daemon is never told where the obstacles are, it
sees them only with its rangefinders):

* ``open``: no obstacles, two legs (0,0) -> (0,30) -> (25,30).
* ``scattered``: the same legs with ``rover-sitl --scatter`` obstacles (seeded; >= 2 m gaps).
* ``walls``: one straight leg of 40 m crossed by two walls, each with a 2.5 m gap off the line.
* ``cul_de_sac``: a U of walls open towards the rover on the line of a 30 m leg.
* ``moving``: a 0.6 m drum crossing the 30 m leg at 0.5 m/s, and one travelling against the rover.
* ``crossing``: crossing traffic on the two legs of ``open``: 2-5 drums (radius 0.3-0.6 m) at
  0.3-1.0 m/s, each crossing one leg at right angles from either side, timed (seeded, +-3 s) to
  reach the leg about when a rover at cruise speed gets there.
* ``narrow_gap``: a 16 m wall across a 30 m leg with one opening 1.5 times the rover's width,
  its centre up to 2 m off the leg (seeded).
* ``dense_clutter``: 30 drums (radius 0.2-0.5 m, >= 1.2 m apart) within 3 m of a 50 m leg (seeded).

Variants: the rule bases ``paper`` and ``default``, and ``default+predict``: the default rule base
with obstacle tracks and prediction on (``proximity.horizon_s`` = ``PREDICT_HORIZON_S``).
A collision is "moving" when the rover's true speed at the contact was above
``STOPPED_SPEED_MPS``, else "stopped" (struck while yielding).

Figures per scenario and rule base: success rate (mission complete, no collision, within the
time budget), collisions, path length over the shortest collision-free path (the planner's
visibility-graph path around the true obstacles, inflated by the robot's half-width only; the
straight legs for moving obstacles), mission time, smoothness as total heading change per metre
(deg/m, from truth), and the control-loop latency p99 (sensor message in to override out).
"""

from __future__ import annotations

import json
import math
import random
import statistics
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from rover_ctl.config import PlannerParams, RobotParams
from rover_ctl.estimation.frame import LocalFrame
from rover_ctl.mission.files import save_mission
from rover_ctl.mission.model import FRAME_GLOBAL_RELATIVE_ALT, Home, Mission, MissionItem
from rover_ctl.navigation.planner import Circle, Planner
from rover_ctl.app.report import read_jsonl
from rover_ctl.app.sim import SimError, SimOptions, simulate

HOME = (-35.363261, 149.165230, 584.0)
PREDICT_HORIZON_S = 2.0
VARIANTS = {"paper": ("paper", []), "default": ("default", []),
            "default+predict": ("default", [f"proximity.horizon_s={PREDICT_HORIZON_S}"])}  # fmt: skip
"""Variant name -> (rule base, daemon config overrides)."""
STOPPED_SPEED_MPS = 0.05
"""A collision with the rover slower than this (truth) was one it was struck in while stopped."""
CRUISE_MPS = 1.2
"""executor.cruise_speed_mps: the crossing traffic is timed for it."""
WORKERS = 2
"""Simulations run side by side (each is two processes; the machine has 2 cores)."""
ACCEPTANCE_RADIUS_M = 0.5
"""Waypoint acceptance radius for the runs: small, so that cutting corners does not shorten paths."""
TIME_BUDGET_S = 240.0
"""Sim seconds a mission may take before it counts as failed."""
NAV_WAYPOINT = 16

EN = tuple[float, float]


@dataclass
class Scenario:
    name: str
    legs_en: list[EN]
    """Home first, then the waypoints."""
    circles: list[tuple[EN, float]] = field(default_factory=list)
    polygons: list[list[EN]] = field(default_factory=list)
    moving: list[dict[str, Any]] = field(default_factory=list)
    """Circle features with a "motion" member (centre_en, radius_m, velocity_en)."""
    scatter: int = 0


def _wall(a: EN, b: EN, thickness_m: float = 0.3) -> list[EN]:
    """A thin rectangle from a to b."""
    (ax, ay), (bx, by) = a, b
    length = math.dist(a, b)
    nx, ny = -(by - ay) / length * thickness_m / 2, (bx - ax) / length * thickness_m / 2
    return [(ax + nx, ay + ny), (bx + nx, by + ny), (bx - nx, by - ny), (ax - nx, ay - ny)]


NARROW_GAP_WIDTH_M = 1.5 * RobotParams.footprint_width_m
"""narrow_gap: the opening, 1.5 times the rover's width (issue 12)."""


def _narrow_gap(seed: int) -> list[list[EN]]:
    """A wall across the 30 m leg at 15 m, 16 m long, with one opening of ``NARROW_GAP_WIDTH_M``
    whose centre lies up to 2 m either side of the leg (seeded)."""
    centre = random.Random(seed * 7919 + 12).uniform(-2.0, 2.0)
    half = NARROW_GAP_WIDTH_M / 2.0
    return [_wall((-8.0, 15.0), (centre - half, 15.0)), _wall((centre + half, 15.0), (8.0, 15.0))]


def _dense_clutter(seed: int, count: int = 30) -> list[tuple[EN, float]]:
    """``count`` drums (radius 0.2-0.5 m) along a 50 m leg, within 3 m of it, none on the first or
    last 3 m, at least 1.2 m apart edge to edge (seeded)."""
    rng = random.Random(seed * 104729 + 30)
    drums: list[tuple[EN, float]] = []
    while len(drums) < count:
        centre, radius = (rng.uniform(-3.0, 3.0), rng.uniform(3.0, 47.0)), rng.uniform(0.2, 0.5)
        if all(math.dist(centre, c) - r - radius >= 1.2 for c, r in drums):
            drums.append((centre, radius))
    return drums


def scenarios(seed: int) -> dict[str, Scenario]:
    two_legs = [(0.0, 0.0), (0.0, 30.0), (25.0, 30.0)]
    line = [(0.0, 0.0), (0.0, 40.0)]
    gap1 = 1.0 + (seed % 3)  # gap position varies with the seed
    walls = [
        _wall((-12.0, 14.0), (gap1, 14.0)), _wall((gap1 + 2.5, 14.0), (12.0, 14.0)),
        _wall((-12.0, 26.0), (-gap1 - 2.5, 26.0)), _wall((-gap1, 26.0), (12.0, 26.0)),
    ]  # fmt: skip
    cul = [_wall((-2.5, 12.0), (-2.5, 17.0)), _wall((-2.5, 17.0), (2.5, 17.0)), _wall((2.5, 17.0), (2.5, 12.0))]
    rng = random.Random(seed)
    crossing = []
    for _ in range(rng.randint(2, 5)):
        speed, radius, side = rng.uniform(0.3, 1.0), rng.uniform(0.3, 0.6), rng.choice((-1.0, 1.0))
        if rng.random() < 0.6:  # the first leg, northwards along x = 0
            along = rng.uniform(6.0, 27.0)
            arrive_s = along / CRUISE_MPS + rng.uniform(-3.0, 3.0)
            crossing.append({"center_en": (side * speed * arrive_s, along), "radius_m": radius, "velocity_en": (-side * speed, 0.0)})
        else:  # the second leg, eastwards along y = 30
            along = rng.uniform(3.0, 22.0)
            arrive_s = (30.0 + along) / CRUISE_MPS + rng.uniform(-3.0, 3.0)
            crossing.append({"center_en": (along, 30.0 + side * speed * arrive_s), "radius_m": radius, "velocity_en": (0.0, -side * speed)})
    narrow = _narrow_gap(seed)
    clutter = _dense_clutter(seed)
    return {
        "open": Scenario("open", two_legs),
        "scattered": Scenario("scattered", two_legs, scatter=10),
        "walls": Scenario("walls", line, polygons=walls),
        "cul_de_sac": Scenario("cul_de_sac", [(0.0, 0.0), (0.0, 30.0)], polygons=cul),
        "moving": Scenario("moving", [(0.0, 0.0), (0.0, 30.0)], moving=[
            {"center_en": (-8.0, 12.0), "radius_m": 0.6, "velocity_en": (0.5, 0.0)},
            {"center_en": (0.5, 28.0), "radius_m": 0.5, "velocity_en": (0.0, -0.3)},
        ]),  # fmt: skip
        "crossing": Scenario("crossing", two_legs, moving=crossing),
        "narrow_gap": Scenario("narrow_gap", [(0.0, 0.0), (0.0, 30.0)], polygons=narrow),
        "dense_clutter": Scenario("dense_clutter", [(0.0, 0.0), (0.0, 50.0)], circles=clutter),
    }


def write_inputs(scenario: Scenario, folder: Path) -> tuple[Path, Path | None]:
    """The mission file and (unless scattered) the world file of a scenario."""
    frame = LocalFrame(*HOME)

    def lonlat(point: EN) -> list[float]:
        lat, lon = frame.to_geodetic(*point)
        return [lon, lat]

    items = []
    for east, north in scenario.legs_en[1:]:
        lat, lon = frame.to_geodetic(east, north)
        items.append(MissionItem(NAV_WAYPOINT, FRAME_GLOBAL_RELATIVE_ALT, x=lat, y=lon))
    mission_path = folder / "mission.waypoints"
    save_mission(Mission(items=items, home=Home(*HOME)), mission_path)
    if scenario.scatter:
        return mission_path, None
    features = [
        {"type": "Feature", "geometry": {"type": "Point", "coordinates": lonlat(c)}, "properties": {"radius_m": r}}
        for c, r in scenario.circles
    ]
    features += [
        {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [[lonlat(p) for p in poly + [poly[0]]]]}, "properties": {}}
        for poly in scenario.polygons
    ]
    features += [
        {"type": "Feature", "geometry": {"type": "Point", "coordinates": lonlat(m["center_en"])},
         "properties": {"radius_m": m["radius_m"], "motion": {"type": "velocity", "velocity_mps": list(m["velocity_en"])}}}
        for m in scenario.moving
    ]  # fmt: skip
    world_path = folder / "world.geojson"
    world_path.write_text(json.dumps({"type": "FeatureCollection", "home": [HOME[1], HOME[0], HOME[2], 0.0], "features": features}))
    return mission_path, world_path


def shortest_length_m(scenario: Scenario, world_path: Path | None) -> float:
    """Shortest collision-free path for the robot's footprint around the true static obstacles."""
    frame = LocalFrame(*HOME)
    circles: list[Circle] = []
    polygons: list[list[EN]] = []
    if world_path is not None and world_path.exists():
        for feature in json.loads(world_path.read_text())["features"]:
            geometry, props = feature["geometry"], feature.get("properties") or {}
            if "motion" in props:
                continue  # moving: no fixed detour; the straight legs are the lower bound
            if geometry["type"] == "Point":
                lon, lat = geometry["coordinates"][:2]
                circles.append(Circle(frame.to_enu(lat, lon), props["radius_m"]))
            elif geometry["type"] == "Polygon":
                polygons.append([frame.to_enu(lat, lon) for lon, lat in geometry["coordinates"][0][:-1]])
    planner = Planner(replace(PlannerParams(), clearance_margin_m=0.0), RobotParams(), polygons=polygons, circles=circles)
    path = planner.plan_route(scenario.legs_en[0], scenario.legs_en[1:])
    if path.ok:
        return path.length_m
    return sum(math.dist(a, b) for a, b in zip(scenario.legs_en, scenario.legs_en[1:]))


def turning_deg_per_m(out: Path) -> float:
    """Total heading change per metre driven (truth), a smoothness figure: lower is smoother."""
    states = [r for r in read_jsonl(out / "truth.jsonl") if r["type"] == "state" and abs(r["speed_mps"]) > 0.05]
    turn = sum(abs((b["yaw_deg"] - a["yaw_deg"] + 180.0) % 360.0 - 180.0) for a, b in zip(states, states[1:]))
    dist = sum(math.hypot(b["east_m"] - a["east_m"], b["north_m"] - a["north_m"]) for a, b in zip(states, states[1:]))
    return turn / dist if dist > 0 else math.nan


def collisions_moving(out: Path) -> tuple[int, int]:
    """(collisions with the rover moving, with it stopped), from the truth log."""
    speed, moving, stopped = 0.0, 0, 0
    for record in read_jsonl(out / "truth.jsonl"):
        if record["type"] == "state":
            speed = abs(record["speed_mps"])
        elif record["type"] == "collision":
            moving, stopped = (moving + 1, stopped) if speed > STOPPED_SPEED_MPS else (moving, stopped + 1)
    return moving, stopped


def one_run(name: str, variant: str, seed: int, root: Path) -> dict[str, Any]:
    scenario = scenarios(seed)[name]
    rulebase, overrides = VARIANTS[variant]
    folder = root / f"{name}-{variant}-{seed}"
    folder.mkdir(parents=True)
    mission_path, world_path = write_inputs(scenario, folder)
    options = SimOptions(mission=mission_path, out=folder / "run", world=world_path, obstacles=scenario.scatter or None,
                         seed=seed, rulebase=rulebase, timeout_s=TIME_BUDGET_S,
                         config_overrides=[f"executor.acceptance_radius_m={ACCEPTANCE_RADIUS_M}", *overrides])  # fmt: skip
    try:
        metrics = simulate(options, plots=False)
    except SimError as exc:
        return {"scenario": name, "rulebase": variant, "seed": seed, "success": False, "error": str(exc)}
    moving, stopped = collisions_moving(folder / "run")
    world_used = folder / "run" / "world.geojson" if scenario.scatter else world_path
    shortest = shortest_length_m(scenario, world_used)
    return {
        "scenario": name, "rulebase": variant, "seed": seed, "success": metrics["success"],
        "timed_out": metrics["timed_out"], "collisions": metrics["collisions"], "collisions_moving": moving, "collisions_stopped": stopped, "path_ratio": metrics["path_length_m"] / shortest if shortest else math.nan,
        "duration_s": metrics["duration_s"], "turning_deg_per_m": turning_deg_per_m(folder / "run"),
        "latency_p99_ms": metrics["loop_latency_p99_ms"],
    }  # fmt: skip


def _mean(values: list[float]) -> float:
    values = [v for v in values if v is not None and math.isfinite(v)]
    return statistics.fmean(values) if values else math.nan


FULL_WORLDS = {"open": 3, "scattered": 100, "walls": 10, "cul_de_sac": 5, "moving": 10, "crossing": 100, "narrow_gap": 100,
               "dense_clutter": 100}  # fmt: skip
QUICK_WORLDS = {"open": 1, "scattered": 3, "walls": 1, "cul_de_sac": 1, "moving": 1, "crossing": 2, "narrow_gap": 2, "dense_clutter": 2}
PREVIOUS = Path(__file__).resolve().parent / "results" / "navigation.json"
"""With ``only``, the rows of the other scenarios are kept from here (the last run)."""


def run(quick: bool, only: list[str] | None = None, worlds: int | None = None) -> dict[str, Any]:
    """All scenarios and variants, or ``only`` these scenarios (the others' rows kept from the
    last run), on ``worlds`` seeded worlds each instead of the default counts."""
    counts = dict(QUICK_WORLDS if quick else FULL_WORLDS)
    unknown = sorted(set(only or ()) - set(counts))
    if unknown:
        raise ValueError(f"unknown scenario(s) {', '.join(unknown)} (known: {', '.join(counts)})")
    if only:
        counts = {name: counts[name] for name in only}
    if worlds:
        counts = {name: worlds for name in counts}
    jobs = [(name, variant, seed) for name, count in counts.items() for variant in VARIANTS for seed in range(1, count + 1)]
    with tempfile.TemporaryDirectory(prefix="bench_nav_") as tmp, ThreadPoolExecutor(WORKERS) as pool:
        runs = list(pool.map(lambda job: one_run(*job, Path(tmp)), jobs))
    today = time.strftime("%Y-%m-%d")
    fresh = []
    for name in counts:
        for variant in VARIANTS:
            group = [r for r in runs if r["scenario"] == name and r["rulebase"] == variant]
            fresh.append({
                "scenario": name, "rulebase": variant, "runs": len(group), "date": today,
                "success_rate": sum(r["success"] for r in group) / len(group),
                "collisions": sum(r.get("collisions", 0) for r in group),
                "collisions_moving": sum(r.get("collisions_moving", 0) for r in group),
                "collisions_stopped": sum(r.get("collisions_stopped", 0) for r in group),
                "timeouts": sum(bool(r.get("timed_out")) for r in group),
                "path_ratio": _mean([r.get("path_ratio") for r in group if r["success"]]),
                "duration_s": _mean([r.get("duration_s") for r in group if r["success"]]),
                "turning_deg_per_m": _mean([r.get("turning_deg_per_m") for r in group if r["success"]]),
                "latency_p99_ms": max((r.get("latency_p99_ms") or 0.0 for r in group), default=math.nan),
            })  # fmt: skip
    rows = fresh
    if only and PREVIOUS.exists():
        previous = json.loads(PREVIOUS.read_text())
        kept = [dict(r, date=r.get("date", previous.get("date"))) for r in previous.get("rows", []) if r["scenario"] not in counts]
        runs = [r for r in previous.get("runs", []) if r["scenario"] not in counts] + runs
        order = list(FULL_WORLDS)
        rows = sorted(kept + fresh, key=lambda r: (order.index(r["scenario"]) if r["scenario"] in order else len(order), list(VARIANTS).index(r["rulebase"])))
    lines = [
        "| scenario | rule base | runs | success | collisions (moving / stopped) | timeouts | path / shortest | time (s) | turning (deg/m) | loop latency p99 (ms, worst run) | measured |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        split = f" ({r['collisions_moving']} / {r['collisions_stopped']})" if "collisions_moving" in r else ""
        lines.append(
            f"| {r['scenario']} | {r['rulebase']} | {r['runs']} | {r['success_rate']:.0%} | {r['collisions']}{split} | {r['timeouts']} | "
            f"{r['path_ratio']:.2f} | {r['duration_s']:.1f} | {r['turning_deg_per_m']:.1f} | {r['latency_p99_ms']:.2f} | {r['date']} |"
        )
    errors = sorted({r["error"] for r in runs if "error" in r})
    markdown = "\n".join(lines)
    markdown += (
        "\n\nEach run: `rover-sitl --lockstep` and `rover-ctl run` as processes, the mission uploaded and "
        f"started over the GCS link (`rover_ctl.app.sim`), waypoint acceptance radius {ACCEPTANCE_RADIUS_M} m. Success = mission complete, no collision, within "
        f"{TIME_BUDGET_S:.0f} s of sim time. Path / shortest: driven length (truth) over the shortest "
        "collision-free path for the robot's footprint around the true static obstacles (straight legs "
        "for moving ones); it can fall below 1 where the carrot look-ahead and the acceptance radius cut "
        "corners. Path, time and turning are means over successful runs (nan: none). Latency: two "
        "simulations side by side on a 2-core machine. The paper's controller has only stop rules "
        "for a near target, so it slows to a crawl as it closes in and rarely gets inside the 0.5 m "
        "acceptance radius within the time budget, even in the open field."
    )
    markdown += (
        f"\n\ndefault+predict: the default rule base with obstacle tracks and prediction "
        f"(`proximity.horizon_s={PREDICT_HORIZON_S:g}`, docs/perception.md). Collisions (moving / stopped): "
        f"the rover's true speed at the contact above {STOPPED_SPEED_MPS} m/s or not (only rows measured since "
        "the split was added have it). Measured: the date of the run that made the row."
    )
    if only or worlds:
        markdown += (f"\n\n_This run: `--only {','.join(counts)}`" if only else "\n\n_This run: all scenarios") + \
            (f" on {worlds} worlds each (to fit the wall time; the full counts are {FULL_WORLDS})" if worlds else "") + \
            "; the other rows are kept from the run named by their date._"  # fmt: skip
    if quick:
        markdown += "\n\n_Quick mode: 1-3 seeds per scenario; the full run uses 100 scattered worlds._"
    if errors:
        markdown += "\n\nRuns that failed to start: " + "; ".join(errors)
    return {"title": "Navigation (emulator in the loop)", "markdown": markdown, "rows": rows, "runs": runs, "quick": quick}
