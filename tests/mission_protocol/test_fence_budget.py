"""A fence upload too complex for the planner (its node budget) is refused with
MAV_MISSION_NO_SPACE and the stored plan stays; one within the budget is stored."""

from __future__ import annotations

import math

import pytest
from mission_protocol.helpers import HOME, MAVPROXY, LinkThread, from_sender, sample_mission
from pymavlink.dialects.v20 import ardupilotmega as mav

from rover_ctl.config import GcsParams
from rover_ctl.mavlink.gcs import DefaultHandlers
from rover_ctl.mavlink.mission import MissionService, item_message
from rover_ctl.mavlink.mission_client import MissionClient, MissionClientError
from rover_ctl.mission.model import Mission, MissionItem, MissionType
from rover_ctl.mission.store import MissionStore
from rover_ctl.mission.validate import FENCE_CIRCLE_SEGMENTS, MAX_PLANNER_NODES
from rover_ctl.vocabulary import Cmd

FAST = GcsParams(client_retry_s=0.2, client_retries=10, heartbeat_period_s=0.2)
AT_BUDGET = MAX_PLANNER_NODES // FENCE_CIRCLE_SEGMENTS


def circles(count: int) -> list[MissionItem]:
    """``count`` exclusion circles of 1 m in a grid 10 m apart, north-east of home."""
    side = math.ceil(math.sqrt(count))
    step = 10.0 / 111_320.0
    return [
        MissionItem(Cmd.NAV_FENCE_CIRCLE_EXCLUSION, param1=1.0, x=HOME.lat_deg + (k // side) * step,
                    y=HOME.lon_deg + (k % side) * step / math.cos(math.radians(HOME.lat_deg)))
        for k in range(count)
    ]  # fmt: skip


def upload(svc: MissionService, wire: list[MissionItem]):
    handle = lambda msg: svc.handle(from_sender(msg, MAVPROXY), 0.0)  # noqa: E731
    replies = handle(mav.MAVLink_mission_count_message(1, 1, len(wire), MissionType.FENCE))
    for seq, item in enumerate(wire):
        assert [r.get_type() for r in replies] == ["MISSION_REQUEST_INT"]
        replies = handle(item_message(item, seq, MissionType.FENCE, (1, 1)))
    (ack,) = replies
    return ack


def test_the_largest_upload_of_circles_is_refused_with_no_space_and_the_plan_stays(tmp_path):
    store = MissionStore(tmp_path / "mission.json")
    before = sample_mission()
    store.save(before)
    saved = store.path.read_bytes()
    svc = MissionService(before, commit=lambda mission, kind: store.save(mission))
    assert svc.params.mission_max_items == 700
    ack = upload(svc, circles(700))
    assert ack.type == mav.MAV_MISSION_NO_SPACE and ack.mission_type == MissionType.FENCE
    assert svc.mission is before and store.path.read_bytes() == saved and not svc.uploading


def test_an_upload_at_the_budget_is_accepted():
    svc = MissionService(Mission())
    assert upload(svc, circles(AT_BUDGET)).type == mav.MAV_MISSION_ACCEPTED
    assert len(svc.mission.fence) == AT_BUDGET


def test_over_the_link_a_fence_too_complex_is_refused_and_one_within_is_stored(tmp_path, udp_port):
    store = MissionStore(tmp_path / "mission.json")
    handlers = DefaultHandlers()
    url = f"udpin:127.0.0.1:{udp_port}"
    with LinkThread(url, params=FAST, store=store, handlers=handlers) as lt, \
            MissionClient(f"udpout:127.0.0.1:{udp_port}", FAST, *MAVPROXY) as client:  # fmt: skip
        client.connect()
        with pytest.raises(MissionClientError, match="fence upload refused by the vehicle: MAV_MISSION_NO_SPACE"):
            client.upload_items(MissionType.FENCE, circles(3 * AT_BUDGET))
        assert lt.link.service.mission.fence == [] and handlers.mission.fence == [] and not store.path.exists()
        client.upload_items(MissionType.FENCE, circles(AT_BUDGET))
        assert len(lt.link.service.mission.fence) == AT_BUDGET and len(handlers.mission.fence) == AT_BUDGET
        assert len(store.load().fence) == AT_BUDGET
