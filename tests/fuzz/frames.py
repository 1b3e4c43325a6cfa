"""Arbitrary MAVLink frames for the fuzz suite and the soak bench (import as ``fuzz.frames``).

``message(kind)`` is a Hypothesis strategy of pymavlink messages of one type with every field
drawn from what the field's wire type can carry (NaN, infinities and extremes often), with the
fields that steer handling (targets, mission types, commands, sequence numbers) biased towards
the values the daemon acts on. ``well_formed_effects`` is the oracle: which autopilot handler
calls a message may legitimately cause.
"""

from __future__ import annotations

import math
import os

os.environ.setdefault("MAVLINK20", "1")
from hypothesis import strategies as st  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mav  # noqa: E402

from rover_ctl.mavlink.gcs import HANDLED as GCS_HANDLED  # noqa: E402
from rover_ctl.mavlink.inbound import ROVER_MODES  # noqa: E402

HANDLED = GCS_HANDLED
"""Every message type the daemon's GCS link acts on."""
OTHERS = ("RC_CHANNELS_OVERRIDE", "MANUAL_CONTROL", "SETUP_SIGNING", "FILE_TRANSFER_PROTOCOL")
"""A few it does not handle (must be ignored)."""
COMMANDS = (
    mav.MAV_CMD_COMPONENT_ARM_DISARM, mav.MAV_CMD_DO_SET_MODE, mav.MAV_CMD_MISSION_START, mav.MAV_CMD_NAV_RETURN_TO_LAUNCH,
    mav.MAV_CMD_DO_SET_MISSION_CURRENT, mav.MAV_CMD_REQUEST_MESSAGE, mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
    mav.MAV_CMD_GET_HOME_POSITION, mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAV_CMD_DO_REPOSITION,
)  # fmt: skip
INT_RANGES = {
    "uint8_t": (0, 2**8 - 1), "int8_t": (-(2**7), 2**7 - 1), "uint16_t": (0, 2**16 - 1), "int16_t": (-(2**15), 2**15 - 1),
    "uint32_t": (0, 2**32 - 1), "int32_t": (-(2**31), 2**31 - 1), "uint64_t": (0, 2**64 - 1), "int64_t": (-(2**63), 2**63 - 1),
}  # fmt: skip
F32_EXTREMES = [math.nan, math.inf, -math.inf, 0.0, 1.0, -1.0, 2.0, 3.4e38, -3.4e38, 1e-45, 21196.0, 4.0, 10.0, 0.5]

floats32 = st.one_of(st.sampled_from(F32_EXTREMES), st.floats(width=32, allow_nan=True, allow_infinity=True))
floats64 = st.one_of(st.sampled_from([*F32_EXTREMES, 1e300]), st.floats(allow_nan=True, allow_infinity=True))
BIASED = {
    "target_system": st.sampled_from([0, 1, 1, 1, 2, 255]),
    "target_component": st.sampled_from([0, 1, 1, 1, 190, 100]),
    "mission_type": st.sampled_from([0, 0, 1, 2, 3, 255]),
    "seq": st.one_of(st.integers(0, 3), st.integers(0, 2**16 - 1)),
    "count": st.one_of(st.integers(0, 3), st.integers(0, 2**16 - 1)),
    "command": st.one_of(st.sampled_from(COMMANDS), st.integers(0, 2**16 - 1)),
    "custom_mode": st.one_of(st.sampled_from(sorted(ROVER_MODES)), st.integers(0, 2**32 - 1)),
    "frame": st.sampled_from([0, 2, 3, 5, 6, 1, 99]),
}


def _field(kind: str, length: int, name: str):
    if name in BIASED and length == 0:
        return BIASED[name]
    if kind == "char":
        return st.binary(max_size=length)
    if kind in ("float", "double"):
        element = floats32 if kind == "float" else floats64
    else:
        low, high = INT_RANGES[kind]
        element = st.one_of(st.sampled_from([low, high, 0, 1]), st.integers(low, high))
    return st.lists(element, min_size=length, max_size=length) if length else element


def message(kind: str):
    """Strategy of ``kind`` messages with arbitrary field values."""
    cls = mav.mavlink_map[getattr(mav, f"MAVLINK_MSG_ID_{kind}")]
    lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths))
    fields = [_field(t, lengths[n], n) for n, t in zip(cls.fieldnames, cls.fieldtypes)]
    return st.tuples(*fields).map(lambda values: cls(*values))


senders = st.sampled_from([(255, 190), (255, 230), (245, 190), (1, 1), (0, 0), (254, 250)])
any_message = st.sampled_from(HANDLED + OTHERS).flatmap(message)


def pack(msg, sender: tuple[int, int]) -> bytes:
    return bytes(msg.pack(mav.MAVLink(None, srcSystem=sender[0], srcComponent=sender[1])))


def _whole(value: float, low: float, high: float) -> bool:
    return math.isfinite(value) and value == int(value) and low <= value <= high


def well_formed_effects(msg, system_id: int = 1, component_id: int = 1) -> set[str]:
    """The autopilot handler calls ``msg`` may cause (a superset of what it must cause): anything
    else taking effect is a defect. Mission uploads are judged by the store (see the tests)."""
    kind = msg.get_type()
    target = (getattr(msg, "target_system", 0), getattr(msg, "target_component", 0))
    if target[0] not in (0, system_id):
        return set()
    if kind == "SET_MODE":
        return {"set_mode"} if msg.custom_mode in ROVER_MODES else set()
    if kind == "PARAM_SET":
        return {"set_param"}  # the parameter service refuses what is not finite or out of range
    if kind in ("MISSION_SET_CURRENT",):
        return {"set_current"}
    if kind == "SET_POSITION_TARGET_GLOBAL_INT":
        return {"guided_target"}
    if kind in ("MISSION_ITEM_INT", "MISSION_ITEM") and msg.current == 2:  # a GUIDED destination
        return {"guided_target"}
    if kind in ("MISSION_CLEAR_ALL", "MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_ITEM"):
        return {"mission_changed"}
    if kind not in ("COMMAND_LONG", "COMMAND_INT") or target[1] not in (0, component_id):
        return set()
    command, p1, p2 = msg.command, msg.param1, msg.param2
    if command == mav.MAV_CMD_COMPONENT_ARM_DISARM and p1 in (0.0, 1.0) and not math.isinf(p2):
        return {"arm"}
    if command == mav.MAV_CMD_DO_SET_MODE and _whole(p2, 0, 2**32 - 1) and int(p2) in ROVER_MODES:
        return {"set_mode"}
    if command == mav.MAV_CMD_MISSION_START:
        return {"mission_start"}
    if command == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
        return {"return_to_launch"}
    if command == mav.MAV_CMD_DO_SET_MISSION_CURRENT and _whole(p1, 0, 2**16 - 1):
        return {"set_current"}
    if command == mav.MAV_CMD_DO_REPOSITION and (math.isnan(p2) or _whole(p2, 0, 2**32 - 1)):
        return {"guided_target"}
    return set()
