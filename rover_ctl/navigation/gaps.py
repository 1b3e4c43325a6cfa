"""Narrow passages: a gap between obstacles, barely wider than the rover, found in the remembered
echoes and driven through on its centre line.

Why. The rule bases read ranges by sector. In a gap 1.5 times the rover's width (0.6 m for a
0.4 m rover) its posts stand 0.1 m from each side: every side and diagonal reads "near", and the
remembered echoes of the posts fall in the front sector too, so the rover sees a wall (the paper's
"inability to identify passable narrow paths"). The geometry to tell a gap from a wall is in the
obstacle memory (``rover_ctl.navigation.proximity``): where each echo is, the range it was
measured at and its beam's axis. The rule base is left unchanged; this module decides what it is
shown and where it steers, as a local planner over the echoes (a 1-D "follow the gap" across the
way ahead, after Sezer and Gokasan 2012, with the rangefinders' beam width accounted for).

**An echo's uncertainty.** A rangefinder reports the nearest hit anywhere in its beam but the
echo is remembered on the beam's axis. At range r the obstacle may lie up to ``s = r tan(b)``
either side of where it is remembered (``b`` = ``beam_half_deg``). Across a direction ``u`` that
spread is ``s_u = s |cos(axis - angle(u))|`` (the beam's perpendicular projected on u's normal).
Edge echoes are pulled into an opening by up to ``s_u``: a 0.6 m gap seen from 2 m with a 15 degree
beam looks 0.08 m wide.

**Finding a gap** (``find_gap``). Take ``u`` the unit vector from the rover towards the point it
steers to and ``n`` its left normal. Every remembered echo ``p`` ahead gets ``a = (p - x) . u``
(0 < a <= ``search_m``) and ``l = (p - x) . n`` (``|l|`` <= ``search_half_m``). Sorted by ``l``,
two neighbours ``i, i+1`` bound an opening of at most

    w = (l_{i+1} - l_i) + s_u,i + s_u,i+1

(each edge may really lie its spread further out). It is a candidate when the echoes themselves leave at least ``min_hole_m`` between them,
both edges lie within ``depth_m`` of each other along ``u`` (a gap in one wall or between two obstacles abreast,
not two obstacles one behind the other) and ``W + 2 c <= w <= max_width_m`` with ``W`` the
footprint's width and ``c`` = ``side_clearance_m``. It matters only when the way ahead is blocked
(an echo could lie in the rover's strip ``|l| < W/2 + c``) or the opening is the one the rover is
heading into (it holds ``l = 0``); among candidates the one nearest the line ``l = 0`` wins. The
gap is then its centre ``g`` (mid-way between the edges, at their mean ``a``), its axis ``v``
(perpendicular to the edge-to-edge line, pointing away from the rover) and width ``w``.

**Looking through it.** A candidate's width is an upper bound; it becomes a passage only once a
beam has been seen through it. A reading of range R (the rangefinder's maximum when there is no
echo) from a sensor at ``o`` along ``d`` shows the beam's whole cone free up to R. Where its axis
crosses the edge-to-edge segment at distance ``x < R - depth_m/2``, the free part of that line is
``x tan(b) / |d . v|`` either side of the crossing. The union of these intervals over the beams of
the last ``proximity.memory_s``, clipped to the segment, is a lower bound of the opening; the gap
is confirmed when it reaches ``W + 2 c``. To get such a beam the rover first lines up: it steers
along the centre line to the point ``verify_m`` before the gap's line and faces it (its front beam's
cone there is ``2 verify_m tan(b)`` wide, 0.53 m at 2 m for a 15 degree beam); a candidate not
confirmed by ``timeout_s`` is given up.

**Passing it** (``Passage``), once confirmed. In gap coordinates ``(a', l')`` (``a'`` along ``v``
from the gap's line, ``l'`` along its left normal):

- steering: pure pursuit on the centre line, target ``g + (a'_rover + lookahead_m) v``, so the
  rover lines up on it before it reaches the line; speed limited to ``speed_mps``.
- the edges set aside: an echo with ``|a'| <= depth_m`` (it is the wall the gap is in) is not shown to
  the rule base when it may lie outside the rover's swept strip, i.e. when
  ``|l' - l'_rover| + s_v >= W/2 + c``. One that must lie inside it (a real obstacle in the gap,
  or a gap too narrow: its posts' echoes come within the strip) still counts, so a gap the
  estimate over-rated stops the rover as any obstacle does. This holds only while the rover
  heads within ``align_heading_deg`` of ``v`` (its swept strip is along ``v``) or its front is
  more than ``commit_m`` from the gap's line; otherwise the rule base sees everything.
- the gap is re-found each step near where it was (``match_m``) and its estimate refreshed: nearer
  echoes are sharper. The passage ends when the rover's back is ``exit_m`` beyond the line, or is
  given up after ``timeout_s`` (that place is then not tried again for ``reject_s``).

Pure: no clock, no I/O; times are passed in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from rover_ctl.config import PassageParams

EN = tuple[float, float]

FACING_MAX_DEG = 60.0
"""An opening is one the rover can pass only if its axis lies within this of the way ahead
(edges nearly in line with the way are two obstacles one behind the other)."""


@dataclass(frozen=True)
class Gap:
    """An opening: centre, unit axis through it (the way the rover passes), width (upper bound)
    and its edges (the two echoes that bound it)."""

    centre_en: EN
    axis_en: EN
    width_m: float
    edges_en: tuple[EN, EN]

    def coordinates(self, points_en: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(along the axis from the gap's line, left of the centre line) for (east, north) rows."""
        d = np.asarray(points_en, dtype=float).reshape(-1, 2) - self.centre_en
        (ue, un) = self.axis_en
        return d[:, 0] * ue + d[:, 1] * un, -d[:, 0] * un + d[:, 1] * ue


