"""Mission executor: which mission item is current, when it is done, and where to drive.

Pure state machine, no I/O and no clock: the daemon calls ``update(now_s, position_en)``
every control step and gets an ``ExecutorOutput`` with the goal (ENU metres; the planner routes
to it), the speed limit, whether to hold still, and the events to report on the GCS link.

Seq numbers are ArduPilot's: seq 0 is home, ``items[0]`` is seq 1.

Commands (anything else is skipped with a STATUSTEXT warning):
- NAV_WAYPOINT 16: drive to (lat, lon) until within param2 m (0: ``acceptance_radius_m``), report
  MISSION_ITEM_REACHED, hold param1 s, go on. Lat = lon = 0 means "here", as in ArduPilot.
- NAV_LOITER_TIME 19: drive there likewise, then hold position param1 s (a rover loiters by holding).
- NAV_RETURN_TO_LAUNCH 20: drive home (within ``rtl_radius_m``), then go on.
- DO_JUMP 177: jump to seq param1, param2 times (-1: forever); each DO_JUMP item counts its own
  jumps, and the counts start over on ``restart`` (ArduPilot's AP_Mission).
- DO_CHANGE_SPEED 178: speed limit param2 m/s (<= 0: unchanged), clamped to the robot's maximum.
- CONDITION_DELAY 112: hold param1 s before the next item. (ArduPilot delays only the following
  DO items while the previous navigation goes on; a rover that has reached its waypoint has nothing
  left to do, so here it holds where it is, which is what a mission author means.)

After the last item the mission is complete: an event, then hold. Modes: ``start`` (AUTO: resume
the current item; restart when complete), ``rtl`` (RTL: drive home, then hold there even if
pushed off), ``stop`` (leave AUTO/RTL: idle, hold). ``set_current(seq)`` is MISSION_SET_CURRENT;
``restart`` goes back to seq 1 and clears the jump counts (MAV_CMD_MISSION_START).

API:
    MissionExecutor(items, to_enu, params, max_speed_mps, home_en=(0, 0))
      (``params`` is read at every update and ``max_speed_mps`` may be a function giving the
      robot's top speed now, so a changed parameter applies at once)
      .start() / .rtl() / .restart() -> list[Event];  .stop()
      .set_current(seq) -> list[Event]     raises ValueError naming the bad seq
      .update(now_s, position_en) -> ExecutorOutput
      .mode, .current_seq, .complete
    Event(kind: EventKind, seq=None, text="", severity=Severity.INFO)
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

from rover_ctl.config import ExecutorParams
from rover_ctl.mission.model import MissionItem
from rover_ctl.vocabulary import Cmd, Severity

EN = tuple[float, float]

NAV_WAYPOINT = Cmd.NAV_WAYPOINT
NAV_LOITER_TIME = Cmd.NAV_LOITER_TIME
NAV_RETURN_TO_LAUNCH = Cmd.NAV_RETURN_TO_LAUNCH
CONDITION_DELAY = Cmd.CONDITION_DELAY
DO_JUMP = Cmd.DO_JUMP
DO_CHANGE_SPEED = Cmd.DO_CHANGE_SPEED
JUMP_FOREVER = -1
NAV_COMMANDS = frozenset({NAV_WAYPOINT, NAV_LOITER_TIME, NAV_RETURN_TO_LAUNCH})


class Mode(enum.Enum):
    IDLE = "idle"
    """Not driving the mission (HOLD/MANUAL in the daemon, or not started)."""
    AUTO = "auto"
    RTL = "rtl"


class EventKind(enum.Enum):
    ITEM_REACHED = "item_reached"
    """MISSION_ITEM_REACHED(seq)."""
    CURRENT = "current"
    """The current item changed: MISSION_CURRENT(seq)."""
    STATUSTEXT = "statustext"
    COMPLETE = "complete"
    """The mission is done (a STATUSTEXT too); the rover holds."""


@dataclass(frozen=True)
class Event:
    kind: EventKind
    seq: int | None = None
    text: str = ""
    severity: Severity = Severity.INFO


@dataclass(frozen=True)
class ExecutorOutput:
    target_en: EN | None
    """Where to go (the planner routes to it); None when there is nothing to drive to."""
    speed_limit_mps: float
    hold: bool
    """Stand still (holding at a waypoint, a delay, a loiter, mission complete, idle)."""
    acceptance_radius_m: float
    current_seq: int
    events: list[Event] = field(default_factory=list)


class _Phase(enum.Enum):
    """Where the current item is: driving to its location, then waiting out its hold time."""

    APPROACH = "approach"
    WAIT = "wait"


class MissionExecutor:
    """Runs a mission (see the module docstring)."""

    def __init__(
        self,
        items: Sequence[MissionItem],
        to_enu: Callable[[float, float], EN],
        params: ExecutorParams,
        max_speed_mps: float | Callable[[], float],
        home_en: EN = (0.0, 0.0),
    ) -> None:
        self.items = list(items)
        self.params = params
        self._max_speed = max_speed_mps if callable(max_speed_mps) else (lambda: max_speed_mps)
        self.home_en = home_en
        self._to_enu = to_enu
        self.mode = Mode.IDLE
        self.current_seq = 1
        self.complete = False
        self._speed_override_mps: float | None = None  # set by DO_CHANGE_SPEED; WP_SPEED otherwise
        self._jumps_done: dict[int, int] = {}
        self._phase = _Phase.APPROACH
        self._wait_until_s = 0.0
        self._target: EN | None = None
        self._fresh = True  # the current item has not been looked at yet
        self._home_reached = False  # in RTL: once home, stay held there

    @property
    def max_speed_mps(self) -> float:
        return self._max_speed()

    @property
    def _mission_speed_mps(self) -> float:
        """The AUTO speed limit: the last DO_CHANGE_SPEED of this run, else WP_SPEED, at most the robot's top speed."""
        speed = self.params.cruise_speed_mps if self._speed_override_mps is None else self._speed_override_mps
        return min(speed, self.max_speed_mps)

    # -- commands from the daemon / GCS -------------------------------------------------------

    def start(self) -> list[Event]:
        """Enter AUTO: resume the current item (restart if the mission was complete)."""
        if not self.items:
            self.mode = Mode.IDLE
            return [Event(EventKind.STATUSTEXT, text="No mission to run", severity=Severity.WARNING)]
        if self.complete:
            return self.restart()
        self.mode = Mode.AUTO
        self._fresh = True
        return []

    def restart(self) -> list[Event]:
        """Start the mission from seq 1 with fresh jump counts (MAV_CMD_MISSION_START)."""
        self._jumps_done.clear()
        self._speed_override_mps = None
        self.complete = False
        self.current_seq = 1
        return self.start()

    def set_current(self, seq: int) -> list[Event]:
        """MISSION_SET_CURRENT: make ``seq`` current (0, home, means 1, as ArduPilot)."""
        seq = max(seq, 1)
        if seq > len(self.items):
            raise ValueError(f"mission seq {seq} does not exist (mission has items 1-{len(self.items)})")
        self.current_seq = seq
        self.complete = False
        self._fresh = True
        return [Event(EventKind.CURRENT, seq)]

    def rtl(self) -> list[Event]:
        """Enter RTL (failsafe or GCS): drive home, then hold there."""
        self.mode = Mode.RTL
        self._home_reached = False
        return [Event(EventKind.STATUSTEXT, text="RTL: returning home")]

    def stop(self) -> None:
        """Leave AUTO/RTL (HOLD, MANUAL); ``start`` resumes the current item."""
        self.mode = Mode.IDLE

    # -- the step -----------------------------------------------------------------------------

    def update(self, now_s: float, position_en: EN) -> ExecutorOutput:
        """Advance the mission for the rover at ``position_en`` and return what to do now."""
        events: list[Event] = []
        if self.mode is Mode.RTL:
            return self._rtl_step(position_en, events)
        if self.mode is Mode.IDLE or self.complete:
            return self._holding(events)
        self._advance(now_s, position_en, events)
        if self.complete or self.mode is Mode.IDLE:
            return self._holding(events)
        item = self.items[self.current_seq - 1]
        radius = self._radius(item)
        if self._phase is _Phase.APPROACH and math.dist(position_en, self._target) <= radius:
            events.append(Event(EventKind.ITEM_REACHED, self.current_seq))
            events.append(Event(EventKind.STATUSTEXT, text=f"Reached waypoint #{self.current_seq}"))
            self._phase = _Phase.WAIT
            self._wait_until_s = now_s + self._hold_time_s(item)
            self._advance(now_s, position_en, events)
            if self.complete or self.mode is Mode.IDLE:
                return self._holding(events)
        radius = self._radius(self.items[self.current_seq - 1])
        waiting = self._phase is _Phase.WAIT
        return ExecutorOutput(self._target, self._mission_speed_mps, waiting, radius, self.current_seq, events)

    def _advance(self, now_s: float, position_en: EN, events: list[Event]) -> None:
        """Run items until the current one is a navigation or delay still in progress."""
        for _ in range(self.params.max_items_per_update):
            if self._fresh:
                if not self._begin(now_s, position_en, events):
                    self._next(events)
                    if self.complete:
                        return
                    continue
                if self._fresh:  # a DO_JUMP moved to its target: start that
                    continue
            if self._phase is _Phase.WAIT and now_s >= self._wait_until_s:
                self._next(events)
                if self.complete:
                    return
                continue
            return
        self.mode = Mode.IDLE
        events.append(Event(EventKind.STATUSTEXT, text="Mission loops without navigating: stopped", severity=Severity.WARNING))

    def _begin(self, now_s: float, position_en: EN, events: list[Event]) -> bool:
        """Start the current item; False when it is done at once (DO items, skipped items)."""
        self._fresh = False
        seq = self.current_seq
        item = self.items[seq - 1]
        self._phase = _Phase.APPROACH
        if item.command in (NAV_WAYPOINT, NAV_LOITER_TIME):
            if not item.is_global:
                events.append(_warning(f"Skipping item #{seq}: frame {item.frame} unsupported"))
                return False
            here = item.x == 0 and item.y == 0
            self._target = position_en if here else tuple(map(float, self._to_enu(item.x, item.y)))
        elif item.command == NAV_RETURN_TO_LAUNCH:
            self._target = self.home_en
        elif item.command == CONDITION_DELAY:
            self._target = position_en
            self._phase = _Phase.WAIT
            self._wait_until_s = now_s + max(_number(item.param1), 0.0)
        else:
            return self._do(seq, item, events)
        events.append(Event(EventKind.CURRENT, seq))
        return True

    def _do(self, seq: int, item: MissionItem, events: list[Event]) -> bool:
        """Execute a DO item or skip an unsupported one; True only for a DO_JUMP taken."""
        if item.command == DO_CHANGE_SPEED:
            speed = _number(item.param2)
            if speed > 0:
                self._speed_override_mps = speed
                if speed > self.max_speed_mps:
                    events.append(_warning(f"Speed {speed:g} m/s clamped to {self.max_speed_mps:.2f}"))
            return False
        if item.command == DO_JUMP:
            return self._jump(seq, item, events)
        events.append(_warning(f"Skipping item #{seq}: command {item.command} unsupported"))
        return False

    def _jump(self, seq: int, item: MissionItem, events: list[Event]) -> bool:
        target, repeat = int(_number(item.param1)), int(_number(item.param2))
        if not 1 <= target <= len(self.items):
            events.append(_warning(f"Skipping DO_JUMP #{seq}: no item #{target}"))
            return False
        done = self._jumps_done.get(seq, 0)
        if repeat != JUMP_FOREVER and done >= repeat:
            return False
        self._jumps_done[seq] = done + 1
        self.current_seq = target
        self._fresh = True
        return True

    def _next(self, events: list[Event]) -> None:
        if self.current_seq >= len(self.items):
            self.complete = True
            events.append(Event(EventKind.COMPLETE, self.current_seq, "Mission complete"))
            events.append(Event(EventKind.STATUSTEXT, text="Mission complete"))
            return
        self.current_seq += 1
        self._fresh = True

    def _radius(self, item: MissionItem) -> float:
        if item.command == NAV_RETURN_TO_LAUNCH:
            return self.params.rtl_radius_m
        if item.command == NAV_WAYPOINT and _number(item.param2) > 0:
            return item.param2
        return self.params.acceptance_radius_m

    @staticmethod
    def _hold_time_s(item: MissionItem) -> float:
        return max(_number(item.param1), 0.0) if item.command in (NAV_WAYPOINT, NAV_LOITER_TIME) else 0.0

    def _rtl_step(self, position_en: EN, events: list[Event]) -> ExecutorOutput:
        speed = self.params.rtl_speed_mps if self.params.rtl_speed_mps > 0 else self._mission_speed_mps
        if not self._home_reached and math.dist(position_en, self.home_en) <= self.params.rtl_radius_m:
            self._home_reached = True
            events.append(Event(EventKind.STATUSTEXT, text="RTL: reached home"))
        speed = min(speed, self.max_speed_mps)
        return ExecutorOutput(self.home_en, speed, self._home_reached, self.params.rtl_radius_m, self.current_seq, events)

    def _holding(self, events: list[Event]) -> ExecutorOutput:
        return ExecutorOutput(None, 0.0, True, self.params.acceptance_radius_m, self.current_seq, events)


def _number(value: float) -> float:
    """A parameter as a number: NaN or infinite (unset in a .plan file, garbage) counts as 0."""
    return value if math.isfinite(value) else 0.0


def _warning(text: str) -> Event:
    return Event(EventKind.STATUSTEXT, text=text, severity=Severity.WARNING)
