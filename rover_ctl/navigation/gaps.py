"""Narrow passages: an opening in a wall barely wider than the rover, seen through by a side
rangefinder as the rover drives along the wall, then lined up on and driven through.

Why. The rule bases read ranges by sector. In a gap 1.5 times the rover's width (0.6 m for a
0.4 m rover) its posts stand 0.1 m from each side: every side and diagonal reads "near" and the
rover sees a wall (the paper's "inability to identify passable narrow paths"). The rule base is
left unchanged; this module finds such a gap and, once it is sure, drives the rover through it
itself (turn in place, straight lines, pure pursuit on the centre line), then hands back.

**Seeing a gap: only a beam that passed it counts.** A rangefinder reports the nearest echo
anywhere in its cone (half-angle ``b`` = ``beam_half_deg``), so echoes say little about where an
opening's edges are (a 0.6 m gap seen from 2 m by a 15 degree beam shows no hole at all) but a
reading with no echo up to range R shows the whole cone free up to R. Approaching a wall head-on,
the front cone fits through a 0.6 m opening only within a few centimetres of its centre line;
the rule base instead turns and follows the wall, and then the side beam (perpendicular to the
motion, 0.26 m wide at 1 m) sweeps the wall: echo, echo, ..., free, free, ..., echo. That is the
classic sonar door detector. For one side sensor, readings ``j`` (echo at ``A``, range ``r_a``),
``j+1 .. k-1`` (free: no echo, or one more than ``depth_m`` beyond the wall) and ``k`` (echo at
``B``), with ``r_a, r_b <= wall_range_m`` and ``|r_a - r_b| <= depth_m``, bound an opening in the
wall whose line is fitted to all that beam's echoes off it (``wall_line``: each cone's incidence
counted, within ``WALL_MAX_RMS_M``). Each free beam with origin ``o`` and unit
axis ``d`` crosses the line at distance ``x``; its cone covers ``x tan(b) / |d . n|`` either side
of the crossing (``n`` the line's normal). The longest contiguous union of these intervals is
**free for sure**: its length ``w_lo`` is a lower bound of the opening and its middle the
estimate of the gap's centre. Its whole width is estimated as ``|AB| + s_a + s_b`` with
``s = r tan(b) / |d . n|`` (each edge may lie its spread outside its echo). The gap is passable when
``w_lo >= W + 2 c`` (``W`` the footprint's width, ``c`` = ``side_clearance_m``) and it is narrow
(``<= max_width_m``: wider ones the rule base passes unaided). With the emulator's cone the
lower bound of a 0.6 m opening in a 0.3 m thick wall is at most 0.52 m (0.47 m measured): the
cone is free only while it is free through the wall's whole depth.

**The frame: dead reckoning, not the pose filter.** The margin in a 1.5x gap is 0.1 m a side.
The GPS-fused pose moves against the ground by 0.1-0.2 m (median, p95 0.4 m) over 5 s as fixes
come in (measured in the emulator), so a gap placed in that frame would not be where the rover
aims a few seconds later. Everything here lives in a frame of its own integrated from the wheel
distances and the gyro (``rover_ctl.navigation.odometry``: 1 cm per metre of slip in the
emulator), where the beams that found the gap and the rover that drives through it agree to a
few centimetres over the few metres involved. The fused pose is used only to know where the
mission's goal is.

**Going through** (``Passage``). ``P0`` is the point on the gap's centre line ``standoff_m``
before it.

0. *inspect*: when a side beam stops echoing off a wall (``WALL_MIN_ECHOES`` over at least
   ``WALL_MIN_SPAN_M`` of travel) and the goal lies beyond that wall, the rover drives on straight
   along it at ``speed_mps`` so that the beam sweeps the opening cleanly. If the sweep proves too
   little but the opening may be wide enough, it sweeps it once more backwards (both passes' free
   cones count); nothing within ``max_width_m`` (plus ``wall_range_m`` backwards), or something
   in the way (the search's test, below): hand back;
0'. *search*: the rule base turns one way at a wall across its way (east, in the benchmark's
   worlds), so an opening on the other side, or one passed while it turned (its side beam faces
   the wall only once it is along it), is never swept. When a side beam has followed one flat wall
   that the goal lies beyond for ``search_m`` of travel with no narrow opening proved, and the
   straight line to the goal meets the wall's line at most ``search_m`` ahead (farther, the wall
   runs along the way to the goal, as a cul-de-sac's side does going round it), and the front
   diagonal on the wall's side still echoes within ``wall_range_m`` times sqrt(2) (free, the wall
   opens or ends ahead, which the rule base takes unaided), the rover
   turns round and drives back along it, on a line parallel to the wall's fitted line at the
   distance it kept, at ``search_speed_mps``, the other side beam sweeping, to ``search_m`` beyond where
   the wall's echoes began. A gap proved on the way is lined up on (an opening that may be wide
   enough gets the inspection's second, backward sweep once); the search ends at its far end, when
   the side beam has been free for more than ``max_width_m`` (the wall's end or a wide opening),
   when the front beam echoes within ``2 stop_m``, a front diagonal within ``CORNER_NEAR_M`` or a
   side or the back within ``SIDE_NEAR_M`` (as the inspection also does), or at ``timeout_s``,
   and hands back. A wall is
   searched once per ``reject_s``. A place where the wall merely stopped echoing and an inspection
   found nothing does not hide a gap the search proves there later;
1. *line up*: turn in place to face ``P0`` (or away from it and reverse, whichever turns less),
   drive to it, turn in place to face the gap's axis and wait until the gyro says the turn has
   stopped (the rover coasts on several degrees after a turn in place: ``SETTLED_DPS``); turned
   past the tolerance, it turns back. Why not trust this line-up: dead reckoning after the turns
   plus the sweep's error put the rover 0.12-0.13 m off the centre line (more than the 0.1 m
   margin) about once in 13 lockstep SITL runs, and it then drove into the post and pushed on for
   20 s (narrow_gap world 8);
2. *look*: for ``look_s`` the front diagonals are read. *Square*: a flat wall seen by the
   front-left and front-right cones (axis 45 degrees off the nose, half-angle ``b``, from the nose's
   corners ``w`` = half the footprint's width either side, the nose ``x`` from the wall) gives
   ``ln(r_left / r_right) = 2 t (tan(45 - b) + w / x)`` for a heading ``t`` counter-clockwise
   of the wall's normal; ``|t|`` beyond ``SQUARE_MAX_DEG``: given up (not square); beyond
   ``heading_tol_deg``: the gap's axis is turned about its centre onto the normal so measured
   (the sweep's wall line was 4-6 degrees off in some emulator worlds) and the rover turns to it.
   *Scan* (``scan_max_deg``; 0: none): the rover turns in place at ``scan_rate_dps``, left until
   the front beam, having been free (no echo to the wall's line plus ``depth_m``), echoes again,
   then right likewise. From the line-up point the front cone is free only while it lies wholly
   inside the opening, so its free headings are an interval ``[psi_r, psi_l]`` about the bearing
   of the opening's centre: to first order, with ``R`` the rover's centre to where the edge rays
   clip the opening's sides (the edge echoes' mean range ``d`` plus half the footprint's length:
   the rover turns about its centre), the centre lies ``y = R tan((psi_l + psi_r) / 2)`` left of
   the rover and the opening is ``R (psi_l - psi_r) + 2 d tan(b)`` wide (0.58-0.62 m measured of
   0.6 m, in the kinematic world and in the emulator). Each edge is taken while turning
   outwards, so a lag between a reading and its heading widens the interval but does not move
   its middle. A width under the footprint plus ``2 side_clearance_m``, or a centre more than
   ``match_m`` from the sweep's: given up. Otherwise the gap's centre is moved onto the measured
   one, independent of the dead reckoning since the sweep; the rover is within ``scan_tol_m``
   of its line: square up and look again; farther: reverse ``RETREAT_M`` behind the line-up point
   on the measured line, drive forwards to it (the lateral error is closed while moving: a point
   within ``NEAR_M`` is reached along the heading only) and scan again, at most ``scan_tries``
   scans. Then the front beam must see through (every front reading while looking) or the gap
   is given up;
3. *pass*: pure pursuit on the centre line (target ``lookahead_m`` ahead of the rover's
   projection) at ``speed_mps``, at half of it from ``SLOW_ZONE_M`` before the wall's line until
   the nose is ``GUARD_ZONE_M`` past it; stopping and giving up if the front beam echoes inside
   ``stop_m`` (something in the gap); done when the rover's back is ``exit_m`` beyond the line.
   *Guard*: with the nose within ``GUARD_ZONE_M`` of the line, a front diagonal's mean of its
   last ``GUARD_READINGS`` readings (each counted as at least ``guard_near_m``: the emulator
   reports anything nearer as 0.2 m) at ``guard_near_m`` while the other's is ``guard_skew_m``
   farther: the near front corner is about to meet the post's face (about 0.1 m off the centre
   line, the other diagonal seeing into the opening: 0.27-0.31 m at 0.12 m off in the emulator);
   or the wheels driving for ``stall_s`` with the rover less than ``stall_m`` farther along: it
   is pushing against something (the emulator puts a colliding rover back and stops its wheels).
   Either: stop, reverse straight (*back*: steering would swing the nose into the post) to
   ``standoff_m`` before the line, give the gap up and *leave*.

A passage not done within ``timeout_s`` is given up; a gap given up or passed is not taken again
for ``reject_s`` (found again within ``match_m`` of it). Giving up hands the rover back to the
rule base, which goes round as it would have; given up while lined up or looking (*leave*), the
rover first turns in place back along the wall as it was going: handed back square to the
opening, the rule base saw a way ahead and nosed into the gap's edge. While lining up and
passing, the rule base does not drive: the wall is in every sector, and the manoeuvre's moves
are short, slow and checked.

Pure: no clock, no I/O; times are passed in.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from rover_ctl.config import PassageParams
from rover_ctl.navigation.odometry import Odometry
from rover_ctl.navigation.sensors import BACK, FRONT, FRONT_LEFT, FRONT_RIGHT, LEFT, RIGHT
from rover_ctl.navigation.tracks import Track

EN = tuple[float, float]

SIDE_BODY_RAD = {RIGHT: -math.pi / 2.0, LEFT: math.pi / 2.0}
"""The side rangefinders: body angle, counter-clockwise."""
WALL_MIN_ECHOES = 5
"""A side beam's echoes in a row that make a wall worth looking along (a quarter of a second)."""
WALL_MIN_SPAN_M = 1.0
"""A side beam's echoes off one surface over at least this much of the rover's travel (m) make a
wall worth looking along (a drum is passed in less). In-process runner, seeds 1-100 with the map
on, 0.6 / 0.8 / 1.0 m: dense_clutter 84.7 / 80.2 / 77.9 s (the map alone 77.4 s), scattered
71.2 / 70.1 / 69.2 s (67.8 s), each inspection along a drum's face costing seconds at
``speed_mps``; narrow_gap 98 / 97 / 97 driven through the opening (seed 66 lost), walls,
cul_de_sac and the three moving scenarios the same within a seed."""
WALL_MAX_RMS_M = 0.08
"""A wall's echoes farther than this (RMS, m) from its fitted line: not one flat wall."""
SQUARE_MAX_DEG = 10.0
"""Looking: the front diagonals say the rover's heading is off the wall's normal by this much
(deg) or more: the wall is not flat there, or something stands before it; the gap is given up.
Less, and more than ``heading_tol_deg``: the gap's axis is turned onto the normal measured (the
wall line's fit from the sweep was off by 4-6 degrees in narrow_gap worlds 9, 24 and 36)."""
SQUARINGS = 3
"""Looking: the gap's axis is turned onto the measured normal at most this many times."""
DIAGONALS = (FRONT_LEFT, FRONT_RIGHT)
RETREAT_M = 0.4
"""A scan found the rover off the opening's centre line: it reverses to this far (m) behind the
line-up point on the measured line and drives forwards to it again, closing the lateral error
while moving (a lateral error under ``NEAR_M`` cannot be closed at the point itself), then scans
again."""
GUARD_ZONE_M = 0.12
"""Passing: the diagonal guard watches while the nose is within this (m) of the wall's line. Off
the centre line by more than the margin, the front corner meets the post's face as the nose
reaches the line; from 0.2 m out a heading 4 degrees off the wall's normal, centred, made the
diagonals differ as much (narrow_gap world 14, in-process)."""
SLOW_ZONE_M = 0.35
"""Passing: from this far (m, the nose to the wall's line) until the nose is ``GUARD_ZONE_M``
past the line, the rover goes at half ``speed_mps``, so that it stops within a few centimetres
when the guard trips."""
GUARD_READINGS = 3
"""Passing: the guard compares the means of each diagonal's last this many readings (0.15 s at
20 Hz): one reading's noise (0.02 m in the emulator) made a centred rover's diagonals differ by
0.06 m."""
HEADING_GAIN_PER_S = 2.5
"""Yaw rate commanded per radian of heading error (rad/s per rad)."""
DRIVE_MAX_ERROR_RAD = math.radians(15.0)
"""Driving to a point: a heading error beyond this turns in place first."""
NEAR_M = 0.1
"""Driving to a point: within this the heading is held and only the distance along it is closed."""
SETTLED_DPS = 2.0
"""Lined up: the heading is taken as settled (the rover coasts several degrees after a turn in
place is stopped: 5.5 degrees past the gap's axis measured in the emulator) once the gyro reads
less than this (deg/s)."""
CORNER_NEAR_M = 0.3
"""Inspecting or searching: a front diagonal echoing this near (m) hands back to the rule base.
The diagonal looks 45 degrees off the heading from a front corner; the near edge of its 15 degree
cone at 0.3 m is 0.24 m ahead and 0.18 m out from the corner, where a turn or a drum's curve meets
the body. Without it the inspection drove on along the line it chose while a drum beside its nose
read 0.2 m (the emulator's least) and pushed against it for seconds (in-process runner,
dense_clutter seeds 33 and 40 with ``passage.enabled``); 0.25 and 0.35 did the same there."""
SIDE_NEAR_M = 0.45
"""Inspecting or searching: a side or the back rangefinder echoing this near (m) hands back to the
rule base and the guards around it, which the passage bypasses while it drives. A followed wall
reads 0.72 m or more from the side beams then (in-process runner, narrow_gap seeds 1-20); what
comes nearer is moving at the rover: a drum crossing at 0.5 m/s, taken for a wall's end by the side
beam, caught up with the slow inspection from the side or from behind (moving seeds 30, 35, 91, 94
with ``passage.enabled``: 4 of 100 struck; none of 300 with this)."""
MOVER_NEAR_M = 0.72
"""Inspecting or searching: a moving obstacle track (``rover_ctl.navigation.tracks``) this near
(m, the rover's centre to the track's position) hands back to the rule base and the yielder, the
evader and the side guards, which the passage bypasses while it drives. Drums crossing a leg came
within 0.51-0.58 m of the slowly inspecting rover from where no side or back beam looked (their
echoes had made the side beam's "wall" that started the inspection) and walked into it: in-process
runner, crossing seeds 1-300 with ``passage.enabled``, 10 failed, 4 of them (226, 258, 282, 287)
not failing without it; with this 6, each failing without the passage too. A followed wall's
echoes make tracks as well, sliding along it as the rover turns: they came within 0.70 m of a
search and 0.81 m of an inspection (narrow_gap seeds 1-100, the map on); 0.8 lost seed 48's
passage there, 0.65 let crossing seed 247's inspection start at 0.66 m (all with
``WALL_MIN_SPAN_M`` at 0.6; seeds 258 and 287 still strike without this at 1.0)."""
FRESH_S = 0.5
"""A gap proved, or a wall seen followed, this recently (s) is acted on; older, it is stale."""
SEARCH_CHECK_S = 0.5
"""While the rule base follows a wall, whether it has followed it ``search_m`` is checked this
often (s): fitting the wall's line costs a millisecond or two."""
SAME_WALL_COS = 0.9
"""Two walls' normals this close in direction (cosine), one's line within ``wall_range_m`` of the
other's where it was seen: the same wall (searched once per ``reject_s``; two fits of one wall
5 m apart differed by 0.42 m and 6 degrees in the emulator)."""


