"""The one MAVLink vocabulary: every mode, command, severity and mission number comes from here.

The numbers themselves are pymavlink's generated enums for the ardupilotmega dialect (``mav``);
this module only names the subsets rover_ctl uses as IntEnums, so that a log or a test prints
``RoverMode.AUTO`` rather than 10. Pure: importing the dialect opens nothing. The emulator
(``sitl/``) uses the same enums through pymavlink, never this module: the two share only the wire.
"""

from __future__ import annotations

import enum
import os

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mav  # noqa: E402  (MAVLINK20 first)

__all__ = ["ARM_FORCE_MAGIC", "Cmd", "MissionState", "MissionType", "PILOT_STEER_TYPE", "RoverMode", "STEER_TWO_PADDLES",
           "STEER_UNCHANGED_WHEN_REVERSING", "Severity", "mav"]


class RoverMode(enum.IntEnum):
    """ArduPilot Rover's custom_mode numbers (ROVER_MODE_*) for the modes rover_ctl implements."""

    MANUAL = mav.ROVER_MODE_MANUAL
    HOLD = mav.ROVER_MODE_HOLD
    LOITER = mav.ROVER_MODE_LOITER
    AUTO = mav.ROVER_MODE_AUTO
    RTL = mav.ROVER_MODE_RTL
    GUIDED = mav.ROVER_MODE_GUIDED

    @classmethod
    def named(cls, name: str) -> "RoverMode":
        """A mode by its name, case-insensitive (``rover-ctl mode auto``); ValueError if unknown."""
        try:
            return cls[name.strip().upper()]
        except KeyError:
            raise ValueError(f"unknown mode {name!r} (known: {', '.join(m.name for m in cls)})") from None


AUTONOMOUS_MODES = frozenset({RoverMode.AUTO, RoverMode.RTL, RoverMode.GUIDED, RoverMode.LOITER})
"""Modes in which the daemon drives (HEARTBEAT sets MAV_MODE_FLAG_AUTO/GUIDED_ENABLED)."""


class Severity(enum.IntEnum):
    """MAV_SEVERITY."""

    EMERGENCY = mav.MAV_SEVERITY_EMERGENCY
    ALERT = mav.MAV_SEVERITY_ALERT
    CRITICAL = mav.MAV_SEVERITY_CRITICAL
    ERROR = mav.MAV_SEVERITY_ERROR
    WARNING = mav.MAV_SEVERITY_WARNING
    NOTICE = mav.MAV_SEVERITY_NOTICE
    INFO = mav.MAV_SEVERITY_INFO
    DEBUG = mav.MAV_SEVERITY_DEBUG


class MissionType(enum.IntEnum):
    """MAV_MISSION_TYPE (ALL, 255, is only a request, never a stored list)."""

    MISSION = mav.MAV_MISSION_TYPE_MISSION
    FENCE = mav.MAV_MISSION_TYPE_FENCE
    RALLY = mav.MAV_MISSION_TYPE_RALLY


class MissionState(enum.IntEnum):
    """MISSION_CURRENT.mission_state."""

    UNKNOWN = mav.MISSION_STATE_UNKNOWN
    NO_MISSION = mav.MISSION_STATE_NO_MISSION
    NOT_STARTED = mav.MISSION_STATE_NOT_STARTED
    ACTIVE = mav.MISSION_STATE_ACTIVE
    PAUSED = mav.MISSION_STATE_PAUSED
    COMPLETE = mav.MISSION_STATE_COMPLETE


class Cmd(enum.IntEnum):
    """The MAV_CMD values rover_ctl names (the rest stay plain ints)."""

    NAV_WAYPOINT = mav.MAV_CMD_NAV_WAYPOINT
    NAV_LOITER_UNLIM = mav.MAV_CMD_NAV_LOITER_UNLIM
    NAV_LOITER_TURNS = mav.MAV_CMD_NAV_LOITER_TURNS
    NAV_LOITER_TIME = mav.MAV_CMD_NAV_LOITER_TIME
    NAV_RETURN_TO_LAUNCH = mav.MAV_CMD_NAV_RETURN_TO_LAUNCH
    NAV_LAND = mav.MAV_CMD_NAV_LAND
    CONDITION_DELAY = mav.MAV_CMD_CONDITION_DELAY
    DO_SET_MODE = mav.MAV_CMD_DO_SET_MODE
    DO_JUMP = mav.MAV_CMD_DO_JUMP
    DO_CHANGE_SPEED = mav.MAV_CMD_DO_CHANGE_SPEED
    DO_SET_HOME = mav.MAV_CMD_DO_SET_HOME
    DO_SET_MISSION_CURRENT = mav.MAV_CMD_DO_SET_MISSION_CURRENT
    DO_REPOSITION = mav.MAV_CMD_DO_REPOSITION
    COMPONENT_ARM_DISARM = mav.MAV_CMD_COMPONENT_ARM_DISARM
    MISSION_START = mav.MAV_CMD_MISSION_START
    NAV_FENCE_RETURN_POINT = mav.MAV_CMD_NAV_FENCE_RETURN_POINT
    NAV_FENCE_POLYGON_VERTEX_INCLUSION = mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
    NAV_FENCE_POLYGON_VERTEX_EXCLUSION = mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
    NAV_FENCE_CIRCLE_INCLUSION = mav.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION
    NAV_FENCE_CIRCLE_EXCLUSION = mav.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION
    NAV_RALLY_POINT = mav.MAV_CMD_NAV_RALLY_POINT


ARM_FORCE_MAGIC = 21196
"""param2 of MAV_CMD_COMPONENT_ARM_DISARM that forces arming/disarming (MAVLink spec, ArduPilot)."""

PILOT_STEER_TYPE = "PILOT_STEER_TYPE"
"""ArduPilot Rover's parameter for how the pilot's steering is read in reverse. At 0 (its default)
and 2 the steering is reversed while the throttle output -- slew-limited by MOT_SLEWRATE -- is
negative (``Mode::get_pilot_desired_steering_and_throttle``): the RC overrides of the daemon's
wheel control, whose inverse mixer assumes left = throttle + steering always, then turn the rover
the wrong way whenever the throttle is negative, and in a pivot (throttle near 0, either sign)
the rover can swing between the two ways and never finish the turn. The daemon reads it at
connect and refuses to arm unless it is STEER_UNCHANGED_WHEN_REVERSING (docs/ardupilot.md)."""
STEER_UNCHANGED_WHEN_REVERSING = 3
"""PILOT_STEER_TYPE 3: "direction unchanged when backing up" (no reversal at any throttle)."""
STEER_TWO_PADDLES = 1
"""PILOT_STEER_TYPE 1: channels 1 and 3 are the left and right paddles, not steering and throttle."""