def spread_m(ranges_m: np.ndarray, axes_rad: np.ndarray, direction_rad: float, beam_half_deg: float) -> np.ndarray:
    """How far across ``direction_rad`` each echo may lie from where it is remembered."""
    return np.asarray(ranges_m) * math.tan(math.radians(beam_half_deg)) * np.abs(np.cos(np.asarray(axes_rad) - direction_rad))


def find_gap(points_en: np.ndarray, ranges_m: np.ndarray, axes_rad: np.ndarray, position_en: EN, towards_en: EN,
             width_m: float, params: PassageParams) -> Gap | None:  # fmt: skip
    """The passage ahead, from the position towards ``towards_en`` (see the module docstring)."""
    p = params
    u = np.subtract(towards_en, position_en)
    norm = float(np.hypot(*u))
    if norm == 0.0 or not len(points_en):
        return None
    u = u / norm
    direction = math.atan2(u[1], u[0])
    rel = np.asarray(points_en, dtype=float) - position_en
    along = rel @ u
    lateral = rel[:, 0] * -u[1] + rel[:, 1] * u[0]
    ahead = (along > 0.0) & (along <= p.search_m) & (np.abs(lateral) <= p.search_half_m)
    if not ahead.any():
        return None
    spread = spread_m(np.asarray(ranges_m)[ahead], np.asarray(axes_rad)[ahead], direction, p.beam_half_deg)
    along, lateral = along[ahead], lateral[ahead]
    order = np.argsort(lateral)
    along, lateral, spread = along[order], lateral[order], spread[order]
    strip = width_m / 2.0 + p.side_clearance_m
    blocked = bool((np.abs(lateral) - spread < strip).any())
    opening = np.diff(lateral) + spread[:-1] + spread[1:]
    abreast = np.abs(np.diff(along)) <= p.depth_m
    wide = (opening >= width_m + 2.0 * p.side_clearance_m) & (opening <= p.max_width_m) & abreast & (np.diff(lateral) >= p.min_hole_m)
    centre_l = (lateral[:-1] + lateral[1:]) / 2.0
    on_the_way = (lateral[:-1] < 0.0) & (lateral[1:] > 0.0)
    candidates = np.flatnonzero(wide & (blocked | on_the_way))
    if not len(candidates):
        return None
    k = int(candidates[np.argmin(np.abs(centre_l[candidates]))])
    n = np.array([-u[1], u[0]])
    edge_a = np.asarray(position_en) + along[k] * u + lateral[k] * n
    edge_b = np.asarray(position_en) + along[k + 1] * u + lateral[k + 1] * n
    centre = (edge_a + edge_b) / 2.0
    across = edge_b - edge_a
    axis = np.array([across[1], -across[0]]) / float(np.hypot(*across))  # right of a->b: away from the rover
    if axis @ u < 0.0:
        axis = -axis
    if axis @ u < math.cos(math.radians(FACING_MAX_DEG)):
        return None  # edges one behind the other along the way: not an opening across it
    edges = ((float(edge_a[0]), float(edge_a[1])), (float(edge_b[0]), float(edge_b[1])))
    return Gap((float(centre[0]), float(centre[1])), (float(axis[0]), float(axis[1])), float(opening[k]), edges)


