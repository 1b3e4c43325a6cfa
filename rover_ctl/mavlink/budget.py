"""The vehicle link's byte budget: which messages the daemon asks for, and at what rates.

A serial line at 57600 baud carries 5760 bytes per second each way (8N1: ten bits per byte; a SiK
radio shares its air rate between the two directions, which the share below leaves room for); the messages a controller could ask for add up to three times that. So the daemon asks only
for what it reads, turns the rest off, and picks each rate so that the total stays inside a share
of the line (``link.line_use_max``), leaving the rest for what it cannot schedule (heartbeats,
command acknowledgements, STATUSTEXT, ArduPilot's TIMESYNC probes).

How ArduPilot is asked (checked on its Rover firmware): REQUEST_DATA_STREAM(ALL, stop) silences
every stream; WHEEL_DISTANCE can only be had through the EXTRA1 stream (SET_MESSAGE_INTERVAL
refuses it), which also carries ATTITUDE and messages the daemon does not read (SIMSTATE, AHRS2,
...), switched off one by one with SET_MESSAGE_INTERVAL(-1); the other messages get their own
SET_MESSAGE_INTERVAL. rover-sitl behaves the same (sitl/mavlink_vehicle.py).

The rates come from a priority order (``TIERS``): every stream first gets its minimum; then,
while the budget lasts, GPS to ``daemon.gps_rate_hz`` and odometry up to ``daemon.core_rate_hz``,
the rangefinders for avoidance up to the same, odometry and attitude up to the control rate, the
rangefinders up to their configured rate, then everything else. A tier that does not fit whole is
filled as far as it goes and the fill stops there. Sizes are the MAVLink 2 frames: measured
averages once the link has seen a message (zero-truncation makes most frames shorter than their
payload), the full frame before.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from rover_ctl.config import DaemonParams, FailsafeParams, LinkParams
from rover_ctl.vocabulary import mav

HEADER_BYTES = 10
"""MAVLink 2 header (STX, len, incompat/compat flags, seq, sysid, compid, 3-byte msgid)."""
CRC_BYTES = 2
BITS_PER_BYTE = 10
"""A UART byte with 8N1 framing: start bit, 8 data bits, stop bit."""

EXTRA1 = "EXTRA1"
"""The stream group that carries WHEEL_DISTANCE and ATTITUDE (and is asked for as a stream)."""
EXTRA1_UNREAD = ("SIMSTATE", "AHRS2", "PID_TUNING", "RPM", "ESC_TELEMETRY_1_TO_4")
"""Messages ArduPilot Rover sends in EXTRA1 that the daemon does not read (SIMSTATE is asked for
separately when ground truth is wanted)."""
MIN_RATE_MARGIN = 1.5
"""The odometry stream is never planned below this times the failsafe's minimum rate, so that one
late or lost frame does not read as a line too slow to drive on."""
FIXED_RATES_HZ = {"HEARTBEAT": 1.0}
"""What the vehicle sends whatever it is asked: counted against the budget, never requested."""


def frame_bytes(name: str) -> int:
    """The largest MAVLink 2 frame of message ``name`` (full payload, unsigned)."""
    return HEADER_BYTES + mav.mavlink_map[getattr(mav, f"MAVLINK_MSG_ID_{name}")].unpacker.size + CRC_BYTES


def line_bytes_per_s(url: str, link: LinkParams) -> tuple[float, str]:
    """The line's capacity one way and where the figure came from.

    ``link.line_bytes_per_s`` when set; else a serial device (``DEVICE,BAUD``, pymavlink's form)
    carries baud / 10; else a network link gets ``link.network_bytes_per_s``."""
    if link.line_bytes_per_s > 0:
        return link.line_bytes_per_s, "LINK_LINE_BPS"
    baud = serial_baud(url)
    if baud is not None:
        return baud / BITS_PER_BYTE, f"{baud} baud"
    return link.network_bytes_per_s, "network link"


def serial_baud(url: str) -> int | None:
    """The baud rate of a serial connection string (``/dev/ttyUSB0,57600``), or None when the
    string is not a serial device or gives no rate."""
    if not is_serial(url) or "," not in url:
        return None
    try:
        baud = int(url.rsplit(",", 1)[1])
    except ValueError:
        return None
    return baud if baud > 0 else None


def is_serial(url: str) -> bool:
    """A serial device rather than a network endpoint, by pymavlink's rule: a device (before any
    ``,BAUD``) with a ``:`` in it is a network address (``udpin:``, ``tcp:``, ``127.0.0.1:14550``,
    ...); ``/dev/ttyUSB0`` or ``COM4`` is serial."""
    return ":" not in url.split(",", 1)[0]


@dataclass(frozen=True)
class Stream:
    """One thing to ask for: a message (or EXTRA1, carrying ``members``) ``count`` times per period."""

    name: str
    members: tuple[str, ...]
    count: int
    minimum_hz: float
    wanted_hz: float


@dataclass(frozen=True)
class StreamPlan:
    rates_hz: dict[str, float]
    """Per stream name (``EXTRA1`` for WHEEL_DISTANCE with ATTITUDE), 0 = off."""
    bytes_per_s: float
    """What the plan asks the vehicle for, fixed messages included."""
    budget_bytes_per_s: float
    line_bytes_per_s: float
    source: str
    """Where the line's capacity came from (baud rate, parameter, network default)."""
    shortfall: str | None = None
    """Why even the minimum rates do not fit, or None."""
    sizes: dict[str, float] = field(default_factory=dict)

    @property
    def line_use(self) -> float:
        return self.bytes_per_s / self.line_bytes_per_s if self.line_bytes_per_s > 0 else math.inf

    def describe(self) -> str:
        rates = ", ".join(f"{name} {hz:g} Hz" for name, hz in self.rates_hz.items() if hz > 0)
        return (f"{self.bytes_per_s:.0f} B/s of {self.line_bytes_per_s:.0f} B/s ({self.source}, "
                f"{100 * self.line_use:.0f}%): {rates}")  # fmt: skip


