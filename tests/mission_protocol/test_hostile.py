"""Hostile or malformed mission-protocol and command messages: the protocol's refusal, never an
exception, and the stored plan unchanged (regressions of issue #10 / #9)."""

from __future__ import annotations

import logging
import math

import pytest
from mission_protocol.helpers import MAVPROXY, LinkThread, expect, from_sender, gcs, sample_mission
from pymavlink.dialects.v20 import ardupilotmega as mav

from rover_ctl.config import GcsParams
from rover_ctl.mavlink.gcs import DefaultHandlers
from rover_ctl.mavlink.inbound import DROP_REASONS, ROVER_MODES, UNKNOWN_MODE, Inbound
from rover_ctl.mavlink.mission import MissionService, item_message
from rover_ctl.mission.model import Mission, MissionItem, MissionType
from rover_ctl.mission.store import MissionStore
from rover_ctl.vocabulary import Cmd, RoverMode

PARAMS = GcsParams(heartbeat_period_s=0.2)
HOME_LAT, HOME_LON = -35.363261, 149.165230


def handle(svc: MissionService, msg) -> list:
    return svc.handle(from_sender(msg, MAVPROXY), 0.0)


def upload(svc: MissionService, wire: list[MissionItem], mission_type: int):
    replies = handle(svc, mav.MAVLink_mission_count_message(1, 1, len(wire), mission_type))
    for seq, item in enumerate(wire):
        assert [r.get_type() for r in replies] == ["MISSION_REQUEST_INT"], replies
        replies = handle(svc, item_message(item, seq, mission_type, (1, 1)))
    assert [r.get_type() for r in replies] == ["MISSION_ACK"], replies
    return replies[0]


@pytest.mark.parametrize("mission_type", [255, 3, 17, 254])
def test_request_list_of_an_unknown_or_all_type_is_unsupported(mission_type):
    svc = MissionService(sample_mission())
    for msg in (
        mav.MAVLink_mission_request_list_message(1, 1, mission_type),
        mav.MAVLink_mission_request_int_message(1, 1, 0, mission_type),
        mav.MAVLink_mission_request_message(1, 1, 0, mission_type),
        mav.MAVLink_mission_count_message(1, 1, 3, mission_type),
    ):
        (ack,) = handle(svc, msg)
        assert ack.get_type() == "MISSION_ACK" and ack.type == mav.MAV_MISSION_UNSUPPORTED


def fence_circle(radius_m: float) -> MissionItem:
    return MissionItem(Cmd.NAV_FENCE_CIRCLE_EXCLUSION, frame=0, param1=radius_m, x=HOME_LAT, y=HOME_LON)


def vertex(count: float, dlat: float, dlon: float) -> MissionItem:
    return MissionItem(Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION, frame=0, param1=count, x=HOME_LAT + dlat, y=HOME_LON + dlon)


BOWTIE = [vertex(4, -1e-3, -1e-3), vertex(4, 1e-3, 1e-3), vertex(4, 1e-3, -1e-3), vertex(4, -1e-3, 1e-3)]


