"""The GCS link: the daemon as the rover's autopilot towards ground stations.

``GcsLink`` owns one pymavlink connection (``udpin:``, ``udpout:``, ``tcpin:``, ``tcp:``), speaks
MAVLink 2 (ardupilotmega) as system ``GcsParams.system_id`` component 1, and has no thread: the
daemon calls ``poll(now_s)`` from its loop, which reads every pending message, hands it to the
microservice that owns it, runs the mission service's timeouts and sends what is due (HEARTBEAT,
MISSION_CURRENT). ``now_s`` is the daemon's clock (monotonic or simulated); only differences are
used. One module per MAVLink microservice, as MAVSDK is built (docs/gcs.md lists what a ground
station gets, with the tested clients):

* ``rover_ctl.mavlink.telemetry``: HEARTBEAT, GLOBAL_POSITION_INT, GPS_RAW_INT, ATTITUDE,
  SYS_STATUS, STATUSTEXT, and the rates ground stations ask for;
* ``rover_ctl.mavlink.commands``: COMMAND_LONG / COMMAND_INT / SET_MODE with COMMAND_ACK;
* ``rover_ctl.mavlink.mission``: the mission protocol for missions, fences and rally points,
  persisted through ``MissionStore`` so a restarted daemon keeps its mission;
* ``rover_ctl.mavlink.params``: the parameter protocol.

The daemon plugs in through ``AutopilotHandlers`` (a Protocol; every MAV_RESULT is an int):

    state() -> VehicleState                 armed, custom_mode, system_status, home, mission_state
    arm(arm: bool, force: bool) -> int      MAV_CMD_COMPONENT_ARM_DISARM (force: ARM_FORCE_MAGIC);
                                            ACK_LATER: acknowledged by ``command_result`` later
    set_mode(custom_mode: int) -> int       DO_SET_MODE / SET_MODE (RoverMode numbers)
    mission_start() -> int                  MAV_CMD_MISSION_START
    return_to_launch() -> int               MAV_CMD_NAV_RETURN_TO_LAUNCH
    set_current(seq: int) -> bool           MISSION_SET_CURRENT / DO_SET_MISSION_CURRENT (wire seq)
    mission_changed(mission, mission_type)  after an accepted upload or clear (255 = all types)
    guided_target(lat, lon, change_mode) -> int   a GUIDED destination, from any of the forms
                                            ground stations send (below)
    params() -> dict[str, float]            the parameter table, in a stable order
    set_param(name: str, value: float) -> (ok: bool, reason: str)   reason: a STATUSTEXT (refusals)

A refusal's reason is the handler's to say (a STATUSTEXT before the ACK, as ArduPilot does).

What a stranger's datagrams can cost is bounded (docs/gcs.md, "The gate"):

* frames are read without pymavlink's ``post_message``: its bookkeeping keeps a table per source
  system and message type, a new entry per instance value (a NAMED_VALUE_FLOAT ``name``, a
  PARAM_VALUE ``param_id``), all before any check; with a new name in each frame it grew the
  daemon by 350 MB in 13 s. Nothing here reads it (``conn.messages``, ``target_system``, the loss
  counters): each microservice keeps its own bounded state;
* the connection's message hooks (the tlog, SETUP_SIGNING) run for the frames that passed the
  signature check and the gate (``rover_ctl.mavlink.inbound``), after it; a refused frame is
  counted there (``inbound.dropped``, ``inbound.refused``, ``signing.rejected``), not logged;
* on ``udpin`` the daemon sends to the ground stations in its own peer table
  (``rover_ctl.mavlink.peers``: those whose frames passed, at most ``GcsParams.max_peers``, the
  one silent longest replaced by a newcomer), not to every address pymavlink ever heard from.

GUIDED destinations arrive as MAV_CMD_DO_REPOSITION (COMMAND_INT, as QGroundControl's "go to
location" and MAVProxy's ``guided LAT LON ALT`` send it, or COMMAND_LONG; its CHANGE_MODE flag
switches to GUIDED), as SET_POSITION_TARGET_GLOBAL_INT (only in GUIDED, no answer), or as a
MISSION_ITEM(_INT) NAV_WAYPOINT with ``current`` = 2 (ArduPilot's guided-WP convention, sent by
MAVProxy with ``guided_use_reposition`` off and by QGroundControl when DO_REPOSITION is
unsupported), answered with MISSION_ACK.

``DefaultHandlers`` implements it in memory (tests, and a base for the daemon).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
import os
from typing import Protocol

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402  (MAVLINK20 first: mavutil's default dialect is MAVLink 1 without it)

from rover_ctl.config import Config, GcsParams
from rover_ctl.mavlink import commands, params
from rover_ctl.mavlink.commands import CommandService
from rover_ctl.mavlink.inbound import Inbound
from rover_ctl.mavlink.mission import MissionService, item_from_message
from rover_ctl.mavlink.params import ConfigParams, ParamService
from rover_ctl.mavlink.peers import UdpPeers, serves_many
from rover_ctl.mavlink.signing import KeyStore, LinkSigning
from rover_ctl.mavlink.telemetry import Telemetry
from rover_ctl.mission.model import Home, Mission
from rover_ctl.mission.store import MissionStore, StoreError
from rover_ctl.vocabulary import RoverMode, mav

log = logging.getLogger(__name__)

HANDLED = ("HEARTBEAT", *sorted(MissionService.HANDLED), *commands.HANDLED, "REQUEST_DATA_STREAM", *params.HANDLED,
           "SET_POSITION_TARGET_GLOBAL_INT")  # fmt: skip
"""Every message type the GCS link acts on (the fuzz suite and the soak bench send each)."""

GUIDED_ITEMS = ("MISSION_ITEM_INT", "MISSION_ITEM")
GUIDED_ITEM_CURRENT = 2
"""MISSION_ITEM.current = 2 marks a GUIDED destination, not an upload (ArduPilot's convention)."""
POSITION_IGNORED = mav.POSITION_TARGET_TYPEMASK_X_IGNORE | mav.POSITION_TARGET_TYPEMASK_Y_IGNORE
"""SET_POSITION_TARGET_GLOBAL_INT without a position (velocity or yaw only): not a destination."""


@dataclass(frozen=True)
class VehicleState:
    armed: bool = False
    custom_mode: int = RoverMode.HOLD
    system_status: int = mav.MAV_STATE_STANDBY
    home: Home | None = None
    mission_state: int = mav.MISSION_STATE_UNKNOWN
    """MISSION_CURRENT.mission_state (MISSION_STATE_*)."""


class AutopilotHandlers(Protocol):
    def state(self) -> VehicleState: ...
    def arm(self, arm: bool, force: bool) -> int: ...
    def set_mode(self, custom_mode: int) -> int: ...
    def mission_start(self) -> int: ...
    def return_to_launch(self) -> int: ...
    def set_current(self, seq: int) -> bool: ...
    def mission_changed(self, mission: Mission, mission_type: int) -> None: ...
    def guided_target(self, lat_deg: float, lon_deg: float, change_mode: bool) -> int: ...
    def params(self) -> dict[str, float]: ...
    def set_param(self, name: str, value: float) -> tuple[bool, str]: ...


class DefaultHandlers:
    """In-memory autopilot: arming, modes, mission start and RTL change only this state."""

    def __init__(self, config: Config | None = None, home: Home | None = None) -> None:
        self.armed = False
        self.custom_mode = int(RoverMode.HOLD)
        self.home = home
        self.mission = Mission()
        self.current_seq = 0
        self.guided: tuple[float, float] | None = None
        self.table = ConfigParams(config or Config())

    def state(self) -> VehicleState:
        status = mav.MAV_STATE_ACTIVE if self.armed else mav.MAV_STATE_STANDBY
        mission_state = mav.MISSION_STATE_NOT_STARTED if self.mission.items else mav.MISSION_STATE_NO_MISSION
        if self.mission.items and self.custom_mode == RoverMode.AUTO:
            mission_state = mav.MISSION_STATE_ACTIVE
        return VehicleState(self.armed, self.custom_mode, status, self.home, mission_state)

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

    def guided_target(self, lat_deg: float, lon_deg: float, change_mode: bool) -> int:
        if self.custom_mode != RoverMode.GUIDED and not change_mode:
            return mav.MAV_RESULT_DENIED
        self.custom_mode = int(RoverMode.GUIDED)
        self.guided = (lat_deg, lon_deg)
        return mav.MAV_RESULT_ACCEPTED

    def params(self) -> dict[str, float]:
        return self.table.params()

    def set_param(self, name: str, value: float) -> tuple[bool, str]:
        return self.table.set_param(name, value)


class GcsLink:
    """The daemon's GCS link (see the module docstring)."""

    def __init__(
        self,
        url: str,
        params: GcsParams | None = None,
        handlers: AutopilotHandlers | None = None,
        store: MissionStore | None = None,
        signing: KeyStore | None = None,
    ) -> None:
        self.params = params or GcsParams()
        self.handlers: AutopilotHandlers = handlers or DefaultHandlers()
        self.store = store
        self.store_error: str | None = None
        """Why the stored mission could not be loaded (the file was moved aside), if it could not."""
        self._changed_type = 0
        self.last_gcs_heartbeat_s: float | None = None
        """When our ground station's (``ground_station_system_id``) last HEARTBEAT came (for the
        GCS-loss failsafe)."""
        self._ground_station_seen = False
        """Whether any ground station's HEARTBEAT came yet (the first is answered at once)."""
        self._next_heartbeat_s: float | None = None
        self.conn = mavutil.mavlink_connection(
            url,
            source_system=self.params.system_id,
            source_component=self.params.component_id,
            dialect="ardupilotmega",
            autoreconnect=True,
        )
        self.conn.mav.WIRE_PROTOCOL_VERSION = "2.0"
        self.peers = UdpPeers(self.conn, self.params) if serves_many(self.conn) else None
        """The ground stations sent to on udpin (before ``Inbound``, which frames its reads)."""
        self.signing = LinkSigning(self.conn, signing, self.params, notify=lambda text, severity: self.send_statustext(text, severity))
        """MAVLink 2 signing (rover_ctl.mavlink.signing): with a key in ``signing`` unsigned frames are dropped."""
        self.inbound = Inbound(self.params, self.conn)
        mission = self._load_store()
        self.service = MissionService(mission, self.params, commit=self._commit, set_current=self.handlers.set_current)
        self.telemetry = Telemetry(self.conn, self.params)
        self.commands = CommandService(self.conn, self.handlers, self.service, self.telemetry, self.home)
        self.param_service = ParamService(self.conn, self.handlers, say=self.telemetry.send_statustext,
                                          rate_hz=lambda: self.params.param_send_rate_hz)  # fmt: skip
        if mission.items or mission.fence or mission.rally:
            self.handlers.mission_changed(mission, mav.MAV_MISSION_TYPE_ALL)

    def close(self) -> None:
        self.signing.close()
        self.conn.close()

    # ---------------------------------------------------------------- loop

    def poll(self, now_s: float, readable: bool = True) -> None:
        """Read and dispatch every pending message, then send what is due. Never blocks.
        ``readable=False``: the caller's ``select`` found nothing waiting on the socket, so only
        frames the parser already holds are read (no system call for nothing)."""
        state = self.handlers.state()
        self.service.vehicle_home = state.home
        self.service.mission_state = state.mission_state
        reads = self.params.max_messages_per_poll if readable or self.conn.mav.buf_len() else 0
        for _ in range(reads):  # a flood must not starve the control loop
            try:
                msg = self._receive()
            except OSError as exc:  # a socket error (ICMP-reported, reset): the next turn tries again
                log.debug("GCS link receive: %s", exc)
                break
            if msg is None:
                break
            self._dispatch(msg, now_s)
        self._send_all(self.service.tick(now_s))
        self.param_service.tick(now_s)
        if self._next_heartbeat_s is None or now_s >= self._next_heartbeat_s:
            self._next_heartbeat_s = now_s + self.params.heartbeat_period_s
            self.send_heartbeat()
        if self.telemetry.rates.due(mav.MAVLINK_MSG_ID_MISSION_CURRENT, now_s):
            self.conn.mav.send(self.service.mission_current())

    def _receive(self):
        """The next frame (None when nothing is waiting), as pymavlink's ``recv_msg`` reads it but
        without its ``post_message`` (see the module docstring); a frame that fails its signature
        is a BAD_DATA here, as there."""
        conn = self.conn
        while True:
            data = conn.recv(conn.mav.bytes_needed())
            if data and conn.first_byte:
                conn.auto_mavlink_version(data)
            msg = conn.mav.parse_char(data)
            if msg is not None or not data:
                return msg

    def _dispatch(self, msg, now_s: float) -> None:
        """Check ``msg`` at the gate (``rover_ctl.mavlink.inbound``); if it passes, admit its sender
        as a peer (udpin; with a key only if it is signed), run the message hooks (the tlog) and hand
        it to its microservice. A handler that raises anyway is logged and counted there, and the
        link goes on."""
        verdict = self.inbound.check(msg)
        if not verdict.ok:
            if verdict.reply is not None:
                self._answer_refusal(verdict.reply)
            return
        if self.peers is not None and (msg.get_signed() or not self.signing.enabled):
            self.peers.admit(now_s)
        for step in (self._run_hooks, self._route):
            try:
                step(msg, now_s)
            except Exception as exc:  # the link edge: one bad message never stops the daemon
                self.inbound.failed(msg, exc)

    def _run_hooks(self, msg, now_s: float) -> None:
        for hook in self.conn.message_hooks:
            hook(self.conn, msg)

    def _answer_refusal(self, reply) -> None:
        """The protocol's refusal goes to whoever asked: on udpin to the sender's address alone
        (a sender whose first frame was refused is no peer, and the other peers did not ask)."""
        if self.peers is None:
            self.conn.mav.send(reply)
            return
        with self.peers.only(self.peers.source):
            self.conn.mav.send(reply)

    def _route(self, msg, now_s: float) -> None:
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            if msg.type == mav.MAV_TYPE_GCS:
                if not self._ground_station_seen:
                    # A first ground station: answer now rather than at the next period, so it
                    # finds its autopilot at once (on udpin nothing reached it before it spoke).
                    self._ground_station_seen = True
                    self._next_heartbeat_s = None
                if self.params.ground_station_system_id in (0, msg.get_srcSystem()):
                    self.last_gcs_heartbeat_s = now_s  # the GCS-loss failsafe's, as ArduPilot's MAV_GCS_SYSID
            return
        if kind in GUIDED_ITEMS and getattr(msg, "current", 0) == GUIDED_ITEM_CURRENT:
            self._guided_item(msg)
            return
        if kind == "SET_POSITION_TARGET_GLOBAL_INT":
            if msg.target_system in (0, self.params.system_id) and not msg.type_mask & POSITION_IGNORED:
                self.handlers.guided_target(msg.lat_int / 1e7, msg.lon_int / 1e7, False)
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
        if kind in commands.HANDLED:
            self.commands.handle(msg)
        elif kind == "REQUEST_DATA_STREAM":
            self.telemetry.on_request_data_stream(msg)
        elif kind in params.HANDLED:
            self.param_service.handle(msg)

    def _guided_item(self, msg) -> None:
        """A MISSION_ITEM(_INT) with current = 2: a GUIDED destination, answered by MISSION_ACK."""
        if msg.target_system not in (0, self.params.system_id):
            return
        item = item_from_message(msg)
        result = mav.MAV_MISSION_UNSUPPORTED
        if item.command == mav.MAV_CMD_NAV_WAYPOINT and item.is_global:
            accepted = self.handlers.guided_target(item.x, item.y, False) == mav.MAV_RESULT_ACCEPTED
            result = mav.MAV_MISSION_ACCEPTED if accepted else mav.MAV_MISSION_ERROR
        self.conn.mav.send(mav.MAVLink_mission_ack_message(msg.get_srcSystem(), msg.get_srcComponent(), result, msg.mission_type))

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

    def _send_all(self, messages: list) -> None:
        for message in messages:
            self.conn.mav.send(message)

    # ---------------------------------------------------------------- what the daemon sends

    def home(self) -> Home | None:
        """The vehicle's home if the daemon has one, else the stored mission's planned home."""
        return self.handlers.state().home or self.service.mission.home

    def send_heartbeat(self) -> None:
        state = self.handlers.state()
        self.telemetry.send_heartbeat(state.armed, state.custom_mode, state.system_status)

    def pose_due(self, now_s: float) -> bool:
        return self.telemetry.pose_due(now_s)

    def sys_status_due(self, now_s: float) -> bool:
        """Whether SYS_STATUS would go out now (its fields are worth computing)."""
        return self.telemetry.rates.pending(mav.MAVLINK_MSG_ID_SYS_STATUS, now_s)

    def send_global_position_int(self, now_s: float, *args) -> bool:
        return self.telemetry.send_global_position_int(now_s, *args)

    def send_gps_raw_int(self, now_s: float, msg) -> bool:
        return self.telemetry.send_gps_raw_int(now_s, msg)

    def send_attitude(self, now_s: float, yaw_rad_ned: float, yawspeed_radps: float, time_boot_ms: int) -> bool:
        return self.telemetry.send_attitude(now_s, yaw_rad_ned, yawspeed_radps, time_boot_ms)

    def send_sys_status(self, now_s: float, voltage_v: float, remaining_pct: int, **bits: int) -> bool:
        return self.telemetry.send_sys_status(now_s, voltage_v, remaining_pct, **bits)

    def command_result(self, command: int, result: int) -> None:
        """The ACK of a command its handler deferred (``commands.ACK_LATER``), to its senders."""
        self.commands.answer(command, result)

    def send_statustext(self, text: str, severity: int = mav.MAV_SEVERITY_INFO) -> None:
        self.telemetry.send_statustext(text, severity)

    def send_mission_current(self, seq: int, mission_state: int = mav.MISSION_STATE_ACTIVE) -> None:
        """The current item or the mission state changed: record it and tell the ground station now."""
        self.service.set_current(seq)
        self.service.mission_state = mission_state
        self.conn.mav.send(self.service.mission_current())

    def send_mission_item_reached(self, seq: int) -> None:
        self.conn.mav.send(self.service.item_reached(seq))
