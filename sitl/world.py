"""The world: obstacles (circles and polygons, static or moving), read from GeoJSON in lat/lon.

World file: a GeoJSON FeatureCollection (RFC 7946, coordinates [lon, lat]).

- A Feature with Polygon geometry (one exterior ring, no holes) is a polygon obstacle; a Point with
  ``properties.radius_m`` is a circle obstacle.
- Optional properties: ``"id"`` (string) and ``"motion"``: ``{"type": "velocity", "velocity_mps":
  [east, north]}`` or ``{"type": "waypoints", "path": [[lon, lat], ...], "speed_mps": s,
  "loop": true}``. The geometry as drawn is the obstacle at t = 0; a waypoint motion translates it
  by (position on the path - path[0]), so a path that starts at the obstacle moves it along the path.
  With ``loop`` the path closes back to its start; without, the obstacle stops at its end.
  Either motion may say ``"start": "armed"``: the obstacle then stays where it is drawn until the
  rover first arms and its motion's clock starts there (default ``"boot"``: at sim time 0). A
  scenario timed against the rover's drive (a pedestrian reaching the leg as the rover does) needs
  this: how long a ground station takes to upload and arm is not part of the scenario.
- Optional top-level members ``"home": [lon, lat, alt_m, heading_deg]`` and ``"faults"`` (see
  ``sitl.faults``).
- Sizes: a circle's radius, a polygon's vertices and a motion path's points reach at most
  ``WORLD_EXTENT_M`` (10 km) from the first; obstacle speeds are at most ``MAX_OBSTACLE_SPEED_MPS``;
  the file is a regular file of at most ``MAX_WORLD_BYTES``.

``World`` keeps the geographic description (what the file says); ``LocalWorld`` is the same world
projected into east/north metres about the run's home, with analytic obstacle motion, ray casting
for the rangefinders and footprint contact tests for collisions.
"""

from __future__ import annotations

import bisect
import json
import math
import os
import stat
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from shapely import affinity
from shapely.geometry import Point, Polygon

from sitl.faults import FaultError, ScheduledFault, parse_fault
from sitl.geodesy import WORLD_EXTENT_M, LocalFrame, distances_m


MAX_OBSTACLE_SPEED_MPS = 50.0
"""A moving obstacle's speed at most (a car on a road): 1e308 m/s put it at NaN a frame later."""
MAX_WORLD_BYTES = 4 * 2**20
"""The largest world file read: 4 MiB holds some ten thousand obstacles (about 300 bytes each);
reading stops there, so /dev/zero or a runaway file is refused instead of read forever."""


class WorldError(ValueError):
    """A world file or description that cannot be used; the message names the file and feature."""


HOME_ALT_RANGE_M = (-1000.0, 10000.0)
"""The ground on Earth with a margin (Dead Sea shore -430 m, Everest 8849 m)."""


@dataclass(frozen=True)
class Home:
    """Where the rover boots: its position and initial compass heading (0 north, clockwise)."""

    lat_deg: float
    lon_deg: float
    alt_m: float = 0.0
    heading_deg: float = 0.0

    def __post_init__(self) -> None:  # one check for --home and a world's home; NaN fails every comparison
        low, high = HOME_ALT_RANGE_M
        if not (-90 <= self.lat_deg <= 90 and -180 <= self.lon_deg <= 180 and low <= self.alt_m <= high
                and 0 <= self.heading_deg < 360):
            raise WorldError(f"need -90 <= lat <= 90, -180 <= lon <= 180, {low:g} <= alt <= {high:g}, 0 <= heading < 360")


@dataclass(frozen=True)
class Motion:
    """How an obstacle moves: constant velocity, or along a path of [lon, lat] points."""

    kind: str
    """"velocity" or "waypoints"."""
    velocity_en_mps: tuple[float, float] = (0.0, 0.0)
    path_lonlat: tuple[tuple[float, float], ...] = ()
    speed_mps: float = 0.0
    loop: bool = True
    start: str = "boot"
    """When the motion's clock starts: "boot" (sim time 0) or "armed" (the rover's first arming)."""

    def to_json(self) -> dict:
        start = {} if self.start == "boot" else {"start": self.start}
        if self.kind == "velocity":
            return {"type": "velocity", "velocity_mps": list(self.velocity_en_mps), **start}
        return {"type": "waypoints", "path": [list(p) for p in self.path_lonlat], "speed_mps": self.speed_mps, "loop": self.loop, **start}


