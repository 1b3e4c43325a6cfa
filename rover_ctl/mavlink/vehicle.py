"""The vehicle link: the daemon's MAVLink connection to the rover (or ``rover-sitl``).

It owns one pymavlink connection (serial, udp or tcp connection string) and does four jobs:

* identify itself as a ground station (HEARTBEAT as MAV_TYPE_GCS with the system id the vehicle
  accepts RC overrides from, ArduPilot's MAV_GCS_SYSID, formerly SYSID_MYGCS, 255 by default),
  find the vehicle's heartbeat and ask for its AUTOPILOT_VERSION (which tells rover-sitl in
  lockstep from anything else, see "Time sync" below) and, from an ArduPilot vehicle, the
  parameters the pre-arm checks need (``VEHICLE_PARAMS``: PILOT_STEER_TYPE);
* ask for the message rates of the daemon's link budget and nothing else
  (``rover_ctl.mavlink.budget``: every stream off, EXTRA1 for WHEEL_DISTANCE, which ArduPilot
  only sends in that stream, SET_MESSAGE_INTERVAL per other message), and measure what arrives
  (``rover_ctl.mavlink.link_health``: rates, bytes, sequence gaps, bad CRCs);
* decode what arrives into typed items (``rover_ctl.estimation.readings`` for sensors, the small classes
  below for the rest); frames that fail to parse are counted and dropped. Input is read in whole
  buffers (one system call for everything waiting) and parsed with pymavlink's parser: its
  ``recv_msg`` makes a system call per message (a few per message on TCP), which at 10x-50x
  speed-up was most of the loop's time;
* send commands: COMMAND_LONG with COMMAND_ACK (asynchronous with retries, or blocking for
  start-up), RC_CHANNELS_OVERRIDE and the lockstep TIMESYNC answers.

Time sync. Every TIMESYNC request (tc1 == 0) is answered as the MAVLink spec asks,
TIMESYNC(tc1 = our clock in ns, ts1 echoed): ArduPilot sends one every 10 s on each port as a latency
probe, and that is all it is. Only a vehicle that announced lockstep (AUTOPILOT_VERSION with
``flight_custom_version == b"lockstep"``, which rover-sitl --lockstep sends) has its requests
taken as end-of-frame markers, and only those from the system and component that announced it:
they become ``FrameMarker`` items, answered by the daemon after its control step for that frame
(docs/architecture.md, "Lockstep handshake"). The answer is the same message either way. Until
the vehicle's AUTOPILOT_VERSION is known (at most ``VERSION_WAIT_S``), its requests wait
unanswered: answered as plain time sync, a lockstep emulator's first markers would let it run on
while the daemon, not yet stepping frame by frame, read its frames in whatever batches the wall
clock made; a lockstep run then went differently from run to run.

SIMSTATE (the emulator's ground truth) is decoded into ``Truth`` for evaluation only; the daemon
never navigates on it. Times in decoded items are vehicle time; the wall clock is used only for
link housekeeping (heartbeats, command retries, silence detection).
"""

from __future__ import annotations

import dataclasses
import logging
from collections import deque
import math
import os
import select
import time
from dataclasses import dataclass
from typing import Any, Callable

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from rover_ctl.config import LinkParams  # noqa: E402
from rover_ctl.estimation.readings import Attitude, GpsFix, RangeReading, WheelDistance  # noqa: E402
from rover_ctl.mavlink import budget  # noqa: E402
from rover_ctl.mavlink.link_health import LinkHealth  # noqa: E402
from rover_ctl.mavlink.telemetry import StatusTextAssembler  # noqa: E402
from rover_ctl.vocabulary import PILOT_STEER_TYPE  # noqa: E402
# The dialect module itself, not mavutil.mavlink: that is whichever dialect was current when this
# module was imported (MAVLink 1's "all" if gcs.py, say, imported mavutil before MAVLINK20 was set).
from rover_ctl.vocabulary import mav as mavlink  # noqa: E402

log = logging.getLogger(__name__)