@pytest.mark.parametrize(
    "mission_type, wire, result",
    [
        (MissionType.FENCE, [fence_circle(0.0)], mav.MAV_MISSION_INVALID_PARAM1),
        (MissionType.FENCE, [fence_circle(-5.0)], mav.MAV_MISSION_INVALID_PARAM1),
        (MissionType.FENCE, [fence_circle(math.nan)], mav.MAV_MISSION_INVALID_PARAM1),
        (MissionType.FENCE, [vertex(3, 0, 0), vertex(3, 1e-3, 0)], mav.MAV_MISSION_INVALID_PARAM1),
        (MissionType.FENCE, [vertex(2, 0, 0), vertex(2, 1e-3, 0)], mav.MAV_MISSION_INVALID_PARAM1),
        (MissionType.FENCE, BOWTIE, mav.MAV_MISSION_INVALID),
        (MissionType.MISSION, [MissionItem(16, frame=0), MissionItem(Cmd.DO_JUMP, frame=2, param1=7.0, param2=1.0)],
         mav.MAV_MISSION_INVALID_PARAM1),
        (MissionType.MISSION, [MissionItem(16, frame=0), MissionItem(16, frame=2, x=HOME_LAT, y=HOME_LON)],
         mav.MAV_MISSION_UNSUPPORTED_FRAME),
        (MissionType.MISSION, [MissionItem(16, frame=0), MissionItem(16, frame=99, x=HOME_LAT, y=HOME_LON)],
         mav.MAV_MISSION_UNSUPPORTED_FRAME),
        (MissionType.MISSION, [MissionItem(16, frame=0), MissionItem(Cmd.CONDITION_DELAY, frame=2, param1=-1.0)],
         mav.MAV_MISSION_INVALID_PARAM1),
        (MissionType.RALLY, [MissionItem(Cmd.NAV_RALLY_POINT, frame=3, x=HOME_LAT, y=-190.0)], mav.MAV_MISSION_INVALID_PARAM6_Y),
        (MissionType.RALLY, [MissionItem(Cmd.NAV_WAYPOINT, frame=3, x=HOME_LAT, y=HOME_LON)], mav.MAV_MISSION_UNSUPPORTED),
    ],
    ids=["circle-r0", "circle-negative", "circle-nan", "polygon-count-mismatch", "polygon-2-vertices", "bowtie",
         "jump-to-nowhere", "waypoint-frame-mission", "unknown-frame", "negative-delay", "rally-lon", "rally-not-a-rally-point"],
)
def test_an_invalid_upload_is_refused_with_its_result_and_the_plan_stays(tmp_path, mission_type, wire, result):
    store = MissionStore(tmp_path / "mission.json")
    before = sample_mission()
    store.save(before)
    saved = store.path.read_bytes()
    svc = MissionService(before, commit=lambda mission, kind: store.save(mission))
    ack = upload(svc, wire, mission_type)
    assert ack.type == result
    assert svc.mission is before and store.path.read_bytes() == saved and not svc.uploading


def test_a_valid_fence_upload_is_still_accepted(tmp_path):
    svc = MissionService(Mission())
    square = [vertex(4, -1e-3, -1e-3), vertex(4, 1e-3, -1e-3), vertex(4, 1e-3, 1e-3), vertex(4, -1e-3, 1e-3)]
    assert upload(svc, [*square, fence_circle(5.0)], MissionType.FENCE).type == mav.MAV_MISSION_ACCEPTED
    assert len(svc.mission.fence) == 5


NON_FINITE = [math.nan, math.inf, -math.inf]
SLOTS = [(mav.MAV_CMD_DO_SET_MODE, 1), (mav.MAV_CMD_DO_SET_MISSION_CURRENT, 0), (mav.MAV_CMD_COMPONENT_ARM_DISARM, 0),
         (mav.MAV_CMD_SET_MESSAGE_INTERVAL, 0), (mav.MAV_CMD_SET_MESSAGE_INTERVAL, 1), (mav.MAV_CMD_REQUEST_MESSAGE, 0)]
# A NaN force flag (ARM_DISARM param2) is MAVLink's "default", not forced: test_a_nan_force_flag_...
CASES = [(c, s, v) for c, s in SLOTS for v in NON_FINITE] + [(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1, v) for v in NON_FINITE[1:]]


@pytest.mark.parametrize("command, slot, value", CASES)
def test_a_non_finite_command_param_is_denied_and_the_link_goes_on(udp_port, command, slot, value):
    handlers = DefaultHandlers()
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=PARAMS, handlers=handlers):
        conn = gcs(udp_port)
        conn.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)  # a ground station: sent to
        params = [1.0, float(4), 0.0, 0.0, 0.0, 0.0, 0.0]
        params[slot] = value
        conn.mav.command_long_send(1, 1, command, 0, *params)
        ack = expect(conn, "COMMAND_ACK", command=command)
        assert ack.result == mav.MAV_RESULT_DENIED
        conn.mav.command_int_send(1, 1, 0, command, 0, 0, *params[:4], 0, 0, params[6])
        if slot < 4:
            assert expect(conn, "COMMAND_ACK", command=command).result == mav.MAV_RESULT_DENIED
        assert not handlers.armed and handlers.custom_mode == RoverMode.HOLD  # nothing took effect
        expect(conn, "HEARTBEAT")  # still alive


def test_a_nan_force_flag_arms_without_forcing(udp_port):
    class Recorder(DefaultHandlers):
        def arm(self, arm: bool, force: bool) -> int:
            self.forced = force
            return super().arm(arm, force)

    handlers = Recorder()
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=PARAMS, handlers=handlers):
        conn = gcs(udp_port)
        conn.mav.command_long_send(1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1.0, math.nan, 0, 0, 0, 0, 0)
        assert expect(conn, "COMMAND_ACK", command=mav.MAV_CMD_COMPONENT_ARM_DISARM).result == mav.MAV_RESULT_ACCEPTED
        assert handlers.armed and handlers.forced is False