def streams(daemon: DaemonParams, failsafe: FailsafeParams, rangefinders: int, truth: bool) -> list[Stream]:
    """What the daemon reads, with its minimum and wanted rates (``rangefinders``: how many
    DISTANCE_SENSOR the vehicle sends per period). The odometry minimum is the failsafe's with a
    margin: below the failsafe's the rover holds, so planning that close would plan a rover that
    holds on one late frame. GPS likewise: at least ``MIN_RATE_MARGIN`` fixes per
    ``failsafe.gps_timeout_s``, or every fix would arrive just as the GPS failsafe (and the
    pre-arm fix check) calls it lost."""
    gps_min_hz = max(daemon.min_gps_rate_hz, MIN_RATE_MARGIN / failsafe.gps_timeout_s)
    out = [
        Stream(EXTRA1, ("WHEEL_DISTANCE", "ATTITUDE"), 1, MIN_RATE_MARGIN * failsafe.min_sensor_rate_hz, daemon.sensor_rate_hz),
        Stream("GPS_RAW_INT", ("GPS_RAW_INT",), 1, gps_min_hz, max(daemon.gps_rate_hz, gps_min_hz)),
        Stream("SYS_STATUS", ("SYS_STATUS",), 1, daemon.status_rate_hz, daemon.status_rate_hz),
    ]
    if rangefinders:
        out.append(Stream("DISTANCE_SENSOR", ("DISTANCE_SENSOR",), rangefinders,
                          daemon.min_rangefinder_rate_hz, daemon.rangefinder_rate_hz))  # fmt: skip
    if truth and daemon.truth_rate_hz > 0:
        out.append(Stream("SIMSTATE", ("SIMSTATE",), 1, 0.0, daemon.truth_rate_hz))
    return out


def tiers(daemon: DaemonParams) -> list[tuple[str, float]]:
    """The fill order after the minimums: (stream, rate to raise it to)."""
    core, control = daemon.core_rate_hz, daemon.control_rate_hz
    return [
        ("GPS_RAW_INT", daemon.gps_rate_hz),  # position: a few bytes a second, never starved
        (EXTRA1, core),  # odometry and heading for the estimator
        ("DISTANCE_SENSOR", core),  # avoidance
        (EXTRA1, control),  # a fresh odometry reading for every control step
        ("DISTANCE_SENSOR", daemon.rangefinder_rate_hz),
        (EXTRA1, daemon.sensor_rate_hz),
        ("SIMSTATE", daemon.truth_rate_hz),  # evaluation only
    ]


def plan(daemon: DaemonParams, link: LinkParams, failsafe: FailsafeParams, url: str, rangefinders: int,
         truth: bool = True, measured_bytes: Mapping[str, float] | None = None) -> StreamPlan:  # fmt: skip
    """Rates for every stream inside ``link.line_use_max`` of the line (see the module doc).
    Whole hertz where a stream is asked for in hertz (REQUEST_DATA_STREAM); at least the minimum."""
    line, source = line_bytes_per_s(url, link)
    budget = line * link.line_use_max
    measured = measured_bytes or {}

    def size(names: tuple[str, ...]) -> float:
        return sum(measured.get(n) or frame_bytes(n) for n in names)

    wanted = {s.name: s for s in streams(daemon, failsafe, rangefinders, truth)}
    per_period = {s.name: size(s.members) * s.count for s in wanted.values()}
    fixed = sum(size((name,)) * hz for name, hz in FIXED_RATES_HZ.items())
    rates = {name: min(s.minimum_hz, s.wanted_hz) for name, s in wanted.items()}
    rates[EXTRA1] = math.ceil(rates[EXTRA1])  # a stream rate is whole hertz

    def used() -> float:
        return fixed + sum(per_period[n] * hz for n, hz in rates.items())

    shortfall = None
    if used() > budget:
        shortfall = (f"the minimum rates need {used():.0f} B/s, the line gives {budget:.0f} B/s "
                     f"({100 * link.line_use_max:.0f}% of {line:.0f} B/s, {source})")  # fmt: skip
    else:
        for name, target_hz in tiers(daemon):
            if name not in wanted or target_hz <= rates[name]:
                continue
            target_hz = min(target_hz, wanted[name].wanted_hz)
            room_hz = (budget - used()) / per_period[name]
            new_hz = min(target_hz, rates[name] + room_hz)
            # Rounded down: whole hertz for the stream, 0.01 Hz (an interval in microseconds) otherwise.
            new_hz = math.floor(new_hz) if name == EXTRA1 else math.floor(new_hz * 100.0) / 100.0
            rates[name] = max(rates[name], new_hz)
            if new_hz < target_hz:
                break  # the line is full: lower tiers keep their minimums
    sizes = {name: per_period[name] / wanted[name].count for name in wanted}
    return StreamPlan(rates, used(), budget, line, source, shortfall, sizes)
