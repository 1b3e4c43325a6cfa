"""The seeded navigation scenarios: missions and emulator worlds at ArduPilot's CMAC field.

Shared by the navigation benchmark (``bench/bench_navigation.py``, which writes them as files for
``rover-ctl sim``) and ``rover-ctl tune`` (whose episode runner builds the same world in memory).
The daemon is never told where the obstacles are: it sees them only with its rangefinders.

* ``open``: no obstacles, two legs (0,0) -> (0,30) -> (25,30).
* ``scattered``: the same legs with ``rover-sitl --scatter`` obstacles (seeded; >= 2 m gaps).
* ``walls``: one straight leg of 40 m crossed by two walls, each with a 2.5 m gap off the line.
* ``cul_de_sac``: a U of walls open towards the rover on the line of a 30 m leg.
* ``moving``: a 0.6 m drum crossing the 30 m leg 12 m out at 0.5 m/s, timed (seeded, +-2 s) to
  reach the leg when a rover at cruise speed gets there, and one walking down the leg towards the
  rover at 0.3 m/s from 28 m out.
* ``crossing``: crossing traffic on the two legs of ``open``: 2-5 drums (radius 0.3-0.6 m) at
  0.3-1.0 m/s (up to 80% of cruise speed), each crossing one leg at right angles from either side,
  timed (seeded, +-2 s) to reach the leg when a rover at cruise speed gets there.
* ``head_on``: 1-2 pedestrians (radius 0.25-0.5 m) walking down a 30 m leg towards the rover at
  0.3-1.0 m/s, starting 18-28 m out within 0.5 m of the line.
* ``overtaking``: one pedestrian walking up the leg ahead of the rover at 0.3-0.6 m/s, starting
  4-8 m out within 0.4 m of the line: the rover has to pass it.

* ``narrow_gap``: a 16 m wall across a 30 m leg with one opening 1.5 times the rover's width,
  its centre up to 2 m off the leg (seeded).
* ``dense_clutter``: 30 drums (radius 0.2-0.5 m, >= 1.2 m apart) within 3 m of a 50 m leg (seeded).

Every scenario's moving obstacles start moving when the rover arms (world file ``"start":
"armed"``, ``"start"`` in their dicts), so the encounter does not depend on how long the ground
station took to upload and arm.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field
from typing import Any

from rover_ctl.config import RobotParams
from rover_ctl.estimation.frame import LocalFrame
from rover_ctl.mission.model import FRAME_GLOBAL_RELATIVE_ALT, Home, Mission, MissionItem
from rover_ctl.vocabulary import Cmd

HOME = (-35.363261, 149.165230, 584.0)
"""lat, lon, alt of every scenario's home (ArduPilot's CMAC field); the rover starts facing north."""
CRUISE_MPS = 1.2
"""executor.cruise_speed_mps: the crossing traffic is timed for it."""
START_LAG_S = 0.55
"""Seconds from arming by which the traffic is timed (``_arrival_s``). It was 1.5 while the daemon
waited for the vehicle's next 1 Hz heartbeat to drive after arming; since it drives on the
vehicle's ACCEPTED, the rover is about 0.95 s earlier (the runner, arming at 3 s: at 10 m along
the open scenario's leg 1.05 s behind a rover at cruise speed from arming, now 0.10 s), and 0.55
keeps the encounters the benchmark was built and measured with."""
ARRIVAL_JITTER_S = 2.0
"""Crossing traffic reaches the leg within this many seconds of the rover (seeded)."""
SCATTER_COUNT = 10
"""Obstacles of the ``scattered`` scenario."""

EN = tuple[float, float]


@dataclass
class Scenario:
    name: str
    legs_en: list[EN]
    """Home first, then the waypoints."""
    circles: list[tuple[EN, float]] = field(default_factory=list)
    polygons: list[list[EN]] = field(default_factory=list)
    moving: list[dict[str, Any]] = field(default_factory=list)
    """Circle features with a "motion" member (center_en, radius_m, velocity_en)."""
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


def _arrival_s(distance_m: float) -> float:
    """When a rover that armed at 0 reaches ``distance_m`` along its route at cruise speed."""
    return START_LAG_S + distance_m / CRUISE_MPS


def _mover(center_en: EN, radius_m: float, velocity_en: EN) -> dict[str, Any]:
    """A drum moving at constant velocity from the rover's arming on (``"start": "armed"``)."""
    return {"center_en": center_en, "radius_m": radius_m, "velocity_en": velocity_en, "start": "armed"}


