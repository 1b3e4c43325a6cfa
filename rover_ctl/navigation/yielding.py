"""Yielding to crossing traffic: the speed along the path at which no moving obstacle comes too close.

Pure: no clock, no I/O. The autopilot asks ``Yielder.limit`` every control step, with the moving
obstacle tracks (``rover_ctl.navigation.tracks``), and caps the navigator's speed with the answer.

**Why.** The fuzzy rule base reacts to where an obstacle *is*: one crossing from the left reads
as an obstacle on the left and the rover turns right, which is where a crossing obstacle is going.
A driver does the opposite: keeps the line and lets it pass. This is the path-velocity
decomposition of Kant and Zucker (1986): the path is the planner's and the navigator's, and only
the speed along it is chosen so as to miss the moving obstacles. While the rover yields, a turn
the navigator makes the way the crosser walks is taken out (``keep_line``): that turn kept the
rover alongside the crosser.

**Method.** The rover at ``p`` is taken to go on along the unit vector ``h`` where it points, at
a fraction ``s`` of the speed it was given, ``V``; a track at ``q`` with velocity ``w`` goes on at
``w``. A skid-steer rover cannot go sideways: whatever it does in the next second it does along
``h``, however far its target's direction ``u`` (the carrot) lies from it. (Taking ``u`` instead,
a rover turning back to its course with a crosser at its flank was modelled as driving into it
and stopped in its lane: the runner's commonest contact, 8 of its 19 failures of seeds 1-100 of
``crossing``, ``head_on`` and ``moving``.) Their separation ``d(tau) = (q - p) + (w - s V h) tau``
is closest at

    tau* = clip(-(r . v) / (v . v), 0, T)   with r = q - p, v = w - s V h

and the rover is in conflict with the track when ``|d(tau*)| < R``, ``R = robot radius +
margin_m`` (the track is an echo on the obstacle's near surface, so its own size is not added).
Each track is checked with two velocities: ``w`` as estimated, and ``w - (w . u) u``, going
straight across the course (without a heading, ``h`` is ``u``). A rangefinder's echo slides over a
crosser's face, so the track's velocity along the course is not to be trusted either way. Forward:
a side beam's echo slides along as the rover drives past (in the runner's ``crossing`` seed 33,
1.0 m/s along for a walker crossing at right angles), and taken as estimated the crosser would
pass ahead of a stopped rover that in fact stands in its lane. Back towards the rover: a walker
crossing a diagonal beam slides down it (seed 118: 0.3 m/s towards a stopped rover for one
walking straight across 1.1 m ahead of it), and taken as estimated it would walk into the stopped
rover. The limit is ``s V`` for the largest ``s`` in 1, (k-1)/k, ... 0 (``k = speed_steps``) that
is in conflict with no track under either velocity; ``None`` (no limit) when full speed is. When
every fraction is in conflict (an obstacle whose course would reach even a stopped rover), the
fraction whose least ``|d(tau*)| - R`` over tracks going straight across is largest: full speed
only when that is the one (passing ahead of it), never by default. (Ranked on the worse of both
velocities, the walker of seed 118 ranked full speed ahead of it above stopping, 0.53 m against
0.23 m; the rover drove on, the rule base turned it away from the walker, which is the way the
walker went, and it struck the rover's flank. That ranking, with ``keep_line`` below as first
written, took the runner's failures of seeds 1-500 of ``crossing`` from 31 to 13; the figures
since are in docs/perception.md.)

Only tracks that *cross* are yielded to: the component of ``w`` across ``u`` of at least
``min_cross_mps`` and at least ``sin(min_cross_deg)`` of its speed (a track's velocity is noisy: a
walker coming head-on must not read as crossing). An obstacle walking along the rover's line
(ahead and slower: to be overtaken; towards it: head-on) is steered around like a static one:
waiting behind it would never end, and one walking at a stopped rover walks into it. Whether a
track crosses is judged against the course ``u``, the line the rover keeps to (judged against
``h`` too, the runner's ``moving`` lost 4 of seeds 1-100 against none).

The autopilot hands over the moving tracks, less those on a persistent obstacle's face
(``obstacle_map.track_on_wall_m``). Only tracks the tracker is sure of start a yield: at least
``min_hits`` echoes, a standard deviation of the velocity across the course (the crossing yielded
for) of at most ``max_speed_sd_mps``, and ``min_travel_m`` travelled since the first echo (as the
rover drives past or turns by a static obstacle its echo slides over the obstacle's face and makes
tracks that seem to move, but never far from where they started). And none starts while the rover
points more than ``max_heading_off_deg`` away from its course (mid-turn around something): the model
has it going along the course, and a turning rover's beams sweep over surfaces and give its tracks
velocities that are not there. The limit (45 degrees) is wider than the evader's (30): a crosser the
rule base has turned the rover from, the way it walks, must still be yielded to, or it strikes the
rover's flank. For ``after_evasion_s`` after the evader last drove, the limit is
``after_evasion_heading_off_deg`` (30): the rover is turning back to its line, and a second walker
coming head-on, its velocity swept sideways, would read as crossing and stop the rover in its way
instead of being stepped aside from. Not for the walker stepped aside from: when the evader ends
its manoeuvre and that track crosses after all (its first estimate came at the rover), it is yielded
to at once within ``max_heading_off_deg`` (lockstep SITL ``crossing`` world 80: the manoeuvre
ended with the crosser's latched estimate behind the rover, the rover 32-40 degrees off its course,
and the rule base turned it alongside the crosser, which struck its flank).

**Hysteresis and lost tracks.** Once a track is yielded to, the rover keeps yielding to it until
full speed clears it by ``release_margin_m`` more, or its course comes within half of
``min_cross_deg`` of the line (the maturity tests no longer apply), so that track noise does not
make the rover lurch. The margin only holds a yield that full speed would end: when no speed is
free it does not count against full speed in the ranking above (it did, and held the rover at a
slower speed nearer the crosser). A yielded-to obstacle often loses its track while it passes
(its echo jumps across its surface from one beam to the next, beyond the tracker's gate, and a
new track starts with no velocity). So the last estimate of every track yielded to is kept, and
while its track is gone (not merely no longer moving: that one is static now, and released) it
stands in for it, moving on at its last velocity, for at most ``max_wait_s``: the rover waits
until that obstacle has passed, not until it was lost.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Collection, Iterable

from rover_ctl.config import YieldParams
from rover_ctl.navigation.tracks import Track


@dataclass(frozen=True)
class YieldDecision:
    """A speed cap for this step, and the track it yields to (None: drive on)."""

    speed_limit_mps: float | None
    track_ident: int | None = None
    across_mps: float = 0.0
    """The velocity of that track across the rover's heading (m/s, positive: to the rover's left)."""


def closest_approach_m(r_east: float, r_north: float, v_east: float, v_north: float, horizon_s: float) -> float:
    """Smallest ``|r + v tau|`` over ``tau`` in ``[0, horizon_s]`` (relative position and velocity)."""
    vv = v_east * v_east + v_north * v_north
    tau = 0.0 if vv <= 1e-12 else min(max(-(r_east * v_east + r_north * v_north) / vv, 0.0), horizon_s)
    return math.hypot(r_east + v_east * tau, r_north + v_north * tau)


def keep_line(left_rpm: float, right_rpm: float, decision: YieldDecision) -> tuple[float, float]:
    """The navigator's wheel setpoints while yielding: a turn the way the obstacle yielded to walks
    across is taken out, so the rover keeps its line and lets it pass. The rule base turns away
    from where an obstacle is, which for a crosser is where it goes: the rover ran alongside it,
    and it struck the rover's flank (module docstring).

    Both wheels go at the slower wheel's setpoint (never below zero): the turn's forward speed on
    its inside. Not at their mean: a yield is sometimes to a false track of a static drum, and the
    turn then clears the drum; the mean drove a hard turn (100 and 0 rpm) straight on at half speed
    into it (the runner's ``dense_clutter``, seeds 1-200: 190 pass with the mean, 197 with the
    slower wheel, 198 with no ``keep_line``; docs/perception.md)."""
    if decision.speed_limit_mps is not None and decision.across_mps * (right_rpm - left_rpm) > 0.0:
        inside_rpm = max(min(left_rpm, right_rpm), 0.0)
        return inside_rpm, inside_rpm
    return left_rpm, right_rpm


class Yielder:
    """Chooses the speed along the path that lets crossing obstacles pass (see the module docstring)."""

    def __init__(self, params: YieldParams, robot_radius_m) -> None:
        """``params`` is read at every call; ``robot_radius_m`` is a function giving the radius in force."""
        self.params = params
        self._robot_radius_m = robot_radius_m
        self._yielding: dict[int, Track] = {}
        """Tracks yielded to: the last estimate of each (a copy), kept while it is in conflict."""
        self._evaded_s = -math.inf
        self._evaded_ident: int | None = None

    def evaded(self, time_s: float, track_ident: int | None = None) -> None:
        """The evader (``rover_ctl.navigation.evasion``) drove the rover at ``time_s``, stepping
        aside from track ``track_ident``."""
        self._evaded_s, self._evaded_ident = time_s, track_ident

    def limit(self, east_m: float, north_m: float, course_rad: float, speed_mps: float,
              tracks: Iterable[Track], time_s: float, alive: Collection[int] = (),
              heading_rad: float | None = None) -> YieldDecision:  # fmt: skip
        """The speed cap for a rover at (``east_m``, ``north_m``) going along ``course_rad`` (ENU,
        towards its target) at ``speed_mps``, among the moving ``tracks``; ``alive`` names every
        track the tracker still has, moving or not (one that stopped moving is no longer waited for;
        one that is gone is, as last seen). ``heading_rad``: where the rover points, along which
        the speeds are tried; no new yield starts while it is more than ``max_heading_off_deg``
        off the course (within ``after_evasion_s`` of ``evaded``: ``after_evasion_heading_off_deg``)."""
        p = self.params
        if not p.enabled or speed_mps <= 0.0:
            self._yielding.clear()
            return YieldDecision(None)
        live = {t.ident: t for t in tracks}
        if not live and not self._yielding:  # nothing moving, nothing waited for: the usual step
            return YieldDecision(None)
        self._yielding = {i: live.get(i, t) for i, t in self._yielding.items()
                          if i in live or (i not in alive and time_s - t.time_s <= p.max_wait_s)}  # fmt: skip
        candidates = {**{i: t for i, t in self._yielding.items() if i not in live}, **live}  # lost ones move on as last seen
        ue, un = math.cos(course_rad), math.sin(course_rad)
        radius_m = self._robot_radius_m() + p.margin_m
        min_share = math.sin(math.radians(p.min_cross_deg))
        off_limit_deg = p.after_evasion_heading_off_deg if time_s - self._evaded_s < p.after_evasion_s else p.max_heading_off_deg
        off_deg = 0.0 if heading_rad is None else math.degrees(abs(math.remainder(heading_rad - course_rad, math.tau)))
        half_share = math.sin(math.radians(p.min_cross_deg / 2.0))
        crossing = []
        for ident, track in candidates.items():
            limit_deg = p.max_heading_off_deg if ident == self._evaded_ident else off_limit_deg  # the one stepped aside from crosses
            e, n = track.position_at(time_s)
            across_mps = abs(track.v_north_mps * ue - track.v_east_mps * un)
            if ident in self._yielding:  # already yielded to: kept while it still crosses at half the angle
                if ident in live and across_mps < half_share * track.speed_mps:
                    continue
            elif (off_deg > limit_deg or across_mps < p.min_cross_mps or across_mps < min_share * track.speed_mps
                  or track.hits < p.min_hits or track.velocity_var(-un, ue) > p.max_speed_sd_mps**2 or track.travel_m < p.min_travel_m):
                continue
            along_mps = track.v_east_mps * ue + track.v_north_mps * un  # either way: maybe the echo sliding
            crossing.append((ident, e - east_m, n - north_m, ((track.v_east_mps - along_mps * ue, track.v_north_mps - along_mps * un),
                                                              (track.v_east_mps, track.v_north_mps))))
        if not crossing:
            self._yielding = {}
            return YieldDecision(None)
        if heading_rad is not None:  # the speeds are tried where the rover points: where it goes next
            ue, un = math.cos(heading_rad), math.sin(heading_rad)
        steps = max(int(p.speed_steps), 1)
        best_fraction, best_m = 1.0, -math.inf
        for fraction in (i / steps for i in range(steps, -1, -1)):
            vr_e, vr_n = fraction * speed_mps * ue, fraction * speed_mps * un
            worst_m, free = math.inf, True  # the closest any track comes straight across, less the margin it needs
            for ident, re, rn, velocities in crossing:
                release_m = p.release_margin_m if ident in self._yielding and fraction == 1.0 else 0.0
                across_m, estimated_m = (closest_approach_m(re, rn, we - vr_e, wn - vr_n, p.horizon_s) - radius_m for we, wn in velocities)
                worst_m, free = min(worst_m, across_m), free and min(across_m, estimated_m) >= release_m
            if free:
                best_fraction = fraction
                break
            if worst_m > best_m + 1e-9:
                best_fraction, best_m = fraction, worst_m
        if best_fraction >= 1.0:
            self._yielding = {}
            return YieldDecision(None)
        conflicts = [c for c in crossing if self._conflicts(c, speed_mps, ue, un, radius_m)] or crossing
        self._yielding = {c[0]: candidates[c[0]].snapshot() for c in conflicts}
        ident = min(self._yielding)
        track = self._yielding[ident]
        return YieldDecision(best_fraction * speed_mps, ident, track.v_north_mps * ue - track.v_east_mps * un)

    def _conflicts(self, track: tuple, speed_mps: float, ue: float, un: float, radius_m: float) -> bool:
        """Whether the track is in conflict with the rover at full speed (one it is yielding to)."""
        _, re, rn, velocities = track
        return any(closest_approach_m(re, rn, we - speed_mps * ue, wn - speed_mps * un, self.params.horizon_s) < radius_m
                   for we, wn in velocities)