@dataclass(frozen=True)
class Obstacle:
    """One obstacle as drawn: a circle (one [lon, lat] centre and radius_m) or a polygon ring."""

    id: str
    kind: str
    """"circle" or "polygon"."""
    coords_lonlat: tuple[tuple[float, float], ...]
    radius_m: float | None = None
    motion: Motion | None = None

    def to_feature(self) -> dict:
        props: dict = {"id": self.id}
        if self.kind == "circle":
            geometry = {"type": "Point", "coordinates": list(self.coords_lonlat[0])}
            props["radius_m"] = self.radius_m
        else:
            ring = [list(p) for p in self.coords_lonlat]
            geometry = {"type": "Polygon", "coordinates": [ring + [ring[0]]]}
        if self.motion is not None:
            props["motion"] = self.motion.to_json()
        return {"type": "Feature", "geometry": geometry, "properties": props}


@dataclass
class World:
    """A world as described in lat/lon: obstacles, optional home and fault schedule."""

    obstacles: list[Obstacle] = field(default_factory=list)
    home: Home | None = None
    faults: list[ScheduledFault] = field(default_factory=list)

    def to_geojson(self) -> dict:
        doc: dict = {"type": "FeatureCollection", "features": [o.to_feature() for o in self.obstacles]}
        if self.home is not None:
            doc["home"] = [self.home.lon_deg, self.home.lat_deg, self.home.alt_m, self.home.heading_deg]
        if self.faults:
            doc["faults"] = [f.to_json() for f in self.faults]
        return doc

    def local(self, frame: LocalFrame) -> "LocalWorld":
        """This world in east/north metres of ``frame``."""
        return LocalWorld([_localise(o, frame) for o in self.obstacles])


# --------------------------------------------------------------------------- loading