def _wrap(angle: float) -> float:
    return math.remainder(angle, math.tau)


@dataclass(frozen=True)
class Beam:
    """One reading in the odometry frame: origin, axis, range (inf: no echo)."""

    time_s: float
    origin_en: EN
    axis_rad: float
    range_m: float

    def point(self) -> EN:
        return (
            self.origin_en[0] + self.range_m * math.cos(self.axis_rad),
            self.origin_en[1] + self.range_m * math.sin(self.axis_rad),
        )


@dataclass(frozen=True)
class Gap:
    """An opening: centre, unit axis (through it, away from the side it was seen from), the
    width seen free (lower bound) and the most it may be (upper bound)."""

    centre_en: EN
    axis_en: EN
    width_low_m: float
    width_high_m: float

    def coordinates(self, point_en: EN) -> tuple[float, float]:
        """(along the axis from the gap's line, left of the centre line)."""
        de, dn = point_en[0] - self.centre_en[0], point_en[1] - self.centre_en[1]
        ue, un = self.axis_en
        return de * ue + dn * un, -de * un + dn * ue


def wall_line(wall: list[Beam], beam_half_deg: float) -> tuple[EN, EN, EN, float]:
    """A flat wall's line from a side beam's echoes off it: a point on it, the unit vector along
    it (the way the sweep went), its unit normal away from the sensors and the RMS of the echoes'
    distances to it.

    A cone at incidence ``a`` (its axis to the wall's normal) echoes from the ray nearest the
    normal, so the wall lies ``r cos(max(|a| - b, 0))`` from the sensor along the normal. The
    normal is the direction that makes these distances agree best (least variance of
    ``r_i cos(...) + o_i . n`` over a grid of 0.25 degree steps within 20 degrees of the
    beams' mean axis); placing the echoes on the beams' axes instead tilts the line by the rover's
    yaw as it drove (5-7 degrees measured)."""
    origins = np.array([beam.origin_en for beam in wall])
    ranges = np.array([beam.range_m for beam in wall])
    axes = np.array([beam.axis_rad for beam in wall])
    mean_axis = math.atan2(float(np.sin(axes).mean()), float(np.cos(axes).mean()))
    half = math.radians(beam_half_deg)
    best = (math.inf, mean_axis, 0.0)
    for phi in mean_axis + np.radians(np.arange(-20.0, 20.001, 0.25)):
        off = np.abs(np.remainder(axes - phi + math.pi, math.tau) - math.pi)
        rho = ranges * np.cos(np.maximum(off - half, 0.0)) + origins @ np.array([math.cos(phi), math.sin(phi)])
        cost = float(rho.var())
        if cost < best[0]:
            best = (cost, float(phi), float(rho.mean()))
    cost, phi, rho = best
    ne, nn = math.cos(phi), math.sin(phi)
    te, tn = -nn, ne
    if (origins[-1][0] - origins[0][0]) * te + (origins[-1][1] - origins[0][1]) * tn < 0.0:
        te, tn = -te, -tn
    last = origins[-1]
    offset = rho - (last[0] * ne + last[1] * nn)  # the foot of the normal from the last sensor
    return (
        (float(last[0] + offset * ne), float(last[1] + offset * nn)),
        (te, tn),
        (ne, nn),
        math.sqrt(cost),
    )


