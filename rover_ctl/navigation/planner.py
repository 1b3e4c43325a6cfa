"""Global path planner: shortest paths in local ENU metres around fences and known obstacles.

Pure: no I/O, no clock (times are passed in). The daemon builds one ``Planner`` per mission
(fence + known obstacles) and one ``PathFollower`` that it asks, every control step, for the path
target the fuzzy navigator steers to.

Method: a visibility graph (shapely for geometry, networkx for the search). Everything the rover
must not enter -- fence exclusion polygons and circles, known obstacles, temporary "blocked"
circles reported by the daemon -- is inflated by the clearance

    c = robot.footprint_width_m / 2 + PlannerParams.clearance_margin_m

and inclusion fences are shrunk by ``c``. The remaining free space F is a polygon with holes; a
shortest path in it is a polyline that bends only at reflex vertices of F, so the graph's nodes are
those vertices and its edges the vertex pairs whose straight segment is tangent to the zones at
both ends (the reduced visibility graph) and stays in F (one vectorised shapely ``covers`` call).
A visibility graph gives exact shortest paths with few nodes in the open, sparse fields a rover
mission crosses; a grid A* would need a fine grid over a ~100 m field for the same accuracy and
still produce staircase paths. The static graph is built once and rebuilt only when temporary
obstacles change or the clearance or ``circle_segments`` parameters did (checked at each query,
so a changed parameter applies to the next plan); a query adds the start and goal.

Persistent obstacles (polygons of places the rangefinders echo from repeatedly,
``rover_ctl.navigation.obstacle_map``) are a fourth kind, replaced as a whole by
``set_persistent``. They are inflated by ``robot.footprint_width_m / 2 + persistent_margin_m``
(their cells already reach beyond the echoes), and they never make a goal unreachable by
themselves: a goal inside one is treated as one in the clearance band.

Node budget: the graph's build is quadratic in its nodes and runs in the control step, so the
planner never builds one over ``MAX_PLANNER_NODES`` (``rover_ctl.mission.validate``, where the
figures behind it are), counted before any geometry by ``node_count``: the vertices of the inflated
shapes (``planner_nodes``: circles x ``circle_segments``, each polygon's corners and their round
arcs), an upper bound of the nodes. Over it -- a fence stored before the budget, a raised
``circle_segments``, many persistent obstacles -- ``plan_leg`` returns ``Path.error`` "too complex
to plan: N nodes, max M" (the daemon holds, as for any missing path; ``PathFollower`` then plans
without the persistent obstacles), except that blocked circles over it are forgotten early, the
oldest first. Uploads and ``rover-ctl mission check`` refuse a fence over it at the default
``circle_segments``. The tangent test runs on all vertex pairs a block of rows at a time
(``PAIR_BLOCK``), so memory stays small.

Circles become regular ``PlannerParams.circle_segments``-gons that circumscribe the inflated
circle, and polygon corners are rounded with the chord error compensated, so the polygonal
approximation never cuts into the clearance. Graph nodes sit ``NODE_OFFSET_M`` further out than
the zone used to check edges, so an edge along a zone's side is not refused by rounding.

The carrot: ``PathFollower`` gives the navigator the point ``lookahead_m`` along the path beyond
the rover's projection, pulled back at bends so that the straight line from the rover to it passes
within ``max_corner_cut_m`` of each bend between (``Path.target``): pure pursuit drives roughly
that line, and an unlimited 3 m carrot cut a detour around a blocked circle into the obstacle.

Ends outside F: a start inside the clearance band or outside the fence (pushed there, or a fence
breach) first goes straight to the nearest free point, so the rover can always get back; a goal in
the clearance band is reached from the nearest free point by a last straight segment. A goal
inside an exclusion zone, a known or blocked obstacle, or outside an inclusion fence is
unreachable: ``plan_leg`` returns a ``Path`` whose ``error`` says why (no exception).

API:
    Fence.from_items(items, to_enu) -> Fence       the fence of MAV_CMD_NAV_FENCE_* items, in ENU
    Planner(params, robot, fence=Fence(), polygons=(), circles=())
      .plan_leg(start_en, goal_en) -> Path        Path.error is None when a path was found
      .plan_route(start_en, goals_en) -> Path     the legs joined (for the planned-path plot)
      .is_inside_fence(point_en) -> bool          fence breach test (raw fence, no clearance)
      .node_count() -> int                        graph nodes at most (the budget's count)
      .block(now_s, center_en, radius_m=None)     temporary circular obstacle (a blocked leg)
      .set_persistent(polygons) -> bool           replace the persistent obstacles (True: changed)
      .near_persistent(path, s_from_m) -> bool    the path beyond s_from_m would touch one
      .expire(now_s) -> bool                      forget blocked circles older than blocked_ttl_s
    Path.project(point_en, s_min_m=0, s_max_m=inf) -> (s_m, cross_track_m)
    Path.point_at(s_m) -> (east_m, north_m);  Path.carrot(point_en, lookahead_m, max_cut_m=inf)
    Path.target(point_en, s_m, lookahead_m, max_cut_m) -> the carrot, pulled back at bends
    PathFollower(planner, params).update(now_s, position_en, goal_en) -> Guidance
      Guidance.target_en (the carrot, None when there is no path), cross_track_m, remaining_m,
      replanned, error;  PathFollower.block(now_s, center_en) re-plans around a blocked leg;
      PathFollower.set_persistent(polygons) re-plans only if the path ahead touches a new one.
"""

