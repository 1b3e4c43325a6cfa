"""The GCS link: the daemon as the rover's autopilot towards ground stations.

``GcsLink`` owns one pymavlink connection (``udpin:``, ``udpout:``, ``tcpin:``, ``tcp:``), speaks
MAVLink 2 (ardupilotmega) as system ``GcsParams.system_id`` component 1, and has no thread: the
daemon calls ``poll(now_s)`` from its loop, which reads every pending message, dispatches it,
runs the mission service's timeouts and sends what is due (HEARTBEAT, MISSION_CURRENT).
``now_s`` is the daemon's clock (monotonic or simulated); only differences are used.

What a ground station gets (docs/gcs.md lists it with the tested clients):

* HEARTBEAT at ``heartbeat_period_s``: MAV_TYPE_GROUND_ROVER, MAV_AUTOPILOT_ARDUPILOTMEGA,
  ArduPilot Rover's custom modes (``RoverMode``), the armed flag and system status.
* The mission protocol for missions, fences and rally points (``rover_ctl.mavlink.mission``),
  persisted through ``MissionStore`` so a restarted daemon keeps its mission.
* COMMAND_LONG / COMMAND_INT, each answered with COMMAND_ACK to the sender: arm/disarm (400),
  DO_SET_MODE (176), MISSION_START (300), NAV_RETURN_TO_LAUNCH (20), DO_SET_MISSION_CURRENT (224),
  REQUEST_MESSAGE (512) and REQUEST_AUTOPILOT_CAPABILITIES (520) for AUTOPILOT_VERSION and
  HOME_POSITION, GET_HOME_POSITION (410), SET_MESSAGE_INTERVAL (511); anything else
  MAV_RESULT_UNSUPPORTED. SET_MODE messages too.
* REQUEST_DATA_STREAM and SET_MESSAGE_INTERVAL set the rates of the telemetry senders.
* PARAM_REQUEST_LIST / PARAM_REQUEST_READ / PARAM_SET on the handlers' parameter table.

The daemon plugs in through ``AutopilotHandlers`` (a Protocol; every MAV_RESULT is an int):

    state() -> VehicleState                 armed, custom_mode, system_status, home
    arm(arm: bool, force: bool) -> int      MAV_CMD_COMPONENT_ARM_DISARM (force: param2 ARM_FORCE_MAGIC)
    set_mode(custom_mode: int) -> int       DO_SET_MODE / SET_MODE (RoverMode numbers)
    mission_start() -> int                  MAV_CMD_MISSION_START
    return_to_launch() -> int               MAV_CMD_NAV_RETURN_TO_LAUNCH
    set_current(seq: int) -> bool           MISSION_SET_CURRENT / DO_SET_MISSION_CURRENT (wire seq)
    mission_changed(mission, mission_type)  after an accepted upload or clear (255 = all types)
    params() -> dict[str, float]            the parameter table, in a stable order
    set_param(name: str, value: float) -> bool

``DefaultHandlers`` implements it in memory (tests, and a base for the daemon); ``ConfigParams``
maps a few ArduPilot parameter names onto the daemon's ``Config``.

Telemetry senders (``send_global_position_int``, ``send_gps_raw_int``, ``send_attitude``,
``send_sys_status``) may be called every loop: each sends only when its message is due at the
rate the ground station asked for (default rates in ``GcsParams``) and returns whether it sent.
``send_mission_item_reached`` and ``send_statustext`` always send.
"""

from __future__ import annotations

import enum
import logging
import math
import os
from dataclasses import dataclass, field
from typing import Protocol

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402  (MAVLINK20 must be set before the import)
from pymavlink.dialects.v20 import ardupilotmega as mav  # noqa: E402

from rover_ctl import __version__  # noqa: E402
from rover_ctl.config import Config, GcsParams  # noqa: E402
from rover_ctl.mission.model import Home, Mission  # noqa: E402
from rover_ctl.mavlink.mission import MissionService  # noqa: E402
from rover_ctl.mission.store import MissionStore, StoreError  # noqa: E402
from rover_ctl.vocabulary import ARM_FORCE_MAGIC, AUTONOMOUS_MODES, RoverMode  # noqa: E402

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class VehicleState:
    armed: bool = False
    custom_mode: int = RoverMode.HOLD
    system_status: int = mav.MAV_STATE_STANDBY
    home: Home | None = None