def seen_open_m(gap: Gap, beams: np.ndarray, beam_half_deg: float, depth_m: float) -> float:
    """Lower bound of the opening: the length of the gap's edge-to-edge segment shown free by the
    beams, rows ``(origin_e, origin_n, axis_rad, reach_m)`` (see the module docstring)."""
    if not len(beams):
        return 0.0
    a = np.asarray(gap.edges_en[0])
    seg = np.asarray(gap.edges_en[1]) - a
    length = float(np.hypot(*seg))
    if length == 0.0:
        return 0.0
    o, reach = beams[:, 0:2], beams[:, 3]
    d = np.column_stack((np.cos(beams[:, 2]), np.sin(beams[:, 2])))
    # o + x d = a + t seg  ->  solve for (x, t) by Cramer's rule
    det = d[:, 0] * -seg[1] - d[:, 1] * -seg[0]
    rhs = a - o
    ok = np.abs(det) > 1e-9
    det = np.where(ok, det, 1.0)
    x = (rhs[:, 0] * -seg[1] - rhs[:, 1] * -seg[0]) / det
    t = (d[:, 0] * rhs[:, 1] - d[:, 1] * rhs[:, 0]) / det
    through = ok & (x > 0.0) & (t >= 0.0) & (t <= 1.0) & (x < reach - depth_m / 2.0)
    if not through.any():
        return 0.0
    incidence = np.abs(d[through] @ np.asarray(gap.axis_en))
    half = x[through] * math.tan(math.radians(beam_half_deg)) / np.maximum(incidence, 0.1) / length
    lo, hi = np.clip(t[through] - half, 0.0, 1.0), np.clip(t[through] + half, 0.0, 1.0)
    order = np.argsort(lo)
    covered, end = 0.0, 0.0
    for start, stop in zip(lo[order], hi[order]):
        start = max(start, end)
        if stop > start:
            covered, end = covered + stop - start, stop
    return covered * length


@dataclass(frozen=True)
class PassageStep:
    """What a passage changes in this control step (None from ``Passage.update``: nothing)."""

    gap: Gap
    confirmed: bool
    """False: lining up to look through it; True: passing it."""
    target_en: EN
    target_distance_m: float | None
    """What the rule base's distance input should read (lining up: to the look-through point, so
    the rover slows there); None: leave it as it is."""
    speed_limit_mps: float
    ignore: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None
    """``ignore(points_en, ranges_m, axes_rad) -> mask`` of the echoes the rule base is not shown."""