from __future__ import annotations

import bisect
import logging
import math
from dataclasses import dataclass, field
from typing import Callable, Iterable, Sequence

import networkx as nx
import numpy as np
import shapely
from shapely.geometry import MultiPolygon, Point, Polygon
from shapely.geometry.polygon import orient
from shapely.ops import nearest_points, unary_union

from rover_ctl.config import PlannerParams, RobotParams
from rover_ctl.mission.model import FENCE_CIRCLE_COMMANDS, Cmd, Mission, MissionItem, MissionType, polygon_runs
from rover_ctl.mission.validate import MAX_PLANNER_NODES, planner_nodes, validate

log = logging.getLogger(__name__)

EN = tuple[float, float]

NODE_OFFSET_M = 0.02
"""Graph vertices sit this much outside the inflated zones used to check edges (rounding margin)."""

TANGENT_TOLERANCE = 1e-9
"""Product of the neighbour sines below which a line still counts as tangent (rounding)."""

UNBOUNDED_M = 1.0e6
"""Half-size of the square that stands for the plane when there is no inclusion fence."""

PAIR_BLOCK = 1 << 16
"""Vertex pairs tested for tangency at once while the graph is built (bounds its memory)."""

CARROT_BISECTIONS = 10
"""Bisection steps of a carrot pulled back at a bend (``Path.target``): the lookahead to 1/1024."""


@dataclass(frozen=True)
class Circle:
    center_en: EN
    radius_m: float


@dataclass(frozen=True)
class Fence:
    """A geofence in ENU metres. The rover must be inside every inclusion and outside every
    exclusion (ArduPilot's AC_PolyFence semantics)."""

    inclusion_polygons: tuple[tuple[EN, ...], ...] = ()
    exclusion_polygons: tuple[tuple[EN, ...], ...] = ()
    inclusion_circles: tuple[Circle, ...] = ()
    exclusion_circles: tuple[Circle, ...] = ()

    @classmethod
    def from_items(cls, items: Sequence[MissionItem], to_enu: Callable[[float, float], EN]) -> "Fence":
        """The fence of MAV_CMD_NAV_FENCE_* items (mission_type FENCE), via the mission model's
        typed views; ``to_enu(lat, lon)`` is the local frame. Never raises: a part that is not
        valid (the rules of ``rover_ctl.mission.validate``, plus self-intersection in ENU) is left
        out with a logged warning naming it -- a stored plan may come from an older version that
        did not check it, and the rover must still start."""
        fence, ignored = cls.checked(items, to_enu)
        for reason in ignored:
            log.warning("fence part ignored: %s", reason)
        return fence

    @classmethod
    def checked(cls, items: Sequence[MissionItem], to_enu: Callable[[float, float], EN]) -> tuple["Fence", list[str]]:
        """``(fence of the valid parts, why each other part was left out)``."""
        mission = Mission(fence=list(items))
        errors, _ = validate(mission, math.inf, parts=(MissionType.FENCE,), circle_segments=None)
        ignored = [str(e) for e in errors]
        polygons: dict[bool, list] = {True: [], False: []}
        for (start, stop), polygon in zip(polygon_runs(mission.fence), mission.fence_polygons()):
            where = f"fence item {start}"
            if any(e.startswith(f"{where}:") or e.startswith(f"fence item {k}:") for e in errors for k in range(start, stop)):
                continue  # reported above
            vertices = tuple(_enu(to_enu, lat, lon) for lat, lon in polygon.vertices_latlon)
            if not all(map(math.isfinite, sum(vertices, ()))) or not Polygon(vertices).is_valid:
                ignored.append(f"{where}: polygon of {len(vertices)} vertices intersects itself")
                continue
            polygons[polygon.inclusion].append(vertices)
        circles: dict[bool, list] = {True: [], False: []}
        for index, item in enumerate(mission.fence):
            if item.command not in FENCE_CIRCLE_COMMANDS or any(e.startswith(f"fence item {index}:") for e in errors):
                continue
            center = _enu(to_enu, item.lat_deg, item.lon_deg)
            if all(map(math.isfinite, center)):
                circles[item.command == Cmd.NAV_FENCE_CIRCLE_INCLUSION].append(Circle(center, float(item.param1)))
        return cls(tuple(polygons[True]), tuple(polygons[False]), tuple(circles[True]), tuple(circles[False])), ignored


def _enu(to_enu: Callable[[float, float], EN], lat_deg: float, lon_deg: float) -> EN:
    east, north = to_enu(lat_deg, lon_deg)
    return (float(east), float(north))