def gap_from_sweep(wall: list[Beam], free: list[Beam], before: Beam, after: Beam, beam_half_deg: float, depth_m: float,
                   max_rms_m: float) -> Gap | None:  # fmt: skip
    """The opening swept by ``free`` beams between the echoes ``before`` and ``after``, in the
    wall whose echoes are ``wall`` (both sides of it), or None (see the module docstring)."""
    if not wall or not free:
        return None
    a, b = before, after
    base, (te, tn), (ne, nn), rms = wall_line(wall, beam_half_deg)
    if rms > max_rms_m:
        return None  # not one flat wall: no line to place an opening on
    tan_b = math.tan(math.radians(beam_half_deg))
    intervals = []
    for beam in free:
        de, dn = math.cos(beam.axis_rad), math.sin(beam.axis_rad)
        incidence = de * ne + dn * nn
        if incidence < 0.2:
            return None  # a beam not looking at the wall: not a sweep of it
        x = ((base[0] - beam.origin_en[0]) * ne + (base[1] - beam.origin_en[1]) * nn) / incidence
        if x <= 0.0 or beam.range_m <= x + depth_m:
            return None  # an echo at the wall (or short of it) inside the run: not free
        t = (beam.origin_en[0] + x * de - base[0]) * te + (beam.origin_en[1] + x * dn - base[1]) * tn
        half = x * tan_b / incidence
        intervals.append((t - half, t + half))
    intervals.sort()
    best, (lo, hi) = (0.0, 0.0, 0.0), intervals[0]
    for start, stop in [*intervals[1:], (math.inf, math.inf)]:
        if start > hi:
            if hi - lo > best[0]:
                best = (hi - lo, lo, hi)
            lo, hi = start, stop
        else:
            hi = max(hi, stop)
    width_low, lo, hi = best
    edges = []
    for beam in (a, b):  # each edge may lie its spread beyond its echo
        t = (beam.point()[0] - base[0]) * te + (beam.point()[1] - base[1]) * tn
        spread = beam.range_m * tan_b / max(math.cos(beam.axis_rad) * ne + math.sin(beam.axis_rad) * nn, 0.2)
        edges.append(t - spread if beam is a else t + spread)
    middle = (lo + hi) / 2.0
    centre = (base[0] + middle * te, base[1] + middle * tn)
    return Gap(centre, (ne, nn), width_low, max(edges[1] - edges[0], width_low))


@dataclass
class _Scan:
    """A scan of the opening with the front beam: turning one way (+1 left, -1 right) until the
    beam, free, echoes again; the heading (relative to the gap's axis) and range where it did,
    for each way."""

    direction: int = 1
    last_free_rad: float | None = None
    edges: dict[int, tuple[float, float]] = field(default_factory=dict)
    turns: int = 0
    any_free: bool = False


@dataclass(frozen=True)
class Drive:
    """What the passage commands this step: forward speed (m/s, negative: reverse) and yaw rate
    (rad/s, counter-clockwise)."""

    speed_mps: float
    yaw_rate_radps: float
    state: str