UINT16_MAX = 65535
RC_RELEASE = 0
"""RC_CHANNELS_OVERRIDE channels 1-8: 0 hands the channel back to the radio, UINT16_MAX leaves it."""
EPOCH_THRESHOLD_US = 10**15
"""A time_usec above this (31 years of uptime) is UNIX epoch time, not time since boot; the MAVLink
spec lets the receiver tell the two apart by magnitude."""
RANGE_CAPPED_CM = 65535
"""What rangefinders report for "nothing seen"; 0 is also used while a sensor starts."""
LOCKSTEP_ANNOUNCEMENT = b"lockstep"
"""AUTOPILOT_VERSION.flight_custom_version of a vehicle whose TIMESYNC requests are lockstep frame
markers (rover-sitl --lockstep; ArduPilot puts the first 8 bytes of its git hash there)."""
READ_SIZE_BYTES = 65536
"""Largest read from the connection at once (a UDP datagram is at most this)."""
VERSION_WAIT_S = 2.0
"""Wall seconds from the vehicle's first TIMESYNC request during which the daemon does not answer
such requests on a socket link, until the vehicle's AUTOPILOT_VERSION says whether they are
lockstep markers: a lockstep emulator then waits for the daemon from its first frame on, every
frame a step (time sync, below). A vehicle that never answers is answered after this; ArduPilot's
latency probe, one in 10 s, is answered a moment late once."""
MAX_READS_PER_POLL = 16
"""Reads of the connection in one ``poll`` (each up to READ_SIZE_BYTES)."""
WRONG_BAUD_BYTES = 4096
"""Bytes received without a single MAVLink frame after which a serial line is called wrong (at
57600 a vehicle sends that in well under two seconds)."""
PYMAVLINK_DEFAULT_BAUD = 115200
NO_ANSWER = -1
"""``CommandResult.result`` of a command no COMMAND_ACK answered after all retries."""
MAX_COMMAND_WAITERS = 8
"""Callers one outstanding command answers (a repeat of it joins them instead of being sent)."""
VEHICLE_PARAMS = (PILOT_STEER_TYPE,)
"""ArduPilot parameters read from the vehicle at connect (PARAM_REQUEST_READ, answered by
PARAM_VALUE), for the pre-arm checks; only an ArduPilot vehicle is asked."""
PARAM_READ_PERIOD_S = 1.0
"""Wall seconds between two PARAM_REQUEST_READs of a parameter not answered yet."""
PARAM_READ_TRIES = 10
"""Requests per parameter before the daemon stops asking (and the check it feeds is skipped)."""


class LinkError(RuntimeError):
    """The vehicle link cannot do what was asked (no vehicle, command refused or unanswered)."""


@dataclass(frozen=True)
class VehicleParam:
    """A PARAM_VALUE of the vehicle for one of VEHICLE_PARAMS."""

    name: str
    value: float


@dataclass(frozen=True)
class VehicleStatus:
    """The vehicle's HEARTBEAT."""

    wall_s: float
    armed: bool
    custom_mode: int
    system_status: int


@dataclass(frozen=True)
class Truth:
    """SIMSTATE ground truth (evaluation only). ``time_s`` is the link's vehicle time at receipt."""

    time_s: float
    lat_deg: float
    lon_deg: float
    yaw_rad: float
    """NED: 0 north, clockwise positive."""


@dataclass(frozen=True)
class VehicleVersion:
    """The vehicle's AUTOPILOT_VERSION (asked for once its heartbeat is seen)."""

    flight_sw_version: int
    custom_version: bytes
    lockstep: bool
    """The vehicle announced lockstep: its TIMESYNC requests are frame markers."""


@dataclass(frozen=True)
class FrameMarker:
    """A lockstep end-of-frame marker: TIMESYNC with tc1 == 0 from a vehicle that announced lockstep."""

    time_s: float
    ts1_ns: int


@dataclass(frozen=True)
class StatusText:
    time_s: float
    severity: int
    text: str


@dataclass(frozen=True)
class RadioStatus:
    """RADIO_STATUS from a SiK telemetry radio: signal levels and the local radio's buffer."""

    rssi: int
    remote_rssi: int
    txbuf_pct: int
    """Free space in the local radio's transmit buffer, percent."""
    rx_errors: int
    fixed: int
    wall_s: float = 0.0
    """When it arrived (wall clock): a radio that stops reporting is not believed for ever."""


@dataclass(frozen=True)
class Battery:
    """SYS_STATUS: battery voltage and remaining charge (-1 when unknown)."""

    voltage_v: float
    remaining_pct: int


@dataclass(frozen=True)
class CommandResult:
    command: int
    result: int
    """MAV_RESULT, or NO_ANSWER when no ACK came after all retries."""

    @property
    def accepted(self) -> bool:
        return self.result == mavlink.MAV_RESULT_ACCEPTED


def decode_range(msg: Any, time_s: float) -> RangeReading:
    """DISTANCE_SENSOR -> RangeReading; 0, the 65535 cap and readings above max mean +inf."""
    current = msg.current_distance
    if current == 0 or current >= RANGE_CAPPED_CM or (msg.max_distance and current > msg.max_distance):
        range_m = math.inf
    else:
        range_m = current / 100.0
    return RangeReading(
        time_s=time_s,
        sensor_id=msg.id,
        orientation=msg.orientation,
        range_m=range_m,
        min_range_m=msg.min_distance / 100.0,
        max_range_m=msg.max_distance / 100.0,
    )


