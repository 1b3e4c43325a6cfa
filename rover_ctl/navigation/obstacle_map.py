"""Persistent obstacles: rangefinder evidence accumulated in a grid, the places seen repeatedly
handed to the planner as polygons, after ArduPilot's AP_OADatabase (echoes kept with a time to
live) feeding a path planner.

The map is frame-agnostic: it takes readings, the rover's position and points in whatever frame
its caller keeps it in. The autopilot keeps it in the odometry frame
(``obstacle_map.odometry_frame``, ``rover_ctl.navigation.odometry``), where echoes of one wall seen
seconds apart fall on one line while GPS fixes move the fused pose by tenths of a metre, and lays
the polygons onto the pose's frame when it hands them to the planner.

Pure: no clock, no I/O. The autopilot hands every rangefinder reading to ``ObstacleMap.add`` (a
cheap append) and, every ``update_period_s``, calls ``update`` (the batch folded into the grid,
vectorised) and, when the persistent set changed, ``obstacles`` (the shapes for the planner). The
obstacle memory (``rover_ctl.navigation.proximity``) is what the fuzzy navigator sees for 1.5 s;
this map is what the planner remembers, so that a leg found blocked is planned around instead of
rediscovered by bumping along it.

**Grid.** A sparse grid of square cells of ``cell_m``, keyed by integer indices
``(floor(x / cell_m), floor(y / cell_m))``; only cells that have had an echo exist. Each
holds an evidence score ``e``, the times of its first and last echo, and is

    hit:   e <- min(e + 1, max_score)            an echo of a reading falls in the cell
    miss:  e <- e - miss_score                   a beam passed through the cell (see below)
    gone:  e <= 0, or t - last echo > ttl_s,     or the cell overlaps the rover's body

(a log-odds occupancy grid with the probabilities left implicit, as ArduPilot's database keeps
points, not probabilities). A reading is a beam from the sensor along its axis: its echo at
``range_m`` is a hit; the axis from the sensor to ``range_m - cell_m`` (to ``max_range_m -
cell_m`` without an echo) is free space, sampled every ``cell_m / 2``, and each cell it passes
gets one miss per reading. The last ``cell_m`` before the echo is not cleared: a rangefinder's
cone returns the *nearest* surface inside it, so the echo placed on the axis can lie up to a cell
in front of the surface's cell. A cell is **persistent** when

    e >= persist_score   and   last echo - first echo >= min_span_s

(seen repeatedly, over a time span: an obstacle walking through a cell at 0.5 m/s or more gives
it echoes over less than ``min_span_s``). An echo in a cell that some beam's free stretch passed
less than ``free_memory_s`` before adds nothing: something moved into a place seen empty, as a
drum crossing a stopped rover's front beam does, its echo standing still on the beam's axis for
the whole crossing (longer than ``min_span_s``). Echoes of the tracks the rover yields to
(``rover_ctl.navigation.yielding``: the obstacle memory returns the track each echo joined, the
autopilot passes the yielded-to ones to ``update``) are dropped, so crossing traffic is yielded
to, not planned around. The tracker's plain *moving* label is not used: an echo sliding over a
wall as the rover drives or turns by it makes tracks that seem to move (docs/perception.md), and
dropping those erased most of the cul-de-sac's walls in a replay of a benchmark run. A slower
obstacle that did become persistent is cleared by the free space the beams see once it has gone,
at ``miss_score`` per reading (from ``max_score`` in ``max_score / miss_score`` readings). Every cell
overlapping the rover's body (a disc of ``body_radius_m``) is dropped at each update: the rover
is there, so it is free, and the rover's own position never ends up inside a persistent obstacle.
At most ``max_cells`` cells are kept (the least recently hit go first).

**Shapes.** The persistent cells are grouped into clusters of 8-connected cells; each cluster
becomes the union of its cells' squares, simplified by ``simplify_m`` (Douglas-Peucker, shapely:
a diagonal staircase of cells becomes a straight side; the simplified outline may cut into a cell
by at most ``simplify_m``, less than the inflation the planner adds), holes filled. So a wall
becomes one polygon of a few vertices, not a cell per echo. At most ``max_obstacles`` clusters are
handed out, the nearest to the rover first. The planner inflates them by the robot's half-width
plus ``margin_m`` (``rover_ctl.navigation.planner``).

**Walls are not movers.** ``near_persistent`` says whether a point lies within a distance of a
persistent cell: the autopilot leaves moving tracks within ``track_on_wall_m`` of one out of what
the yielder, the evader, the side guard's rear check and narrow passages see, since a turning
rover's beam sweeping over a wall's face gives an echo that slides like a walker
(``rover_ctl.navigation.tracks``, "Limits").

**Rate.** ``update`` reports how many cells changed persistence since the last ``obstacles``;
the autopilot rebuilds the planner's graph only when that is at least ``min_change_cells`` and
``rebuild_min_interval_s`` has passed since the last rebuild (the visibility graph's rebuild is
the costly part), and the path follower re-plans only when its current path comes within the
robot's half-width of a persistent obstacle.

Limits: an echo is placed on the beam's axis while the cone (15 deg for the emulator's ultrasonic
sensors) may have returned a surface up to ``range * tan(7.5 deg)`` to the side, so a gap narrower
than about two of those seen from afar may read closed; the planner then plans around the whole
obstacle and the fuzzy navigator still drives through what it sees. If the persistent obstacles
leave no way to the goal, the path follower plans without them (``PathFollower``).
"""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry import Polygon
from shapely.ops import unary_union