class Passage:
    """Finds a narrow gap with the side rangefinders and drives through it (module docstring)."""

    def __init__(self, params: PassageParams, footprint_length_m, footprint_width_m, odometry: Odometry | None = None) -> None:
        """The footprint: functions giving the value in force; ``odometry``: the dead reckoning
        the caller feeds (a new one when None)."""
        self.params = params
        self._length_m, self._width_m = footprint_length_m, footprint_width_m
        self.odometry = odometry if odometry is not None else Odometry()
        self._sweeps: dict[int, deque[Beam]] = {o: deque() for o in SIDE_BODY_RAD}
        self._front: list[float] = []
        self._diagonal_m: dict[int, float] = {}
        self._flank_m: dict[int, float] = {}  # the sides' and the back's latest readings
        self._mover_m = math.inf  # the nearest moving track, as of this step
        self._diagonals: dict[int, deque[float]] = {o: deque(maxlen=GUARD_READINGS) for o in DIAGONALS}
        self._look_diagonals: dict[int, list[float]] = {o: [] for o in DIAGONALS}  # looking: every reading since it began
        self._rejected: list[tuple[float, EN, bool]] = []  # (until when, centre, a gap proved there)
        self._searched: list[tuple[float, EN, EN]] = []  # walls searched: (until when, a point on it, its normal)
        self._follow: tuple[float, EN, EN, EN, float] | None = None  # (when, point, along, normal, where its echoes began along it)
        self._follow_checked_s = -math.inf
        self._beside: dict[int, tuple[float, tuple[EN, EN, EN] | None]] = {o: (math.nan, None) for o in SIDE_BODY_RAD}  # wall_beside's cache
        self._search: tuple[EN, EN, float, float] | None = None  # searching: (point, normal, offset, end along the wall)
        self._search_free_from: EN | None = None  # searching: where the side beam last stopped echoing
        self._gap_proved = False  # self.gap was proved free (not a place the wall stopped echoing)
        self.found: Gap | None = None
        """The latest passable gap seen (kept until used, superseded or older than ``history_s``)."""
        self._found_s = -math.inf
        self._candidate: tuple[float, Gap, EN] | None = None  # (when, where the wall stopped echoing, along it)
        self._inspect_from: EN = (0.0, 0.0)
        self._inspect_along: EN = (1.0, 0.0)
        self._reversing = False  # inspecting: the second pass, backwards
        self._seen_free: list[Beam] = []  # inspecting: the free beams of the first pass
        self.gap: Gap | None = None
        """The gap being passed."""
        self.state = ""
        self._since_s = 0.0
        self._look_from_s = 0.0
        self._scan: _Scan | None = None  # scanning: where the front beam's free headings ended
        self._scan_readings: list[tuple[float, float]] = []  # scanning: (heading, front range) as they came
        self._scan_ok = False  # the last scan found the rover on the opening's centre line
        self._retreat = False  # the last scan found it off the line: line up again from RETREAT_M farther back
        self._squarings = 0  # turns of the gap's axis onto the wall's normal the diagonals measured
        self._look_front: list[float] = []  # looking: the front readings since it began
        self._scans = 0  # scans of this gap
        self._progress: tuple[float, float] | None = None  # passing: (since when, along the axis then) for the stall check
        self.events: list[str] = []
        """What happened (found, passing, through, given up), for the shell to say; the caller clears it."""

    def reset(self) -> None:
        """Stop any passage (mode change, feature off); what was seen is forgotten."""
        self.gap, self.found, self.state, self._candidate = None, None, "", None
        self._follow, self._search = None, None
        for sweep in self._sweeps.values():
            sweep.clear()
        self._beside = {o: (math.nan, None) for o in SIDE_BODY_RAD}

    # ---- inputs --------------------------------------------------------------------------------

    def on_range(self, time_s: float, orientation: int, range_m: float) -> None:
        """A new rangefinder reading (inf: no echo), placed with the odometry's pose now."""
        p, odo = self.params, self.odometry
        if orientation == FRONT:
            self._front.append(range_m)
            if self.state == "look":
                self._look_front.append(range_m)
            if self.state == "scan":
                self._scan_readings.append((odo.heading_rad, range_m))
            return
        if orientation in DIAGONALS:
            self._diagonal_m[orientation] = range_m
            self._diagonals[orientation].append(range_m)
            if self.state == "look":
                self._look_diagonals[orientation].append(range_m)
            return
        if orientation == BACK or orientation in SIDE_BODY_RAD:
            self._flank_m[orientation] = range_m
        if orientation not in SIDE_BODY_RAD:
            return
        left = math.copysign(self._width_m() / 2.0, SIDE_BODY_RAD[orientation])
        c, s = math.cos(odo.heading_rad), math.sin(odo.heading_rad)
        beam = Beam(time_s, (odo.east_m - left * s, odo.north_m + left * c), odo.heading_rad + SIDE_BODY_RAD[orientation],
                    range_m if math.isfinite(range_m) and range_m >= 0.0 else math.inf)  # fmt: skip
        sweep = self._sweeps[orientation]
        while sweep and sweep[0].time_s < time_s - p.history_s:
            sweep.popleft()
        sweep.append(beam)
        if self.state == "" and len(sweep) >= WALL_MIN_ECHOES + 1 and sweep[-2].range_m <= p.wall_range_m \
                and beam.range_m > sweep[-2].range_m + p.depth_m:  # fmt: skip
            wall = self._wall_before(list(sweep)[:-1])
            if len(wall) >= WALL_MIN_ECHOES and math.dist(wall[0].origin_en, wall[-1].origin_en) >= WALL_MIN_SPAN_M:
                _, along, normal, rms = wall_line(wall, p.beam_half_deg)
                if rms <= WALL_MAX_RMS_M:
                    self._candidate = (
                        time_s,
                        Gap(wall[-1].point(), normal, 0.0, 0.0),
                        along,
                    )
        if self.state == "" and p.search_m > 0.0 and beam.range_m <= p.wall_range_m and time_s - self._follow_checked_s >= SEARCH_CHECK_S:
            self._check_follow(time_s, list(sweep))
        if math.isfinite(beam.range_m) and len(sweep) >= 3 and sweep[-2].range_m > beam.range_m + p.depth_m:
            self._look_back(time_s, sweep)

    def _check_follow(self, time_s: float, beams: list[Beam]) -> None:
        """Has a side beam followed one flat wall for ``search_m``? Then it may be searched back."""
        p = self.params
        wall = self._wall_before(beams)
        if len(wall) < WALL_MIN_ECHOES or math.dist(wall[0].origin_en, wall[-1].origin_en) < p.search_m:
            return
        self._follow_checked_s = time_s
        base, along, normal, rms = wall_line(wall, p.beam_half_deg)
        if rms > WALL_MAX_RMS_M:
            return
        began = (wall[0].origin_en[0] - base[0]) * along[0] + (wall[0].origin_en[1] - base[1]) * along[1]
        self._follow = (time_s, base, along, normal, began)

    def _look_back(self, time_s: float, sweep: deque[Beam]) -> None:
        """The newest beam echoes after free ones: back over them to the wall's run before."""
        p = self.params
        beams = list(sweep)
        last = beams[-1]
        j = len(beams) - 2
        while j >= 0 and beams[j].range_m > last.range_m + p.depth_m:
            j -= 1
        free = beams[j + 1 : -1]
        if j < 0 or len(free) < p.min_free:
            return
        if len(self._wall_before(beams[: j + 1])) < WALL_MIN_ECHOES or last.range_m > p.wall_range_m:
            return
        # The wall's line from all its echoes in the history, both sides of the opening: the
        # longer the baseline, the better its direction (the gap's axis).
        wall = [b for b in beams if b.range_m <= p.wall_range_m and abs(b.range_m - last.range_m) <= p.depth_m]
        if self.state == "inspect":
            free = self._seen_free + free  # the first pass's free cones count on the way back
        gap = gap_from_sweep(wall, free, beams[j], last, p.beam_half_deg, p.depth_m, WALL_MAX_RMS_M)
        if gap is None or gap.width_high_m > p.max_width_m:
            return
        if gap.width_low_m < self._needed_m():
            if self.state in ("inspect", "search") and not self._reversing and gap.width_high_m >= self._needed_m():
                if self.state == "search":  # along the way the search goes, backwards over it
                    self.state, self._inspect_along = "inspect", self._search_direction()
                    self._since_s = time_s
                self._seen_free, self._reversing = (
                    free,
                    True,
                )  # it may be wide enough: sweep it again, backwards
                self._inspect_from = self.odometry.position_en
            return
        if any(math.dist(gap.centre_en, c) <= p.match_m for until, c, proved in self._rejected if proved and until > time_s):
            return  # (a place inspected in vain does not hide a gap proved later: a second sweep saw more)
        self.found, self._found_s = gap, time_s
        self.events.append(f"Narrow passage seen: {gap.width_low_m:.2f} m free (at most {gap.width_high_m:.2f} m)")

    def _wall_before(self, beams: list[Beam]) -> list[Beam]:
        """The run of echoes off one wall that ends ``beams`` (each within ``depth_m`` of the
        last's range, all within ``wall_range_m``)."""
        p = self.params
        if not beams or beams[-1].range_m > p.wall_range_m:
            return []
        i = len(beams) - 1
        while i > 0 and beams[i - 1].range_m <= p.wall_range_m and abs(beams[i - 1].range_m - beams[-1].range_m) <= p.depth_m:
            i -= 1
        return beams[i:]

    def _needed_m(self) -> float:
        return self._width_m() + 2.0 * self.params.side_clearance_m

    # ---- the step ------------------------------------------------------------------------------

    def step(self, time_s: float, pose_en: EN, pose_heading_rad: float, goal_en: EN, tracks: Sequence[Track] = (),
             mapped: Callable[[float, float, float], bool] | None = None) -> Drive | None:  # fmt: skip
        """The command of this step, or None (the rule base drives). ``pose_*`` is the fused pose
        and ``goal_en`` the goal in its frame: they say only which side of the wall the goal is.
        ``tracks``: the moving obstacle tracks, in that frame too. ``mapped(east_m, north_m,
        distance_m)``: whether the persistent-obstacle map holds an obstacle within ``distance_m``
        of a point of the odometry's frame (``ObstacleMap.near_persistent``; None: no map in that
        frame; ``wall_mapped_m``)."""
        p = self.params
        self._mover_m = min((math.hypot(t.east_m - pose_en[0], t.north_m - pose_en[1]) for t in tracks), default=math.inf)
        front, self._front = self._front, []
        self._rejected = [r for r in self._rejected if r[0] > time_s]
        self._searched = [r for r in self._searched if r[0] > time_s]
        if self.state == "":
            follow, self._follow = self._follow, None
            if follow is not None and time_s - follow[0] <= FRESH_S and not self._was_searched(follow[1], follow[3]) \
                    and self.gap_leads_to(Gap(follow[1], follow[3], 0.0, 0.0), pose_en, pose_heading_rad, goal_en) \
                    and self._goal_line_ahead_m(follow[1:4], pose_en, pose_heading_rad, goal_en) <= p.search_m \
                    and self._wall_ahead(follow[3]):  # fmt: skip
                self._start_search(time_s, follow)
                return self._searching(time_s, front, pose_en, pose_heading_rad, goal_en)
            candidate, self._candidate = self._candidate, None
            if candidate is None or time_s - candidate[0] > FRESH_S or not self.gap_leads_to(candidate[1], pose_en, pose_heading_rad, goal_en):
                return None
            if any(math.dist(candidate[1].centre_en, c) <= p.match_m for _, c, _ in self._rejected):
                return None
            if p.wall_mapped_m > 0.0 and mapped is not None and not mapped(*candidate[1].centre_en, p.wall_mapped_m):
                return None  # a wall the map does not hold: maybe a walker passed at the side
            self.state, self._since_s, self.found, self._gap_proved = "inspect", time_s, None, False
            self._inspect_from, self._inspect_along = (
                self.odometry.position_en,
                candidate[2],
            )
            self._reversing, self._seen_free = False, []
            self.gap = candidate[1]
        if self.state == "inspect":
            return self._inspect(time_s, front, pose_en, pose_heading_rad, goal_en)
        if self.state == "search":
            return self._searching(time_s, front, pose_en, pose_heading_rad, goal_en)
        return self._manoeuvre(time_s, front)

    def _line_up(self, time_s: float, gap: Gap, along: EN) -> None:
        self.gap, self.state, self._since_s, self._gap_proved = gap, "line_up", time_s, True
        self._scan_ok, self._retreat, self._scans, self._scan, self._squarings = False, False, 0, None, 0
        self._inspect_along, self._search = along, None
        self.events.append("Narrow passage: lining up")

    def _was_searched(self, point_en: EN, normal_en: EN) -> bool:
        p = self.params
        for _, base, normal in self._searched:
            if normal[0] * normal_en[0] + normal[1] * normal_en[1] >= SAME_WALL_COS \
                    and abs((point_en[0] - base[0]) * normal[0] + (point_en[1] - base[1]) * normal[1]) <= p.wall_range_m:  # fmt: skip
                return True
        return False

    def _wall_ahead(self, normal_en: EN) -> bool:
        """The diagonal on the wall's side echoes within ``wall_range_m`` times sqrt(2) (where a
        wall followed at ``wall_range_m`` crosses it): the wall goes on ahead. Free, the rover is
        at an opening or the wall's end, which the rule base takes unaided. No such rangefinder:
        the wall is taken to go on."""
        range_m = self._diagonal_m.get(FRONT_LEFT if LEFT in self._wall_sides(normal_en) else FRONT_RIGHT)
        return range_m is None or range_m <= self.params.wall_range_m * math.sqrt(2.0)

    def _wall_sides(self, normal_en: EN) -> list[int]:
        """The side rangefinders facing the wall of normal ``normal_en`` (towards the wall), as
        the rover is headed now."""
        heading, wall_rad = self.odometry.heading_rad, math.atan2(normal_en[1], normal_en[0])
        return [o for o, body in SIDE_BODY_RAD.items() if math.cos(heading + body - wall_rad) > 0.0]

    def _start_search(self, time_s: float, follow: tuple[float, EN, EN, EN, float]) -> None:
        """Followed a wall across the way ``search_m`` with nothing found: search it back the other
        way, on a line parallel to it at the distance the rover kept, to ``search_m`` beyond
        where its echoes began."""
        p, odo = self.params, self.odometry
        _, base, along, normal, began = follow
        offset = (odo.east_m - base[0]) * normal[0] + (odo.north_m - base[1]) * normal[1]
        # The line's frame: t along ``along``; the search goes towards -along.
        self._search = (base, normal, offset, began - p.search_m)
        self._searched.append((time_s + p.reject_s, base, normal))
        self.state, self._since_s, self._reversing, self._seen_free, self.gap, self.found = "search", time_s, False, [], None, None
        self._inspect_along = (-along[0], -along[1])
        self._search_free_from = None
        for sweep in self._sweeps.values():
            sweep.clear()
        self.events.append("Narrow passage: searching the wall back the other way")

    def _search_direction(self) -> EN:
        assert self._search is not None
        base, normal, _, _ = self._search
        along = (-normal[1], normal[0])
        if along[0] * self._inspect_along[0] + along[1] * self._inspect_along[1] < 0.0:
            along = (-along[0], -along[1])
        return along

    def _searching(self, time_s: float, front: list[float], pose_en: EN, pose_heading_rad: float, goal_en: EN) -> Drive | None:
        """Along the wall at the offset it was followed, the side beam sweeping it; a gap proved
        is lined up on; the end of the search, the wall's end (the side beam free for more than
        ``max_width_m``: the rule base passes wider openings unaided), something ahead or the
        timeout hand back."""
        p, odo = self.params, self.odometry
        assert self._search is not None
        if self.found is not None:
            gap, self.found = self.found, None
            if self.gap_leads_to(gap, pose_en, pose_heading_rad, goal_en):
                self._line_up(time_s, gap, self._search_direction())
                return self._manoeuvre(time_s, front)
        base, normal, offset, end = self._search
        direction = self._search_direction()
        de, dn = odo.east_m - base[0], odo.north_m - base[1]
        t_abs = de * -direction[0] + dn * -direction[1]  # along the wall the way it was followed
        side = [self._sweeps[o][-1] for o in self._wall_sides(normal) if self._sweeps[o]]
        if any(math.isfinite(b.range_m) and b.range_m <= p.wall_range_m for b in side):
            self._search_free_from = None
        elif self._search_free_from is None:
            self._search_free_from = odo.position_en
        wall_ended = self._search_free_from is not None and math.dist(odo.position_en, self._search_free_from) > p.max_width_m
        if t_abs <= end or wall_ended or self._blocked(front) or time_s - self._since_s > p.timeout_s:
            self._search = None
            self._end(time_s)
            return None
        # pure pursuit on the line ``offset`` from the wall
        px, py = base[0] + offset * normal[0], base[1] + offset * normal[1]
        here = (odo.east_m - px) * direction[0] + (odo.north_m - py) * direction[1]
        target = (px + (here + p.lookahead_m) * direction[0], py + (here + p.lookahead_m) * direction[1])
        error = _wrap(math.atan2(target[1] - odo.north_m, target[0] - odo.east_m) - odo.heading_rad)
        if abs(error) > DRIVE_MAX_ERROR_RAD:
            return self._turn(error)
        return Drive(p.search_speed_mps * math.cos(error), self._rate(error), self.state)

    def _inspect(
        self,
        time_s: float,
        front: list[float],
        pose_en: EN,
        pose_heading_rad: float,
        goal_en: EN,
    ) -> Drive | None:
        """A side beam stopped echoing off a wall the goal lies beyond: drive on straight along the
        wall, slowly, so that the beam sweeps the opening cleanly, until the wall echoes again."""
        p, odo = self.params, self.odometry
        if self.found is not None:
            gap, self.found = self.found, None
            if self.gap_leads_to(gap, pose_en, pose_heading_rad, goal_en):
                self._line_up(time_s, gap, self._inspect_along)
                return self._manoeuvre(time_s, front)
        travelled = math.dist(odo.position_en, self._inspect_from)
        if (
            travelled > p.max_width_m + (p.wall_range_m if self._reversing else 0.0)
            or self._blocked(front)
            or time_s - self._since_s > p.timeout_s
        ):
            if self._search is not None and self._reversing:  # a second sweep in vain: the search goes on
                self.state, self._inspect_along = "search", self._search_direction()  # (no third sweep: _reversing stays)
                return self._searching(time_s, front, pose_en, pose_heading_rad, goal_en)
            self._end(time_s)  # no narrow opening here (the wall's end, a wide gap, or in the way)
            return None
        error = _wrap(math.atan2(self._inspect_along[1], self._inspect_along[0]) - odo.heading_rad)
        if abs(error) > math.pi / 2.0:
            self._end(time_s)  # the wall runs the other way: not going along it
            return None
        return Drive(
            (-1.0 if self._reversing else 1.0) * p.speed_mps * max(math.cos(error), 0.0),
            self._rate(error),
            self.state,
        )

    def _blocked(self, front: list[float]) -> bool:
        """Inspecting or searching: something in the way ahead (the front beam within ``2 stop_m``),
        at a front corner (a diagonal within ``CORNER_NEAR_M``), closing on a side or the back
        (within ``SIDE_NEAR_M``) or a moving obstacle near (``MOVER_NEAR_M``): the rule base and
        the guards take over."""
        p = self.params
        return (any(r <= 2.0 * p.stop_m for r in front) or any(self._diagonal_m.get(o, math.inf) <= CORNER_NEAR_M for o in DIAGONALS)
                or any(r <= SIDE_NEAR_M for r in self._flank_m.values()) or self._mover_m <= MOVER_NEAR_M)

    def _goal_in_odometry(self, pose_en: EN, pose_heading_rad: float, goal_en: EN) -> EN:
        """The goal, given in the fused pose's frame, in the odometry's."""
        return self.odometry.link(pose_en, pose_heading_rad).to_odometry(goal_en)

    def _goal_line_ahead_m(self, line: tuple[EN, EN, EN], pose_en: EN, pose_heading_rad: float, goal_en: EN) -> float:
        """How far ahead along a followed wall (m, the way the rover follows it) the straight line
        from the rover to the goal meets the wall's line (-inf where it does not). ``line``: a point
        on it, the unit vector along it (the way the rover follows it) and its unit normal."""
        base, along, normal = line
        odo = self.odometry
        goal = self._goal_in_odometry(pose_en, pose_heading_rad, goal_en)
        here_n = (odo.east_m - base[0]) * normal[0] + (odo.north_m - base[1]) * normal[1]
        goal_n = (goal[0] - base[0]) * normal[0] + (goal[1] - base[1]) * normal[1]
        if here_n * goal_n >= 0.0:
            return -math.inf
        k = here_n / (here_n - goal_n)
        return k * ((goal[0] - odo.east_m) * along[0] + (goal[1] - odo.north_m) * along[1])

    def wall_beside(self, direction_rad: float, pose_en: EN, pose_heading_rad: float, goal_en: EN) -> bool:
        """The side beam on the side of ``direction_rad`` (body, counter-clockwise) is following a
        flat wall (its latest run of echoes: ``WALL_MIN_ECHOES`` over ``WALL_MIN_SPAN_M`` of
        travel, one line) that the goal lies beyond. A turn in place towards that side swings the beam off the wall
        and cuts short the run that a search of the wall is measured from: in narrow_gap world 33
        the planner's path ran through the part of the wall not yet mapped, behind the rover; the
        rover turned to it, the path flipped to the wall's other end, it turned back, and the
        search it then made stopped short of the gap (lockstep SITL; the rule base alone had
        followed the wall on and searched it back past the gap). Each side's line is fitted only
        when asked, at most every ``SEARCH_CHECK_S``."""
        if self.state:
            return False
        for orientation, sweep in self._sweeps.items():
            if SIDE_BODY_RAD[orientation] * direction_rad <= 0.0 or not sweep:
                continue
            fitted_s = self._beside[orientation][0]
            if not sweep[-1].time_s - SEARCH_CHECK_S < fitted_s <= sweep[-1].time_s:
                self._beside[orientation] = (sweep[-1].time_s, self._wall_run_line(list(sweep)))
            line = self._beside[orientation][1]
            if line is not None and self._goal_line_ahead_m(line, pose_en, pose_heading_rad, goal_en) > -math.inf:
                return True
        return False

    def _wall_run_line(self, beams: list[Beam]) -> tuple[EN, EN, EN] | None:
        """(point, along, normal) of the flat wall whose echoes end ``beams``, or None."""
        wall = self._wall_before(beams)
        if len(wall) < WALL_MIN_ECHOES or math.dist(wall[0].origin_en, wall[-1].origin_en) < WALL_MIN_SPAN_M:
            return None
        base, along, normal, rms = wall_line(wall, self.params.beam_half_deg)
        return (base, along, normal) if rms <= WALL_MAX_RMS_M else None

    def gap_leads_to(self, gap: Gap, pose_en: EN, pose_heading_rad: float, goal_en: EN) -> bool:
        """The goal lies beyond the gap's line (the goal taken into the odometry frame)."""
        return gap.coordinates(self._goal_in_odometry(pose_en, pose_heading_rad, goal_en))[0] > self.params.standoff_m

    def _give_up(self, time_s: float, why: str, leave: bool = False) -> None:
        """Hand back to the rule base; with ``leave``, after turning back along the wall."""
        self.events.append(f"Narrow passage: given up ({why})")
        if leave:
            self.state, self._since_s = "leave", time_s
        else:
            self._end(time_s)

    def _leave(self, time_s: float) -> Drive | None:
        """Turn in place to head along the wall as when the inspection began; then hand back."""
        error = _wrap(math.atan2(self._inspect_along[1], self._inspect_along[0]) - self.odometry.heading_rad)
        if abs(error) <= math.radians(self.params.heading_tol_deg) or time_s - self._since_s > self.params.timeout_s:
            self._end(time_s)
            return None
        return self._turn(error)

    def _end(self, time_s: float) -> None:
        if self.gap is not None:
            self._rejected.append((time_s + self.params.reject_s, self.gap.centre_en, self._gap_proved))
        self.gap, self.state, self._search = None, "", None
        for sweep in self._sweeps.values():
            sweep.clear()

    def _manoeuvre(self, time_s: float, front: list[float]) -> Drive | None:
        if self.state == "leave":
            return self._leave(time_s)
        p, gap, odo = self.params, self.gap, self.odometry
        assert gap is not None
        if time_s - self._since_s > p.timeout_s:
            self._give_up(time_s, "timeout")
            return None
        axis = math.atan2(gap.axis_en[1], gap.axis_en[0])
        along, _ = gap.coordinates(odo.position_en)
        nose_to_line = -along - self._length_m() / 2.0
        if self.state == "back":
            return self._back(time_s, along, axis)
        if self.state == "line_up":
            start = (
                gap.centre_en[0] - p.standoff_m * gap.axis_en[0],
                gap.centre_en[1] - p.standoff_m * gap.axis_en[1],
            )
            if self._retreat:  # off the measured line: back along it first, then forwards to P0 on it
                drive = self._go_to((start[0] - RETREAT_M * gap.axis_en[0], start[1] - RETREAT_M * gap.axis_en[1]), axis)
                if drive is not None:
                    return drive
                self._retreat = False
            # On the line the last scan measured: only square up (a few centimetres short of P0 or
            # past it do not matter; a move there could not close a lateral error under NEAR_M).
            drive = None if self._scan_ok else self._go_to(start, axis)
            if drive is not None:
                return drive
            error = _wrap(axis - odo.heading_rad)
            if abs(error) > math.radians(p.heading_tol_deg):
                return self._turn(error)
            if abs(odo.yaw_rate_radps) > math.radians(SETTLED_DPS):
                return Drive(0.0, 0.0, self.state)  # still coasting round: see where it stops
            self.state, self._look_from_s, self._look_front = "look", time_s, []
            for readings in self._look_diagonals.values():
                readings.clear()
            return Drive(0.0, 0.0, self.state)
        if self.state == "scan":
            return self._scanning(time_s, gap, axis, nose_to_line)
        if self.state == "look":
            if abs(_wrap(axis - odo.heading_rad)) > math.radians(p.heading_tol_deg):
                self.state = "line_up"  # it turned on past the axis: turn back, look again
                return self._turn(_wrap(axis - odo.heading_rad))
            if time_s - self._look_from_s < p.look_s:
                return Drive(0.0, 0.0, self.state)
            tilt = self._tilt(nose_to_line)
            if not math.isfinite(tilt) or abs(tilt) > math.radians(SQUARE_MAX_DEG) or self._squarings > SQUARINGS:
                self._give_up(time_s, "not square to the wall", leave=True)
                return self._leave(time_s)
            normal = _wrap(odo.heading_rad - tilt)
            if abs(_wrap(normal - axis)) > math.radians(p.heading_tol_deg):
                # The gap's axis (the wall line's normal, from the sweep) is off by more than the
                # tolerance: turn it about the gap's centre onto the wall's normal measured here.
                self._squarings += 1
                self.gap = gap = Gap(gap.centre_en, (math.cos(normal), math.sin(normal)), gap.width_low_m, gap.width_high_m)
                if self._scan_ok and abs(gap.coordinates(odo.position_en)[1]) > p.scan_tol_m:
                    self._scan_ok, self._retreat = False, True  # now off the centre line: line up on it again
                self.state = "line_up"
                return self._turn(_wrap(normal - odo.heading_rad))
            if p.scan_max_deg > 0.0 and not self._scan_ok:
                if self._scans >= p.scan_tries:
                    self._give_up(time_s, "not on the opening's centre line after scanning it", leave=True)
                    return self._leave(time_s)
                self.state, self._scan, self._scan_readings = "scan", _Scan(), []
                self._scans += 1
                return Drive(0.0, math.radians(p.scan_rate_dps), self.state)
            if any(r <= nose_to_line + p.depth_m for r in front) or any(r <= nose_to_line + p.depth_m for r in self._look_front):
                self._give_up(time_s, "the front beam does not see through", leave=True)
                return self._leave(time_s)
            self.state, self._progress = "pass", (time_s, along)
            for readings in self._diagonals.values():
                readings.clear()
            self.events.append("Narrow passage: seen through, passing")
        if any(r <= p.stop_m for r in front) or any(r <= nose_to_line + p.depth_m for r in front if nose_to_line > 0.0):
            self._give_up(time_s, "something in the gap")
            return None
        if along - self._length_m() / 2.0 >= p.exit_m:
            self.events.append("Narrow passage: through")
            self._end(time_s)
            return None
        why = self._about_to_touch(time_s, along, nose_to_line)
        if why:
            self.events.append(f"Narrow passage: backing out ({why})")
            self.state, self._since_s = "back", time_s
            return Drive(0.0, 0.0, self.state)
        ahead = along + p.lookahead_m
        target = (
            gap.centre_en[0] + ahead * gap.axis_en[0],
            gap.centre_en[1] + ahead * gap.axis_en[1],
        )
        error = _wrap(math.atan2(target[1] - odo.north_m, target[0] - odo.east_m) - odo.heading_rad)
        speed = p.speed_mps * (0.5 if -GUARD_ZONE_M < nose_to_line <= SLOW_ZONE_M else 1.0)
        return Drive(speed * max(math.cos(error), 0.0), self._rate(error), self.state)

    def _tilt(self, nose_to_line: float) -> float:
        """The rover's heading from the wall's normal (rad, counter-clockwise), from the means of
        the front diagonals' readings while looking (nan without both).

        Each diagonal's cone (axis 45 degrees off the nose, half-angle ``b``) echoes first along
        its ray nearest the normal, at ``a = 45 - b`` degrees from it when square, from a corner
        ``w`` (half the footprint's width) beside the nose, ``x`` (the nose) from the wall:
        ``r = (x -+ w sin t) / cos(a +- t)``, so ``ln(r_left / r_right) = 2 t (tan a + w / x)``
        to first order."""
        left, right = (sum(r) / len(r) if r else math.nan for r in (self._look_diagonals[o] for o in DIAGONALS))
        if not (math.isfinite(left) and math.isfinite(right) and left > 0.0 and right > 0.0):
            return math.nan
        a = math.radians(45.0 - self.params.beam_half_deg)
        return math.log(left / right) / (2.0 * (math.tan(a) + self._width_m() / 2.0 / max(nose_to_line, 0.2)))

    def _about_to_touch(self, time_s: float, along: float, nose_to_line: float) -> str:
        """Passing: why the body is about to touch (or touches) the opening's edge, or ''.

        With the nose within ``GUARD_ZONE_M`` of the wall's line, a front diagonal at
        ``guard_near_m`` (readings nearer count as that: the emulator reports 0.2 m for anything
        nearer) with the other ``guard_skew_m`` farther: off the centre line by about the margin,
        0.1 m, or more (module docstring; farther out a heading a few degrees off the wall's normal
        reads the same, past the line the diagonals see round the far corners). The
        wheels driving for ``stall_s`` and the rover less than ``stall_m`` farther along: pushing
        against something."""
        p = self.params
        left, right = (sum(max(x, p.guard_near_m) for x in r) / len(r) if len(r) == GUARD_READINGS else math.nan
                       for r in (self._diagonals[o] for o in DIAGONALS))  # fmt: skip
        near, far = min(left, right), max(left, right)
        if 0.0 < nose_to_line <= GUARD_ZONE_M and not math.isnan(left + right) and near <= p.guard_near_m and far - near >= p.guard_skew_m:
            return f"{'front-left' if left < right else 'front-right'} {near:.2f} m, the other {far:.2f} m"
        assert self._progress is not None
        since, then = self._progress
        if along - then >= p.stall_m:
            self._progress = (time_s, along)
        elif time_s - since >= p.stall_s:
            return f"{along - then:.2f} m in {time_s - since:.1f} s"
        return ""

    def _back(self, time_s: float, along: float, axis: float) -> Drive | None:
        """Reverse straight (the heading held: steering would swing the nose into the post it is
        beside) to ``standoff_m`` before the gap's line, then give the gap up and turn back along
        the wall (``leave``)."""
        p = self.params
        if along <= -p.standoff_m or time_s - self._since_s > p.timeout_s:
            self._give_up(time_s, "about to touch its edge", leave=True)
            return self._leave(time_s)
        return Drive(-p.speed_mps, 0.0, self.state)

    def _scanning(self, time_s: float, gap: Gap, axis: float, nose_to_line: float) -> Drive | None:
        """Turn slowly in place, the front beam scanning the opening (``scan_max_deg``): each edge
        of the free headings is taken turning outwards (a lag between reading and heading shifts
        both edges alike, not their middle). Both found: the opening's centre is measured; on its
        line (``scan_tol_m``), look again and pass; off it, line up again on it."""
        p, odo = self.params, self.odometry
        sc = self._scan
        assert sc is not None
        limit = math.radians(p.scan_max_deg)
        readings, self._scan_readings = self._scan_readings, []
        for heading, range_m in readings:
            rel = _wrap(heading - axis)
            if range_m > nose_to_line + p.depth_m:
                sc.last_free_rad, sc.any_free = rel, True
            elif sc.last_free_rad is not None and sc.direction * (rel - sc.last_free_rad) > 0.0 and sc.direction not in sc.edges:
                sc.edges[sc.direction] = ((sc.last_free_rad + rel) / 2.0, range_m)
                sc.direction, sc.last_free_rad, sc.turns = -sc.direction, None, sc.turns + 1
        rel = _wrap(odo.heading_rad - axis)
        if sc.direction in sc.edges or sc.direction * rel >= limit:
            sc.direction, sc.last_free_rad, sc.turns = -sc.direction, None, sc.turns + 1
        if len(sc.edges) == 2:
            return self._scanned(time_s, gap, axis)
        if sc.turns > 4 or (sc.turns >= 2 and not sc.any_free):
            self._give_up(time_s, "the front beam's scan found no way through", leave=True)
            return self._leave(time_s)
        return Drive(0.0, sc.direction * math.radians(p.scan_rate_dps), self.state)

    def _scanned(self, time_s: float, gap: Gap, axis: float) -> Drive | None:
        """Both edges of the free headings found: the opening's width and centre from them
        (module docstring), the gap moved onto the measured centre line."""
        p, odo = self.params, self.odometry
        assert self._scan is not None
        (left, left_m), (right, right_m) = self._scan.edges[1], self._scan.edges[-1]
        sensor_m = (left_m + right_m) / 2.0  # the front sensor to where the cone's edge rays clip the opening's sides
        reach = sensor_m + self._length_m() / 2.0  # the same from the rover's centre (the turn's centre)
        width = reach * (left - right) + 2.0 * sensor_m * math.tan(math.radians(p.beam_half_deg))
        offset = reach * math.tan((left + right) / 2.0)  # the opening's centre, left of the rover
        along, lateral = gap.coordinates(odo.position_en)
        shift = lateral + offset  # the measured centre, left of the sweep's
        self._scan = None
        self.events.append(f"Narrow passage scanned: {width:.2f} m wide, {offset:+.2f} m to its centre ({shift:+.2f} m from the sweep's)")
        if left <= right or width < self._needed_m() or abs(shift) > p.match_m:
            self._give_up(time_s, "the front beam's scan does not agree", leave=True)
            return self._leave(time_s)
        ue, un = gap.axis_en
        self.gap = Gap((gap.centre_en[0] - shift * un, gap.centre_en[1] + shift * ue), gap.axis_en, gap.width_low_m, gap.width_high_m)
        self._scan_ok = abs(offset) <= p.scan_tol_m
        if not self._scan_ok:
            self._retreat = True
            self._since_s = time_s  # a line-up again: the timeout counts from it (scan_tries bounds them)
        self.state = "line_up"  # back square to the axis (and onto the measured line if off it), then look
        return self._manoeuvre(time_s, [])

    def _rate(self, error_rad: float) -> float:
        limit = math.radians(self.params.turn_rate_dps)
        return max(-limit, min(limit, HEADING_GAIN_PER_S * error_rad))

    def _turn(self, error_rad: float) -> Drive:
        return Drive(0.0, self._rate(error_rad), self.state)

    def _go_to(self, point_en: EN, final_rad: float) -> Drive | None:
        """Towards a point, forwards or in reverse, whichever turns less on the way there and to
        ``final_rad`` from there; None once there."""
        p, odo = self.params, self.odometry
        de, dn = point_en[0] - odo.east_m, point_en[1] - odo.north_m
        distance = math.hypot(de, dn)
        if distance <= p.position_tol_m:
            return None
        c, s = math.cos(odo.heading_rad), math.sin(odo.heading_rad)
        ahead = de * c + dn * s
        if distance <= NEAR_M:  # close: hold the heading, close the distance along it
            if abs(ahead) <= p.position_tol_m:
                return None
            return Drive(
                math.copysign(min(p.speed_mps, 2.0 * abs(ahead) + 0.05), ahead),
                0.0,
                self.state,
            )
        bearing = math.atan2(dn, de)
        forwards = abs(_wrap(bearing - odo.heading_rad)) + abs(_wrap(final_rad - bearing))
        backwards = abs(_wrap(bearing + math.pi - odo.heading_rad)) + abs(_wrap(final_rad - bearing - math.pi))
        reverse = backwards < forwards
        error = _wrap(bearing + (math.pi if reverse else 0.0) - odo.heading_rad)
        if abs(error) > DRIVE_MAX_ERROR_RAD:
            return self._turn(error)
        speed = min(p.speed_mps, 2.0 * distance + 0.05) * math.cos(error)
        return Drive(-speed if reverse else speed, self._rate(error), self.state)