class AutopilotHandlers(Protocol):
    def state(self) -> VehicleState: ...
    def arm(self, arm: bool, force: bool) -> int: ...
    def set_mode(self, custom_mode: int) -> int: ...
    def mission_start(self) -> int: ...
    def return_to_launch(self) -> int: ...
    def set_current(self, seq: int) -> bool: ...
    def mission_changed(self, mission: Mission, mission_type: int) -> None: ...
    def params(self) -> dict[str, float]: ...
    def set_param(self, name: str, value: float) -> bool: ...


_FS_ACTIONS = {0: "continue", 1: "rtl", 2: "hold"}


class ConfigParams:
    """ArduPilot-named parameters backed by the daemon's ``Config``.

    SYSID_THISMAV (read-only here: it takes a restart), WP_RADIUS (executor.acceptance_radius_m),
    WP_SPEED (executor.cruise_speed_mps), RTL_SPEED (executor.rtl_speed_mps), FS_GCS_TIMEOUT
    (failsafe.gcs_timeout_s), FS_ACTION (failsafe.gcs_action: 0 continue, 1 RTL, 2 hold).
    """

    def __init__(self, config: Config) -> None:
        self.config = config
        ex, fs = config.executor, config.failsafe
        self._fields: dict[str, tuple[object, str]] = {
            "WP_RADIUS": (ex, "acceptance_radius_m"),
            "WP_SPEED": (ex, "cruise_speed_mps"),
            "RTL_SPEED": (ex, "rtl_speed_mps"),
            "FS_GCS_TIMEOUT": (fs, "gcs_timeout_s"),
        }

    def params(self) -> dict[str, float]:
        values = {"SYSID_THISMAV": float(self.config.gcs.system_id)}
        values.update({name: float(getattr(obj, attr)) for name, (obj, attr) in self._fields.items()})
        actions = {v: k for k, v in _FS_ACTIONS.items()}
        values["FS_ACTION"] = float(actions.get(self.config.failsafe.gcs_action, 0))
        return values

    def set_param(self, name: str, value: float) -> bool:
        if not math.isfinite(value):
            return False
        if name in self._fields:
            if value < 0:
                return False
            obj, attr = self._fields[name]
            setattr(obj, attr, value)
            return True
        if name == "FS_ACTION" and int(value) == value and int(value) in _FS_ACTIONS:
            self.config.failsafe.gcs_action = _FS_ACTIONS[int(value)]
            return True
        return False


class DefaultHandlers:
    """In-memory autopilot: arming, modes, mission start and RTL change only this state."""

    def __init__(self, config: Config | None = None, home: Home | None = None) -> None:
        self.armed = False
        self.custom_mode = int(RoverMode.HOLD)
        self.home = home
        self.mission = Mission()
        self.current_seq = 0
        self.table = ConfigParams(config or Config())

    def state(self) -> VehicleState:
        status = mav.MAV_STATE_ACTIVE if self.armed else mav.MAV_STATE_STANDBY
        return VehicleState(self.armed, self.custom_mode, status, self.home)

    def arm(self, arm: bool, force: bool) -> int:
        self.armed = arm
        return mav.MAV_RESULT_ACCEPTED

    def set_mode(self, custom_mode: int) -> int:
        if custom_mode not in tuple(RoverMode):
            return mav.MAV_RESULT_DENIED
        self.custom_mode = custom_mode
        return mav.MAV_RESULT_ACCEPTED

    def mission_start(self) -> int:
        if not self.mission.items:
            return mav.MAV_RESULT_DENIED
        self.custom_mode = int(RoverMode.AUTO)
        return mav.MAV_RESULT_ACCEPTED

    def return_to_launch(self) -> int:
        self.custom_mode = int(RoverMode.RTL)
        return mav.MAV_RESULT_ACCEPTED

    def set_current(self, seq: int) -> bool:
        self.current_seq = seq
        return True

    def mission_changed(self, mission: Mission, mission_type: int) -> None:
        self.mission = mission

    def params(self) -> dict[str, float]:
        return self.table.params()

    def set_param(self, name: str, value: float) -> bool:
        return self.table.set_param(name, value)