def decode_gps(msg: Any) -> GpsFix:
    def unknown16(value: int, scale: float) -> float:
        return math.nan if value == UINT16_MAX else value * scale

    return GpsFix(
        time_s=msg.time_usec / 1e6,
        lat_deg=msg.lat / 1e7,
        lon_deg=msg.lon / 1e7,
        alt_m=msg.alt / 1000.0,
        fix_type=msg.fix_type,
        eph_m=unknown16(msg.eph, 0.01),
        speed_mps=unknown16(msg.vel, 0.01),
        course_deg=unknown16(msg.cog, 0.01),
        satellites=msg.satellites_visible,
    )


@dataclass
class _Pending:
    command: int
    params: tuple[float, ...]
    sent_wall_s: float
    attempts: int
    waiters: list[Callable[[CommandResult], None]]

    def answer(self, result: CommandResult) -> None:
        for waiter in self.waiters:
            waiter(result)


class VehicleLink:
    """One MAVLink connection to the vehicle. Non-blocking except ``wait_vehicle`` and ``command``.

    ``poll()`` returns the decoded items received since the last call, in arrival order.
    """

    def __init__(
        self,
        url: str,
        params: LinkParams,
        *,
        command_timeout_s: float = 0.5,
        command_retries: int = 3,
        reconnect_period_s: float = 1.0,
        conn: Any = None,
        wall: Callable[[], float] = time.monotonic,
    ):
        self.params = params
        self.command_timeout_s = command_timeout_s
        self.command_retries = command_retries
        self._wall = wall
        try:
            self.conn = conn or mavutil.mavlink_connection(
                url,
                source_system=params.source_system,
                source_component=params.source_component,
                dialect="ardupilotmega",
                autoreconnect=True,
            )
        except Exception as exc:  # pymavlink raises bare OSError/SerialException/ValueError
            raise LinkError(f"vehicle link {url!r}: cannot open: {exc}") from None
        if hasattr(self.conn, "reconnect_delay"):
            # A TCP peer that went away is reconnected by pymavlink inside recv/write; one quick
            # attempt each time, never its default sleep-and-retry, which would stall the loop.
            self.conn.retries, self.conn.reconnect_delay = 0, 0.0
        self.link_error: str | None = None
        """Why the connection is down (None while it works); reads are retried every reconnect_period_s."""
        self.reconnect_period_s = reconnect_period_s
        self._retry_wall_s = 0.0
        # Every send goes through the connection's write: a failed one marks the link down
        # instead of raising out of whatever was sending.
        write = self.conn.write

        def guarded_write(buf: bytes) -> Any:
            try:
                return write(buf)
            except OSError as exc:
                self._down(exc)
                return None

        self.conn.write = guarded_write
        self._byte_stream = isinstance(self.conn, (mavutil.mavtcp, mavutil.mavtcpin, mavutil.mavserial))
        """TCP or a serial line (a read returns what is waiting), not datagrams (one per read)."""
        self.url = url
        self.target_system = 1
        self.target_component = 1
        self.vehicle: VehicleStatus | None = None
        self.last_rx_wall_s: float | None = None
        """Wall time of the last message from the vehicle (lockstep markers excluded)."""
        self.last_poll_wall_s: float | None = None
        """Wall time at the start of the latest poll. Silence is known only up to the last look at
        the link: a daemon that stalled after it (a slow SD card, a starved core) has not heard
        silence, whatever the wall clock says, until it reads again."""
        self.last_rx_vehicle_s: float | None = None
        """Vehicle time at the last message from the vehicle (lockstep markers excluded)."""
        self.vehicle_time_s = 0.0
        """Latest vehicle timestamp seen (sensor clock)."""
        self.last_gps_msg: Any = None
        """The latest GPS_RAW_INT as received, forwarded to ground stations unchanged."""
        self.frames_received = 0
        self.garbage_frames = 0
        self.rx_bytes = 0
        self.health = LinkHealth(lambda: params.rate_window_s)
        """Rates, bytes and losses of what the vehicle sends (``rover_ctl.mavlink.link_health``)."""
        self.radio: RadioStatus | None = None
        """The latest RADIO_STATUS of a telemetry radio on the line, if there is one."""
        self._next_heartbeat_s = 0.0
        self._pending: dict[int, _Pending] = {}
        self._queued: dict[int, _Pending] = {}
        """Per command, the request with other parameters waiting for the pending one's answer."""
        self._held: list[Any] = []
        self._parsed: deque[Any] = deque()  # messages read but not decoded yet (a read can span frames)
        self.version: VehicleVersion | None = None
        self.lockstep_source: tuple[int, int] | None = None
        """(system, component) that announced lockstep; its TIMESYNC requests are frame markers."""
        self.probes_answered = 0
        """TIMESYNC requests answered as plain time sync (ArduPilot's latency probe)."""
        self._unanswered: tuple[int, int, int] | None = None
        """(system, component, ts1) of the vehicle's latest TIMESYNC request held until its version is known."""
        self._version_wait_end_s: float | None = None
        """Wall time until which requests are held (set by the first one; ``VERSION_WAIT_S``)."""
        self._serial = budget.is_serial(url)
        """A serial line carries requests and answers only as the vehicle's time goes on (an
        emulator's line in lockstep): its TIMESYNC requests are answered at once, and markers
        during blocking calls too (``_pump``)."""
        self._released: FrameMarker | None = None
        """The held request, a lockstep marker after all: handed over right after the version."""
        self.readings_dropped = 0
        """Stale sensor readings skipped because newer ones of the same kind came in the same batch."""
        self._texts = StatusTextAssembler()
        self._param_reads: dict[str, int] = {}
        """VEHICLE_PARAMS not answered yet -> requests sent (asked from the first ArduPilot heartbeat)."""
        self._next_param_read_s = 0.0

    # ---- receiving -------------------------------------------------------------------------

    def fileno(self) -> int | None:
        """The connection's current descriptor (a reconnected TCP link has a new one), or None."""
        port = getattr(self.conn, "port", None)
        try:
            return port.fileno() if port is not None else None
        except (AttributeError, OSError, ValueError):
            return None

    def wait_readable(self, timeout_s: float) -> None:
        """Block until the link has bytes or ``timeout_s`` (wall) passes."""
        fd = self.fileno()
        if fd is None:
            time.sleep(timeout_s)  # nothing to wait on while the connection is down
            return
        select.select([fd], [], [], timeout_s)

    @property
    def backlog(self) -> bool:
        """Whether messages already read wait for the next ``poll`` (one that stopped at a lockstep
        marker leaves the rest of its read): the caller must not sleep on the socket then."""
        return bool(self._held or self._parsed)

    def poll(self, max_frames: int = 10_000, stop_at_marker: bool = True) -> list[Any]:
        """Decoded items received so far (non-blocking). Stops after a lockstep marker when
        ``stop_at_marker`` so that a frame's control step sees exactly that frame's data."""
        items, self._held = self._held, []
        self.last_poll_wall_s = self._wall()
        if self.link_error is not None and self.last_poll_wall_s < self._retry_wall_s:
            return items
        decoded = reads = 0
        drained = False
        while decoded < max_frames:
            if not self._parsed:
                # A read may hold no whole frame (a partial one, bytes a line corrupted); bounded,
                # so that a stream of junk cannot keep the loop from its step and its failsafes.
                reads += 1
                if drained or reads > MAX_READS_PER_POLL:
                    break
                got = self._read()
                if not got:
                    break
                # A byte stream (TCP, a serial line) read short has nothing more waiting: one more
                # read would only come back empty (a system call and pymavlink's EAGAIN exception
                # every loop turn). A datagram socket reads one datagram at a time.
                drained = self._byte_stream and got < READ_SIZE_BYTES
                continue
            msg = self._parsed.popleft()
            decoded += 1
            item = self._decode(msg)
            if item is not None:
                items.append(item)
                if self._released is not None:  # the version came: the marker held until now
                    item, self._released = self._released, None
                    items.append(item)
                if stop_at_marker and isinstance(item, FrameMarker):
                    break
        if self.lockstep_source is None and len(items) > 1:
            items = self._coalesce(items)
        return items

    def _coalesce(self, items: list[Any]) -> list[Any]:
        """Outside lockstep, keep only the newest sensor reading of each kind in one batch.

        A vehicle running faster than the daemon can read (a simulator at 50x, or a loop stalled
        by the machine) leaves a backlog; processing every stale reading makes each loop turn
        longer and the backlog longer still, and the overrides sent come from ever older data
        (a rover at 50x ran away). Wheel distances are cumulative and attitude is absolute, so
        the newest of each loses only resolution. ``readings_dropped`` counts what was skipped."""
        seen: set[Any] = set()
        kept: list[Any] = []
        for item in reversed(items):
            if isinstance(item, (WheelDistance, Attitude, GpsFix, Truth, Battery)):
                key: Any = type(item)
            elif isinstance(item, RangeReading):
                key = (RangeReading, item.orientation)
            else:
                kept.append(item)
                continue
            if key in seen:
                self.readings_dropped += 1
                continue
            seen.add(key)
            kept.append(item)
        kept.reverse()
        return kept

    def _read(self) -> int:
        """One read of everything waiting, parsed; the bytes read (0: nothing came, or the link failed)."""
        conn = self.conn
        try:
            data = conn.recv(READ_SIZE_BYTES)
        except OSError as exc:  # the connection itself failed (peer gone, port vanished)
            self._down(exc)
            return 0
        if not data:
            return 0
        self.link_error = None
        data = bytes(data) if not isinstance(data, bytes) else data
        self.rx_bytes += len(data)
        if conn.first_byte:
            conn.auto_mavlink_version(data)
        chunk = data
        for _ in range(len(data) + 1):  # bounded: each round consumes bytes or ends
            try:
                msg = conn.mav.parse_char(chunk)
            except Exception as exc:  # a frame pymavlink could not unpack: dropped, counted
                self.garbage_frames += 1
                if "CRC" in str(exc):
                    self.health.bad_crc()
                else:
                    self.health.bad_bytes()
                chunk = b""
                continue
            chunk = b""
            if msg is None:
                break
            # Only the message hooks (the tlog), not pymavlink's post_message: its bookkeeping (a
            # table per source and type with two copies of every DISTANCE_SENSOR for its instance
            # field, a loss counter) duplicates self.health and nothing reads it.
            for hook in conn.message_hooks:
                hook(conn, msg)
            self._parsed.append(msg)
        return len(data)

    def _down(self, exc: OSError) -> None:
        self.link_error = str(exc) or type(exc).__name__
        self._retry_wall_s = self._wall() + self.reconnect_period_s

    def _decode(self, msg: Any) -> Any:
        kind = msg.get_type()
        if kind == "BAD_DATA":  # pymavlink's robust parsing hands back what it could not decode
            self.garbage_frames += 1
            if "CRC" in str(getattr(msg, "reason", "")):
                self.health.bad_crc()
            else:
                self.health.bad_bytes()
            return None
        if msg.get_srcSystem() == self.params.source_system:
            return None  # our own frames echoed by a broadcast medium
        if kind == "RADIO_STATUS":  # the telemetry radio speaks with its own system id
            self.radio = RadioStatus(msg.rssi, msg.remrssi, msg.txbuf, msg.rxerrors, msg.fixed, self._wall())
            return self.radio
        if self.vehicle is not None and msg.get_srcSystem() != self.target_system:
            return None  # another system on a shared link (a second GCS, a companion computer)
        self.frames_received += 1
        source = (msg.get_srcSystem(), msg.get_srcComponent())
        # Lockstep markers (TIMESYNC requests) number on a sequence of their own
        # (docs/architecture.md, "Lockstep handshake"): until the vehicle's AUTOPILOT_VERSION says
        # it is no lockstep emulator, a TIMESYNC request stays out of the link's sequence count.
        # (ArduPilot's latency probe, one every 10 s, shares the vehicle's sequence: skipped before
        # that answer, it reads as one frame lost.)
        if not (kind == "TIMESYNC" and msg.tc1 == 0 and (self.version is None or self.version.lockstep)):
            self.health.frame(self.vehicle_time_s, kind, source, msg.get_seq(), len(msg.get_msgbuf()))
        if kind == "TIMESYNC":
            if msg.tc1 != 0:
                return None  # a response: we send no requests of our own
            if self.lockstep_source == (msg.get_srcSystem(), msg.get_srcComponent()):
                # Lockstep markers keep coming from an emulator whose vehicle side went quiet:
                # they advance time but are not a sign of life of the vehicle.
                self._advance(msg.ts1 / 1e9, alive=False)
                return FrameMarker(time_s=msg.ts1 / 1e9, ts1_ns=msg.ts1)
            if self.version is None and not self._serial and (self.vehicle is None or source == (self.target_system, self.target_component)):
                if self._version_wait_end_s is None:
                    self._version_wait_end_s = self._wall() + VERSION_WAIT_S
                if self._wall() < self._version_wait_end_s:  # a lockstep marker, perhaps: wait for the version
                    self._unanswered = (*source, msg.ts1)
                    return None
            self._answer_timesync(msg.ts1)
            self.probes_answered += 1
            return None
        self.last_rx_wall_s = self._wall()
        self.last_rx_vehicle_s = self.vehicle_time_s
        if kind == "HEARTBEAT":
            if msg.type == mavlink.MAV_TYPE_GCS or msg.autopilot == mavlink.MAV_AUTOPILOT_INVALID:
                return None  # a ground station or a peripheral component, not the autopilot
            first = self.vehicle is None
            self.target_system, self.target_component = msg.get_srcSystem(), msg.get_srcComponent()
            if first:
                self.command_async(mavlink.MAV_CMD_REQUEST_MESSAGE, float(mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION))
                if msg.autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA:
                    self._param_reads, self._next_param_read_s = dict.fromkeys(VEHICLE_PARAMS, 0), 0.0
            self.vehicle = VehicleStatus(
                wall_s=self.last_rx_wall_s,
                armed=bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED),
                custom_mode=msg.custom_mode,
                system_status=msg.system_status,
            )
            return self.vehicle
        if kind == "PARAM_VALUE":
            name = msg.param_id
            if name not in VEHICLE_PARAMS or not math.isfinite(msg.param_value):
                return None  # another ground station's traffic, or a value no check can use
            self._param_reads.pop(name, None)
            return VehicleParam(name, float(msg.param_value))
        if kind == "ATTITUDE":
            self._advance(msg.time_boot_ms / 1000.0)
            return Attitude(time_s=msg.time_boot_ms / 1000.0, yaw_rad=msg.yaw, yaw_rate_radps=msg.yawspeed)
        if kind == "WHEEL_DISTANCE":
            p = self.params
            if msg.count <= max(p.wheel_left_index, p.wheel_right_index):
                self.garbage_frames += 1
                return None
            time_s = self._boot_time_s(msg.time_usec)
            return WheelDistance(time_s=time_s, left_m=p.wheel_left_sign * msg.distance[p.wheel_left_index],
                                 right_m=p.wheel_right_sign * msg.distance[p.wheel_right_index])
        if kind == "GPS_RAW_INT":
            self.last_gps_msg = msg
            return dataclasses.replace(decode_gps(msg), time_s=self._boot_time_s(msg.time_usec))
        if kind == "SYS_STATUS":
            return Battery(msg.voltage_battery / 1000.0, msg.battery_remaining)
        if kind == "DISTANCE_SENSOR":
            self._advance(msg.time_boot_ms / 1000.0)
            return decode_range(msg, msg.time_boot_ms / 1000.0)
        if kind == "SIMSTATE":
            return Truth(self.vehicle_time_s, msg.lat / 1e7, msg.lng / 1e7, msg.yaw)
        if kind == "STATUSTEXT":
            text = self._texts.add(msg)  # ArduPilot sends a long text in chunks: passed on whole
            return None if text is None else StatusText(self.vehicle_time_s, msg.severity, text)
        if kind == "COMMAND_ACK":
            return self._on_ack(msg)
        if kind == "AUTOPILOT_VERSION":
            return self._on_version(msg)
        return None

    def _on_version(self, msg: Any) -> VehicleVersion | None:
        if self.vehicle is None or msg.get_srcComponent() != self.target_component:
            return None
        custom = bytes(msg.flight_custom_version)
        lockstep = custom == LOCKSTEP_ANNOUNCEMENT
        self.lockstep_source = (msg.get_srcSystem(), msg.get_srcComponent()) if lockstep else None
        self.version = VehicleVersion(msg.flight_sw_version, custom, lockstep)
        held, self._unanswered = self._unanswered, None
        if held is not None:
            if held[:2] == self.lockstep_source:  # the frame it waits on: stepped, then answered
                self._advance(held[2] / 1e9, alive=False)
                self._released = FrameMarker(time_s=held[2] / 1e9, ts1_ns=held[2])
            else:
                self._answer_timesync(held[2])
                self.probes_answered += 1
        return self.version

    def _boot_time_s(self, time_usec: int) -> float:
        """Vehicle (boot) time of a time_usec field: epoch stamps (a real GPS) are replaced by the
        arrival time on the vehicle clock, so one clock drives everything."""
        if time_usec >= EPOCH_THRESHOLD_US:
            return self.vehicle_time_s
        self._advance(time_usec / 1e6)
        return time_usec / 1e6

    def _advance(self, time_s: float, alive: bool = True) -> None:
        if time_s > self.vehicle_time_s:
            self.vehicle_time_s = time_s
        if alive:
            self.last_rx_vehicle_s = self.vehicle_time_s

    # ---- sending ---------------------------------------------------------------------------

    def tick(self) -> None:
        """Housekeeping, call every loop turn: our heartbeat and command retries (wall clock)."""
        now = self._wall()
        if self._unanswered is not None and now >= self._version_wait_end_s:  # no version came: plain time sync
            self._answer_timesync(self._unanswered[2])
            self.probes_answered += 1
            self._unanswered = None
        if now >= self._next_heartbeat_s:
            self.conn.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE)
            self._next_heartbeat_s = now + self.params.heartbeat_period_s
        for pending in list(self._pending.values()):
            if now - pending.sent_wall_s < self.command_timeout_s:
                continue
            if pending.attempts > self.command_retries:
                del self._pending[pending.command]
                pending.answer(CommandResult(pending.command, NO_ANSWER))
                self._send_queued(pending.command, now)
                continue
            self._send_command(pending, now)
        if self._param_reads and now >= self._next_param_read_s:
            self._read_params(now)

    def _read_params(self, now: float) -> None:
        """Ask for each VEHICLE_PARAMS value not answered yet, at most PARAM_READ_TRIES times."""
        for name, tries in list(self._param_reads.items()):
            if tries >= PARAM_READ_TRIES:
                del self._param_reads[name]
                log.warning("vehicle link: no answer to PARAM_REQUEST_READ %s after %d tries", name, tries)
                continue
            self.conn.mav.param_request_read_send(self.target_system, self.target_component, name.encode(), -1)
            self._param_reads[name] = tries + 1
        self._next_param_read_s = now + PARAM_READ_PERIOD_S

    def send_override(self, steering_us: int, throttle_us: int) -> None:
        """RC_CHANNELS_OVERRIDE: ch1 steering, ch3 throttle; the other channels released."""
        r = RC_RELEASE
        self.conn.mav.rc_channels_override_send(
            self.target_system, self.target_component, int(steering_us), r, int(throttle_us), r, r, r, r, r
        )

    def release_override(self) -> None:
        """Hand every channel back to the radio (MANUAL pass-through)."""
        r = RC_RELEASE
        self.conn.mav.rc_channels_override_send(self.target_system, self.target_component, r, r, r, r, r, r, r, r)

    def answer_marker(self, marker: FrameMarker) -> None:
        """Answer a lockstep marker: the vehicle may advance to the next frame."""
        self._answer_timesync(marker.ts1_ns)

    def _answer_timesync(self, ts1_ns: int) -> None:
        """TIMESYNC response: tc1 = our clock in ns (never 0, which would read as a request), ts1 echoed."""
        self.conn.mav.timesync_send(max(1, int(self._wall() * 1e9)), ts1_ns)

    def request_streams(self, plan: budget.StreamPlan) -> None:
        """Ask for the plan's rates and nothing else (``rover_ctl.mavlink.budget``): every stream
        off, EXTRA1 (WHEEL_DISTANCE with ATTITUDE) at its rate with the EXTRA1 messages the daemon
        does not read switched off, then one SET_MESSAGE_INTERVAL per other message (-1: off).
        Each interval is a separate command (ACKs keyed by command id would replace each other),
        so they are sent without waiting for ACKs; the vehicle sends what it can, we measure."""
        t, c = self.target_system, self.target_component
        self.conn.mav.request_data_stream_send(t, c, mavlink.MAV_DATA_STREAM_ALL, 0, 0)
        rates = dict(plan.rates_hz)
        extra1_hz = int(rates.pop(budget.EXTRA1, 0))
        if extra1_hz > 0:
            self.conn.mav.request_data_stream_send(t, c, mavlink.MAV_DATA_STREAM_EXTRA1, extra1_hz, 1)
            rates |= {name: 0.0 for name in budget.EXTRA1_UNREAD if name not in rates}
            rates["ATTITUDE"] = float(extra1_hz)
        for name, hz in rates.items():
            msg_id = getattr(mavlink, f"MAVLINK_MSG_ID_{name}")
            interval_us = 1e6 / hz if hz > 0 else -1.0
            self.conn.mav.command_long_send(t, c, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0, msg_id, interval_us, 0, 0, 0, 0, 0)

    def param_set(self, name: str, value: float) -> None:
        self.conn.mav.param_set_send(
            self.target_system, self.target_component, name.encode(), float(value), mavlink.MAV_PARAM_TYPE_REAL32
        )

    def command_async(self, command: int, *params: float, on_result: Callable[[CommandResult], None] | None = None) -> None:
        """Send COMMAND_LONG; retried by ``tick`` until acknowledged; ``on_result`` gets the outcome.

        One request per command is on the wire at a time, because a COMMAND_ACK names only the
        command: a disarm still being retried when an arm replaced it had its ACCEPTED taken as the
        arm's. So a request with other parameters waits (queued) for the pending one's answer or
        last retry, then goes; a later one replaces it in the queue (its waiters are not answered:
        the ground station's are, by the command's next result, ``GcsLink.command_result``). The
        same request again, pending or queued, is not sent again: it
        waits for that answer (a ground station repeating a disarm a thousand times put a
        thousand COMMAND_LONGs on the vehicle's radio); its ``on_result`` joins the waiters unless
        already among them, up to ``MAX_COMMAND_WAITERS``."""
        full = tuple(float(p) for p in params) + (0.0,) * (7 - len(params))
        for waiting in (self._pending.get(command), self._queued.get(command)):
            if waiting is not None and waiting.params == full:
                if on_result is not None and on_result not in waiting.waiters and len(waiting.waiters) < MAX_COMMAND_WAITERS:
                    waiting.waiters.append(on_result)
                return
        request = _Pending(command, full, 0.0, 0, [on_result] if on_result is not None else [])
        if command not in self._pending:
            self._pending[command] = request
            self._send_command(request, self._wall())
            return
        self._queued[command] = request

    def _send_queued(self, command: int, now: float) -> None:
        """The pending request of ``command`` is answered or given up: the queued one goes."""
        request = self._queued.pop(command, None)
        if request is not None:
            self._pending[command] = request
            self._send_command(request, now)

    def _send_command(self, pending: _Pending, now: float) -> None:
        self.conn.mav.command_long_send(
            self.target_system, self.target_component, pending.command, pending.attempts, *pending.params
        )
        pending.attempts += 1
        pending.sent_wall_s = now

    def _on_ack(self, msg: Any) -> CommandResult | None:
        if getattr(msg, "target_system", 0) not in (0, self.params.source_system) or \
                getattr(msg, "target_component", 0) not in (0, self.params.source_component):
            return None  # another ground station's answer on a shared link (ArduPilot addresses its ACKs)
        pending = self._pending.get(msg.command)
        if pending is None or msg.result == mavlink.MAV_RESULT_IN_PROGRESS:
            return None
        del self._pending[msg.command]
        result = CommandResult(msg.command, msg.result)
        pending.answer(result)
        self._send_queued(msg.command, self._wall())
        return result

    def arm_async(self, arm: bool, on_result: Callable[[CommandResult], None] | None = None) -> None:
        self.command_async(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0 if arm else 0.0, on_result=on_result)

    def set_mode_async(self, custom_mode: int, on_result: Callable[[CommandResult], None] | None = None) -> None:
        self.command_async(
            mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, float(custom_mode), on_result=on_result
        )

    # ---- blocking helpers for start-up ---------------------------------------------------------

    def wait_vehicle(self, timeout_s: float, cancelled: Callable[[], bool] = lambda: False) -> VehicleStatus | None:
        """Heartbeat until the vehicle's heartbeat arrives (None if ``cancelled()`` first). Decoded
        items are kept for the next ``poll`` (``_pump``)."""
        deadline = self._wall() + timeout_s
        while self.vehicle is None:
            if cancelled():
                return None
            if self.rx_bytes >= WRONG_BAUD_BYTES and self.frames_received == 0 and self._serial:
                baud = budget.serial_baud(self.url) or PYMAVLINK_DEFAULT_BAUD
                raise LinkError(f"vehicle link {self.url}: {self.rx_bytes} bytes but not one MAVLink frame at "
                                f"{baud} baud: wrong baud rate? (write DEVICE,BAUD, e.g. /dev/ttyUSB0,57600)")  # fmt: skip
            if self._wall() > deadline:
                heard = f" ({self.rx_bytes} bytes, no MAVLink frame)" if self.rx_bytes and not self.frames_received else ""
                raise LinkError(f"vehicle link {self.url}: no vehicle heartbeat within {timeout_s:g} s{heard}")
            self._pump(0.05)
        return self.vehicle

    def command(self, command: int, *params: float, timeout_s: float | None = None) -> CommandResult:
        """COMMAND_LONG and wait (wall clock) for its ACK, retrying; markers are answered meanwhile."""
        results: list[CommandResult] = []
        self.command_async(command, *params, on_result=results.append)
        limit = timeout_s or self.command_timeout_s * (self.command_retries + 1) + 1.0
        deadline = self._wall() + limit
        while not results:
            if self._wall() > deadline:
                for table in (self._queued, self._pending):
                    waiting = table.get(command)
                    if waiting is not None and results.append in waiting.waiters:
                        del table[command]
                        if table is self._pending:
                            self._send_queued(command, self._wall())
                return CommandResult(command, NO_ANSWER)
            self._pump(0.02)
        return results[0]

    def _pump(self, wait_s: float) -> None:
        """Read while a blocking call waits; everything read is kept for the next ``poll``. On a
        socket, lockstep markers too: the emulator waits at its frame until the control loop has
        stepped it, and answers commands meanwhile. On a serial line they are answered: the line
        carries the command and its answer only as the vehicle's time goes on."""
        self.tick()
        self.wait_readable(wait_s)
        for item in self.poll(stop_at_marker=False):
            if self._serial and isinstance(item, FrameMarker):
                self.answer_marker(item)
            else:
                self._held.append(item)

    def close(self) -> None:
        try:
            self.conn.close()
        except (OSError, AttributeError):  # pymavlink's TCP close fails when already disconnected
            pass