@dataclass(frozen=True)
class Path:
    """A polyline in ENU metres from the start to the goal; ``error`` is set (and ``points`` holds
    at most the start) when no path exists."""

    points: tuple[EN, ...]
    error: str | None = None
    _cumulative_m: np.ndarray = field(init=False, repr=False, compare=False)
    _cumulative: list[float] = field(init=False, repr=False, compare=False)
    _segments: tuple[tuple[float, ...], ...] = field(init=False, repr=False, compare=False)
    """Per segment: start east, north, direction east, north, length, squared length, arc length
    at its start and at its end; for ``project`` at every control step."""

    def __post_init__(self) -> None:
        pts = np.asarray(self.points, dtype=float).reshape(-1, 2)
        steps = np.hypot(*np.diff(pts, axis=0).T) if len(pts) > 1 else np.zeros(0)
        cum = np.concatenate([[0.0], np.cumsum(steps)])
        object.__setattr__(self, "_cumulative_m", cum)
        # Plain floats from here on: a path has a few segments, too few for numpy's per-call cost
        # to pay at every step. Computed with numpy once, so ``project`` sees the same numbers.
        object.__setattr__(self, "_cumulative", cum.tolist())
        seg_len, d = np.diff(cum), np.diff(pts, axis=0)
        columns = (pts[:-1, 0], pts[:-1, 1], d[:, 0], d[:, 1], seg_len, seg_len**2, cum[:-1], cum[1:])
        object.__setattr__(self, "_segments", tuple(zip(*(c.tolist() for c in columns))))

    @property
    def ok(self) -> bool:
        return self.error is None

    @property
    def length_m(self) -> float:
        return self._cumulative[-1] if self.points else 0.0

    def point_at(self, s_m: float) -> EN:
        """The point at arc length ``s_m`` (clamped to the path)."""
        cum = self._cumulative
        s = min(max(s_m, 0.0), cum[-1])
        i = min(bisect.bisect_right(cum, s) - 1, len(self.points) - 2)
        if i < 0:
            return self.points[0]
        seg = cum[i + 1] - cum[i]
        f = 0.0 if seg == 0 else (s - cum[i]) / seg
        (ax, ay), (bx, by) = self.points[i], self.points[i + 1]
        return (float(ax + f * (bx - ax)), float(ay + f * (by - ay)))

    def project(self, point_en: EN, s_min_m: float = 0.0, s_max_m: float = math.inf) -> tuple[float, float]:
        """Nearest point of the path within arc lengths [s_min_m, s_max_m]: its arc length and the
        signed cross-track error (positive when ``point_en`` is left of the path direction)."""
        if len(self.points) < 2:
            return 0.0, math.dist(point_en, self.points[0]) if self.points else 0.0
        px, py = float(point_en[0]), float(point_en[1])
        best_m, found = math.inf, None
        for ax, ay, dx, dy, length, length2, s0, s1 in self._segments:
            lo, hi = max(s0, s_min_m), min(s1, s_max_m)
            if lo > hi:
                continue  # the window misses this segment
            t = ((px - ax) * dx + (py - ay) * dy) / length2 if length2 > 0 else 0.0
            s = min(max(s0 + t * length, lo), hi)
            f = (s - s0) / length if length > 0 else 0.0
            nx, ny = ax + f * dx, ay + f * dy
            # abs(complex) is C's hypot, as numpy's: math.hypot rounds differently now and then.
            distance_m = abs(complex(px - nx, py - ny))
            if distance_m < best_m:  # the first of equals, as argmin
                best_m = distance_m
                # Sign from the segment's direction: cross(d, p - nearest) > 0 means left.
                found = (s, math.copysign(distance_m, dx * (py - ny) - dy * (px - nx)))
        if found is None:  # window beyond the path: the end
            return self.length_m, math.dist(point_en, self.points[-1])
        return found

    def carrot(self, point_en: EN, lookahead_m: float, max_cut_m: float = math.inf) -> EN:
        """Pure-pursuit target: ``lookahead_m`` along the path beyond the projection of ``point_en``
        (pulled back at bends as ``target``)."""
        s, _ = self.project(point_en)
        return self.target(point_en, s, lookahead_m, max_cut_m)

    def target(self, point_en: EN, s_m: float, lookahead_m: float, max_cut_m: float = math.inf) -> EN:
        """The carrot for a rover at ``point_en`` projected at arc length ``s_m``: the point at
        ``s_m + lookahead_m``, pulled back towards ``s_m`` until the straight line from the rover
        to it passes within ``max_cut_m`` of every path vertex (bend) between them.

        The rover drives roughly that straight line, so this bounds how far it cuts a bend. The
        first bend ahead is always acceptable (no vertex lies between), so the carrot never comes
        closer than it; beyond it the largest acceptable arc length is found by bisection (the
        cut grows with the arc length along a convex bend)."""
        cum = self._cumulative
        far = min(s_m + lookahead_m, cum[-1])
        first = bisect.bisect_right(cum, s_m)  # the first vertex beyond s_m
        if max_cut_m == math.inf or first >= len(cum) - 1 or cum[first] >= far:
            return self.point_at(far)  # no bend between: the plain carrot
        if self._cut(point_en, self.point_at(far), first, far) <= max_cut_m:
            return self.point_at(far)
        ok_s, bad_s = cum[first], far
        for i in range(first + 1, len(cum) - 1):  # the last bend the rover can aim at directly
            if cum[i] >= far:
                break
            if self._cut(point_en, self.points[i], first, cum[i]) > max_cut_m:
                bad_s = cum[i]
                break
            ok_s = cum[i]
        for _ in range(CARROT_BISECTIONS):
            mid = 0.5 * (ok_s + bad_s)
            if self._cut(point_en, self.point_at(mid), first, mid) <= max_cut_m:
                ok_s = mid
            else:
                bad_s = mid
        return self.point_at(ok_s)

    def _cut(self, a: EN, b: EN, first: int, s_end_m: float) -> float:
        """How far the segment a-b passes from the path's vertices ``first``.. (arc length below
        ``s_end_m``): the largest of their distances to it."""
        ax, ay = a
        dx, dy = b[0] - ax, b[1] - ay
        d2 = dx * dx + dy * dy
        worst, cum = 0.0, self._cumulative
        for i in range(first, len(cum) - 1):
            if cum[i] >= s_end_m:
                break
            px, py = self.points[i]
            t = 0.0 if d2 == 0 else min(1.0, max(0.0, ((px - ax) * dx + (py - ay) * dy) / d2))
            worst = max(worst, math.hypot(px - ax - t * dx, py - ay - t * dy))
        return worst


