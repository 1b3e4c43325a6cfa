"""The vehicle side of the MAVLink link, as ArduPilot Rover behaves in MANUAL (skid-steer frame).

:class:`MavlinkVehicle` is transport-free: the main loop hands it received messages
(:meth:`handle`, which returns the direct replies) and asks it, each frame, for the telemetry due
at the current sim time (:meth:`due`). It owns the autopilot state (armed, mode, RC overrides,
parameters, stream intervals) and drives the rover's motors through the skid-steer mixer.

ArduPilot behaviours reproduced (see docs/sitl.md):
- RC_CHANNELS_OVERRIDE only from SYSID_MYGCS; per channel, 0 releases and UINT16_MAX leaves the
  channel as it was (MAVLink spec); each channel times out after RC_OVERRIDE_TIME -> trim.
- Motors follow the mixer only when armed and in MANUAL; disarmed or HOLD -> trim (1500 us).
- COMMAND_LONG always gets a COMMAND_ACK; arming refused with MAV_RESULT_FAILED and a
  "PreArm:" STATUSTEXT unless checks pass or param2 = 21196 (force). The GPS check reads the
  receiver's state as ArduPilot's AP_GPS keeps it: the last fix stands until GPS_TIMEOUT_S without
  one, so a single dropped epoch does not refuse an arming.
- WHEEL_DISTANCE is only in the EXTRA1 stream: SET_MESSAGE_INTERVAL cannot set it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from sitl.endpoints import mavlink
from sitl.faults import FaultError
from sitl.mixer import MixerParams, mix_rc

MODE_MANUAL = mavlink.ROVER_MODE_MANUAL
MODE_HOLD = mavlink.ROVER_MODE_HOLD
MODES = {MODE_MANUAL: "MANUAL", MODE_HOLD: "HOLD"}
"""ArduPilot Rover custom modes the emulator implements (others are refused)."""
FORCE_ARM_MAGIC = 21196
"""COMMAND_LONG ARM_DISARM param2 that skips the arming checks (ArduPilot)."""
OVERRIDE_IGNORE = 65535
"""RC_CHANNELS_OVERRIDE value meaning "leave this channel as it is" (UINT16_MAX)."""
STEERING_CHANNEL = 0
THROTTLE_CHANNEL = 2
"""Zero-based RC channel indexes: ch1 steering, ch3 throttle (ArduPilot Rover defaults)."""
STATUSTEXT_MAX_CHARS = 50
GPS_TIMEOUT_S = 4.0
"""How long the last GPS fix stands for the arming check with no new one (ArduPilot's
AP_GPS GPS_TIMEOUT_MS, after which it marks the receiver NO_GPS)."""
LOCKSTEP_ANNOUNCEMENT = b"lockstep"
"""AUTOPILOT_VERSION.flight_custom_version in lockstep: tells a controller that this vehicle's
TIMESYNC requests are end-of-frame markers (docs/architecture.md, "Lockstep handshake")."""
PARAM_ID_CHARS = 16
"""MAVLink param_id length; every parameter name here fits (a test checks it)."""

# Streams of ArduPilot's REQUEST_DATA_STREAM (GCS_MAVLINK stream groups, restricted to what we send).
DATA_STREAMS = {
    mavlink.MAV_DATA_STREAM_EXTENDED_STATUS: ("SYS_STATUS", "GPS_RAW_INT"),
    mavlink.MAV_DATA_STREAM_RC_CHANNELS: ("SERVO_OUTPUT_RAW",),
    mavlink.MAV_DATA_STREAM_EXTRA1: ("ATTITUDE", "SIMSTATE", "WHEEL_DISTANCE"),
    mavlink.MAV_DATA_STREAM_EXTRA3: ("DISTANCE_SENSOR",),
}
STREAM_ONLY = frozenset({"WHEEL_DISTANCE"})
"""Messages ArduPilot cannot set with SET_MESSAGE_INTERVAL (they only come in their stream)."""


@dataclass(frozen=True)
class LinkParams:
    """Autopilot-side parameters of the emulator (MAVLink shell); defaults = docs/architecture.md."""

    sysid_mygcs: int = 255
    """[SYSID_MYGCS] the only system id whose RC overrides are accepted."""
    rc_override_time_s: float = 1.0
    """[RC_OVERRIDE_TIME] an override not refreshed for this long is released (ArduPilot default 3 s)."""
    arming_check: int = 1
    """[ARMING_CHECK] 1: require a 3D GPS fix to arm (ArduPilot Rover does not in MANUAL; 0 = as ArduPilot)."""
    pilot_steer_type: int = 3
    """[PILOT_STEER_TYPE] read-only 3, "direction unchanged when backing up": the mixer (``sitl.mixer``)
    never reverses the steering. ArduPilot's default, 0, reverses it while the slew-limited
    throttle output is negative, which this emulator does not model; a daemon driving ArduPilot
    needs 3 and checks it (docs/ardupilot.md)."""
    rates_hz: dict[str, float] = field(default_factory=lambda: {
        "HEARTBEAT": 1.0, "GPS_RAW_INT": 5.0, "ATTITUDE": 50.0, "DISTANCE_SENSOR": 20.0,
        "WHEEL_DISTANCE": 50.0, "SERVO_OUTPUT_RAW": 10.0, "SYS_STATUS": 1.0, "SIMSTATE": 10.0,
    })
    """Default telemetry rates in sim time (the architecture's table)."""


PARAM_NAMES = {"SYSID_MYGCS": "sysid_mygcs", "RC_OVERRIDE_TIME": "rc_override_time_s", "ARMING_CHECK": "arming_check",
               "PILOT_STEER_TYPE": "pilot_steer_type"}  # fmt: skip
PARAM_RANGES = {"SYSID_MYGCS": (1, 255), "RC_OVERRIDE_TIME": (-1.0, 120.0), "ARMING_CHECK": (0, 2**31 - 1),
                "PILOT_STEER_TYPE": (3, 3)}  # fmt: skip
"""ArduPilot's ranges; an int bound: whole numbers. RC_OVERRIDE_TIME -1: overrides never time out,
0: overrides off. ARMING_CHECK is ArduPilot's bitmask of checks: any bit set turns on the
emulator's one check (a 3D fix), 0 turns it off. PILOT_STEER_TYPE: only 3, the mixer's behaviour."""


def check_link_param(name: str, value) -> float:
    """The value of one of PARAM_NAMES as float, or FaultError naming the parameter and what is wrong."""
    low, high = PARAM_RANGES[name]
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise FaultError(f"{name}: expected a number, got {value!r}") from None
    if not low <= number <= high or (isinstance(low, int) and not number.is_integer()):  # NaN fails the range
        kind = "a whole number" if isinstance(low, int) else "a number"
        raise FaultError(f"{name}: expected {kind} {low}..{high}, got {value!r}")
    return number


@dataclass
class _Stream:
    interval_s: float | None
    next_s: float = 0.0


def next_slot(slot_s: float, period_s: float, t_s: float) -> float:
    """The first slot of the grid ``slot_s + n * period_s`` after ``t_s`` (slots missed by a coarse frame are skipped)."""
    return slot_s + period_s * max(1, math.floor((t_s + 1e-9 - slot_s) / period_s) + 1)


def _text(text: str) -> bytes:
    return text[:STATUSTEXT_MAX_CHARS].encode()


class MavlinkVehicle:
    """ArduPilot-Rover-like autopilot state machine around a SimRover."""

    def __init__(self, rover, params: LinkParams = LinkParams(), mixer: MixerParams = MixerParams(),
                 fault_params: dict[str, tuple[float, str]] | None = None) -> None:
        self.rover = rover
        self.mixer = mixer
        self.sysid_mygcs = params.sysid_mygcs
        self.rc_override_time_s = params.rc_override_time_s
        self.arming_check = params.arming_check
        self.pilot_steer_type = params.pilot_steer_type
        self.armed = False
        self.mode = MODE_MANUAL
        self.overrides: dict[int, tuple[int, float]] = {}
        """channel index -> (pwm_us, sim time set)."""
        self.motor_pwm = (mixer.servo_trim_us, mixer.servo_trim_us)
        self.default_rates_hz = dict(params.rates_hz)
        self.streams = {name: _Stream(1.0 / hz if hz > 0 else None) for name, hz in params.rates_hz.items()}
        self.fault_values = {name: float(default) for name, (default, _doc) in (fault_params or {}).items()}
        self.pending_text: list[tuple[int, str]] = []
        self.builders = self._builders()
        self.on_gps: Callable[[object], None] | None = None
        """Called with each GPS sample (or None when dropped) as it is taken (the truth log's hook)."""
        sensors = rover.params
        self.sensor_periods_s = {"gps": 1.0 / sensors.gps.rate_hz, "imu": 1.0 / sensors.imu.rate_hz,
                                 "ranges": 1.0 / sensors.rangefinder.rate_hz, "wheels": 1.0 / sensors.encoder.rate_hz}
        self.sensor_next_s = dict.fromkeys(self.sensor_periods_s, 0.0)
        self.gps = self.attitude = self.wheels = None
        self._fix_s: float | None = None
        """Sim time of the last GPS sample with a 3D fix (the arming check's, ``GPS_TIMEOUT_S``)."""
        self.ranges: list = []
        self.lockstep = False
        """Announced in AUTOPILOT_VERSION (set by the main loop in --lockstep)."""

    # ---- parameters -------------------------------------------------------------------
    def param_names(self) -> list[str]:
        return [*PARAM_NAMES, *self.fault_values]

    def get_param(self, name: str) -> float | None:
        if name in PARAM_NAMES:
            return float(getattr(self, PARAM_NAMES[name]))
        return self.fault_values.get(name)

    def set_param(self, name: str, value: float) -> bool:
        """Set a parameter (SIM_* faults apply to the rover at once); False if unknown."""
        if name in PARAM_NAMES:
            attr = PARAM_NAMES[name]
            setattr(self, attr, type(getattr(self, attr))(check_link_param(name, value)))  # FaultError before any change
            return True
        if name in self.fault_values:
            self.rover.set_fault(name, value)  # FaultError on a bad value, before anything changes
            self.fault_values[name] = float(value)
            return True
        return False

    def wire_name(self, param_id: str) -> str:
        """The parameter a MAVLink param_id means (ids are cut to 16 characters on the wire)."""
        return next((n for n in self.param_names() if n[:PARAM_ID_CHARS] == param_id[:PARAM_ID_CHARS]), param_id)

    def _param_value(self, name: str):
        names = self.param_names()
        return mavlink.MAVLink_param_value_message(
            name[:PARAM_ID_CHARS].encode(), self.get_param(name), mavlink.MAV_PARAM_TYPE_REAL32, len(names), names.index(name))

    # ---- incoming ---------------------------------------------------------------------
    def handle(self, msg, t_s: float) -> list:
        """Apply one received message at sim time ``t_s``; return the replies for its sender."""
        kind = msg.get_type()
        if kind == "RC_CHANNELS_OVERRIDE":
            self._override(msg, t_s)
        elif kind == "COMMAND_LONG":
            return self._command(msg, t_s)
        elif kind == "SET_MODE":
            result = self._set_mode(msg.base_mode, msg.custom_mode)
            return [mavlink.MAVLink_command_ack_message(mavlink.MAVLINK_MSG_ID_SET_MODE, result)]
        elif kind == "REQUEST_DATA_STREAM":
            self._request_stream(msg.req_stream_id, msg.req_message_rate, msg.start_stop, t_s)
        elif kind == "PARAM_REQUEST_LIST":
            return [self._param_value(name) for name in self.param_names()]
        elif kind == "PARAM_REQUEST_READ":
            names = self.param_names()
            name = self.wire_name(msg.param_id) if msg.param_index < 0 else \
                (names[msg.param_index] if msg.param_index < len(names) else "")
            return [self._param_value(name)] if name in names else []
        elif kind == "PARAM_SET":
            name = self.wire_name(msg.param_id)
            try:
                known = self.set_param(name, msg.param_value)
            except FaultError as exc:
                self.say(mavlink.MAV_SEVERITY_WARNING, str(exc))
                known = True
            return [self._param_value(name)] if known else []
        elif kind == "TIMESYNC" and msg.tc1 == 0:
            # a request: answer with our clock (sim time), never 0, which would read as a request
            return [mavlink.MAVLink_timesync_message(max(1, round(t_s * 1e9)), msg.ts1)]
        return []

    def _override(self, msg, t_s: float) -> None:
        if msg.get_srcSystem() != self.sysid_mygcs:
            return
        for index, pwm_us in enumerate((msg.chan1_raw, msg.chan2_raw, msg.chan3_raw, msg.chan4_raw,
                                         msg.chan5_raw, msg.chan6_raw, msg.chan7_raw, msg.chan8_raw)):
            if pwm_us == OVERRIDE_IGNORE:
                continue
            if pwm_us == 0:
                self.overrides.pop(index, None)
            else:
                self.overrides[index] = (pwm_us, t_s)

    def _command(self, msg, t_s: float) -> list:
        command = msg.command
        if command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            result = self._arm(msg.param1 >= 0.5, msg.param2 == FORCE_ARM_MAGIC, t_s)  # as ArduPilot, a float compare
        elif command in (mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAV_CMD_REQUEST_MESSAGE) \
                and not (math.isfinite(msg.param1) and math.isfinite(msg.param2)):
            result = mavlink.MAV_RESULT_FAILED  # a mode, a message id, an interval: NaN or inf is none of them
        elif command == mavlink.MAV_CMD_DO_SET_MODE:
            result = self._set_mode(int(msg.param1), int(msg.param2))
        elif command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            result = self._set_interval(int(msg.param1), msg.param2, t_s)
        elif command == mavlink.MAV_CMD_REQUEST_MESSAGE:
            replies = self._request_message(int(msg.param1), t_s)
            result = mavlink.MAV_RESULT_ACCEPTED if replies is not None else mavlink.MAV_RESULT_FAILED
            return [mavlink.MAVLink_command_ack_message(command, result), *(replies or [])]
        else:
            result = mavlink.MAV_RESULT_UNSUPPORTED
        return [mavlink.MAVLink_command_ack_message(command, result)]

    def _arm(self, arm: bool, force: bool, t_s: float) -> int:
        if not arm:
            if self.armed:
                self.say(mavlink.MAV_SEVERITY_INFO, "Throttle disarmed")
            self.armed = False
            return mavlink.MAV_RESULT_ACCEPTED
        if self.armed:
            return mavlink.MAV_RESULT_ACCEPTED
        if not force and self.arming_check:
            if self._fix_s is None or t_s - self._fix_s > GPS_TIMEOUT_S:
                self.say(mavlink.MAV_SEVERITY_CRITICAL, "PreArm: GPS 1: Bad fix")
                return mavlink.MAV_RESULT_FAILED
        self.armed = True
        self.say(mavlink.MAV_SEVERITY_INFO, "Throttle armed")
        return mavlink.MAV_RESULT_ACCEPTED

    def _set_mode(self, base_mode: int, custom_mode: int) -> int:
        if not base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED or custom_mode not in MODES:
            self.say(mavlink.MAV_SEVERITY_WARNING, f"Mode change to {custom_mode} failed: not supported")
            return mavlink.MAV_RESULT_FAILED
        self.mode = custom_mode
        return mavlink.MAV_RESULT_ACCEPTED

    def _set_interval(self, msg_id: int, interval_us: float, t_s: float) -> int:
        name = mavlink.mavlink_map[msg_id].msgname if msg_id in mavlink.mavlink_map else None
        if name not in self.streams or name in STREAM_ONLY:
            return mavlink.MAV_RESULT_FAILED
        if interval_us == 0:
            hz = self.default_rates_hz[name]
            self.streams[name] = _Stream(1.0 / hz if hz > 0 else None, t_s)
        else:
            self.streams[name] = _Stream(None if interval_us < 0 else interval_us / 1e6, t_s)
        return mavlink.MAV_RESULT_ACCEPTED

    def _request_stream(self, stream_id: int, rate_hz: int, start: int, t_s: float) -> None:
        names = {n for ns in DATA_STREAMS.values() for n in ns} if stream_id == mavlink.MAV_DATA_STREAM_ALL \
            else DATA_STREAMS.get(stream_id, ())
        for name in names:
            on = start and rate_hz > 0
            self.streams[name] = _Stream(1.0 / rate_hz if on else None, t_s)

    def _request_message(self, msg_id: int, t_s: float) -> list | None:
        if msg_id == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            custom = list(LOCKSTEP_ANNOUNCEMENT) if self.lockstep else [0] * 8
            return [mavlink.MAVLink_autopilot_version_message(
                mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT,
                0, 0, 0, 0, custom, [0] * 8, [0] * 8, 0, 0, 0)]
        name = mavlink.mavlink_map[msg_id].msgname if msg_id in mavlink.mavlink_map else None
        builder = self.builders.get(name)
        return builder(t_s) if builder else None

    # ---- outgoing ---------------------------------------------------------------------
    def say(self, severity: int, text: str) -> None:
        """Queue a STATUSTEXT for every endpoint (sent with the next frame's telemetry)."""
        self.pending_text.append((severity, text))

    def apply_outputs(self, t_s: float) -> None:
        """Expire stale overrides and drive the motors: mixed RC when armed in MANUAL, else trim."""
        for channel, (_pwm, set_s) in list(self.overrides.items()):
            if self.rc_override_time_s >= 0 and t_s - set_s >= self.rc_override_time_s:  # -1: never; 0: at once
                del self.overrides[channel]
        trim = self.mixer.servo_trim_us
        if self.armed and self.mode == MODE_MANUAL:
            steering = self.overrides.get(STEERING_CHANNEL, (self.mixer.steering.trim_us, 0.0))[0]
            throttle = self.overrides.get(THROTTLE_CHANNEL, (self.mixer.throttle.trim_us, 0.0))[0]
            self.motor_pwm = mix_rc(steering, throttle, self.mixer)
        else:
            self.motor_pwm = (trim, trim)
        self.rover.set_motor_pwm(*self.motor_pwm)

    def sample_sensors(self, t_s: float) -> None:
        """Read each sensor due at ``t_s`` at its own rate (the autopilot's drivers run whatever is streamed)."""
        due = [name for name, next_s in self.sensor_next_s.items() if t_s + 1e-9 >= next_s]
        for name in due:
            self.sensor_next_s[name] = next_slot(self.sensor_next_s[name], self.sensor_periods_s[name], t_s)
        if "gps" in due:
            self.gps = self.rover.gps()
            if self.gps is not None:  # a 2D fix or none marks the receiver so at once; a dropout does not
                self._fix_s = t_s if self.gps.fix_type >= mavlink.GPS_FIX_TYPE_3D_FIX else None
            if self.on_gps is not None:
                self.on_gps(self.gps)
        if "imu" in due:
            self.attitude = self.rover.attitude()
        if "ranges" in due:
            self.ranges = self.rover.rangefinders()
        if "wheels" in due:
            self.wheels = self.rover.wheels()

    def due(self, t_s: float) -> list:
        """Messages due at sim time ``t_s`` (each stream at its own rate), STATUSTEXTs first."""
        out = [mavlink.MAVLink_statustext_message(sev, _text(text)) for sev, text in self.pending_text]
        self.pending_text.clear()
        builders = self.builders
        for name, stream in self.streams.items():
            if stream.interval_s is None or t_s + 1e-9 < stream.next_s:
                continue
            stream.next_s = next_slot(stream.next_s, stream.interval_s, t_s)
            out.extend(builders[name](t_s))
        return out

    def _builders(self) -> dict[str, Callable[[float], list]]:
        return {
            "HEARTBEAT": self._heartbeat, "GPS_RAW_INT": self._gps_raw_int, "ATTITUDE": self._attitude,
            "DISTANCE_SENSOR": self._distance_sensors, "WHEEL_DISTANCE": self._wheel_distance,
            "SERVO_OUTPUT_RAW": self._servo_output_raw, "SYS_STATUS": self._sys_status, "SIMSTATE": self._simstate,
        }

    def _heartbeat(self, t_s: float) -> list:
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        if self.armed:
            base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        status = mavlink.MAV_STATE_ACTIVE if self.armed else mavlink.MAV_STATE_STANDBY
        return [mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_GROUND_ROVER, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                                  base, self.mode, status, 3)]

    def _gps_raw_int(self, t_s: float) -> list:
        gps = self.gps
        if gps is None:
            return [mavlink.MAVLink_gps_raw_int_message(int(t_s * 1e6), mavlink.GPS_FIX_TYPE_NO_FIX,
                                                        0, 0, 0, 65535, 65535, 0, 65535, 0)]
        return [mavlink.MAVLink_gps_raw_int_message(
            int(round(t_s * 1e6)), gps.fix_type, int(round(gps.lat_deg * 1e7)), int(round(gps.lon_deg * 1e7)),
            int(round(gps.alt_m * 1000)), min(int(round(gps.eph_m * 100)), 65535), 65535,
            int(round(gps.speed_mps * 100)), int(round((gps.course_deg % 360.0) * 100)) % 36000, gps.satellites)]

    def _attitude(self, t_s: float) -> list:
        att = self.attitude
        if att is None:
            return []
        yaw = math.remainder(att.yaw_rad, math.tau)
        return [mavlink.MAVLink_attitude_message(int(t_s * 1000), 0.0, 0.0, yaw, 0.0, 0.0, att.yaw_rate_radps)]

    def _distance_sensors(self, t_s: float) -> list:
        out = []
        for sample in self.ranges:
            max_cm = int(round(sample.max_m * 100))
            # no echo: above max_distance, which ArduPilot consumers read as "nothing in range"
            current_cm = max_cm + 1 if sample.range_m is None else int(round(sample.range_m * 100))
            out.append(mavlink.MAVLink_distance_sensor_message(
                int(t_s * 1000), int(round(sample.min_m * 100)), max_cm, current_cm,
                mavlink.MAV_DISTANCE_SENSOR_ULTRASOUND, sample.sensor_id, sample.orientation, 0))
        return out

    def _wheel_distance(self, t_s: float) -> list:
        wheels = self.wheels
        if wheels is None:
            return []
        return [mavlink.MAVLink_wheel_distance_message(int(round(t_s * 1e6)), 2, [wheels.left_m, wheels.right_m] + [0.0] * 14)]

    def _servo_output_raw(self, t_s: float) -> list:
        left, right = self.motor_pwm
        return [mavlink.MAVLink_servo_output_raw_message(int(round(t_s * 1e6)) & 0xFFFFFFFF, 0, left, 0, right, 0, 0, 0, 0, 0)]

    def _sys_status(self, t_s: float) -> list:
        sensors = (mavlink.MAV_SYS_STATUS_SENSOR_GPS | mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO
                   | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG | mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS)
        battery_v = self.rover.truth().battery_v
        return [mavlink.MAVLink_sys_status_message(sensors, sensors, sensors, 0, int(round(battery_v * 1000)),
                                                   -1, -1, 0, 0, 0, 0, 0, 0)]

    def _simstate(self, t_s: float) -> list:
        truth = self.rover.truth()
        return [mavlink.MAVLink_simstate_message(
            0.0, 0.0, math.remainder(math.radians(truth.yaw_deg), math.tau), 0.0, 0.0, 0.0, 0.0, 0.0,
            math.radians(truth.yaw_rate_dps), int(round(truth.lat_deg * 1e7)), int(round(truth.lon_deg * 1e7)))]
