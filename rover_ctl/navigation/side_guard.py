"""Keeping the flanks clear: a turn away from whatever the side rangefinders see at the rover's side.

Pure: no clock, no I/O. The autopilot adds ``side_turn_radps`` to the fuzzy navigator's wheel
setpoints every step it drives by the rule base.

**Why.** The rule base (the paper's and the default) never turns away from a side reading alone:
with the target on the side where something stands close, it drives straight on. That is right
beside a wall and wrong beside a drum crossing the rover's way. A crosser seen late from the left
makes the rule base turn right, the way the crosser walks; the rover then runs beside it, slowed
by the near reading, turns back towards its target, and the crosser strikes its flank. This was
the commonest collision of the ``moving``, ``crossing`` and ``head_on`` benchmarks (in-process
runner, seeds 1-200, default rule base: 18 of 23 collisions struck the rover 60-150 degrees off
its heading, docs/perception.md "Flank contacts").

**Method.** With ``r_L`` and ``r_R`` the ranges of the left and right rangefinders
(MAV_SENSOR_ROTATION_YAW_270 and _YAW_90) and ``R = range_m``::

    push(r) = clip((R - r) / R, 0, 1)
    yaw rate = max_yaw_rate_radps * (push(r_R) - push(r_L))     (rad/s, counter-clockwise)

which the autopilot adds to the rule base's wheel setpoints as a speed difference of
``yaw rate * track`` (half to each wheel), the forward speed unchanged: a rover a yield holds
still pivots away in place, and near full speed the faster wheel meets its limit, where the wheel
loop saturates and the turn is smaller. A rangefinder the rover lacks, or one silent and left out
by the failsafe, pushes nothing: the failsafe slows the rover for it already. A rover driving at
1 m/s along a wall 0.22 m from its side turns away by 18 degrees until the wall reads beyond
``range_m`` (tests/navigator/test_side_guard.py); the rule base then steers it back towards its
target.

**Passing, not escorting.** While the guard turns the rover away, the rule base turns it back
towards its target, and slows to turn: the two settle on a heading a little off the course at a
crawl (0.45 m/s with a 0.25 m left reading and the way ahead clear, tests/navigator/
test_side_guard.py, against 1.2 m/s of cruise). Beside a drum that moves the rover's way, or
crosses from behind its flank, that keeps the two abreast: the rover at 0.35-0.45 m/s and the drum
at about the same, its side reading at 0.2-0.3 m for seconds, until the drum closes on the flank
(the runner's ``crossing`` seeds 23, 45 and 58). So while the guard turns and the way ahead is
clear (every front rangefinder the rover has, front and both front diagonals, reading beyond
``front_clear_m``), ``pass_speed_mps`` is a floor on the forward speed (never above the speed the
rover was given): it draws ahead of what is at its side, a static obstacle or a moving one,
instead of staying beside it. The autopilot raises both wheels by the same amount, so the turn is
kept; not while a yield holds the rover back.

**Not turning back into it.** Once the guard has turned the rover far enough off its course, the
rule base turns back towards its target, towards the side that reads close, harder than the guard
turns away (at the rangefinder's 0.2 m minimum the guard gives 1.18 rad/s): beside a walker that
converges on the rover's flank the two ran abreast and the rover turned into it (the runner's
``head_on`` seeds 36 and 147). So while the guard turns and the way ahead is clear, a turn of the
rule base against the guard's is taken out (``against_guard_removed``: both wheels at their mean,
the forward speed kept); with something ahead the rule base's turn stands, as it may be turning
away from that.

**Walked into from behind.** No rangefinder looks at the rear quarters (the six are front, the
front diagonals, the sides and the back), and a walker that has passed the rover on its flank is
there. Having stepped aside from one walker and met a second late, the rule base turns the rover
right round, away from its target; with the walker at its side the guard keeps it going, but once
the walker slips aft of the side beam the guard lets go and the rule base, its target behind,
stops to pivot back, and the walker, converging at 0.5-0.8 m/s, walks into its rear quarter (most
of the runner's ``head_on`` failures, seeds 1-500). The tracker still holds the walker there. So
while a moving track that has travelled ``rear_min_travel_m`` (a real mover, not a static drum's
echo sliding along with the rover) is behind the side beams (``rear_min_bearing_deg`` round from
the heading) within ``rear_range_m`` (``rear_mover_side``), the way ahead is clear and no yield
holds the rover, it goes on as beside a walker: at least the passing speed, and a turn towards
the track's side taken out (the rule base's, or the guard's away from something on the other
flank: the rover then goes straight), until the walker is left behind. Not abeam: there the side
beam sees what is there, and among walls most of the tracks the check acted on lay there, a
wall's echo sliding along the beam of a rover passing or turning by it; acting on them took the
rover wide, and back into a cul-de-sac it had planned its way out of (docs/perception.md
"Walked into from behind").
"""