# Telemetry the senders rate-limit, by MAVLink message id.
_TELEMETRY = {
    mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: "position_rate_hz",
    mav.MAVLINK_MSG_ID_GPS_RAW_INT: "gps_rate_hz",
    mav.MAVLINK_MSG_ID_ATTITUDE: "attitude_rate_hz",
    mav.MAVLINK_MSG_ID_SYS_STATUS: "sys_status_rate_hz",
    mav.MAVLINK_MSG_ID_MISSION_CURRENT: "mission_current_rate_hz",
}
# REQUEST_DATA_STREAM stream -> our messages in it (as ArduPilot groups them).
_STREAMS = {
    mav.MAV_DATA_STREAM_EXTENDED_STATUS: (
        mav.MAVLINK_MSG_ID_SYS_STATUS, mav.MAVLINK_MSG_ID_GPS_RAW_INT, mav.MAVLINK_MSG_ID_MISSION_CURRENT,
    ),
    mav.MAV_DATA_STREAM_POSITION: (mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,),
    mav.MAV_DATA_STREAM_EXTRA1: (mav.MAVLINK_MSG_ID_ATTITUDE,),
}  # fmt: skip
_STREAMS[mav.MAV_DATA_STREAM_ALL] = tuple(_TELEMETRY)

CAPABILITIES = (
    mav.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mav.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mav.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | mav.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
    | mav.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY
)
"""What AUTOPILOT_VERSION claims: only what this link implements."""
FIRMWARE_VERSION_TYPE_DEV = 0
STATUSTEXT_CHUNK = 50
"""STATUSTEXT carries 50 characters; longer texts go out in chunks sharing an id (MAVLink 2)."""


def _software_version() -> int:
    """AUTOPILOT_VERSION.flight_sw_version: major, minor, patch, type in the four bytes."""
    parts = [int(p) if p.isdigit() else 0 for p in __version__.split(".")[:3]] + [0, 0, 0]
    return (parts[0] << 24) | (parts[1] << 16) | (parts[2] << 8) | FIRMWARE_VERSION_TYPE_DEV


@dataclass
class _Rates:
    """Per-message send intervals (None = off) and when each was last sent."""

    interval_s: dict[int, float | None] = field(default_factory=dict)
    last_s: dict[int, float] = field(default_factory=dict)

    def pending(self, msg_id: int, now_s: float) -> bool:
        """Whether the message is due now (without taking its slot)."""
        interval = self.interval_s.get(msg_id)
        if interval is None:
            return False
        last = self.last_s.get(msg_id)
        return last is None or now_s - last >= interval

    def due(self, msg_id: int, now_s: float) -> bool:
        """Whether the message is due now; if so, its slot is taken."""
        if not self.pending(msg_id, now_s):
            return False
        self.last_s[msg_id] = now_s
        return True


