"""The command microservice on the GCS link: COMMAND_LONG / COMMAND_INT and SET_MODE.

Each command is answered with COMMAND_ACK to its sender: arm/disarm (once the vehicle has answered
it, as ArduPilot's ACK carries the outcome of its own arming checks), DO_SET_MODE, MISSION_START,
NAV_RETURN_TO_LAUNCH, DO_SET_MISSION_CURRENT, DO_REPOSITION (a GUIDED destination: COMMAND_INT x/y
in degE7, COMMAND_LONG param5/6 in degrees; param2's MAV_DO_REPOSITION_FLAGS_CHANGE_MODE switches
to GUIDED), REQUEST_MESSAGE and REQUEST_AUTOPILOT_CAPABILITIES (AUTOPILOT_VERSION, HOME_POSITION),
GET_HOME_POSITION, SET_MESSAGE_INTERVAL; anything else MAV_RESULT_UNSUPPORTED. What a command does
is the autopilot handlers' decision.
"""

from __future__ import annotations

import math
from typing import Any, Callable

from rover_ctl import __version__
from rover_ctl.mission.model import Home
from rover_ctl.vocabulary import ARM_FORCE_MAGIC, mav

HANDLED = ("COMMAND_LONG", "COMMAND_INT", "SET_MODE")
ACK_LATER = -1
"""What a handler returns when the answer is not its own to give yet (arming: the vehicle decides);
the ACK goes out when ``CommandService.answer`` is called with the result."""
MAX_WAITING_SENDERS = 8
"""Ground stations waiting for one command's deferred ACK (a retransmission from the same sender
counts once; beyond this the oldest is dropped: a flood of senders cannot grow the table)."""
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
GLOBAL_INT_FRAMES = frozenset({
    mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, mav.MAV_FRAME_GLOBAL_INT,
    mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mav.MAV_FRAME_GLOBAL_TERRAIN_ALT, mav.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
})  # fmt: skip
"""COMMAND_INT frames whose x/y are latitude/longitude in degE7 (the rover ignores altitude)."""


def software_version() -> int:
    """AUTOPILOT_VERSION.flight_sw_version: major, minor, patch, type in the four bytes."""
    parts = [int(p) if p.isdigit() else 0 for p in __version__.split(".")[:3]] + [0, 0, 0]
    return (parts[0] << 24) | (parts[1] << 16) | (parts[2] << 8) | FIRMWARE_VERSION_TYPE_DEV


def autopilot_version():
    return mav.MAVLink_autopilot_version_message(
        CAPABILITIES, software_version(), 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0, [0] * 18
    )


def home_position(home: Home):
    return mav.MAVLink_home_position_message(
        round(home.lat_deg * 1e7), round(home.lon_deg * 1e7), round(home.alt_m * 1000),
        0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, 0,
    )  # fmt: skip


class CommandService:
    """Dispatches commands to the handlers; ``mission`` is the MissionService (set current),
    ``telemetry`` the rate owner (SET_MESSAGE_INTERVAL), ``home()`` the home to report."""

    def __init__(self, conn: Any, handlers: Any, mission: Any, telemetry: Any, home: Callable[[], Home | None]) -> None:
        self.conn = conn
        self.handlers = handlers
        self.mission = mission
        self.telemetry = telemetry
        self.home = home
        self.waiting: dict[int, list[tuple[int, int]]] = {}
        """Command -> senders waiting for its deferred ACK, oldest first."""

    def handle(self, msg) -> None:
        if msg.get_type() == "SET_MODE":
            self.handlers.set_mode(msg.custom_mode)
            return
        sender = (msg.get_srcSystem(), msg.get_srcComponent())
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
        elif command == mav.MAV_CMD_DO_REPOSITION:
            result = self._reposition(msg)
        elif command == mav.MAV_CMD_DO_SET_MISSION_CURRENT:
            replies = self.mission.request_current(int(msg.param1))
            ok = replies[0].get_type() == "MISSION_CURRENT"
            result = mav.MAV_RESULT_ACCEPTED if ok else mav.MAV_RESULT_DENIED
            followup = replies[0] if ok else None
        elif command in (mav.MAV_CMD_REQUEST_MESSAGE, mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES):
            msg_id = int(msg.param1) if command == mav.MAV_CMD_REQUEST_MESSAGE else mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION
            result, followup = self._requested(msg_id)
        elif command == mav.MAV_CMD_GET_HOME_POSITION:
            result, followup = self._requested(mav.MAVLINK_MSG_ID_HOME_POSITION)
        elif command == mav.MAV_CMD_SET_MESSAGE_INTERVAL:
            result = self.telemetry.set_interval(int(msg.param1), msg.param2)
        else:
            result = mav.MAV_RESULT_UNSUPPORTED
        if result == ACK_LATER:
            senders = self.waiting.setdefault(command, [])
            if sender not in senders:
                senders.append(sender)
                del senders[:-MAX_WAITING_SENDERS]
            return
        self.conn.mav.send(mav.MAVLink_command_ack_message(command, result, 0, 0, sender[0], sender[1]))
        if followup is not None:
            self.conn.mav.send(followup)

    def answer(self, command: int, result: int) -> None:
        """The deferred ACK of ``command``, to every sender waiting for it (none: nothing)."""
        for system, component in self.waiting.pop(command, ()):
            self.conn.mav.send(mav.MAVLink_command_ack_message(command, result, 0, 0, system, component))

    def _reposition(self, msg) -> int:
        if msg.get_type() == "COMMAND_INT":
            if msg.frame not in GLOBAL_INT_FRAMES:
                return mav.MAV_RESULT_DENIED
            lat_deg, lon_deg = msg.x / 1e7, msg.y / 1e7
        else:
            lat_deg, lon_deg = msg.param5, msg.param6
        flags = int(msg.param2) if math.isfinite(msg.param2) else 0
        return self.handlers.guided_target(lat_deg, lon_deg, bool(flags & mav.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE))

    def _requested(self, msg_id: int):
        if msg_id == mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            return mav.MAV_RESULT_ACCEPTED, autopilot_version()
        if msg_id == mav.MAVLINK_MSG_ID_HOME_POSITION:
            home = self.home()
            if home is None:
                return mav.MAV_RESULT_FAILED, None
            return mav.MAV_RESULT_ACCEPTED, home_position(home)
        return mav.MAV_RESULT_UNSUPPORTED, None