def _circle_polygon(center: EN, radius_m: float, segments: int, circumscribed: bool) -> Polygon:
    """Regular polygon for a circle: circumscribed (edges touch it, vertices at r / cos(pi/n)) or
    inscribed (vertices on it)."""
    r = radius_m / math.cos(math.pi / segments) if circumscribed else radius_m
    angles = np.arange(segments) * 2 * math.pi / segments
    return Polygon(np.column_stack([center[0] + r * np.cos(angles), center[1] + r * np.sin(angles)]))


def _polygons(geometry) -> list[Polygon]:
    if geometry.is_empty:
        return []
    if isinstance(geometry, Polygon):
        return [geometry]
    return [g for g in getattr(geometry, "geoms", []) if isinstance(g, Polygon) and not g.is_empty]


def _reflex_vertices(free: Polygon | MultiPolygon) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices where the free space turns reflex (interior angle > 180 deg), the only places a
    shortest path bends, with their ring neighbours (previous, next). With every ring oriented so
    the free space is on its left, those are the right turns."""
    found = []
    for poly in _polygons(free):
        poly = orient(poly, 1.0)
        for ring in [poly.exterior, *poly.interiors]:
            pts = np.asarray(ring.coords)[:-1]
            prev, nxt = np.roll(pts, 1, axis=0), np.roll(pts, -1, axis=0)
            u, v = pts - prev, nxt - pts
            reflex = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0] < 0
            found.append(np.stack([pts[reflex], prev[reflex], nxt[reflex]]))
    if not found:
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2))
    pts, prev, nxt = np.concatenate(found, axis=1)
    return pts, prev, nxt


def _tangent(at: np.ndarray, prev: np.ndarray, nxt: np.ndarray, other: np.ndarray) -> np.ndarray:
    """Whether the line from each vertex ``at`` towards ``other`` leaves both ring neighbours on
    one side. A shortest path only wraps around a vertex along such a line (it would otherwise
    cut the corner), so other edges are dropped before the costlier visibility test: the
    reduced visibility graph."""
    d = other - at
    # Sines of the angles from the line to each neighbour; a query point on a ring edge makes one
    # of them zero up to rounding, which must count as tangent.
    return _sine(d, prev - at) * _sine(d, nxt - at) >= -TANGENT_TOLERANCE


def _tangent_pairs(pts: np.ndarray, prev: np.ndarray, nxt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The vertex pairs (i < j, in row order) whose line is ``_tangent`` at both ends: the same
    arithmetic as ``_tangent`` on every pair, a block of rows at a time against all vertices
    (broadcast, no index arrays of all the pairs), so memory stays at ``PAIR_BLOCK`` pairs."""
    n = len(pts)
    found_i, found_j = [np.zeros(0, dtype=np.intp)], [np.zeros(0, dtype=np.intp)]
    rows = max(1, PAIR_BLOCK // max(n, 1))
    to_prev, to_next = prev - pts, nxt - pts
    # The far end's side: the line from j towards i is -d, and cross(-d, u) == cross(d, -u) exactly.
    far = _sine_each(to_prev, to_next, negate=True)
    for first in range(0, n - 1, rows):
        block = np.arange(first, min(n - 1, first + rows))
        d = pts[None, :, :] - pts[block, None, :]  # (rows, n, 2): from each vertex of the block to every vertex
        near = _sine_each(to_prev[block], to_next[block])
        ok = (near(d) >= -TANGENT_TOLERANCE) & (far(d) >= -TANGENT_TOLERANCE) & (np.arange(n)[None, :] > block[:, None])
        r, c = np.nonzero(ok)
        found_i.append(block[r])
        found_j.append(c)
    return np.concatenate(found_i), np.concatenate(found_j)


def _sine_each(to_prev: np.ndarray, to_next: np.ndarray, negate: bool = False) -> Callable[[np.ndarray], np.ndarray]:
    """``d -> _sine(d, to_prev) * _sine(d, to_next)`` for directions ``d`` of shape (rows, n, 2):
    ``to_prev``/``to_next`` of shape (rows, 2) go with the rows, of shape (n, 2) with the columns.
    ``negate``: for -to_prev and -to_next."""
    sign = -1.0 if negate else 1.0
    axis = 0 if negate else 1  # the columns' vectors broadcast over the rows, the rows' over the columns

    def column(a: np.ndarray) -> np.ndarray:
        return np.expand_dims(a, axis)

    ux, uy, vx, vy = (column(sign * a) for a in (to_prev[:, 0], to_prev[:, 1], to_next[:, 0], to_next[:, 1]))
    nu, nv = column(np.hypot(to_prev[:, 0], to_prev[:, 1])), column(np.hypot(to_next[:, 0], to_next[:, 1]))

    def product(d: np.ndarray) -> np.ndarray:
        dx, dy = d[..., 0], d[..., 1]
        nd = np.hypot(dx, dy)
        return _ratio(dx * uy - dy * ux, nd * nu) * _ratio(dx * vy - dy * vx, nd * nv)

    return product


def _ratio(cross: np.ndarray, norms: np.ndarray) -> np.ndarray:
    return np.divide(cross, norms, out=np.zeros_like(cross), where=norms > 0)


def _sine(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row-wise sine of the angle from u to v (0 where either is zero)."""
    cross = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    norms = np.hypot(u[:, 0], u[:, 1]) * np.hypot(v[:, 0], v[:, 1])
    return np.divide(cross, norms, out=np.zeros_like(cross), where=norms > 0)


class Planner:
    """Shortest paths around the fence and known obstacles (see the module docstring)."""

    def __init__(
        self,
        params: PlannerParams,
        robot: RobotParams,
        fence: Fence = Fence(),
        polygons: Iterable[Sequence[EN]] = (),
        circles: Iterable[Circle] = (),
        persistent_margin_m: Callable[[], float] = lambda: 0.0,
    ) -> None:
        """``persistent_margin_m()``: the margin in force for persistent obstacles."""
        self.params = params
        self._persistent_margin_m = persistent_margin_m
        self._persistent: list[Polygon] = []
        self._persistent_near = Polygon()  # the persistent obstacles grown by the half-width, prepared
        self.robot = robot
        self.fence = fence
        self._obstacle_polygons = [Polygon(p) for p in polygons]
        self._obstacle_circles = list(circles)
        self._blocked: list[tuple[float, Circle]] = []  # (time added, circle)
        self._inclusion_polygons = [Polygon(p) for p in fence.inclusion_polygons]
        self._exclusion_polygons = [Polygon(p) for p in fence.exclusion_polygons]
        self._rebuild()

    @property
    def clearance_m(self) -> float:
        return self.robot.footprint_width_m / 2.0 + self.params.clearance_margin_m

    def _geometry(self) -> tuple[float, int, float]:
        """The parameters the free space and graph are built from."""
        return self.clearance_m, self.params.circle_segments, self._persistent_margin_m()

    # -- geometry -------------------------------------------------------------------------------

    def _inflated(self, extra_m: float):
        """The region inside the inclusion fences shrunk, and the union of the zones inflated, by
        clearance + extra_m (region None: no inclusion fence)."""
        n = self.params.circle_segments
        quad_segs = max(1, n // 4)
        # Round joins are chords of the offset arc; dividing by cos(half the chord angle) keeps
        # every chord at least the clearance away.
        margin = self.clearance_m + extra_m
        grow = margin / math.cos(math.pi / (4 * quad_segs))
        circles = self._obstacle_circles + list(self.fence.exclusion_circles) + [c for _, c in self._blocked]
        persistent_grow = (self.robot.footprint_width_m / 2.0 + self._persistent_margin_m() + extra_m) / math.cos(math.pi / (4 * quad_segs))
        zones = unary_union(
            [z.buffer(grow, quad_segs=quad_segs) for z in self._exclusion_polygons + self._obstacle_polygons]
            + [z.buffer(persistent_grow, quad_segs=quad_segs) for z in self._persistent]
            + [_circle_polygon(c.center_en, c.radius_m + margin, n, circumscribed=True) for c in circles]
        )
        shrunk = [p.buffer(-grow, quad_segs=quad_segs) for p in self._inclusion_polygons] + [
            _circle_polygon(c.center_en, c.radius_m - margin, n, circumscribed=False) if c.radius_m > margin else Polygon()
            for c in self.fence.inclusion_circles
        ]
        region = None
        for inside in shrunk:
            region = inside if region is None else region.intersection(inside)
        return region, zones

    def node_count(self, fixed_only: bool = False) -> int:
        """The graph nodes the fence, known obstacles, blocked circles and persistent obstacles
        can make at the current ``circle_segments`` (an upper bound, see ``planner_nodes``);
        ``fixed_only``: the fence's and known obstacles' alone (what arming checks: the others
        come and go, and are dropped first when over the budget)."""
        circles = len(self._obstacle_circles) + len(self.fence.exclusion_circles) + len(self.fence.inclusion_circles)
        circles += 0 if fixed_only else len(self._blocked)
        rings = [(p, False) for p in self.fence.inclusion_polygons] + [(p, True) for p in self.fence.exclusion_polygons]
        for shape in self._obstacle_polygons + ([] if fixed_only else self._persistent):
            for poly in _polygons(shape):  # a hole of a grown zone shrinks
                rings += [(poly.exterior.coords[:-1], True)] + [(ring.coords[:-1], False) for ring in poly.interiors]
        return planner_nodes(circles, rings, self.params.circle_segments)

    def _rebuild(self) -> None:
        self._built_for = self._geometry()
        nodes = self.node_count()
        segments = self.params.circle_segments
        unblocked = nodes - segments * len(self._blocked)
        if nodes > MAX_PLANNER_NODES >= unblocked:
            # Blocked circles are temporary detours: the oldest go early rather than the plan.
            fit = (MAX_PLANNER_NODES - unblocked) // segments
            log.warning("planner: %d blocked area(s) forgotten early (max %d graph nodes)", len(self._blocked) - fit, MAX_PLANNER_NODES)
            self._blocked = self._blocked[len(self._blocked) - fit :]
            nodes = self.node_count()
        if nodes > MAX_PLANNER_NODES:
            self._refuse(nodes)  # before the geometry, whose cost grows with the vertices too
            return
        self._too_complex = None
        region, zones = self._inflated(0.0)
        node_region, node_zones = self._inflated(NODE_OFFSET_M)
        if region is None:  # no inclusion fence: a box far beyond any mission bounds the plane
            region = node_region = shapely.box(-UNBOUNDED_M, -UNBOUNDED_M, UNBOUNDED_M, UNBOUNDED_M)
        self._free = region.difference(zones)
        self._node_free = node_region.difference(node_zones)
        shapely.prepare(self._free)
        pts, self._prev, self._next = _reflex_vertices(self._node_free)
        if len(pts) > MAX_PLANNER_NODES:  # never, as node_count is an upper bound; but never build it
            self._refuse(len(pts))
            return
        self._pts = pts
        self._nodes = [(float(e), float(n)) for e, n in pts]
        self._graph = nx.Graph()
        self._graph.add_nodes_from(range(len(pts)))
        i, j = _tangent_pairs(pts, self._prev, self._next)
        visible = self._visible(pts[i], pts[j])
        self._graph.add_weighted_edges_from(
            (int(a), int(b), math.dist(self._nodes[a], self._nodes[b])) for a, b in zip(i[visible], j[visible])
        )

    def _refuse(self, nodes: int) -> None:
        """Over the node budget: no graph (its build is quadratic in the nodes); every plan_leg
        says why until a rebuild fits."""
        self._too_complex = f"too complex to plan: {nodes} nodes, max {MAX_PLANNER_NODES}"
        log.warning("planner: %s (fence, obstacles, circle_segments %d)", self._too_complex, self.params.circle_segments)
        self._free = self._node_free = Polygon()
        self._graph, self._nodes = nx.Graph(), []
        self._pts = self._prev = self._next = np.zeros((0, 2))

    def _visible(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        lines = shapely.linestrings(np.stack([a, b], axis=1))
        return shapely.covers(self._free, lines)

    def _raw_violation(self, point_en: EN) -> str | None:
        """Why a goal is not allowed at all (no clearance involved), or None."""
        where = f"goal ({point_en[0]:.1f}, {point_en[1]:.1f}) m"
        if not self._inside_inclusions(point_en):
            return f"{where} is outside the inclusion fence"
        if self._in_any(point_en, self._exclusion_polygons, self.fence.exclusion_circles):
            return f"{where} is inside a fence exclusion zone"
        if self._in_any(point_en, self._obstacle_polygons, self._obstacle_circles):
            return f"{where} is inside a known obstacle"
        if self._in_any(point_en, [], [c for _, c in self._blocked]):
            return f"{where} is inside a blocked area"
        return None

    def _inside_inclusions(self, point_en: EN) -> bool:
        # The shapely Point only when there are polygons: this runs at every control step.
        if self._inclusion_polygons:
            p = Point(point_en)
            if not all(poly.covers(p) for poly in self._inclusion_polygons):
                return False
        return all(math.dist(point_en, c.center_en) <= c.radius_m for c in self.fence.inclusion_circles)

    @staticmethod
    def _in_any(point_en: EN, polygons: Sequence[Polygon], circles: Iterable[Circle]) -> bool:
        if polygons:
            p = Point(point_en)
            if any(poly.contains(p) for poly in polygons):
                return True
        return any(math.dist(point_en, c.center_en) < c.radius_m for c in circles)

    def _to_free(self, point_en: EN) -> EN | None:
        """``point_en`` if it is in free space, else the nearest point of it (None: none at all)."""
        if self._free.covers(Point(point_en)):
            return point_en
        if self._node_free.is_empty:
            return None
        nearest = nearest_points(self._node_free, Point(point_en))[0]
        return (float(nearest.x), float(nearest.y))

    # -- public ---------------------------------------------------------------------------------

    def is_inside_fence(self, point_en: EN) -> bool:
        """True unless ``point_en`` is outside an inclusion or inside an exclusion zone (no clearance)."""
        return self._inside_inclusions(point_en) and not self._in_any(point_en, self._exclusion_polygons, self.fence.exclusion_circles)

    def plan_leg(self, start_en: EN, goal_en: EN) -> Path:
        """Shortest path from ``start_en`` to ``goal_en``; ``Path.error`` explains a failure."""
        start_en = (float(start_en[0]), float(start_en[1]))
        goal_en = (float(goal_en[0]), float(goal_en[1]))
        if not all(map(math.isfinite, start_en + goal_en)):
            return Path((start_en,), error=f"cannot plan from {start_en} to {goal_en}: not a finite position")
        reason = self._raw_violation(goal_en)
        if reason is not None:
            return Path((start_en,), error=reason)
        if self._built_for != self._geometry():
            self._rebuild()
        if self._too_complex is not None:
            return Path((start_en,), error=self._too_complex)
        start_free, goal_free = self._to_free(start_en), self._to_free(goal_en)
        if start_free is None or goal_free is None:
            return Path((start_en,), error="no free space: the inclusion fence is narrower than the rover's clearance")
        head = [start_en] if start_free != start_en else []
        tail = [goal_en] if goal_free != goal_en else []
        if self._visible(np.array([start_free]), np.array([goal_free]))[0]:
            middle = [start_free, goal_free]
        else:
            middle = self._search(start_free, goal_free)
            if middle is None:
                e, n = goal_en
                return Path((start_en,), error=f"goal ({e:.1f}, {n:.1f}) m cannot be reached: fences or obstacles block every way")
        points = [p for k, p in enumerate(head + middle + tail) if k == 0 or p != (head + middle + tail)[k - 1]]
        if len(points) == 1:
            points.append(points[0])
        return Path(tuple(points))

    def _search(self, start: EN, goal: EN) -> list[EN] | None:
        graph, nodes, pts = self._graph, self._nodes, self._pts
        if not nodes:
            return None
        graph.add_nodes_from(["start", "goal"])
        try:
            for name, end in (("start", start), ("goal", goal)):
                here = np.repeat(np.array([end]), len(nodes), axis=0)
                candidates = np.flatnonzero(_tangent(pts, self._prev, self._next, here))
                seen = candidates[self._visible(here[candidates], pts[candidates])]
                if not len(seen):
                    # A point a hair outside an outline (the rover pushed against an obstacle's
                    # clearance band): its tangent lines graze the outline and rounding hides them.
                    # Any visible vertex will do; the filter only saves work.
                    seen = np.flatnonzero(self._visible(here, pts))
                for k in seen:
                    graph.add_edge(name, int(k), weight=math.dist(end, nodes[k]))
            try:
                route = nx.astar_path(
                    graph,
                    "start",
                    "goal",
                    heuristic=lambda u, v: math.dist(start if u == "start" else goal if u == "goal" else nodes[u], goal),
                    weight="weight",
                )
            except nx.NetworkXNoPath:
                return None
        finally:
            graph.remove_nodes_from(["start", "goal"])
        return [start] + [nodes[k] for k in route[1:-1]] + [goal]

    def plan_route(self, start_en: EN, goals_en: Sequence[EN]) -> Path:
        """The legs start -> goals[0] -> goals[1] ... joined into one path (first error wins)."""
        points: list[EN] = [tuple(start_en)]
        for goal in goals_en:
            leg = self.plan_leg(points[-1], goal)
            if not leg.ok:
                return Path((tuple(start_en),), error=leg.error)
            points.extend(leg.points[1:])
        if len(points) == 1:
            points.append(points[0])
        return Path(tuple(points))

    def block(self, now_s: float, center_en: EN, radius_m: float | None = None) -> None:
        """Add a temporary circular obstacle (a leg reported blocked) for ``blocked_ttl_s``."""
        radius = self.params.blocked_radius_m if radius_m is None else radius_m
        self._blocked.append((now_s, Circle((float(center_en[0]), float(center_en[1])), float(radius))))
        self._rebuild()

    def set_persistent(self, polygons: Iterable[Sequence[EN]]) -> bool:
        """Replace the persistent obstacles (rebuilds the graph); False when they are the same."""
        shapes = [Polygon(p) for p in polygons]
        shapes = [s if s.is_valid else s.buffer(0) for s in shapes if len(s.exterior.coords) >= 4]
        if len(shapes) == len(self._persistent) and all(a.equals_exact(b, 0.0) for a, b in zip(shapes, self._persistent)):
            return False
        self._persistent = shapes
        self._persistent_near = unary_union(shapes).buffer(self.robot.footprint_width_m / 2.0) if shapes else Polygon()
        shapely.prepare(self._persistent_near)
        self._rebuild()
        return True

    @property
    def has_persistent(self) -> bool:
        return bool(self._persistent)

    def near_persistent(self, path: Path, s_from_m: float = 0.0) -> bool:
        """Whether ``path`` beyond arc length ``s_from_m`` comes within the robot's half-width of
        a persistent obstacle (the rover would touch it)."""
        if not self._persistent or not path.ok or len(path.points) < 2:
            return False
        points = [path.point_at(s_from_m)] + [pt for pt, s in zip(path.points, path._cumulative_m) if s > s_from_m]
        if len(points) < 2:
            return False
        return bool(self._persistent_near.intersects(shapely.LineString(points)))

    def expire(self, now_s: float) -> bool:
        """Forget blocked circles older than ``blocked_ttl_s``; True if any went."""
        if not self._blocked:  # the usual case, at every control step
            return False
        kept = [(t, c) for t, c in self._blocked if now_s - t < self.params.blocked_ttl_s]
        if len(kept) == len(self._blocked):
            return False
        self._blocked = kept
        self._rebuild()
        return True


@dataclass(frozen=True)
class Guidance:
    """What the navigator steers to this step."""

    target_en: EN | None
    """The carrot on the path; None when there is no path (the daemon holds)."""
    cross_track_m: float
    """Signed distance from the path (positive: rover left of the path)."""
    remaining_m: float
    """Path length left from the rover's projection to the goal."""
    path: Path | None
    replanned: bool
    error: str | None = None


class PathFollower:
    """Keeps a path to the executor's current goal, re-plans when needed, and gives the carrot.

    Re-plans from the current position when the goal changes, when a leg is reported blocked,
    when a blocked area expires, when new persistent obstacles come within the robot's half-width
    of the path ahead, and -- at most once per ``replan_min_interval_s`` -- when the cross-track
    error exceeds ``replan_off_path_m`` or the last plan failed. When the persistent obstacles
    leave no way to the goal (a gap that reads closed), it plans without them until the goal
    changes or other persistent obstacles are handed to it (the map changed: tried again).
    """

    def __init__(self, planner: Planner, params: PlannerParams) -> None:
        self.planner = planner
        self.params = params
        self.path: Path | None = None
        self._goal: EN | None = None
        self._progress_s = 0.0
        self._last_plan_s = -math.inf
        self._force = False
        self._persistent: tuple[tuple[EN, ...], ...] = ()
        self._without_persistent: EN | None = None  # the goal planned for without persistent obstacles
        self._blocking: tuple[tuple[EN, ...], ...] = ()  # the persistent obstacles that left it no way

    def block(self, now_s: float, center_en: EN, radius_m: float | None = None) -> None:
        """A leg is blocked at ``center_en``: avoid it (temporarily) and re-plan on the next update."""
        self.planner.block(now_s, center_en, radius_m)
        self._force = True

    def set_persistent(self, polygons: Iterable[Sequence[EN]]) -> bool:
        """New persistent obstacles for the planner; the next update re-plans only if the path
        ahead would touch one. True when the planner's map changed."""
        self._persistent = tuple(tuple(p) for p in polygons)
        if self._without_persistent is not None:
            if self._persistent == self._blocking:
                return False  # the ones that left no way, handed again
            self._without_persistent = None  # new ones may leave a way again (a gap seen open since)
            self._force = True
        changed = self.planner.set_persistent(self._persistent)
        if changed and self.path is not None and self.planner.near_persistent(self.path, self._progress_s):
            self._force = True
        return changed

    def reset(self) -> None:
        """Forget the path (mode change): the next update plans afresh."""
        self.path, self._goal, self._progress_s = None, None, 0.0

    def update(self, now_s: float, position_en: EN, goal_en: EN, lookahead_m: float | None = None) -> Guidance:
        """The carrot for this step (re-planning first when due); ``lookahead_m`` replaces
        ``params.lookahead_m`` for this step (the autopilot's rejoin after stepping aside)."""
        goal = (float(goal_en[0]), float(goal_en[1]))
        if self.planner.expire(now_s):
            self._force = True
        replan = self._force or self.path is None or goal != self._goal
        cross_track = 0.0
        if not replan:
            cross_track = self._project(position_en)
            off_path = abs(cross_track) > self.params.replan_off_path_m or not self.path.ok
            replan = off_path and now_s - self._last_plan_s >= self.params.replan_min_interval_s
        if replan:
            if self._without_persistent is not None and self._without_persistent != goal:
                self._without_persistent = None
                self.planner.set_persistent(self._persistent)
            self.path = self.planner.plan_leg(position_en, goal)
            if not self.path.ok and self.planner.has_persistent:
                self._without_persistent, self._blocking = goal, self._persistent
                self.planner.set_persistent(())
                self.path = self.planner.plan_leg(position_en, goal)
            self._goal, self._progress_s, self._last_plan_s, self._force = goal, 0.0, now_s, False
            cross_track = self._project(position_en)
        path = self.path
        if not path.ok:
            return Guidance(None, 0.0, math.inf, path, replan, path.error)
        lookahead_m = self.params.lookahead_m if lookahead_m is None else lookahead_m
        target = path.target(position_en, self._progress_s, lookahead_m, self.params.max_corner_cut_m)
        return Guidance(target, cross_track, path.length_m - self._progress_s, path, replan)

    def _project(self, position_en: EN) -> float:
        """Advance the progress along the path (never backwards, within the projection window)."""
        if not self.path.ok:
            return 0.0
        s, cross_track = self.path.project(position_en, self._progress_s, self._progress_s + self.params.projection_window_m)
        self._progress_s = max(self._progress_s, s)
        return cross_track