class Passage:
    """Finds a narrow passage and drives the rover through it (see the module docstring)."""

    def __init__(self, params: PassageParams, memory_s: Callable[[], float], footprint_length_m: Callable[[], float],
                 footprint_width_m: Callable[[], float]) -> None:  # fmt: skip
        self.params = params
        self._memory_s, self._length_m, self._width_m = memory_s, footprint_length_m, footprint_width_m
        self.gap: Gap | None = None
        self.confirmed = False
        self._since_s = 0.0
        self._anchor_en: EN = (0.0, 0.0)
        self._beams = np.empty((0, 5))  # rows: time_s, origin east, origin north, axis_rad, reach_m
        self._rejected: list[tuple[float, EN]] = []  # (until when, centre)
        self.events: list[str] = []
        """What happened (candidate, confirmed, through, given up), for the shell to say; the caller clears it."""

    def reset(self) -> None:
        self.gap, self.confirmed = None, False

    def beam(self, time_s: float, origin_en: EN, axis_rad: float, range_m: float, max_m: float) -> None:
        """One rangefinder reading: its beam is free up to ``range_m`` (no echo: ``max_m``)."""
        reach = range_m if math.isfinite(range_m) and range_m >= 0.0 else max_m
        self._beams = np.vstack((self._beams[self._beams[:, 0] > time_s - self._memory_s()], (time_s, *origin_en, axis_rad, reach)))

    def update(self, time_s: float, position_en: EN, heading_rad: float, towards_en: EN,
               echoes: tuple[np.ndarray, np.ndarray, np.ndarray]) -> PassageStep | None:  # fmt: skip
        """A step: ``towards_en`` is where the rover steers otherwise (the planner's carrot),
        ``echoes`` the obstacle memory's (points, ranges, axes)."""
        p = self.params
        self._rejected = [(until, c) for until, c in self._rejected if until > time_s]
        self._beams = self._beams[self._beams[:, 0] > time_s - self._memory_s()]
        if not p.enabled:
            self.reset()
            return None
        width = self._width_m()
        needed = width + 2.0 * p.side_clearance_m
        found = find_gap(*echoes, position_en, self.gap.centre_en if self.gap else towards_en, width, p)
        if found is not None and any(math.dist(found.centre_en, c) <= p.match_m for _, c in self._rejected):
            found = None
        if self.gap is None:
            if found is None:
                return None
            self.gap, self.confirmed, self._since_s, self._anchor_en = found, False, time_s, found.centre_en
            self.events.append(f"Narrow passage ahead (up to {found.width_m:.2f} m): lining up")
        elif found is not None and math.dist(found.centre_en, self.gap.centre_en) <= p.match_m and not self.confirmed:
            # Nearer echoes, a sharper estimate of the same gap (its centre may not wander off: the
            # first estimate anchors it); once confirmed the gap stays put.
            if math.dist(found.centre_en, self._anchor_en) <= p.match_m:
                self.gap = found
        gap = self.gap
        if not self.confirmed and seen_open_m(gap, self._beams[:, 1:], p.beam_half_deg, p.depth_m) >= needed:
            self.confirmed = True
            self.events.append("Narrow passage: seen through, passing")
        along, lateral = (float(v[0]) for v in gap.coordinates(np.array([position_en])))
        if self.confirmed and along - self._length_m() / 2.0 >= p.exit_m:
            self.events.append("Narrow passage: through")
            self.reset()
            return None
        if time_s - self._since_s > p.timeout_s or (not self.confirmed and along > -self._length_m() / 2.0):
            self.events.append("Narrow passage: given up")
            self._rejected.append((time_s + p.reject_s, gap.centre_en))
            self.reset()
            return None
        ve, vn = gap.axis_en
        direction = math.atan2(vn, ve)
        if not self.confirmed:  # pursue the centre line up to the look-through point, and face the gap there
            stop = -p.verify_m
            ahead = min(along + p.lookahead_m, stop)
            target = (gap.centre_en[0] + ahead * ve, gap.centre_en[1] + ahead * vn)
            if along >= stop - p.side_clearance_m:
                target = (gap.centre_en[0], gap.centre_en[1])  # there: look at the gap itself
            distance = max(stop - along, 0.0)
            return PassageStep(gap, False, target, distance, p.speed_mps, None)
        target = (gap.centre_en[0] + (along + p.lookahead_m) * ve, gap.centre_en[1] + (along + p.lookahead_m) * vn)
        aligned = abs(math.remainder(heading_rad - direction, math.tau)) <= math.radians(p.align_heading_deg)
        far = -(along + self._length_m() / 2.0) > p.commit_m
        strip = width / 2.0 + p.side_clearance_m

        def ignore(points_en: np.ndarray, ranges_m: np.ndarray, axes_rad: np.ndarray) -> np.ndarray:
            if not (aligned or far) or not len(points_en):
                return np.zeros(len(points_en), dtype=bool)
            a, l = gap.coordinates(points_en)
            spread = spread_m(ranges_m, axes_rad, direction, p.beam_half_deg)
            return (np.abs(a) <= p.depth_m) & (np.abs(l - lateral) + spread >= strip)

        return PassageStep(gap, True, target, None, p.speed_mps, ignore)
