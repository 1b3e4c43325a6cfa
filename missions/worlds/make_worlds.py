"""Regenerate the bundled SITL worlds from their east/north descriptions.

    .venv/bin/python missions/worlds/make_worlds.py

Obstacles are laid out in metres about each mission's home (the shared mission facts) and written
in lat/lon with ``sitl.geodesy``, so the files stay in step with the mission legs.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from sitl.faults import parse_fault
from sitl.geodesy import LocalFrame
from sitl.world import Home, Motion, Obstacle, World

HERE = Path(__file__).resolve().parent

CMAC = Home(-35.363261, 149.165230, 584.0, 0.0)
BOULDER = Home(40.071377, -105.229790, 1584.0, 0.0)


def box(center_en: tuple[float, float], length_m: float, width_m: float, bearing_deg: float) -> list[tuple[float, float]]:
    """Corners of a length x width rectangle whose length runs along ``bearing_deg`` (ENU, CCW from east)."""
    c, s = math.cos(math.radians(bearing_deg)), math.sin(math.radians(bearing_deg))
    half = [(length_m / 2, width_m / 2), (-length_m / 2, width_m / 2), (-length_m / 2, -width_m / 2), (length_m / 2, -width_m / 2)]
    return [(center_en[0] + c * a - s * b, center_en[1] + s * a + c * b) for a, b in half]


class Builder:
    """Obstacles given in east/north metres about home, stored as lat/lon."""

    def __init__(self, home: Home) -> None:
        self.home = home
        self.frame = LocalFrame(home.lat_deg, home.lon_deg)
        self.obstacles: list[Obstacle] = []

    def lonlat(self, east_m: float, north_m: float) -> tuple[float, float]:
        lat, lon = self.frame.to_latlon(east_m, north_m)
        return round(float(lon), 8), round(float(lat), 8)

    def circle(self, ident: str, center_en: tuple[float, float], radius_m: float, motion: Motion | None = None) -> None:
        self.obstacles.append(Obstacle(ident, "circle", (self.lonlat(*center_en),), radius_m, motion))

    def polygon(self, ident: str, ring_en: list[tuple[float, float]], motion: Motion | None = None) -> None:
        self.obstacles.append(Obstacle(ident, "polygon", tuple(self.lonlat(*p) for p in ring_en), None, motion))

    def path(self, points_en: list[tuple[float, float]], speed_mps: float, loop: bool = True) -> Motion:
        return Motion("waypoints", path_lonlat=tuple(self.lonlat(*p) for p in points_en), speed_mps=speed_mps, loop=loop)

    def world(self, faults: list[dict] | None = None) -> World:
        return World(self.obstacles, self.home, [parse_fault(f) for f in faults or []])


def cmac_loop() -> World:
    """Legs home -> (0, 40) -> (30, 55) -> (55, 30) -> (35, 5) -> home; one obstacle per leg, each
    leaving a gap of at least 2 m on one side, and a walker crossing the first leg."""
    b = Builder(CMAC)
    b.circle("barrel", (0.6, 20.0), 0.6)
    b.polygon("crate", box((15.8, 47.2), 2.0, 1.5, math.degrees(math.atan2(15, 30))))
    b.circle("tree", (43.0, 43.0), 0.8)
    b.polygon("wall", box((45.6, 17.4), 3.0, 0.4, math.degrees(math.atan2(-25, -20)) + 90.0))
    b.circle("cone", (18.0, 2.8), 0.4)
    b.circle("walker", (-4.0, 30.0), 0.35, b.path([(-4.0, 30.0), (4.0, 30.0)], 0.5))
    return b.world()


def boulder_fence() -> World:
    """Static obstacles inside the geofence of missions/boulder_fence.plan (legs home -> (10, 25)
    -> (60, 25) -> (60, -10), exclusion zone 31..39 x 20..30): one on each leg with a gap of at
    least 2 m beside it, and a parked car away from the legs."""
    b = Builder(BOULDER)
    b.circle("hay_bale", (5.5, 12.0), 0.7)
    b.polygon("barrier", box((50.0, 24.0), 2.0, 0.5, 90.0))
    b.circle("post", (60.5, 8.0), 0.3)
    b.polygon("car", box((25.0, -15.0), 4.5, 1.8, 0.0))
    return b.world()


def playground() -> World:
    """Every world feature at once: static and moving circles and polygons (velocity, looping and
    one-way paths) and one scheduled fault of each kind."""
    b = Builder(CMAC)
    b.circle("pillar", (0.0, 12.0), 0.5)
    b.polygon("shed", [(6.0, 6.0), (10.0, 6.0), (10.0, 9.0), (8.0, 11.0), (6.0, 9.0)])
    b.circle("drifter", (-8.0, 20.0), 0.4, Motion("velocity", velocity_en_mps=(0.2, 0.0)))
    b.polygon("cart", box((12.0, 20.0), 1.2, 0.8, 90.0), b.path([(12.0, 20.0), (12.0, 30.0), (18.0, 30.0)], 0.6))
    b.circle("dog", (-5.0, 5.0), 0.3, b.path([(-5.0, 5.0), (-5.0, -5.0)], 1.0, loop=False))
    return b.world([
        {"name": "gps_glitch", "start_s": 20.0, "duration_s": 5.0, "north_m": 8.0, "east_m": -5.0},
        {"name": "rangefinder_silent", "start_s": 30.0, "duration_s": 5.0, "sensor_id": 2},
        {"name": "gps_outage", "start_s": 40.0, "duration_s": 10.0},
        {"name": "rangefinder_stuck", "start_s": 50.0, "duration_s": 5.0, "sensor_id": 0},
        {"name": "wheel_slip", "start_s": 60.0, "duration_s": 5.0, "fraction": 0.3},
        {"name": "link_loss", "start_s": 70.0, "duration_s": 5.0, "pct": 20.0},
        {"name": "link_quiet", "start_s": 80.0, "duration_s": 2.0},
    ])


WORLDS = {"cmac_loop": cmac_loop, "boulder_fence": boulder_fence, "playground": playground}


def main() -> None:
    for name, build in WORLDS.items():
        (HERE / f"{name}.geojson").write_text(json.dumps(build().to_geojson(), indent=1) + "\n")


if __name__ == "__main__":
    main()
