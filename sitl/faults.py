"""Faults: the SIM_* parameters a test sets at run time, and the schedule a world file declares.

Both end up in one ``FaultState``: the value of each SIM_* parameter is the one set at run time,
overlaid by any scheduled fault active now (bitmasks are OR-ed, numbers replaced). Faults are named
after ArduPilot's SITL parameters where one exists. Link faults are held here but applied by the
MAVLink layer (``link_loss_pct``, ``link_quiet``).

Scheduled faults (world file ``"faults"``: ``{"name": ..., "start_s": t, "duration_s": d, ...}``):

============== ===================== ==========================================
name           extra members         effect while active
============== ===================== ==========================================
gps_outage                           no GPS fixes (SIM_GPS_DISABLE = 1)
gps_glitch     north_m, east_m       fixes jump by the offset (SIM_GPS_GLITCH_X/Y)
rangefinder_silent  sensor_id        that sensor sends nothing (SIM_RF_FAIL bit)
rangefinder_stuck   sensor_id        that sensor repeats its last value (SIM_RF_STUCK bit)
wheel_slip     fraction              ground moves (1 - fraction) of what the wheels roll
link_quiet                           the vehicle sends nothing (SIM_LINK_QUIET = 1)
link_loss      pct                   that percentage of messages is lost both ways
============== ===================== ==========================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from sitl.geodesy import WORLD_EXTENT_M

FAULT_PARAMS: dict[str, tuple[float, str]] = {
    "SIM_GPS_DISABLE": (0.0, "1: the GPS reports no fix (outage)"),
    "SIM_GPS_GLITCH_X": (0.0, "GPS position offset north, m (a glitch is a jump of this size)"),
    "SIM_GPS_GLITCH_Y": (0.0, "GPS position offset east, m"),
    "SIM_RF_FAIL": (0.0, "bitmask of rangefinder ids that go silent"),
    "SIM_RF_STUCK": (0.0, "bitmask of rangefinder ids that repeat their last reading"),
    "SIM_WHEEL_SLIP": (0.0, "fraction 0..1 of the wheels' rolling lost to slip (encoders over-read)"),
    "SIM_LINK_LOSS": (0.0, "percentage 0..100 of MAVLink messages dropped, both directions"),
    "SIM_LINK_QUIET": (0.0, "1: the vehicle stops sending anything"),
}

_MASKS = ("SIM_RF_FAIL", "SIM_RF_STUCK")
_RANGES = {"SIM_WHEEL_SLIP": (0.0, 1.0), "SIM_LINK_LOSS": (0.0, 100.0),
           "SIM_GPS_GLITCH_X": (-WORLD_EXTENT_M, WORLD_EXTENT_M), "SIM_GPS_GLITCH_Y": (-WORLD_EXTENT_M, WORLD_EXTENT_M)}
"""The numeric parameters' ranges (the others are any finite number, or a bitmask). A glitch moves
the fix at most a world's extent (sitl.geodesy.WORLD_EXTENT_M): a receiver's own jumps are tens of
metres, and 1e300 m wrapped the fix around the Earth to a meaningless place. PARAM_SET, --param
and a world's gps_glitch fault all pass through check_param."""

# Scheduled fault name -> (its required members, function of the members -> SIM_* values).
_SCHEDULED = {
    "gps_outage": ((), lambda p: {"SIM_GPS_DISABLE": 1.0}),
    "gps_glitch": (("north_m", "east_m"), lambda p: {"SIM_GPS_GLITCH_X": p["north_m"], "SIM_GPS_GLITCH_Y": p["east_m"]}),
    "rangefinder_silent": (("sensor_id",), lambda p: {"SIM_RF_FAIL": float(1 << int(p["sensor_id"]))}),
    "rangefinder_stuck": (("sensor_id",), lambda p: {"SIM_RF_STUCK": float(1 << int(p["sensor_id"]))}),
    "wheel_slip": (("fraction",), lambda p: {"SIM_WHEEL_SLIP": p["fraction"]}),
    "link_quiet": ((), lambda p: {"SIM_LINK_QUIET": 1.0}),
    "link_loss": (("pct",), lambda p: {"SIM_LINK_LOSS": p["pct"]}),
}
SCHEDULED_FAULTS = tuple(_SCHEDULED)


class FaultError(ValueError):
    """An unknown fault or parameter, or a value out of range."""


def check_param(name: str, value: float) -> float:
    """The value as float, or FaultError naming the parameter and what is wrong."""
    if name not in FAULT_PARAMS:
        raise FaultError(f"unknown fault parameter {name!r} (known: {', '.join(FAULT_PARAMS)})")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise FaultError(f"{name}: expected a number, got {value!r}") from None
    if not math.isfinite(number):
        raise FaultError(f"{name}: expected a finite number, got {value!r}")
    low, high = _RANGES.get(name, (-math.inf, math.inf))
    if name in _MASKS and (number < 0 or number != int(number)):
        raise FaultError(f"{name}: expected a non-negative integer bitmask, got {value!r}")
    if not low <= number <= high:
        raise FaultError(f"{name}: {number:g} is outside {low:g}..{high:g}")
    return number