from rover_ctl.config import ObstacleMapParams

EN = tuple[float, float]
Key = tuple[int, int]

JOIN_FRACTION = 0.01
"""Cells are unioned as squares grown by this fraction of a cell, so that cells touching only at a
corner (a diagonal wall) join into one polygon."""


@dataclass
class Cell:
    score: float
    first_s: float
    last_s: float


class ObstacleMap:
    """Echo evidence in a sparse grid, in the caller's frame; the persistent places as polygons
    (module docstring)."""

    def __init__(self, params: ObstacleMapParams) -> None:
        """``params`` is read at every call (a parameter changed by a ground station applies at once)."""
        self.params = params
        self.cells: dict[Key, Cell] = {}
        self._beams: list[tuple[float, float, float, float, float, float, int]] = []
        self._persistent: set[Key] = set()
        self._free_s: dict[Key, float] = {}  # when a beam last saw each cell free (within free_memory_s)
        self._handed: set[Key] = set()
        self._cell_m = params.cell_m

    # ---- input -------------------------------------------------------------------------------

    def add(self, time_s: float, sensor_east_m: float, sensor_north_m: float, axis_rad: float, range_m: float,
            max_range_m: float, track_ident: int = 0) -> None:  # fmt: skip
        """Queue one reading (a beam from the sensor along ``axis_rad``; ``range_m`` inf: no echo
        within ``max_range_m``) and the ident of the track its echo joined (0: none)."""
        if math.isnan(range_m) or range_m < 0.0 or not math.isfinite(max_range_m):
            return
        self._beams.append((time_s, sensor_east_m, sensor_north_m, axis_rad, range_m, max_range_m, track_ident))

    def clear(self) -> None:
        """Forget every cell and queued reading (a new cell size, or a new frame): nothing is
        persistent until new echoes say so; the next ``update`` counts the cells the planner was
        handed as changed, so that it gets the empty set."""
        self.cells.clear()
        self._free_s.clear()
        self._beams.clear()
        self._persistent = set()
        self._cell_m = self.params.cell_m

    def update(self, time_s: float, rover_en: EN, body_radius_m: float, moving_idents: Collection[int] = ()) -> int:
        """Fold the queued readings into the grid at ``time_s`` (the echoes of the tracks
        ``moving_idents`` left out), forget the cells overlapping the rover's body (a disc of
        ``body_radius_m`` at ``rover_en``); returns how many cells changed persistence since the
        last ``obstacles`` call."""
        p = self.params
        if p.cell_m != self._cell_m:  # a new cell size: the old cells mean nothing
            self.clear()
        beams, self._beams = self._beams, []
        if beams:
            self._misses(beams)
            self._hits([b for b in beams if math.isfinite(b[4]) and b[4] <= b[5] and b[6] not in moving_idents])
        self._free_s = {k: t for k, t in self._free_s.items() if time_s - t <= p.free_memory_s}
        self._forget(time_s, rover_en, body_radius_m)
        self._persistent = {k for k, c in self.cells.items() if c.score >= p.persist_score and c.last_s - c.first_s >= p.min_span_s}
        return len(self._persistent ^ self._handed)

    def _hits(self, beams: list) -> None:
        p, cell = self.params, self._cell_m
        memory_s, free_s = p.free_memory_s, self._free_s
        for time_s, e, n, axis, range_m, _, _ in beams:
            key = (math.floor((e + range_m * math.cos(axis)) / cell), math.floor((n + range_m * math.sin(axis)) / cell))
            if memory_s > 0.0 and 0.0 < time_s - free_s.get(key, -math.inf) <= memory_s:
                continue  # seen free just before: something moved in, not a place to plan around
            c = self.cells.get(key)
            if c is None:
                self.cells[key] = Cell(min(1.0, p.max_score), time_s, time_s)
            else:
                c.score = min(c.score + 1.0, p.max_score)
                c.first_s, c.last_s = min(c.first_s, time_s), max(c.last_s, time_s)

    def _misses(self, beams: list) -> None:
        """One miss per reading for each existing cell its free stretch passes (vectorised); and
        when each cell was last seen free."""
        memory_s = self.params.free_memory_s
        if not self.cells and memory_s <= 0.0:
            return
        cell = self._cell_m
        data = np.array([b[1:6] for b in beams])
        e, n, axis, range_m, max_m = data.T
        free_m = np.where(np.isfinite(range_m), np.minimum(range_m, max_m), max_m) - cell
        step = cell / 2.0
        s = np.arange(0.0, max(float(free_m.max()), 0.0) + step, step)
        if not len(s):
            return
        along = np.broadcast_to(s, (len(beams), len(s)))
        inside = along <= free_m[:, None]
        ix = np.floor((e[:, None] + along * np.cos(axis)[:, None]) / cell).astype(np.int64)
        iy = np.floor((n[:, None] + along * np.sin(axis)[:, None]) / cell).astype(np.int64)
        # One miss per beam and cell: (cell, beam) pairs packed into one integer each, so that
        # numpy's one-dimensional unique sorts them by cell, then beam.
        ix, iy = ix[inside], iy[inside]
        if not len(ix):
            return
        i0, j0 = int(ix.min()), int(iy.min())
        span_j, beams_n = int(iy.max()) - j0 + 1, len(beams)
        beam = np.broadcast_to(np.arange(beams_n)[:, None], inside.shape)[inside]
        packed = np.unique(((ix - i0) * span_j + (iy - j0)) * beams_n + beam)
        cell_code, beam = np.divmod(packed, beams_n)
        first = np.flatnonzero(np.r_[True, cell_code[1:] != cell_code[:-1]])
        counts = np.diff(np.r_[first, len(cell_code)])
        newest = np.maximum.reduceat(np.array([b[0] for b in beams])[beam], first)  # when each cell was last seen free
        miss, free_s, cells = self.params.miss_score, self._free_s, self.cells
        for code, count, time_s in zip(cell_code[first].tolist(), counts.tolist(), newest.tolist()):
            key = (code // span_j + i0, code % span_j + j0)
            c = cells.get(key)
            if c is not None:
                for _ in range(count):  # one at a time: the same rounding as one reading at a time
                    c.score -= miss
            if memory_s > 0.0 and free_s.get(key, -math.inf) < time_s:
                free_s[key] = time_s

    def _forget(self, time_s: float, rover_en: EN, body_radius_m: float) -> None:
        p, cell = self.params, self._cell_m
        re, rn = rover_en
        gone = [k for k, c in self.cells.items() if c.score <= 0.0 or time_s - c.last_s > p.ttl_s]
        reach = math.ceil(body_radius_m / cell) + 1
        ci, cj = math.floor(re / cell), math.floor(rn / cell)
        for i in range(ci - reach, ci + reach + 1):
            for j in range(cj - reach, cj + reach + 1):
                if (i, j) in self.cells:  # distance from the rover to the square, compared with the body's radius
                    de = max(i * cell - re, 0.0, re - (i + 1) * cell)
                    dn = max(j * cell - rn, 0.0, rn - (j + 1) * cell)
                    if math.hypot(de, dn) < body_radius_m:
                        gone.append((i, j))
        for key in gone:
            self.cells.pop(key, None)
        if len(self.cells) > p.max_cells:
            for key in sorted(self.cells, key=lambda k: self.cells[k].last_s)[: len(self.cells) - p.max_cells]:
                del self.cells[key]

    # ---- output ------------------------------------------------------------------------------

    @property
    def persistent(self) -> frozenset[Key]:
        """The persistent cells as of the last ``update``."""
        return frozenset(self._persistent)

    def near_persistent(self, east_m: float, north_m: float, distance_m: float) -> bool:
        """Some persistent cell lies within ``distance_m`` of the point (cell squares, as of the
        last ``update``; 0: never)."""
        if distance_m <= 0.0 or not self._persistent:
            return False
        cell = self._cell_m
        reach = math.ceil(distance_m / cell)
        ke, kn = math.floor(east_m / cell), math.floor(north_m / cell)
        if (2 * reach + 1) ** 2 <= len(self._persistent):  # look up the window's cells
            keys = ((ke + de, kn + dn) for de in range(-reach, reach + 1) for dn in range(-reach, reach + 1))
            near = [k for k in keys if k in self._persistent]
        else:  # fewer persistent cells than the window holds: test those (a bounded cost either way)
            near = [k for k in self._persistent if abs(k[0] - ke) <= reach and abs(k[1] - kn) <= reach]
        for i, j in near:  # the square's nearest point to the point
            dx = max(i * cell - east_m, 0.0, east_m - (i + 1) * cell)
            dy = max(j * cell - north_m, 0.0, north_m - (j + 1) * cell)
            if math.hypot(dx, dy) <= distance_m:
                return True
        return False

    def obstacles(self, rover_en: EN) -> tuple[tuple[EN, ...], ...]:
        """The persistent cells as at most ``max_obstacles`` polygons (exterior rings in the map's
        frame, metres, the nearest cluster to ``rover_en`` first); marks them handed to the planner."""
        p, cell = self.params, self._cell_m
        self._handed = set(self._persistent)
        clusters = _clusters(self._persistent)
        grow = cell * JOIN_FRACTION
        shapes: list[tuple[float, Polygon]] = []
        for cluster in clusters:
            keys = np.array(sorted(cluster), dtype=float)
            boxes = shapely.box(
                keys[:, 0] * cell - grow, keys[:, 1] * cell - grow, (keys[:, 0] + 1) * cell + grow, (keys[:, 1] + 1) * cell + grow
            )
            merged = unary_union(boxes).simplify(p.simplify_m, preserve_topology=True)
            for part in getattr(merged, "geoms", [merged]):
                if isinstance(part, Polygon) and not part.is_empty:
                    shapes.append((part.distance(shapely.Point(rover_en)), Polygon(part.exterior)))
        shapes.sort(key=lambda item: item[0])
        return tuple(tuple((float(x), float(y)) for x, y in poly.exterior.coords[:-1]) for _, poly in shapes[: p.max_obstacles])


def _clusters(keys: set[Key]) -> list[set[Key]]:
    """8-connected components of a set of cells."""
    left, out = set(keys), []
    while left:
        seed = left.pop()
        cluster, frontier = {seed}, [seed]
        while frontier:
            i, j = frontier.pop()
            for di in (-1, 0, 1):
                for dj in (-1, 0, 1):
                    k = (i + di, j + dj)
                    if k in left:
                        left.remove(k)
                        cluster.add(k)
                        frontier.append(k)
        out.append(cluster)
    return out