class GcsLink:
    """The daemon's GCS link (see the module docstring)."""

    def __init__(
        self,
        url: str,
        params: GcsParams | None = None,
        handlers: AutopilotHandlers | None = None,
        store: MissionStore | None = None,
    ) -> None:
        self.params = params or GcsParams()
        self.handlers: AutopilotHandlers = handlers or DefaultHandlers()
        self.store = store
        self.store_error: str | None = None
        """Why the stored mission could not be loaded (the file was moved aside), if it could not."""
        self._changed_type = 0
        self.rates = _Rates({msg_id: self._default_interval(msg_id) for msg_id in _TELEMETRY})
        self.last_gcs_heartbeat_s: float | None = None
        """When a ground station's HEARTBEAT last arrived (for the GCS failsafe)."""
        self._next_heartbeat_s: float | None = None
        self._statustext_id = 0
        self.conn = mavutil.mavlink_connection(
            url,
            source_system=self.params.system_id,
            source_component=self.params.component_id,
            dialect="ardupilotmega",
            autoreconnect=True,
        )
        self.conn.mav.WIRE_PROTOCOL_VERSION = "2.0"
        mission = self._load_store()
        self.service = MissionService(mission, self.params, commit=self._commit, set_current=self.handlers.set_current)
        if mission.items or mission.fence or mission.rally:
            self.handlers.mission_changed(mission, mav.MAV_MISSION_TYPE_ALL)

    def close(self) -> None:
        self.conn.close()

    # ---------------------------------------------------------------- loop

    def poll(self, now_s: float) -> None:
        """Read and dispatch every pending message, then send what is due. Never blocks."""
        state = self.handlers.state()
        self.service.vehicle_home = state.home
        while (msg := self.conn.recv_msg()) is not None:
            if msg.get_type() != "BAD_DATA":
                self._dispatch(msg, now_s)
        self._send_all(self.service.tick(now_s))
        if self._next_heartbeat_s is None or now_s >= self._next_heartbeat_s:
            self._next_heartbeat_s = now_s + self.params.heartbeat_period_s
            self.send_heartbeat()
        if self.rates.due(mav.MAVLINK_MSG_ID_MISSION_CURRENT, now_s):
            self.conn.mav.send(self.service.mission_current())

    def _dispatch(self, msg, now_s: float) -> None:
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            if msg.type == mav.MAV_TYPE_GCS:
                if self.last_gcs_heartbeat_s is None:
                    # A first ground station: answer now rather than at the next period, so it
                    # finds its autopilot at once (on udpin nothing reached it before it spoke).
                    self._next_heartbeat_s = None
                self.last_gcs_heartbeat_s = now_s
            return
        if kind in MissionService.HANDLED:
            before = self.service.mission
            replies = self.service.handle(msg, now_s)
            if self.service.mission is not before:  # tell the daemon before the GCS hears the ACK
                self.handlers.mission_changed(self.service.mission, self._changed_type)
            self._send_all(replies)
            return
        if getattr(msg, "target_system", 0) not in (0, self.params.system_id):
            return
        sender = (msg.get_srcSystem(), msg.get_srcComponent())
        if kind in ("COMMAND_LONG", "COMMAND_INT"):
            self._on_command(msg, sender)
        elif kind == "SET_MODE":
            self.handlers.set_mode(msg.custom_mode)
        elif kind == "REQUEST_DATA_STREAM":
            rate = msg.req_message_rate if msg.start_stop else 0
            for msg_id in _STREAMS.get(msg.req_stream_id, ()):
                self.rates.interval_s[msg_id] = 1.0 / rate if rate > 0 else None
        elif kind == "PARAM_REQUEST_LIST":
            table = self.handlers.params()
            for index, name in enumerate(table):
                self._send_param(name, table, index)
        elif kind == "PARAM_REQUEST_READ":
            table = self.handlers.params()
            names = list(table)
            name = msg.param_id if msg.param_index < 0 else (names[msg.param_index] if msg.param_index < len(names) else None)
            if name in table:
                self._send_param(name, table)
        elif kind == "PARAM_SET":
            if self.handlers.set_param(msg.param_id, msg.param_value):
                log.info("parameter %s set to %g", msg.param_id, msg.param_value)
            table = self.handlers.params()  # echo the value in force, as ArduPilot does
            if msg.param_id in table:
                self._send_param(msg.param_id, table)

    def _commit(self, mission: Mission, mission_type: int) -> None:
        if self.store is not None:
            self.store.save(mission)
        self._changed_type = mission_type

    def _load_store(self) -> Mission:
        if self.store is None:
            return Mission()
        try:
            return self.store.load()
        except StoreError as exc:
            aside = self.store.quarantine()
            kept = f"moved to {aside}" if aside else "left as it is"
            self.store_error = f"{exc}; {kept}, starting with no mission"
            log.error("%s", self.store_error)
            return Mission()

    def _default_interval(self, msg_id: int) -> float | None:
        rate_hz = getattr(self.params, _TELEMETRY[msg_id])
        return 1.0 / rate_hz if rate_hz > 0 else None

    def _send_all(self, messages: list) -> None:
        for message in messages:
            self.conn.mav.send(message)

    # ---------------------------------------------------------------- commands

    def _on_command(self, msg, sender: tuple[int, int]) -> None:
        command = msg.command
        h = self.handlers
        followup = None
        if command == mav.MAV_CMD_COMPONENT_ARM_DISARM:
            result = h.arm(msg.param1 == 1, round(msg.param2) == ARM_FORCE_MAGIC)
        elif command == mav.MAV_CMD_DO_SET_MODE:
            result = h.set_mode(int(msg.param2))
        elif command == mav.MAV_CMD_MISSION_START:
            result = h.mission_start()
        elif command == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            result = h.return_to_launch()
        elif command == mav.MAV_CMD_DO_SET_MISSION_CURRENT:
            replies = self.service.request_current(int(msg.param1))
            ok = replies[0].get_type() == "MISSION_CURRENT"
            result = mav.MAV_RESULT_ACCEPTED if ok else mav.MAV_RESULT_DENIED
            followup = replies[0] if ok else None
        elif command in (mav.MAV_CMD_REQUEST_MESSAGE, mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES):
            msg_id = int(msg.param1) if command == mav.MAV_CMD_REQUEST_MESSAGE else mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION
            result, followup = self._requested(msg_id)
        elif command == mav.MAV_CMD_GET_HOME_POSITION:
            result, followup = self._requested(mav.MAVLINK_MSG_ID_HOME_POSITION)
        elif command == mav.MAV_CMD_SET_MESSAGE_INTERVAL:
            result = self._set_interval(int(msg.param1), msg.param2)
        else:
            result = mav.MAV_RESULT_UNSUPPORTED
        self.conn.mav.send(mav.MAVLink_command_ack_message(command, result, 0, 0, sender[0], sender[1]))
        if followup is not None:
            self.conn.mav.send(followup)

    def _requested(self, msg_id: int):
        if msg_id == mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            return mav.MAV_RESULT_ACCEPTED, self.autopilot_version()
        if msg_id == mav.MAVLINK_MSG_ID_HOME_POSITION:
            home = self.home()
            if home is None:
                return mav.MAV_RESULT_FAILED, None
            return mav.MAV_RESULT_ACCEPTED, self.home_position(home)
        return mav.MAV_RESULT_UNSUPPORTED, None

    def _set_interval(self, msg_id: int, interval_us: float) -> int:
        if msg_id not in _TELEMETRY:
            return mav.MAV_RESULT_DENIED
        if interval_us == 0:
            self.rates.interval_s[msg_id] = self._default_interval(msg_id)
        elif interval_us < 0:
            self.rates.interval_s[msg_id] = None
        else:
            self.rates.interval_s[msg_id] = interval_us * 1e-6
        return mav.MAV_RESULT_ACCEPTED

    def _send_param(self, name: str, table: dict[str, float], index: int | None = None) -> None:
        if index is None:
            index = list(table).index(name)
        self.conn.mav.param_value_send(
            name.encode(), table[name], mav.MAV_PARAM_TYPE_REAL32, len(table), index
        )

    # ---------------------------------------------------------------- messages

    def home(self) -> Home | None:
        """The vehicle's home if the daemon has one, else the stored mission's planned home."""
        return self.handlers.state().home or self.service.mission.home

    def autopilot_version(self):
        return mav.MAVLink_autopilot_version_message(
            CAPABILITIES, _software_version(), 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0, [0] * 18
        )

    @staticmethod
    def home_position(home: Home):
        return mav.MAVLink_home_position_message(
            round(home.lat_deg * 1e7), round(home.lon_deg * 1e7), round(home.alt_m * 1000),
            0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, 0,
        )  # fmt: skip

    def send_heartbeat(self) -> None:
        state = self.handlers.state()
        base_mode = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mav.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        if state.armed:
            base_mode |= mav.MAV_MODE_FLAG_SAFETY_ARMED
        if state.custom_mode in AUTONOMOUS_MODES:
            base_mode |= mav.MAV_MODE_FLAG_GUIDED_ENABLED | mav.MAV_MODE_FLAG_AUTO_ENABLED
        self.conn.mav.heartbeat_send(
            mav.MAV_TYPE_GROUND_ROVER, mav.MAV_AUTOPILOT_ARDUPILOTMEGA, base_mode, state.custom_mode, state.system_status
        )

    def send_global_position_int(
        self, now_s: float, lat_deg: float, lon_deg: float, alt_m: float, relative_alt_m: float,
        ve_mps: float, vn_mps: float, heading_deg: float, time_boot_ms: int,
    ) -> bool:  # fmt: skip
        """GLOBAL_POSITION_INT from the fused estimate (heading: compass degrees, 0 north)."""
        if not self.rates.due(mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, now_s):
            return False
        self.conn.mav.global_position_int_send(
            time_boot_ms, round(lat_deg * 1e7), round(lon_deg * 1e7), round(alt_m * 1000),
            round(relative_alt_m * 1000), round(vn_mps * 100), round(ve_mps * 100), 0,
            round((heading_deg % 360.0) * 100) % 36000,
        )  # fmt: skip
        return True

    def send_gps_raw_int(self, now_s: float, msg) -> bool:
        """Forward the vehicle's GPS_RAW_INT (a pymavlink message) as ours."""
        if not self.rates.due(mav.MAVLINK_MSG_ID_GPS_RAW_INT, now_s):
            return False
        self.conn.mav.send(msg)
        return True

    def pose_due(self, now_s: float) -> bool:
        """Whether GLOBAL_POSITION_INT or ATTITUDE would go out now, so that a caller polling every
        loop turn computes the pose for them only a few times a second."""
        return any(self.rates.pending(m, now_s) for m in (mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, mav.MAVLINK_MSG_ID_ATTITUDE))

    def send_attitude(self, now_s: float, yaw_rad_ned: float, yawspeed_radps: float, time_boot_ms: int) -> bool:
        """ATTITUDE with the estimate's heading (NED: 0 north, clockwise positive)."""
        if not self.rates.due(mav.MAVLINK_MSG_ID_ATTITUDE, now_s):
            return False
        yaw = math.remainder(yaw_rad_ned, 2.0 * math.pi)
        self.conn.mav.attitude_send(time_boot_ms, 0.0, 0.0, yaw, 0.0, 0.0, yawspeed_radps)
        return True

    def send_sys_status(self, now_s: float, voltage_v: float, remaining_pct: int, present: int = 0,
                        enabled: int | None = None, failed: int = 0) -> bool:
        """SYS_STATUS with the battery (``remaining_pct`` -1 when unknown) and MAV_SYS_STATUS_*
        sensor bits. As ArduPilot reports them, a bit is healthy unless it is in ``failed``, and
        the GEOFENCE bit is healthy whenever the fence is not breached: ground stations (MAVProxy)
        announce a breach when that health bit is clear."""
        if not self.rates.due(mav.MAVLINK_MSG_ID_SYS_STATUS, now_s):
            return False
        health = (present | mav.MAV_SYS_STATUS_GEOFENCE) & ~failed & 0xFFFFFFFF
        self.conn.mav.sys_status_send(
            present, present if enabled is None else enabled, health, 0, round(voltage_v * 1000), -1, remaining_pct,
            0, 0, 0, 0, 0, 0,
        )  # fmt: skip
        return True

    def send_mission_current(self, seq: int, mission_state: int = mav.MISSION_STATE_ACTIVE) -> None:
        """The executor moved to wire seq ``seq``: record it and tell the ground station now."""
        self.service.set_current(seq)
        self.conn.mav.send(self.service.mission_current(mission_state))

    def send_mission_item_reached(self, seq: int) -> None:
        self.conn.mav.send(self.service.item_reached(seq))

    def send_statustext(self, text: str, severity: int = mav.MAV_SEVERITY_INFO) -> None:
        data = text.encode("utf-8", "replace")
        if len(data) <= STATUSTEXT_CHUNK:
            self.conn.mav.statustext_send(severity, data, 0, 0)
            return
        self._statustext_id = self._statustext_id % 65535 + 1
        chunks = [data[i : i + STATUSTEXT_CHUNK] for i in range(0, len(data), STATUSTEXT_CHUNK)]
        if len(chunks[-1]) == STATUSTEXT_CHUNK:
            chunks.append(b"")  # a full last chunk needs an empty one to end the text
        for index, chunk in enumerate(chunks):
            self.conn.mav.statustext_send(severity, chunk, self._statustext_id, index)