@dataclass(frozen=True)
class ScheduledFault:
    """One fault window from a world file."""

    name: str
    start_s: float
    duration_s: float
    params: dict = field(default_factory=dict)

    @property
    def end_s(self) -> float:
        return self.start_s + self.duration_s

    def values(self) -> dict[str, float]:
        """The SIM_* parameters this fault sets while active."""
        return _SCHEDULED[self.name][1](self.params)

    def to_json(self) -> dict:
        return {"name": self.name, "start_s": self.start_s, "duration_s": self.duration_s, **self.params}


def parse_fault(entry: object) -> ScheduledFault:
    """A ScheduledFault from its JSON object, or FaultError saying what is wrong."""
    if not isinstance(entry, dict):
        raise FaultError(f"expected an object, got {type(entry).__name__}")
    name = entry.get("name")
    if name not in _SCHEDULED:
        raise FaultError(f"unknown fault {name!r} (known: {', '.join(SCHEDULED_FAULTS)})")
    numbers = {}
    required = _SCHEDULED[name][0]
    for key in ("start_s", "duration_s", *required):
        value = entry.get(key)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise FaultError(f"{name}: {key!r} must be a number, got {value!r}")
        numbers[key] = float(value)
    extra = sorted(set(entry) - {"name", "start_s", "duration_s", *required})
    if extra:
        raise FaultError(f"{name}: unexpected member(s) {', '.join(extra)}")
    # the rover counts to the end in physics substeps: 1e308 + 1e308 overflowed it
    if numbers["start_s"] < 0 or numbers["duration_s"] <= 0 or math.isinf(numbers["start_s"] + numbers["duration_s"]):
        raise FaultError(f"{name}: start_s must be >= 0 and duration_s > 0, with a finite end")
    fault = ScheduledFault(name, numbers["start_s"], numbers["duration_s"], {k: numbers[k] for k in required})
    if "sensor_id" in fault.params and not (fault.params["sensor_id"].is_integer() and 0 <= fault.params["sensor_id"] < 32):
        raise FaultError(f"{name}: sensor_id must be an integer 0..31")
    for param, value in fault.values().items():
        check_param(param, value)
    return fault


class FaultState:
    """The effective SIM_* values now: run-time settings overlaid by the active scheduled faults."""

    def __init__(self, schedule: list[ScheduledFault] | tuple = ()) -> None:
        self.schedule = sorted(schedule, key=lambda f: f.start_s)
        self.manual = {name: default for name, (default, _doc) in FAULT_PARAMS.items()}
        self.active: list[ScheduledFault] = []
        self.values = dict(self.manual)

    def set(self, name: str, value: float) -> None:
        self.manual[name] = check_param(name, value)
        self._combine()

    def transitions(self) -> list[float]:
        """Every time at which a scheduled fault starts or ends, sorted."""
        return sorted({t for f in self.schedule for t in (f.start_s, f.end_s)})

    def update(self, time_s: float) -> list[tuple[ScheduledFault, bool]]:
        """Activate and deactivate scheduled faults for ``time_s``; the (fault, active) changes."""
        now = [f for f in self.schedule if f.start_s <= time_s < f.end_s]
        changes = [(f, False) for f in self.active if f not in now] + [(f, True) for f in now if f not in self.active]
        if changes:
            self.active = now
            self._combine()
        return changes

    def _combine(self) -> None:
        values = dict(self.manual)
        for fault in self.active:
            for name, value in fault.values().items():
                values[name] = float(int(values[name]) | int(value)) if name in _MASKS else value
        self.values = values

    # Typed views of the effective values, used by the sensors and the MAVLink layer.
    @property
    def gps_disabled(self) -> bool:
        return self.values["SIM_GPS_DISABLE"] != 0

    @property
    def gps_glitch_en_m(self) -> tuple[float, float]:
        return self.values["SIM_GPS_GLITCH_Y"], self.values["SIM_GPS_GLITCH_X"]

    def rangefinder_silent(self, sensor_id: int) -> bool:
        return bool(int(self.values["SIM_RF_FAIL"]) >> sensor_id & 1)

    def rangefinder_stuck(self, sensor_id: int) -> bool:
        return bool(int(self.values["SIM_RF_STUCK"]) >> sensor_id & 1)

    @property
    def wheel_slip(self) -> float:
        return self.values["SIM_WHEEL_SLIP"]

    @property
    def link_loss_pct(self) -> float:
        return self.values["SIM_LINK_LOSS"]

    @property
    def link_quiet(self) -> bool:
        return self.values["SIM_LINK_QUIET"] != 0
