"""Failsafe decisions from message ages, estimator health, the fence test and progress.

Pure: the daemon measures (ages in vehicle time, never the wall clock), this module decides. Every
control step the daemon calls ``Failsafes.update(now_s, FailsafeInputs) -> FailsafeDecision`` and
applies ``decision.action``; docs/failsafes.md lists each failsafe's trigger, action, recovery
and parameters.

Hysteresis: a failsafe triggers as soon as its condition holds (after its own delay where it has
one) and clears only after the condition has been gone for ``recovery_s`` continuously, so a
flapping link or sensor keeps it active instead of making it chatter. Each trigger and each
clear is reported once as an event for STATUSTEXT (text <= 50 characters, MAV_SEVERITY).

Actions, by precedence when several failsafes are active:
    NEUTRAL  > HOLD  > RTL  > BACK_OFF  > NONE
NEUTRAL, HOLD and BACK_OFF are levels: apply them while they are reported. RTL is reported while
its cause lasts; the daemon switches its mode to RTL when it first sees it, and that mode stays
until the GCS changes it (ArduPilot's failsafe mode change), even after the cause is gone.

Inputs are the daemon's view: ``driving`` is the mode the GCS selected (AUTO or RTL, armed), not
changed by failsafe actions; ``commanded_speed_mps`` is the navigator's forward setpoint (0 while
a failsafe holds). Leaving the driving modes forgets the stuck state.

API:
    Failsafes(params).update(now_s, inputs: FailsafeInputs) -> FailsafeDecision
    FailsafeDecision.action: Action, .reasons (active failsafe names), .events (new this step),
        .blocked_orientations (silent rangefinders: the navigator treats those sides as blocked),
        .dead_reckoning, .replan (once, when a back-off ends: re-plan from here), .speed_limit_mps
        (degraded sensing: a silent rangefinder that is not required; and always at most
        ``range_travel_m`` per interval between two readings of the slowest used rangefinder)

Rangefinders: those the navigator reads (``used_rangefinders``, the rangefinder plan's, set by the
autopilot) and those ``params.required_rangefinders`` names (``[-1]``: the used ones) are watched.
A silent required one is HOLD; a silent used one that is not required blocks its side and limits
the speed to ``degraded_speed_mps``; others are not watched.

Rates: odometry messages measured on the link below ``min_sensor_rate_hz`` hold a driving rover (a
line that cannot carry what the estimator needs; before that, the arming checks refuse); rangefinders that report slowly limit the speed to
``range_travel_m`` per reading interval.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Mapping

from rover_ctl.config import FailsafeParams
from rover_ctl.vocabulary import Severity

EN = tuple[float, float]


class Action(enum.IntEnum):
    """What the daemon must do; a higher value wins."""

    NONE = 0
    BACK_OFF = 1
    """Drive backwards at ``back_off_speed_mps`` (stuck)."""
    RTL = 2
    HOLD = 3
    """Stop and stay (motors commanded to zero speed)."""
    NEUTRAL = 4
    """Motors neutral and hold: no point commanding a vehicle that does not answer."""


RANGE_INTERVAL_GAIN = 0.2
"""Smoothing of the measured interval between rangefinder readings (first-order, per reading)."""

GCS_ACTIONS = {"continue": Action.NONE, "hold": Action.HOLD, "rtl": Action.RTL}
FENCE_ACTIONS = {"hold": Action.HOLD, "rtl": Action.RTL}


@dataclass(frozen=True)
class FailsafeInputs:
    vehicle_age_s: float
    """Since the last message of any kind on the vehicle link."""
    gcs_age_s: float = math.inf
    """Since the last GCS heartbeat; inf while none was ever seen (no GCS failsafe then)."""
    gps_age_s: float = 0.0
    """Since the last GPS fix with fix_type >= 2."""
    range_ages_s: Mapping[int, float] = field(default_factory=dict)
    """Age of the last DISTANCE_SENSOR per orientation (0 front, 2 right, 4 back, 6 left, ...)."""
    estimator_healthy: bool = True
    inside_fence: bool = True
    """``Planner.is_inside_fence`` of the estimated position."""
    driving: bool = False
    commanded_speed_mps: float = 0.0
    wants_progress: bool = False
    """The rule base was given a speed to make, with no yield holding the rover back and something
    ahead of it, whatever it commands."""
    position_en: EN | None = None
    """Estimated position, for the stuck test."""
    range_times_s: Mapping[int, float] = field(default_factory=dict)
    """Vehicle time of the last DISTANCE_SENSOR per orientation (the reading interval)."""
    sensor_rates_hz: Mapping[str, float] = field(default_factory=dict)
    """Measured rate on the vehicle link of each odometry message that has arrived at all
    (ATTITUDE, WHEEL_DISTANCE); one below ``min_sensor_rate_hz`` holds the rover."""


@dataclass(frozen=True)
class FailsafeEvent:
    text: str
    severity: Severity


@dataclass(frozen=True)
class FailsafeDecision:
    action: Action
    reasons: tuple[str, ...]
    events: tuple[FailsafeEvent, ...]
    blocked_orientations: frozenset[int]
    dead_reckoning: bool
    replan: bool
    stuck_tries: int = 0
    """Back-offs so far in the current stuck episode (the daemon widens each re-plan's detour)."""
    speed_limit_mps: float | None = None
    """Degraded sensing: drive no faster than this (None: no failsafe limit)."""


class _Latch:
    """Active once ``bad`` has held for ``trigger_s``; inactive once it has been false for
    ``recovery_s``. The delays are passed on every update, so a changed parameter applies at once."""

    def __init__(self) -> None:
        self.active = False
        self._since: float | None = None  # start of the current run of bad (or good, when active)

    def update(self, now_s: float, bad: bool, trigger_s: float, recovery_s: float) -> bool | None:
        """Returns True on the trigger edge, False on the clear edge, None otherwise."""
        if bad != self.active:
            self._since = now_s if self._since is None else self._since
            if now_s - self._since >= (trigger_s if bad else recovery_s):
                self.active, self._since = bad, None
                return bad
        else:
            self._since = None
        return None


class _Stuck(enum.Enum):
    WATCHING = "watching"
    BACKING_OFF = "backing_off"
    GAVE_UP = "gave_up"


class Failsafes:
    """All failsafes with their state (see the module docstring)."""

    def __init__(self, params: FailsafeParams) -> None:
        if params.gcs_action not in GCS_ACTIONS:
            raise ValueError(f"failsafe.gcs_action: {params.gcs_action!r} is not one of {', '.join(GCS_ACTIONS)}")
        if params.fence_action not in FENCE_ACTIONS:
            raise ValueError(f"failsafe.fence_action: {params.fence_action!r} is not one of {', '.join(FENCE_ACTIONS)}")
        self.params = params  # read at every update: a changed parameter applies at the next step
        self.used_rangefinders: frozenset[int] = frozenset()
        """Orientations the navigator reads: the rangefinder plan's (``rover_ctl.navigation.sensors``),
        set by the autopilot once the rover's rangefinders are known."""
        self._vehicle = _Latch()
        self._gcs = _Latch()
        self._gps = _Latch()
        self._dead_reckoning_over = _Latch()
        self._estimator = _Latch()
        self._fence = _Latch()
        self._sensor_rate = _Latch()
        self._range_seen_s: dict[int, float] = {}
        self._range_interval_s: dict[int, float] = {}
        self._ranges: dict[int, _Latch] = {}
        self._stuck = _Stuck.WATCHING
        self._tries = 0
        self._anchor: tuple[float, EN] | None = None  # (time, position) progress is measured from
        self._back_off_until_s = 0.0
        self._free_from: EN | None = None  # where the last back-off ended

    def update(self, now_s: float, inputs: FailsafeInputs) -> FailsafeDecision:
        p = self.params
        events: list[FailsafeEvent] = []
        actions: dict[str, Action] = {}

        def check(latch: _Latch, name: str, bad: bool, action: Action, what: str, trigger_s: float = 0.0) -> None:
            edge = latch.update(now_s, bad, trigger_s, p.recovery_s)
            if edge is True:
                severity = Severity.CRITICAL if action >= Action.HOLD else Severity.WARNING
                events.append(FailsafeEvent(f"FS {name}: {what}"[:50], severity))
            elif edge is False:
                events.append(FailsafeEvent(f"FS {name} cleared"[:50], Severity.INFO))
            if latch.active:
                actions[name] = action

        check(self._vehicle, "vehicle link", inputs.vehicle_age_s > p.vehicle_timeout_s, Action.NEUTRAL, "motors neutral")
        gcs_action = GCS_ACTIONS[p.gcs_action]
        gcs_bad = math.isfinite(inputs.gcs_age_s) and inputs.gcs_age_s > p.gcs_timeout_s
        check(self._gcs, "GCS lost", gcs_bad, gcs_action, p.gcs_action)
        # Before the first fix (age inf) and the first estimate there is nothing to lose: the
        # arming checks wait for them ("no position").
        had_fix = math.isfinite(inputs.gps_age_s)
        check(self._gps, "GPS lost", had_fix and inputs.gps_age_s > p.gps_timeout_s, Action.NONE, "dead reckoning")
        dr_over = had_fix and inputs.gps_age_s > p.gps_timeout_s + p.dead_reckoning_max_s
        check(self._dead_reckoning_over, "GPS lost too long", dr_over, Action.HOLD, "hold")
        unhealthy = inputs.position_en is not None and not inputs.estimator_healthy
        check(self._estimator, "estimator", unhealthy, Action.HOLD, "unhealthy, hold", p.estimator_unhealthy_s)
        fence_action = FENCE_ACTIONS[p.fence_action]
        check(self._fence, "fence breach", not inputs.inside_fence, fence_action, p.fence_action)
        # Only while driving: a vehicle still booting sends nothing yet; arming checks the rates.
        slow = sorted((hz, name) for name, hz in inputs.sensor_rates_hz.items() if hz < p.min_sensor_rate_hz and inputs.driving)
        what = f"{slow[0][1]} {slow[0][0]:.1f} Hz, hold" if slow else ""
        check(self._sensor_rate, "sensor rate", bool(slow), Action.HOLD, what)

        required = self.required_rangefinders()
        watched = self.used_rangefinders | required
        ages = {o: math.inf for o in watched} | {o: a for o, a in inputs.range_ages_s.items() if o in watched}
        for orientation in sorted(self._ranges.keys() - ages.keys()):  # no longer watched
            if self._ranges.pop(orientation).active:
                events.append(FailsafeEvent(f"FS rangefinder {orientation} cleared", Severity.INFO))
        for orientation in sorted(ages):
            rf = self._ranges.get(orientation)
            if rf is None:
                rf = self._ranges[orientation] = _Latch()
            name = f"rangefinder {orientation}"
            silent = ages[orientation] > p.rangefinder_timeout_s
            if orientation in required:
                check(rf, name, silent, Action.HOLD, "silent, hold")
            else:
                check(rf, name, silent, Action.NONE, "silent, side blocked")
        blocked = frozenset(o for o, rf in self._ranges.items() if rf.active)
        degraded = any(o not in required for o in blocked)
        limit = p.degraded_speed_mps if degraded else None
        interval_s = self._range_intervals(inputs.range_times_s, blocked)
        if interval_s is not None:
            limit = min(limit if limit is not None else math.inf, p.range_travel_m / interval_s)

        replan = self._stuck_step(now_s, inputs, events, actions)

        action = max(actions.values(), default=Action.NONE)
        reasons = tuple(actions)
        return FailsafeDecision(action, reasons, tuple(events), blocked, self._gps.active, replan, self._tries, limit)

    def _range_intervals(self, times_s: Mapping[int, float], blocked: frozenset[int]) -> float | None:
        """The longest smoothed interval between two readings of a used, reporting rangefinder.
        A reading is new when its time moved on; the interval is smoothed over a few
        readings so one late message does not brake the rover; a gap longer than
        ``rangefinder_timeout_s`` is a silence, the failsafe's business, and is not counted."""
        for orientation in self.used_rangefinders:
            seen_s = times_s.get(orientation)
            if seen_s is None:
                continue
            last_s = self._range_seen_s.get(orientation)
            # A gap longer than the timeout is a silence (the failsafe above), not a rate.
            if last_s is not None and last_s + 1e-9 < seen_s <= last_s + self.params.rangefinder_timeout_s:
                gap_s = seen_s - last_s
                previous = self._range_interval_s.get(orientation, gap_s)
                self._range_interval_s[orientation] = previous + RANGE_INTERVAL_GAIN * (gap_s - previous)
            self._range_seen_s[orientation] = seen_s
        intervals = [s for o, s in self._range_interval_s.items() if o in self.used_rangefinders and o not in blocked]
        return max(intervals) if intervals else None

    def required_rangefinders(self) -> frozenset[int]:
        """Orientations whose silence holds the rover (``params.required_rangefinders``; [-1]: the used ones)."""
        listed = list(self.params.required_rangefinders)
        return self.used_rangefinders if listed == [-1] else frozenset(listed)

    def _stuck_step(self, now_s: float, inputs: FailsafeInputs, events: list[FailsafeEvent], actions: dict[str, Action]) -> bool:
        """Commanded motion without progress: back off, re-plan; after ``stuck_max_tries``, hold."""
        p = self.params
        if not inputs.driving or inputs.position_en is None:
            if self._stuck is not _Stuck.WATCHING:
                events.append(FailsafeEvent("FS stuck cleared", Severity.INFO))
            self._stuck, self._tries, self._anchor, self._free_from = _Stuck.WATCHING, 0, None, None
            return False
        here = inputs.position_en
        if self._stuck is _Stuck.GAVE_UP:
            actions["stuck"] = Action.HOLD
            return False
        if self._stuck is _Stuck.BACKING_OFF:
            if now_s < self._back_off_until_s:
                actions["stuck"] = Action.BACK_OFF
                return False
            self._stuck, self._anchor, self._free_from = _Stuck.WATCHING, None, here
            return True
        if self._free_from is not None and math.dist(here, self._free_from) >= p.stuck_clear_m:
            self._tries, self._free_from = 0, None
        commanded = inputs.commanded_speed_mps > p.stuck_min_command_mps
        if not commanded and not (inputs.wants_progress and p.parked_window_s > 0.0):
            self._anchor = None
            return False
        if self._anchor is None or math.dist(here, self._anchor[1]) >= p.stuck_progress_m:
            self._anchor = (now_s, here)
            return False
        if now_s - self._anchor[0] < (p.stuck_window_s if commanded else p.parked_window_s):
            return False
        self._tries += 1
        if self._tries > p.stuck_max_tries:
            self._stuck = _Stuck.GAVE_UP
            events.append(FailsafeEvent("FS stuck: gave up, hold", Severity.CRITICAL))
            actions["stuck"] = Action.HOLD
            return False
        self._stuck, self._back_off_until_s = _Stuck.BACKING_OFF, now_s + p.back_off_s
        events.append(FailsafeEvent(f"FS stuck: backing off ({self._tries}/{p.stuck_max_tries})", Severity.WARNING))
        actions["stuck"] = Action.BACK_OFF
        return False