def scenarios(seed: int) -> dict[str, Scenario]:
    """Every scenario for one seed (the seed moves walls' gaps and draws the crossing traffic)."""
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
            arrive_s = _arrival_s(along) + rng.uniform(-ARRIVAL_JITTER_S, ARRIVAL_JITTER_S)
            crossing.append(_mover((side * speed * arrive_s, along), radius, (-side * speed, 0.0)))
        else:  # the second leg, eastwards along y = 30
            along = rng.uniform(3.0, 22.0)
            arrive_s = _arrival_s(30.0 + along) + rng.uniform(-ARRIVAL_JITTER_S, ARRIVAL_JITTER_S)
            crossing.append(_mover((along, 30.0 + side * speed * arrive_s), radius, (0.0, -side * speed)))
    crossing_s = _arrival_s(12.0) + random.Random(seed * 104729 + 2).uniform(-ARRIVAL_JITTER_S, ARRIVAL_JITTER_S)  # moving's drum
    rng = random.Random(seed * 7919 + 1)
    head_on = [_mover((rng.uniform(-0.5, 0.5), rng.uniform(18.0, 28.0)), rng.uniform(0.25, 0.5), (0.0, -rng.uniform(0.3, 1.0)))
               for _ in range(rng.randint(1, 2))]  # fmt: skip
    overtaking = [_mover((rng.uniform(-0.4, 0.4), rng.uniform(4.0, 8.0)), rng.uniform(0.25, 0.5), (0.0, rng.uniform(0.3, 0.6)))]
    return {
        "open": Scenario("open", two_legs),
        "scattered": Scenario("scattered", two_legs, scatter=SCATTER_COUNT),
        "walls": Scenario("walls", line, polygons=walls),
        "cul_de_sac": Scenario("cul_de_sac", [(0.0, 0.0), (0.0, 30.0)], polygons=cul),
        "moving": Scenario("moving", [(0.0, 0.0), (0.0, 30.0)], moving=[  # one crosses the leg, one walks down it
            _mover((-0.5 * crossing_s, 12.0), 0.6, (0.5, 0.0)), _mover((0.5, 28.0), 0.5, (0.0, -0.3)),
        ]),  # fmt: skip
        "crossing": Scenario("crossing", two_legs, moving=crossing),
        "head_on": Scenario("head_on", [(0.0, 0.0), (0.0, 30.0)], moving=head_on),
        "overtaking": Scenario("overtaking", [(0.0, 0.0), (0.0, 30.0)], moving=overtaking),
        "narrow_gap": Scenario("narrow_gap", [(0.0, 0.0), (0.0, 30.0)], polygons=_narrow_gap(seed)),
        "dense_clutter": Scenario("dense_clutter", [(0.0, 0.0), (0.0, 50.0)], circles=_dense_clutter(seed)),
    }


NAMES = tuple(scenarios(1))
"""Every scenario's name, in the benchmark's order."""


def mission(scenario: Scenario) -> Mission:
    """The scenario's mission: one NAV_WAYPOINT per leg end, home at ``HOME``."""
    frame = LocalFrame(*HOME)
    items = []
    for east, north in scenario.legs_en[1:]:
        lat, lon = frame.to_geodetic(east, north)
        items.append(MissionItem(Cmd.NAV_WAYPOINT, FRAME_GLOBAL_RELATIVE_ALT, x=float(lat), y=float(lon)))
    return Mission(items=items, home=Home(*HOME))


def world_doc(scenario: Scenario) -> dict[str, Any]:
    """The scenario's emulator world as a GeoJSON document (scattered obstacles excluded: the
    emulator draws those itself from the seed, ``sitl.world.scatter_obstacles``)."""
    frame = LocalFrame(*HOME)

    def lonlat(point: EN) -> list[float]:
        lat, lon = frame.to_geodetic(*point)
        return [float(lon), float(lat)]

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
         "properties": {"radius_m": m["radius_m"],
                        "motion": {"type": "velocity", "velocity_mps": list(m["velocity_en"]), "start": m.get("start", "boot")}}}
        for m in scenario.moving
    ]  # fmt: skip
    return {"type": "FeatureCollection", "home": [HOME[1], HOME[0], HOME[2], 0.0], "features": features}
