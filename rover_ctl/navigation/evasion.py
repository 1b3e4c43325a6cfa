"""Stepping aside for oncoming traffic: the heading and speed that let a walker coming head-on pass.

Pure: no clock, no I/O. The autopilot asks ``Evader.step`` every control step with the moving
obstacle tracks (``rover_ctl.navigation.tracks``); while it answers a ``Drive`` that drives the
wheels, the fuzzy navigator waits (as for a narrow passage, ``rover_ctl.navigation.gaps``).

**Why.** Yielding (``rover_ctl.navigation.yielding``) chooses only the speed along the path, which
is right for crossing traffic and wrong for a walker coming down the rover's line: a stopped rover
is walked into. The rule base reacts to where an obstacle *is*, and only once it is near: against
a walker closing at up to 2.2 m/s it starts turning about 2 m out, always to the same side, slows
to half speed as it turns, and is struck on its flank with its turn half done (the commonest
collision of the ``head_on`` benchmark). A walker has to be stepped aside from early and briskly,
to the side it is not on.

**Method: velocity obstacles by rollout** (after Fiorini and Shiller, 1998, with the rover's turn
rate in the model). An oncoming track at ``q`` with velocity ``w`` is taken to go on at ``w``. For
each candidate heading ``psi_c = course + side * delta`` (``delta`` in ``deltas_deg``, ``side`` +1
left or -1 right) and speed ``s`` (the speed given, then ``slow_fraction`` of it), the rover is
rolled out from its pose over ``horizon_s`` in steps of ``rollout_step_s`` with the law the drive
uses::

    omega = clip(heading_gain * wrap(psi_c - psi), +-max_yaw_rate_radps)
    psi  += omega dt;   v += clip(s - v, +-accel_mps2 dt);   p += v (cos psi, sin psi) dt

and its clearance is ``min_k |p_k - (q + w t_k)|``. The track is an echo on the obstacle's near
surface, so the clearance needed, ``R = robot half-width + margin_m``, carries the obstacle's own
size in ``margin_m``. The first candidate, in order of growing ``delta`` and the faster speed
first, whose clearance is at least ``R`` wins; when none is, the one with the largest clearance.
The side is chosen when the manoeuvre starts and kept to its end, so that the rover does not
weave: the side whose winner comes first in that order (the smaller turn), then the one with more
clearance, then the side away from the track, the sign of ``-(u x r)``, ``u`` the course's unit
vector and ``r = q - p`` (right when the track is dead ahead, as road users keep right). A rover
coming back to its line at an angle, with a walker on the line, is often already clear on its own
side: turning across the walker's way towards the "away" side would be the larger manoeuvre.

**Which tracks.** Confirmed moving tracks (none on a persistent obstacle's face:
``obstacle_map.track_on_wall_m``) with at least ``min_hits`` echoes, a standard deviation of the
velocity along the course (the closing stepped aside for) of at most ``max_speed_sd_mps`` and
``min_travel_m`` travelled from the first echo (a drum crossing the narrow front beam at first looks
exactly like a walker coming down it: its echo, placed on the beam's axis, comes at the rover as its
face passes, by up to its radius), ahead of the rover (``r . u >= min_start_range_m``: nearer, there
is no room left to step aside, and the rule base is better at close quarters), coming towards it
along its line (``w . u <= -min_closing_mps``, and ``|w x u| < sin(max_cross_deg) |w|``: a crosser
is the yielder's), which the rover going on along ``u`` at its speed would pass closer than ``R``
within ``horizon_s``. None starts while the rover points more than ``max_heading_off_deg`` off its
course (its beams then sweep over surfaces and give tracks velocities that are not there), goes
slower than ``min_start_speed_mps`` or yields to crossing traffic (a crosser passing in front of a
slowed rover gives echoes that seem to come at it).

**While evading** the track's estimate is latched when the manoeuvre starts and moved on at its
velocity; a live estimate replaces it only while its velocity stays within ``max_velocity_jump_mps``
of the one latched at the start (a turning rover's beams slide over the walker and corrupt its
velocity). A side whose 45-degree rangefinder reads nearer than ``side_free_m`` is not stepped to
while the other reads farther. The manoeuvre ends when the obstacle is behind the rover
(``r . h < 0``, ``h`` its heading, and separating), when going straight along the course clears it by
``release_margin_m`` more than ``R``, after ``max_s``, or once the live track has not closed on the
rover (``-w . u < min_closing_mps``) for ``not_oncoming_s``: the latched estimate was wrong (a
crosser first taken for a walker coming at the rover), and no manoeuvre starts again for that track.
It also ends, and none starts, while the front rangefinder reads nearer than ``front_free_m``: the
rollouts see only the walker, and the rover, stepping aside at full speed, drove into a second
obstacle its front rangefinder had read closing from 0.66 m (the runner's ``head_on`` seed 5); at
close quarters the rule base drives.

**Back to the path.** For ``rejoin_s`` after the last step a manoeuvre drove, the autopilot gives
the navigator a carrot ``rejoin_lookahead_m`` along the path instead of the planner's 3 m, so the
rover comes back to its path at a shallow angle (about 11 degrees from 1.5 m off it, against about
30). Walkers come down the path; a second one, hidden behind the first from the front beam, can
otherwise stay in the blind wedge between the front beam and a front diagonal until it is too late
(first read 1.15 m out in the runner's ``head_on`` seed 45, and by the front beam 4.15 m out with
the rejoin: tests/evasion/test_rejoin.py; seeds 1-500: 13 failed turning straight back, 5 with it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Mapping

from rover_ctl.config import EvadeParams
from rover_ctl.navigation.tracks import Track
from rover_ctl.navigation.sensors import FRONT, FRONT_LEFT, FRONT_RIGHT
from rover_ctl.navigation.yielding import closest_approach_m


def _closing_mps(track: Track, ue: float, un: float) -> float:
    """How fast the track comes back along the course (unit vector ``(ue, un)``): ``-w . u``."""
    return -(track.v_east_mps * ue + track.v_north_mps * un)


@dataclass(frozen=True)
class Drive:
    """What the evasion commands this step: forward speed (m/s) and yaw rate (rad/s, CCW)."""

    speed_mps: float
    yaw_rate_radps: float
    track_ident: int


class Evader:
    """Steps aside from walkers coming head-on (see the module docstring)."""

    def __init__(self, params: EvadeParams, half_width_m) -> None:
        """``params`` is read at every call; ``half_width_m`` is a function giving the value in force."""
        self.params = params
        self._half_width_m = half_width_m
        self._track: Track | None = None
        self._side = 0.0
        self._started_s = 0.0
        self._v0 = (0.0, 0.0)
        """The latched track's velocity when the manoeuvre started."""
        self._not_oncoming_s: float | None = None
        """Since when the live track has not been coming at the rover (None: it has)."""
        self._dropped: int | None = None
        """The track whose manoeuvre ended because it stopped closing: none starts for it again."""

    @property
    def active(self) -> bool:
        return self._track is not None

    def reset(self) -> None:
        self._track = None
        self._dropped = None

    def step(self, time_s: float, east_m: float, north_m: float, heading_rad: float, speed_now_mps: float,
             course_rad: float, speed_mps: float, tracks: Iterable[Track],
             ranges: Mapping[int, float] | None = None, may_start: bool = True) -> Drive | None:  # fmt: skip
        """The drive for this step, or None to let the navigator drive. The rover is at
        (``east_m``, ``north_m``) pointing ``heading_rad`` at ``speed_now_mps``; ``course_rad`` is
        towards its target and ``speed_mps`` the speed it may go; ``tracks`` the moving tracks;
        ``ranges`` the obstacle memory's range per rangefinder orientation (m). ``may_start``: a
        manoeuvre may start (not while the rover yields to crossing traffic: a crosser passing in
        front of a stopped rover gives echoes that seem to come at it)."""
        p = self.params
        if not p.enabled or speed_mps <= 0.0:
            self._track = None
            return None
        if ranges is not None and ranges.get(FRONT, math.inf) < p.front_free_m:  # something else is in the way
            self._track = None
            return None
        live = {t.ident: t for t in tracks}
        radius_m = self._half_width_m() + p.margin_m
        ue, un = math.cos(course_rad), math.sin(course_rad)
        start = self._track is None
        if start:
            if not may_start:
                return None
            self._track = self._threat(time_s, east_m, north_m, heading_rad, speed_now_mps, course_rad, speed_mps, live.values(), radius_m)
            if self._track is None:
                return None
            self._started_s = time_s
            self._v0 = (self._track.v_east_mps, self._track.v_north_mps)
            self._not_oncoming_s = None
        else:
            current = live.get(self._track.ident)
            if p.not_oncoming_s > 0.0 and current is not None and _closing_mps(current, ue, un) < p.min_closing_mps:
                self._not_oncoming_s = time_s if self._not_oncoming_s is None else self._not_oncoming_s
                if time_s - self._not_oncoming_s >= p.not_oncoming_s:
                    self._dropped = self._track.ident
                    self._track = None
                    return None
            else:
                self._not_oncoming_s = None
            self._refresh(current)
        track = self._track
        e, n = track.position_at(time_s)
        re, rn = e - east_m, n - north_m
        behind = re * math.cos(heading_rad) + rn * math.sin(heading_rad) < 0.0 and re * track.v_east_mps + rn * track.v_north_mps > 0.0
        straight_m = closest_approach_m(re, rn, track.v_east_mps - speed_mps * ue, track.v_north_mps - speed_mps * un, p.horizon_s)
        if not start and (behind or straight_m >= radius_m + p.release_margin_m or time_s - self._started_s > p.max_s):
            self._track = None
            return None
        def choose(side: float) -> tuple[float, float, float, float]:
            return self._choose(east_m, north_m, heading_rad, speed_now_mps, course_rad, speed_mps, e, n, track, side, radius_m)

        free = {side: ranges is None or ranges.get(FRONT_LEFT if side > 0 else FRONT_RIGHT, 0.0) >= p.side_free_m for side in (1.0, -1.0)}
        if start:  # the side whose manoeuvre is smallest (fewest degrees off, then most clearance)
            away = -1.0 if ue * rn - un * re >= 0.0 else 1.0  # u x r > 0: the track is left of the course
            options = {side: choose(side) for side in (away, -away)}
            sides = [side for side in options if free[side]] or list(options)  # a silent rangefinder is not free
            self._side = min(sides, key=lambda side: (options[side][2], -options[side][3], side != away))
            target_rad, speed = options[self._side][:2]
        else:
            if not free[self._side] and free[-self._side]:
                self._side = -self._side
            target_rad, speed = choose(self._side)[:2]
        omega = max(-p.max_yaw_rate_radps, min(p.max_yaw_rate_radps, p.heading_gain * math.remainder(target_rad - heading_rad, math.tau)))
        return Drive(speed, omega, track.ident)

    def _threat(self, time_s, east_m, north_m, heading_rad, speed_now_mps, course_rad, speed_mps, tracks, radius_m) -> Track | None:
        """The oncoming track that going on along the course would pass nearest, if nearer than ``radius_m``."""
        p = self.params
        if abs(math.remainder(heading_rad - course_rad, math.tau)) > math.radians(p.max_heading_off_deg) or speed_now_mps < p.min_start_speed_mps:
            return None
        ue, un = math.cos(course_rad), math.sin(course_rad)
        best, best_m = None, radius_m
        for track in tracks:
            e, n = track.position_at(time_s)
            re, rn = e - east_m, n - north_m
            if (track.ident == self._dropped or track.hits < p.min_hits or track.velocity_var(ue, un) > p.max_speed_sd_mps**2 or track.travel_m < p.min_travel_m or re * ue + rn * un < p.min_start_range_m
                    or not self._oncoming(track, ue, un)):  # fmt: skip
                continue
            miss_m = closest_approach_m(re, rn, track.v_east_mps - speed_mps * ue, track.v_north_mps - speed_mps * un, p.horizon_s)
            if miss_m < best_m:
                best, best_m = track, miss_m
        return None if best is None else best.snapshot()

    def _oncoming(self, track: Track, ue: float, un: float) -> bool:
        """The track comes towards the rover along its course (unit vector ``(ue, un)``): closing
        at ``min_closing_mps`` or more, within ``max_cross_deg`` of the line (a crosser is the yielder's)."""
        p = self.params
        across = abs(track.v_north_mps * ue - track.v_east_mps * un)
        return _closing_mps(track, ue, un) >= p.min_closing_mps and across < math.sin(math.radians(p.max_cross_deg)) * track.speed_mps

    def _refresh(self, live: Track | None) -> None:
        """A live estimate replaces the latched one while its velocity agrees with the one latched
        at the start (not the last one: a velocity creeping off step by step would pass)."""
        if live is None:
            return
        if math.hypot(live.v_east_mps - self._v0[0], live.v_north_mps - self._v0[1]) <= self.params.max_velocity_jump_mps:
            self._track = live.snapshot()

    def _choose(self, east_m, north_m, heading_rad, speed_now_mps, course_rad, speed_mps, e, n, track, side, radius_m):
        """(heading, speed, rank, clearance): the first candidate on ``side`` that clears
        ``radius_m`` and its rank in the order tried, else the clearest one and rank infinity."""
        p = self.params
        best, rank = None, 0
        for delta_deg in p.deltas_deg:
            target_rad = course_rad + side * math.radians(delta_deg)
            for speed in (speed_mps, speed_mps * p.slow_fraction):
                clear_m = self._rollout(east_m, north_m, heading_rad, speed_now_mps, target_rad, speed, e, n,
                                        track.v_east_mps, track.v_north_mps)  # fmt: skip
                if clear_m >= radius_m:
                    return target_rad, speed, rank, clear_m
                if best is None or clear_m > best[3]:
                    best = (target_rad, speed, math.inf, clear_m)
                rank += 1
        return best

    def _rollout(self, x, y, psi, v, target_rad, speed, qe, qn, we, wn) -> float:
        """Smallest distance (m) between the rover driven by the drive's law towards ``target_rad``
        at ``speed`` and the track, over the horizon (module docstring)."""
        p = self.params
        dt = p.rollout_step_s
        dv = p.accel_mps2 * dt
        nearest = math.hypot(qe - x, qn - y)
        for _ in range(max(1, round(p.horizon_s / dt))):
            omega = max(-p.max_yaw_rate_radps, min(p.max_yaw_rate_radps, p.heading_gain * math.remainder(target_rad - psi, math.tau)))
            psi += omega * dt
            v += max(-dv, min(dv, speed - v))
            x += v * math.cos(psi) * dt
            y += v * math.sin(psi) * dt
            qe += we * dt
            qn += wn * dt
            nearest = min(nearest, math.hypot(qe - x, qn - y))
        return nearest
