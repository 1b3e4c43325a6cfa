"""Which rangefinders the rover has, which the rule base reads, and what a missing one means.

Pure: the daemon tells ``plan_rangefinders`` the orientations the rule base reads and those the
rover has (configured, or learnt from the DISTANCE_SENSOR orientations the vehicle reported in its
first seconds); it answers with a ``RangefinderPlan`` or refuses with ``SensorSetupError`` (one
line, shown at start or when arming is refused):

* **No rangefinder at all**: GPS-only navigation. Every obstacle input reads "clear" (+inf) and
  ``avoidance`` is False, so the daemon says "avoidance off" once (STATUSTEXT and log). Nothing is
  required, so nothing can fail.
* **A rule-base input with its rangefinder present**: read as is; that rangefinder is required,
  and one that was there and goes silent is the rangefinder failsafe (that side blocked), as before.
* **A diagonal input (front-left 7, front-right 1) without its rangefinder** but with both of its
  neighbours (front 0 and that side, 6 or 2): the substitute is the nearer of the two neighbours.
  The beams either side of the missing diagonal bound what it would see from the front and the
  side; taking the nearer is the conservative reading. Both neighbours are then required.
* **Any other rule-base input without its rangefinder**: refused. A side the rule base needs and the
  rover cannot see would read as blocked for ever (the rover turns in place) or as clear (it drives
  into what it cannot see); neither is navigation.

Rangefinders the rover has but the rule base does not read (e.g. back, for the default rule
base) are not required: their silence changes nothing the rover does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

from rover_ctl.vocabulary import mav

ORIENTATION_NAMES = {0: "front", 1: "front_right", 2: "right", 3: "back_right", 4: "back", 5: "back_left", 6: "left", 7: "front_left"}
"""MAV_SENSOR_ORIENTATION yaw steps (45 deg clockwise each) as the rule bases name them."""
FRONT, FRONT_RIGHT, RIGHT = mav.MAV_SENSOR_ROTATION_NONE, mav.MAV_SENSOR_ROTATION_YAW_45, mav.MAV_SENSOR_ROTATION_YAW_90
BACK, LEFT, FRONT_LEFT = mav.MAV_SENSOR_ROTATION_YAW_180, mav.MAV_SENSOR_ROTATION_YAW_270, mav.MAV_SENSOR_ROTATION_YAW_315
"""The orientations the navigation modules read by name (the guards, the evader, passages)."""
DIAGONAL_NEIGHBOURS = {FRONT_RIGHT: (FRONT, RIGHT), FRONT_LEFT: (FRONT, LEFT)}
"""A missing diagonal is read from the nearer of these two (front and its side)."""
HORIZONTAL = frozenset(ORIENTATION_NAMES)
"""Orientations that can see an obstacle on the ground (25 down, 24 up and the rest are ignored)."""


class SensorSetupError(ValueError):
    """A rangefinder configuration the rule base cannot work with (one line)."""


@dataclass(frozen=True)
class RangefinderPlan:
    avoidance: bool
    """False: no rangefinders, every obstacle input reads clear (GPS-only navigation)."""
    required: frozenset[int]
    """Orientations whose silence is the rangefinder failsafe."""
    substitutes: Mapping[int, tuple[int, ...]] = field(default_factory=dict)
    """Rule-base orientation -> the present ones whose nearest reading stands for it."""

    def inputs(self, ranges_m: Mapping[int, float], wanted: Sequence[int]) -> dict[int, float]:
        """The range for each orientation in ``wanted`` the rule base reads, from ``ranges_m``
        (present sensors, possibly with blocked sides removed: those stay missing, i.e. blocked)."""
        if not self.avoidance:
            return {o: math.inf for o in wanted}
        out = {}
        for orientation in wanted:
            sources = self.substitutes.get(orientation)
            if sources is None:
                if orientation in ranges_m:
                    out[orientation] = ranges_m[orientation]
            elif all(s in ranges_m for s in sources):
                out[orientation] = min(ranges_m[s] for s in sources)
        return out

    def describe(self) -> str:
        if not self.avoidance:
            return "Avoidance off: no rangefinders, GPS only"
        subs = ", ".join(f"{ORIENTATION_NAMES[o]}=min({'/'.join(ORIENTATION_NAMES[s] for s in src)})" for o, src in sorted(self.substitutes.items()))
        need = ",".join(ORIENTATION_NAMES[o] for o in sorted(self.required))
        return f"Rangefinders: need {need}" + (f"; {subs}" if subs else "")


def plan_rangefinders(rule_orientations: list[int], present: set[int] | frozenset[int]) -> RangefinderPlan:
    """The plan for a rule base reading ``rule_orientations`` on a rover with rangefinders at
    ``present`` (non-horizontal ones ignored); ``SensorSetupError`` if it cannot work."""
    present = frozenset(present) & HORIZONTAL
    if not present:
        return RangefinderPlan(avoidance=False, required=frozenset())
    required: set[int] = set()
    substitutes: dict[int, tuple[int, ...]] = {}
    missing = []
    for orientation in rule_orientations:
        if orientation in present:
            required.add(orientation)
        elif orientation in DIAGONAL_NEIGHBOURS and set(DIAGONAL_NEIGHBOURS[orientation]) <= present:
            substitutes[orientation] = DIAGONAL_NEIGHBOURS[orientation]
            required.update(DIAGONAL_NEIGHBOURS[orientation])
        else:
            missing.append(orientation)
    if missing:
        names = ", ".join(f"obstacle_{ORIENTATION_NAMES[o]} ({o})" for o in missing)
        have = ", ".join(f"{ORIENTATION_NAMES[o]} ({o})" for o in sorted(present))
        raise SensorSetupError(f"the rule base reads {names} but the rover has no such rangefinder (it has {have})")
    return RangefinderPlan(avoidance=True, required=frozenset(required), substitutes=substitutes)
