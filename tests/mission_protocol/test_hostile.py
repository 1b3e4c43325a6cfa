"""Hostile or malformed mission-protocol and command messages: the protocol's refusal, never an
exception, and the stored plan unchanged (regressions of issue #10 / #9)."""

from __future__ import annotations

import math

import pytest
from mission_protocol.helpers import MAVPROXY, LinkThread, expect, from_sender, gcs, sample_mission
from pymavlink.dialects.v20 import ardupilotmega as mav

from rover_ctl.config import GcsParams
from rover_ctl.mavlink.gcs import DefaultHandlers
from rover_ctl.mavlink.mission import MissionService, item_message, wire_items
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


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize(
    "command, slot",
    [(mav.MAV_CMD_DO_SET_MODE, 1), (mav.MAV_CMD_DO_SET_MISSION_CURRENT, 0), (mav.MAV_CMD_COMPONENT_ARM_DISARM, 0),
     (mav.MAV_CMD_COMPONENT_ARM_DISARM, 1), (mav.MAV_CMD_SET_MESSAGE_INTERVAL, 0), (mav.MAV_CMD_SET_MESSAGE_INTERVAL, 1),
     (mav.MAV_CMD_REQUEST_MESSAGE, 0)],
)
def test_a_non_finite_or_huge_command_param_is_denied_and_the_link_goes_on(udp_port, command, slot, value):
    handlers = DefaultHandlers()
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=PARAMS, handlers=handlers):
        conn = gcs(udp_port)
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
