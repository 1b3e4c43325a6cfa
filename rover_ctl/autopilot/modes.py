"""The modes and when each may be entered (ArduPilot Rover's mode numbers and meanings).

| mode | what the autopilot does | needs |
|---|---|---|
| MANUAL | hands the RC channels back to the vehicle's radio | nothing |
| HOLD | stops: brakes to zero wheel speed, then neutral | nothing |
| LOITER | holds the position where it was entered; pushed farther than ``loiter_radius_m``, drives back | a position |
| AUTO | runs the mission (``MissionExecutor``): resumes the current item, restarts a completed one | a position and a mission |
| RTL | drives home, then holds there | a position |
| GUIDED | drives to the last guided target (planner + navigator), then loiters there; without one it loiters where it was entered | a position |

``refusal`` says why a mode cannot be entered now, or None. A mode number rover_ctl does not
implement is refused too (``unsupported``). Failsafes and a completed mission change modes on
their own (RTL, HOLD); those changes are the autopilot's, not checked here.
"""

from __future__ import annotations

from dataclasses import dataclass

from rover_ctl.vocabulary import RoverMode

DRIVING_MODES = frozenset({RoverMode.AUTO, RoverMode.RTL, RoverMode.GUIDED, RoverMode.LOITER})
"""Modes in which the autopilot drives (armed): the stuck failsafe watches these."""
STATION_MODES = frozenset({RoverMode.LOITER, RoverMode.GUIDED})
"""Modes that keep a station (a point to hold, driven back to when pushed away)."""
FAILSAFE_RTL_MODES = frozenset({RoverMode.AUTO, RoverMode.GUIDED, RoverMode.LOITER})
"""Modes a failsafe whose action is RTL switches out of (RTL already is; HOLD and MANUAL stay)."""


@dataclass(frozen=True)
class ModeContext:
    has_position: bool
    """The estimator has a position and the local frame (home) exists."""
    has_mission: bool


def unsupported(custom_mode: int) -> str | None:
    """Why a custom_mode number is not a mode of this autopilot, or None."""
    try:
        RoverMode(custom_mode)
    except ValueError:
        return f"mode {custom_mode} not supported"
    return None


def refusal(mode: RoverMode, context: ModeContext) -> str | None:
    """Why ``mode`` cannot be entered now (text for "Mode change refused: ..."), or None."""
    if mode in (RoverMode.MANUAL, RoverMode.HOLD):
        return None
    if not context.has_position:
        return f"{mode.name} needs a position"
    if mode == RoverMode.AUTO and not context.has_mission:
        return "AUTO needs a mission"
    return None