from __future__ import annotations

import math
from typing import Iterable, Mapping

from rover_ctl.config import SideGuardParams
from rover_ctl.navigation.sensors import FRONT, FRONT_LEFT, FRONT_RIGHT, LEFT, RIGHT
from rover_ctl.navigation.tracks import Track

AHEAD = (FRONT, FRONT_RIGHT, FRONT_LEFT)
"""The front rangefinder and the two front diagonals: the way ahead."""


def side_turn_radps(ranges_m: Mapping[int, float], params: SideGuardParams) -> float:
    """The yaw rate (rad/s, counter-clockwise positive) that turns the rover away from what its
    side rangefinders see within ``params.range_m``; 0 when nothing is that close (or disabled)."""
    if not params.enabled or params.range_m <= 0.0:
        return 0.0

    def push(orientation: int) -> float:
        range_m = ranges_m.get(orientation)
        if range_m is None or not range_m < params.range_m:  # absent, NaN or clear
            return 0.0
        return min((params.range_m - max(range_m, 0.0)) / params.range_m, 1.0)

    return params.max_yaw_rate_radps * (push(RIGHT) - push(LEFT))


def way_ahead_clear(ranges_m: Mapping[int, float], params: SideGuardParams) -> bool:
    """Whether every front rangefinder the rover has (front and both front diagonals) reads beyond
    ``params.front_clear_m``; False without any (NaN is not clear)."""
    ahead = [ranges_m[o] for o in AHEAD if o in ranges_m]
    return bool(ahead) and all(r > params.front_clear_m for r in ahead)


def against_guard_removed(left_rpm: float, right_rpm: float, side_turn: float) -> tuple[float, float]:
    """The rule base's wheel setpoints with a turn against the guard's (``side_turn``, rad/s CCW)
    taken out: both wheels at their mean, the forward speed kept; unchanged otherwise."""
    if side_turn * (right_rpm - left_rpm) < 0.0:  # the rule base turns back towards the near side
        mean = (left_rpm + right_rpm) / 2.0
        return mean, mean
    return left_rpm, right_rpm


def pass_speed_mps(ranges_m: Mapping[int, float], given_speed_mps: float, params: SideGuardParams) -> float | None:
    """The least forward speed (m/s) while the guard turns and the way ahead is clear: the smaller
    of ``params.pass_speed_mps`` and ``given_speed_mps``; None when the guard does not turn, a front
    reading is within ``params.front_clear_m`` (or not a number), the rover has no front
    rangefinder, or the floor is off."""
    if params.pass_speed_mps <= 0.0 or side_turn_radps(ranges_m, params) == 0.0 or not way_ahead_clear(ranges_m, params):
        return None
    return max(min(params.pass_speed_mps, given_speed_mps), 0.0)


def rear_mover_side(tracks: Iterable[Track], time_s: float, east_m: float, north_m: float, heading_rad: float,
                    params: SideGuardParams) -> float:  # fmt: skip
    """The side (+1 left, -1 right, 0 none) of the nearest moving track behind the side beams (its
    point at ``time_s`` at least ``params.rear_min_bearing_deg`` round from the heading, seen from
    the rover's centre) within ``params.rear_range_m`` of the centre that has gone at least
    ``params.rear_min_travel_m`` from its first echo."""
    if not params.enabled or params.rear_range_m <= 0.0:
        return 0.0
    c, s = math.cos(heading_rad), math.sin(heading_rad)
    aft_cos = math.cos(math.radians(params.rear_min_bearing_deg))
    side, nearest_m = 0.0, params.rear_range_m
    for track in tracks:
        if track.travel_m < params.rear_min_travel_m:
            continue
        e, n = track.position_at(time_s)
        d_east, d_north = e - east_m, n - north_m
        distance_m = math.hypot(d_east, d_north)
        if d_east * c + d_north * s <= aft_cos * distance_m and distance_m < nearest_m:
            side, nearest_m = (1.0 if d_north * c - d_east * s > 0.0 else -1.0), distance_m
    return side