def load_world(path: str | Path) -> World:
    """Read a world file; WorldError("file: feature 3: what is wrong") on any problem, also for a
    file that is not a regular one (a device or FIFO could be read forever) or is over MAX_WORLD_BYTES."""
    path = Path(path)
    try:
        # non-blocking: opening a FIFO would wait for a writer; only the file's type is read before it is refused
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except OSError as exc:
        raise WorldError(f"{path}: cannot read: {exc.strerror or exc}") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise WorldError(f"{path}: not a regular file (a device, FIFO or directory is not a world file)")
        with os.fdopen(fd, "rb", closefd=False) as file:
            data = file.read(MAX_WORLD_BYTES + 1)
    except OSError as exc:
        raise WorldError(f"{path}: cannot read: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    if len(data) > MAX_WORLD_BYTES:
        raise WorldError(f"{path}: larger than {MAX_WORLD_BYTES // 2**20} MiB, the most a world file may be (some ten thousand obstacles)")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise WorldError(f"{path}: not UTF-8 text") from None
    try:
        # integers as floats: one too large for a float reads as inf, which the checks refuse by field
        doc = json.loads(text, parse_int=float)
    except json.JSONDecodeError as exc:
        raise WorldError(f"{path}: not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from None
    except RecursionError:
        raise WorldError(f"{path}: not a world file: JSON nested too deeply") from None
    return parse_world(doc, str(path))


def parse_world(doc: object, source: str = "<world>") -> World:
    """A World from a decoded GeoJSON document; errors name ``source`` and the feature index."""
    if not isinstance(doc, dict) or doc.get("type") != "FeatureCollection":
        raise WorldError(f"{source}: expected a GeoJSON FeatureCollection")
    features = doc.get("features")
    if not isinstance(features, list):
        raise WorldError(f"{source}: 'features' must be a list")
    obstacles = []
    for index, feature in enumerate(features):
        try:
            obstacles.append(_parse_feature(feature, index))
        except (WorldError, TypeError, ValueError) as exc:
            raise WorldError(f"{source}: feature {index}: {exc}") from None
    ids = [o.id for o in obstacles]
    duplicate = next((i for i in ids if ids.count(i) > 1), None)
    if duplicate is not None:
        raise WorldError(f"{source}: obstacle id {duplicate!r} is used twice")
    home = None
    if "home" in doc:
        try:
            home = _parse_home(doc["home"])
        except WorldError as exc:
            raise WorldError(f"{source}: home: {exc}") from None
    faults = []
    raw_faults = doc.get("faults", [])
    if not isinstance(raw_faults, list):
        raise WorldError(f"{source}: 'faults' must be a list")
    for index, entry in enumerate(raw_faults):
        try:
            faults.append(parse_fault(entry))
        except FaultError as exc:
            raise WorldError(f"{source}: faults[{index}]: {exc}") from None
    return World(obstacles, home, faults)


def _number(value: object, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise WorldError(f"{what} must be a finite number, got {value!r}")
    return float(value)


def _lonlat(value: object, what: str) -> tuple[float, float]:
    if not isinstance(value, (list, tuple)) or len(value) < 2:
        raise WorldError(f"{what} must be [lon, lat], got {value!r}")
    lon, lat = _number(value[0], f"{what} longitude"), _number(value[1], f"{what} latitude")
    if not (-180 <= lon <= 180 and -90 <= lat <= 90):
        raise WorldError(f"{what} [{lon}, {lat}] is not a [lon, lat] position")
    return lon, lat


def _within_extent(points, what: str) -> None:
    """WorldError unless every [lon, lat] of ``points`` (``what`` 0, 1, ...) is within WORLD_EXTENT_M of the first."""
    for index, distance in enumerate(distances_m(*points[0], points[1:]), 1):
        if distance > WORLD_EXTENT_M:
            raise WorldError(f"{what} {index} is {distance:.0f} m from {what} 0, over {WORLD_EXTENT_M:g} m (a world's extent)")


def _parse_home(value: object) -> Home:
    if not isinstance(value, list) or len(value) != 4:
        raise WorldError(f"expected [lon, lat, alt_m, heading_deg], got {value!r}")
    lon, lat = _lonlat(value[:2], "position")
    return Home(lat, lon, _number(value[2], "alt_m"), _number(value[3], "heading_deg"))


def _parse_feature(feature: object, index: int) -> Obstacle:
    if not isinstance(feature, dict) or feature.get("type") != "Feature":
        raise WorldError("expected a GeoJSON Feature")
    geometry = feature.get("geometry")
    props = feature.get("properties") or {}
    if not isinstance(geometry, dict):
        raise WorldError("missing geometry")
    if not isinstance(props, dict):
        raise WorldError("'properties' must be an object")
    ident = props.get("id", f"obstacle{index}")
    if not isinstance(ident, str) or not ident:
        raise WorldError(f"'id' must be a non-empty string, got {ident!r}")
    kind = geometry.get("type")
    coords = geometry.get("coordinates")
    if kind == "Point":
        if "radius_m" not in props:
            raise WorldError("a Point obstacle needs properties.radius_m")
        radius = _number(props["radius_m"], "radius_m")
        if not 0 < radius <= WORLD_EXTENT_M:
            raise WorldError(f"radius_m must be > 0 and <= {WORLD_EXTENT_M:g} m (a world's extent), got {radius:g}")
        obstacle = Obstacle(ident, "circle", (_lonlat(coords, "Point"),), radius)
    elif kind == "Polygon":
        if not isinstance(coords, list) or not coords:
            raise WorldError("Polygon coordinates must be a list of rings")
        if len(coords) > 1:
            raise WorldError("Polygon holes are not supported (give one exterior ring)")
        ring = coords[0]
        if not isinstance(ring, list):
            raise WorldError("Polygon ring must be a list of [lon, lat]")
        points = [_lonlat(p, f"vertex {i}") for i, p in enumerate(ring)]
        if len(points) > 1 and points[0] == points[-1]:
            points.pop()
        if len(set(points)) < 3:
            raise WorldError("a Polygon needs at least 3 distinct vertices")
        if not Polygon(points).is_valid:
            raise WorldError("Polygon is self-intersecting or degenerate")
        _within_extent(points, "vertex")
        obstacle = Obstacle(ident, "polygon", tuple(points))
    else:
        raise WorldError(f"unsupported geometry {kind!r} (use Polygon, or Point with radius_m)")
    if "motion" in props:
        obstacle = Obstacle(obstacle.id, obstacle.kind, obstacle.coords_lonlat, obstacle.radius_m, _parse_motion(props["motion"]))
    return obstacle


MOTION_STARTS = ("boot", "armed")


def _parse_motion(value: object) -> Motion:
    if not isinstance(value, dict):
        raise WorldError("'motion' must be an object")
    kind = value.get("type")
    start = value.get("start", "boot")
    if start not in MOTION_STARTS:
        raise WorldError(f"motion start must be one of {', '.join(map(repr, MOTION_STARTS))}, got {start!r}")
    if kind == "velocity":
        vel = value.get("velocity_mps")
        if not isinstance(vel, list) or len(vel) != 2:
            raise WorldError("motion velocity_mps must be [east, north]")
        velocity = (_number(vel[0], "velocity east"), _number(vel[1], "velocity north"))
        if math.hypot(*velocity) > MAX_OBSTACLE_SPEED_MPS:
            raise WorldError(f"motion velocity_mps {math.hypot(*velocity):g} m/s is over {MAX_OBSTACLE_SPEED_MPS:g} m/s")
        return Motion("velocity", velocity_en_mps=velocity, start=start)
    if kind == "waypoints":
        path = value.get("path")
        if not isinstance(path, list) or len(path) < 2:
            raise WorldError("motion path must list at least 2 [lon, lat] points")
        points = tuple(_lonlat(p, f"motion path point {i}") for i, p in enumerate(path))
        _within_extent(points, "motion path point")
        speed = _number(value.get("speed_mps"), "motion speed_mps")
        if not 0 < speed <= MAX_OBSTACLE_SPEED_MPS:
            raise WorldError(f"motion speed_mps must be > 0 and <= {MAX_OBSTACLE_SPEED_MPS:g}, got {speed:g}")
        loop = value.get("loop", True)
        if not isinstance(loop, bool):
            raise WorldError(f"motion loop must be true or false, got {loop!r}")
        return Motion("waypoints", path_lonlat=points, speed_mps=speed, loop=loop, start=start)
    raise WorldError(f"unknown motion type {kind!r} (use 'velocity' or 'waypoints')")


# --------------------------------------------------------------------------- local frame


class LocalObstacle:
    """An obstacle in east/north metres. Its shape is rigid; it is translated by ``offset(t)``.

    The shape is kept relative to a reference point (circle centre, polygon vertex mean) so that ray
    casting moves the ray into the obstacle's frame instead of moving the obstacle."""

    def __init__(self, ident: str, kind: str, ref_en: tuple[float, float], radius_m: float,
                 vertices_rel: list[tuple[float, float]], motion_path_en: list[tuple[float, float]] | None,
                 velocity_en_mps: tuple[float, float], speed_mps: float, loop: bool, armed_clock: bool = False) -> None:
        self.id = ident
        self.kind = kind
        self.ref_en = ref_en
        self.radius_m = radius_m
        """Circle radius, or for polygons the bounding radius about the reference point."""
        self.vertices_rel = vertices_rel
        self._edges = [(ax, ay, bx - ax, by - ay) for (ax, ay), (bx, by) in zip(vertices_rel, vertices_rel[1:] + vertices_rel[:1])]
        self._velocity = velocity_en_mps
        self._speed = speed_mps
        self._loop = loop
        self._path = None
        if motion_path_en:
            path = list(motion_path_en) + ([motion_path_en[0]] if loop else [])
            lengths = [0.0]
            for (ax, ay), (bx, by) in zip(path, path[1:]):
                lengths.append(lengths[-1] + math.hypot(bx - ax, by - ay))
            self._path, self._cumulative = path, lengths
        self.moving = self._path is not None or velocity_en_mps != (0.0, 0.0)
        self.epoch_s: float | None = None if armed_clock else 0.0
        """Sim time at which the motion's clock reads 0 (None: waiting for the rover to arm)."""
        self._shape0 = Point(ref_en).buffer(radius_m, 32) if kind == "circle" else Polygon(
            [(ref_en[0] + x, ref_en[1] + y) for x, y in vertices_rel])

    def offset(self, time_s: float) -> tuple[float, float]:
        """Translation of the obstacle at ``time_s`` from where it is drawn."""
        if self.epoch_s is None:
            return 0.0, 0.0
        time_s = max(time_s - self.epoch_s, 0.0)
        if self._path is None:
            return self._velocity[0] * time_s, self._velocity[1] * time_s
        total = self._cumulative[-1]
        s = self._speed * time_s
        s = s % total if self._loop and total > 0 else min(s, total)
        i = min(bisect.bisect_right(self._cumulative, s) - 1, len(self._path) - 2)
        (ax, ay), (bx, by) = self._path[i], self._path[i + 1]
        seg = self._cumulative[i + 1] - self._cumulative[i]
        f = (s - self._cumulative[i]) / seg if seg > 0 else 0.0
        return ax + f * (bx - ax) - self._path[0][0], ay + f * (by - ay) - self._path[0][1]

    def ref_at(self, time_s: float) -> tuple[float, float]:
        dx, dy = self.offset(time_s)
        return self.ref_en[0] + dx, self.ref_en[1] + dy

    def shape(self, time_s: float):
        """The shapely geometry at ``time_s``."""
        if not self.moving:
            return self._shape0
        dx, dy = self.offset(time_s)
        return affinity.translate(self._shape0, dx, dy)

    def ray(self, px: float, py: float, dx: float, dy: float, max_m: float) -> float | None:
        """Distance along the unit ray (px, py) + t (dx, dy), 0 <= t <= max_m, to the obstacle, with
        the origin (px, py) given relative to the obstacle's current reference point."""
        along = -(px * dx + py * dy)
        miss2 = px * px + py * py - along * along
        r2 = self.radius_m * self.radius_m
        if miss2 > r2 or along + self.radius_m < 0 or along - self.radius_m > max_m:
            return None  # the ray passes outside the (bounding) circle
        if self.kind == "circle":
            half = math.sqrt(r2 - miss2)
            if along - half >= 0:
                t = along - half
            elif along + half >= 0:
                t = 0.0  # the origin is inside
            else:
                return None
            return t if t <= max_m else None
        best = None
        for ax, ay, ex, ey in self._edges:
            denom = dx * ey - dy * ex
            if abs(denom) < 1e-12:
                continue
            wx, wy = ax - px, ay - py
            t = (wx * ey - wy * ex) / denom
            u = (wx * dy - wy * dx) / denom
            if 0.0 <= t <= max_m and 0.0 <= u <= 1.0 and (best is None or t < best):
                best = t
        return best


def _localise(obstacle: Obstacle, frame: LocalFrame) -> LocalObstacle:
    lons = [p[0] for p in obstacle.coords_lonlat]
    lats = [p[1] for p in obstacle.coords_lonlat]
    east, north = frame.to_en(np.array(lats), np.array(lons))
    if obstacle.kind == "circle":
        ref = (float(east[0]), float(north[0]))
        radius, vertices = obstacle.radius_m, []
    else:
        ref = (float(np.mean(east)), float(np.mean(north)))
        vertices = [(float(e) - ref[0], float(n) - ref[1]) for e, n in zip(east, north)]
        radius = max(math.hypot(x, y) for x, y in vertices)
    motion = obstacle.motion
    path = None
    velocity, speed, loop = (0.0, 0.0), 0.0, True
    armed_clock = motion is not None and motion.start == "armed"
    if motion is not None and motion.kind == "velocity":
        velocity = motion.velocity_en_mps
    elif motion is not None:
        pe, pn = frame.to_en(np.array([p[1] for p in motion.path_lonlat]), np.array([p[0] for p in motion.path_lonlat]))
        path = [(float(e), float(n)) for e, n in zip(pe, pn)]
        speed, loop = motion.speed_mps, motion.loop
    return LocalObstacle(obstacle.id, obstacle.kind, ref, radius, vertices, path, velocity, speed, loop, armed_clock)


class LocalWorld:
    """Obstacles in east/north metres, with the queries the vehicle needs."""

    def __init__(self, obstacles: list[LocalObstacle]) -> None:
        self.obstacles = obstacles
        self._refs_time_s: float | None = None
        self._refs: list[tuple[float, float]] = []
        self._started = False

    def armed(self, time_s: float) -> None:
        """The rover armed at ``time_s``: motions that start at arming start now (first arming only)."""
        if self._started:
            return
        self._started = True
        for obstacle in self.obstacles:
            if obstacle.epoch_s is None:
                obstacle.epoch_s = time_s
                self._refs_time_s = None

    def ray_cast(self, origin_en: tuple[float, float], bearing_rad: float, max_m: float,
                 time_s: float) -> tuple[float, str] | None:
        """Nearest (distance_m, obstacle id) along a ray at ENU bearing (0 east, CCW) within max_m."""
        return self.fan_cast(origin_en, (bearing_rad,), max_m, time_s)

    def fan_cast(self, origin_en: tuple[float, float], bearings_rad, max_m: float,
                 time_s: float) -> tuple[float, str] | None:
        """Nearest (distance_m, obstacle id) over several rays from one origin within max_m.

        Obstacles whose bounding circle is out of reach are dropped once for the whole fan."""
        ox, oy = origin_en
        candidates = []
        for obstacle, (cx, cy) in zip(self.obstacles, self.refs_at(time_s)):
            px, py = ox - cx, oy - cy
            reach = max_m + obstacle.radius_m
            if px * px + py * py <= reach * reach:
                candidates.append((obstacle, px, py))
        best = None
        for bearing in bearings_rad if candidates else ():
            dx, dy = math.cos(bearing), math.sin(bearing)
            for obstacle, px, py in candidates:
                t = obstacle.ray(px, py, dx, dy, max_m)
                if t is not None and (best is None or t < best[0]):
                    best = (t, obstacle.id)
        return best

    def refs_at(self, time_s: float) -> list[tuple[float, float]]:
        """Every obstacle's reference point at ``time_s`` (kept for repeated queries at one time)."""
        if time_s != self._refs_time_s:
            self._refs = [o.ref_at(time_s) for o in self.obstacles]
            self._refs_time_s = time_s
        return self._refs

    def near(self, center_en: tuple[float, float], radius_m: float, time_s: float) -> list[LocalObstacle]:
        """Obstacles whose bounding circle comes within ``radius_m`` of ``center_en``."""
        found = []
        for obstacle, (cx, cy) in zip(self.obstacles, self.refs_at(time_s)):
            if math.hypot(cx - center_en[0], cy - center_en[1]) <= radius_m + obstacle.radius_m:
                found.append(obstacle)
        return found


# --------------------------------------------------------------------------- generator


def scatter_obstacles(legs_latlon: list[tuple[float, float]], count: int, seed: int, *,
                      min_gap_m: float = 2.0, clear_radius_m: float = 4.0, lateral_m: float = 2.5,
                      radius_range_m: tuple[float, float] = (0.3, 0.9), polygon_fraction: float = 0.5,
                      max_tries: int = 5000) -> World:
    """Seeded random obstacles along the polyline through ``legs_latlon`` [(lat, lon), ...].

    Each obstacle (a circle, or a jittered convex polygon with probability ``polygon_fraction``)
    is centred within ``lateral_m`` of a leg, at least ``clear_radius_m`` (plus its size) from every
    waypoint, and at least ``min_gap_m`` from every other obstacle so the rover can always pass
    between two of them. Raises WorldError if ``count`` cannot be placed in ``max_tries`` draws.
    """
    if len(legs_latlon) < 2:
        raise WorldError("scatter_obstacles: need at least two points (one leg)")
    rng = np.random.default_rng(seed)
    frame = LocalFrame(*legs_latlon[0])
    east, north = frame.to_en(np.array([p[0] for p in legs_latlon]), np.array([p[1] for p in legs_latlon]))
    points = np.column_stack([east, north])
    legs = [(points[i], points[i + 1]) for i in range(len(points) - 1)]
    lengths = np.array([np.linalg.norm(b - a) for a, b in legs])
    if lengths.sum() <= 0:
        raise WorldError("scatter_obstacles: the legs have zero length")
    shapes: list = []
    obstacles: list[Obstacle] = []
    for _ in range(max_tries):
        if len(obstacles) == count:
            break
        leg = rng.choice(len(legs), p=lengths / lengths.sum())
        a, b = legs[leg]
        direction = (b - a) / lengths[leg]
        normal = np.array([-direction[1], direction[0]])
        center = a + direction * rng.uniform(0, lengths[leg]) + normal * rng.uniform(-lateral_m, lateral_m)
        radius = rng.uniform(*radius_range_m)
        is_polygon = rng.uniform() < polygon_fraction
        if is_polygon:
            sides = int(rng.integers(3, 7))
            angles = np.sort(rng.uniform(0, 2 * np.pi, sides))
            radii = radius * rng.uniform(0.7, 1.0, sides)
            ring = [(center[0] + r * math.cos(t), center[1] + r * math.sin(t)) for r, t in zip(radii, angles)]
            shape = Polygon(ring).convex_hull
        else:
            shape = Point(center).buffer(radius, 32)
        if shape.area <= 0 or np.min(np.linalg.norm(points - center, axis=1)) < clear_radius_m + radius:
            continue
        if any(shape.distance(other) < min_gap_m for other in shapes):
            continue
        shapes.append(shape)
        ident = f"scatter{len(obstacles)}"
        if is_polygon:
            xs, ys = shape.exterior.coords.xy
            lat, lon = frame.to_latlon(np.array(xs[:-1]), np.array(ys[:-1]))
            obstacles.append(Obstacle(ident, "polygon", tuple(zip(map(float, lon), map(float, lat)))))
        else:
            lat, lon = frame.to_latlon(center[0], center[1])
            obstacles.append(Obstacle(ident, "circle", ((float(lon), float(lat)),), float(radius)))
    if len(obstacles) < count:
        raise WorldError(f"scatter_obstacles: placed only {len(obstacles)} of {count} obstacles with gaps >= {min_gap_m} m")
    return World(obstacles)