def test_a_handler_that_raises_is_caught_at_the_link_edge_and_logged_once(udp_port, caplog):
    class Broken(DefaultHandlers):
        def return_to_launch(self) -> int:
            raise ZeroDivisionError("boom")

    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=PARAMS, handlers=Broken()) as lt:
        conn = gcs(udp_port)
        for _ in range(3):
            conn.mav.command_long_send(1, 1, mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0, 0, 0, 0, 0, 0, 0)
        conn.mav.command_long_send(1, 1, mav.MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0)
        expect(conn, "COMMAND_ACK", command=mav.MAV_CMD_MISSION_START)  # after the three failures
        expect(conn, "HEARTBEAT")
        assert lt.link.inbound.failures == {("COMMAND_LONG", "ZeroDivisionError"): 3}
    logged = [r for r in caplog.records if "ZeroDivisionError" in r.getMessage()]
    assert len(logged) == 1 and "frame fd" in logged[0].getMessage()


def test_messages_for_another_component_and_unknown_modes_are_dropped_and_counted(udp_port):
    handlers = DefaultHandlers()
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=PARAMS, handlers=handlers) as lt:
        conn = gcs(udp_port)
        conn.mav.command_long_send(1, 100, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        conn.mav.set_mode_send(1, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 99)
        conn.write(b"\xfd\x09garbage that is no frame")  # an unfinished frame: must not swallow the next datagram
        conn.mav.command_long_send(1, 1, mav.MAV_CMD_DO_SET_MODE, 0, 1, RoverMode.MANUAL, 0, 0, 0, 0, 0)
        assert expect(conn, "COMMAND_ACK", command=mav.MAV_CMD_DO_SET_MODE).result == mav.MAV_RESULT_ACCEPTED
        assert not handlers.armed and handlers.custom_mode == RoverMode.MANUAL
        dropped = lt.link.inbound.dropped
        assert dropped["command for another component"] == 1
        assert dropped["SET_MODE to an unknown mode"] == 1
        assert dropped["unfinished frame at the end of a datagram"] == 1


def test_the_drop_counter_has_one_key_per_reason_whatever_values_come(caplog):
    """The reason carried the mode number: 100,000 distinct modes were 100,000 keys (11 MB)."""
    inbound = Inbound(PARAMS)
    inbound._drop_log.clock = inbound._refusal_log.clock = lambda: 0.0  # all within one log interval
    caplog.set_level(logging.DEBUG, logger="rover_ctl.mavlink.inbound")
    unknown = [mode for mode in range(100, 20_100) if mode not in ROVER_MODES]
    for mode in unknown:
        assert not inbound.check(from_sender(mav.MAVLink_set_mode_message(1, 1, mode), MAVPROXY)).ok
        bad = mav.MAVLink_command_long_message(1, 1, mav.MAV_CMD_DO_SET_MODE, 0, 1, mode + 0.5, 0, 0, 0, 0, 0)
        assert inbound.check(from_sender(bad, MAVPROXY)).reply is not None  # refused: counted, not keyed
    assert inbound.dropped == {UNKNOWN_MODE: len(unknown)} and set(inbound.dropped) <= set(DROP_REASONS)
    assert inbound.refused == len(unknown)
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 2 and "custom_mode 100" in lines[0]  # the value goes to a debug line, rate-limited


def test_each_datagram_is_parsed_on_its_own(udp_port):
    """40 random datagrams, each followed by a valid command: every command is answered (a byte
    stream parser lost about half of them to the unfinished frames the garbage starts)."""
    import random

    rng = random.Random(5)
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=PARAMS, handlers=DefaultHandlers()):
        conn = gcs(udp_port)
        for k in range(40):
            conn.write(bytes([0xFD]) + bytes(rng.randrange(256) for _ in range(rng.randint(0, 200))))
            conn.mav.command_long_send(1, 1, mav.MAV_CMD_REQUEST_MESSAGE, k, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0)
            expect(conn, "COMMAND_ACK", command=mav.MAV_CMD_REQUEST_MESSAGE)
