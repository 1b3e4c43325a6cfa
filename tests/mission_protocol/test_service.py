"""The vehicle-side mission state machine, message by message (no sockets)."""

from __future__ import annotations

import pytest
from mission_protocol.helpers import HOME, MAVPROXY, MAVSDK, from_sender, sample_mission
from pymavlink.dialects.v20 import ardupilotmega as mav

from rover_ctl.config import GcsParams
from rover_ctl.mission.model import Home, Mission, MissionItem, MissionType
from rover_ctl.mavlink.mission import (
    MissionService,
    decode_xy,
    encode_xy,
    item_from_message,
    item_message,
    wire_items,
)

PARAMS = GcsParams(mission_item_retry_s=0.5, mission_upload_timeout_s=8.0, mission_max_items=50)


class Recorder:
    """A commit callback that records what it was given and can be told to fail."""

    def __init__(self) -> None:
        self.commits: list[tuple[Mission, int]] = []
        self.fail = False

    def __call__(self, mission: Mission, mission_type: int) -> None:
        if self.fail:
            raise OSError("disk full")
        self.commits.append((mission, mission_type))


@pytest.fixture
def rec() -> Recorder:
    return Recorder()


@pytest.fixture
def svc(rec: Recorder) -> MissionService:
    return MissionService(Mission(), PARAMS, commit=rec)


def send(svc: MissionService, msg, sender=MAVPROXY, now_s: float = 0.0) -> list:
    return svc.handle(from_sender(msg, sender), now_s)


def one(replies: list, kind: str):
    assert [r.get_type() for r in replies] == [kind], replies
    return replies[0]


def item_int(item: MissionItem, seq: int, mission_type: int = 0):
    return item_message(item, seq, mission_type, (1, 1))


def upload(svc: MissionService, wire: list[MissionItem], mission_type: int = 0, sender=MAVPROXY, now_s: float = 0.0):
    """Drive a clean upload; returns the final reply."""
    reply = one(send(svc, mav.MAVLink_mission_count_message(1, 1, len(wire), mission_type), sender, now_s), "MISSION_REQUEST_INT")
    for seq, item in enumerate(wire):
        assert reply.get_type() == "MISSION_REQUEST_INT" and reply.seq == seq
        assert (reply.target_system, reply.target_component) == sender
        reply = send(svc, item_int(item, seq, mission_type), sender, now_s)[0]
    return reply


def test_upload_mission_with_home_at_seq0_commits_and_acks_the_sender(svc, rec, mission):
    ack = upload(svc, wire_items(mission, MissionType.MISSION), sender=MAVSDK)
    assert ack.get_type() == "MISSION_ACK" and ack.type == mav.MAV_MISSION_ACCEPTED
    assert (ack.target_system, ack.target_component) == MAVSDK
    assert svc.mission.home.same_as(HOME)
    assert len(svc.mission.items) == len(mission.items)
    assert all(a.same_as(b) for a, b in zip(svc.mission.items, mission.items))
    assert len(rec.commits) == 1 and rec.commits[0][1] == MissionType.MISSION


def test_fence_and_rally_upload_leave_the_other_parts_alone(svc, mission):
    upload(svc, wire_items(mission, MissionType.MISSION))
    for kind in (MissionType.FENCE, MissionType.RALLY):
        ack = upload(svc, wire_items(mission, kind), kind)
        assert ack.type == mav.MAV_MISSION_ACCEPTED and ack.mission_type == kind
    assert svc.mission.same_as(mission)


def test_legacy_mission_item_is_accepted_in_an_upload(svc):
    one(send(svc, mav.MAVLink_mission_count_message(1, 1, 2, 0)), "MISSION_REQUEST_INT")
    home = mav.MAVLink_mission_item_message(1, 1, 0, 0, 16, 0, 1, 0, 0, 0, 0, HOME.lat_deg, HOME.lon_deg, 584.0, 0)
    one(send(svc, home), "MISSION_REQUEST_INT")
    wp = mav.MAVLink_mission_item_message(1, 1, 1, 3, 16, 0, 1, 0, 0, 0, 0, -35.36, 149.166, 0.0, 0)
    assert one(send(svc, wp), "MISSION_ACK").type == mav.MAV_MISSION_ACCEPTED
    assert svc.mission.items[0].same_as(MissionItem(16, frame=3, x=-35.36, y=149.166), tol_deg=1e-6)


def test_download_counts_home_and_answers_legacy_requests_with_item_int(svc, mission):
    svc.mission = mission
    count = one(send(svc, mav.MAVLink_mission_request_list_message(1, 1, 0), MAVSDK), "MISSION_COUNT")
    assert count.count == len(mission.items) + 1 and (count.target_system, count.target_component) == MAVSDK
    got = []
    for seq in range(count.count):
        request = mav.MAVLink_mission_request_message(1, 1, seq, 0) if seq % 2 else mav.MAVLink_mission_request_int_message(1, 1, seq, 0)
        reply = one(send(svc, request, MAVSDK), "MISSION_ITEM_INT")
        assert reply.seq == seq and reply.target_system == MAVSDK[0]
        got.append(item_from_message(reply))
    assert got[0].same_as(MissionItem(16, frame=0, x=HOME.lat_deg, y=HOME.lon_deg, z=HOME.alt_m))
    assert all(a.same_as(b) for a, b in zip(got[1:], mission.items))
    bad = one(send(svc, mav.MAVLink_mission_request_int_message(1, 1, count.count, 0)), "MISSION_ACK")
    assert bad.type == mav.MAV_MISSION_INVALID_SEQUENCE


def test_download_reports_the_vehicle_home_when_it_has_one(svc, mission):
    svc.mission = mission
    svc.vehicle_home = Home(-35.0, 149.0, 600.0)
    reply = one(send(svc, mav.MAVLink_mission_request_int_message(1, 1, 0, 0)), "MISSION_ITEM_INT")
    assert (reply.x, reply.y, reply.z) == (-350000000, 1490000000, 600.0)


def test_fence_and_rally_download(svc, mission):
    svc.mission = mission
    for kind, items in ((MissionType.FENCE, mission.fence), (MissionType.RALLY, mission.rally)):
        count = one(send(svc, mav.MAVLink_mission_request_list_message(1, 1, kind)), "MISSION_COUNT")
        assert count.count == len(items) and count.mission_type == kind
        last = one(send(svc, mav.MAVLink_mission_request_int_message(1, 1, count.count - 1, kind)), "MISSION_ITEM_INT")
        assert last.mission_type == kind and item_from_message(last).same_as(items[-1])


def test_repeated_count_from_the_uploader_restarts(svc, rec, mission):
    wire = wire_items(mission, MissionType.MISSION)
    send(svc, mav.MAVLink_mission_count_message(1, 1, 9, 0))
    send(svc, item_int(wire[0], 0))
    send(svc, item_int(wire[1], 1))
    reply = one(send(svc, mav.MAVLink_mission_count_message(1, 1, len(wire), 0)), "MISSION_REQUEST_INT")
    assert reply.seq == 0
    assert upload(svc, wire).type == mav.MAV_MISSION_ACCEPTED
    assert len(svc.mission.items) == len(wire) - 1 and len(rec.commits) == 1


def test_another_sender_is_denied_during_an_upload_which_then_completes(svc, mission):
    wire = wire_items(mission, MissionType.MISSION)
    one(send(svc, mav.MAVLink_mission_count_message(1, 1, len(wire), 0)), "MISSION_REQUEST_INT")
    for intruder in (
        mav.MAVLink_mission_count_message(1, 1, 3, 0),
        mav.MAVLink_mission_clear_all_message(1, 1, 0),
        item_int(wire[0], 0),
    ):
        denied = one(send(svc, intruder, MAVSDK), "MISSION_ACK")
        assert denied.type == mav.MAV_MISSION_DENIED and denied.target_system == MAVSDK[0]
    for seq, item in enumerate(wire):
        reply = send(svc, item_int(item, seq))[0]
    assert reply.type == mav.MAV_MISSION_ACCEPTED and len(svc.mission.items) == len(wire) - 1


def test_out_of_sequence_items_are_re_requested_and_duplicates_ignored(svc, mission):
    wire = wire_items(mission, MissionType.MISSION)
    send(svc, mav.MAVLink_mission_count_message(1, 1, len(wire), 0))
    send(svc, item_int(wire[0], 0))
    ahead = one(send(svc, item_int(wire[3], 3)), "MISSION_REQUEST_INT")
    assert ahead.seq == 1
    assert send(svc, item_int(wire[0], 0)) == []  # duplicate
    for seq in range(1, len(wire)):
        reply = send(svc, item_int(wire[seq], seq))[0]
    assert reply.type == mav.MAV_MISSION_ACCEPTED
    assert all(a.same_as(b) for a, b in zip(svc.mission.items, mission.items))


def test_tick_re_requests_then_times_out_leaving_the_mission_untouched(svc, rec, mission):
    svc.mission = mission
    wire = wire_items(sample_mission(7), MissionType.MISSION)
    send(svc, mav.MAVLink_mission_count_message(1, 1, len(wire), 0), now_s=0.0)
    send(svc, item_int(wire[0], 0), now_s=0.1)
    assert svc.tick(0.3) == []
    again = one(svc.tick(0.7), "MISSION_REQUEST_INT")
    assert again.seq == 1 and again.target_system == MAVPROXY[0]
    assert svc.tick(0.8) == []
    cancelled = one(svc.tick(8.2), "MISSION_ACK")
    assert cancelled.type == mav.MAV_MISSION_OPERATION_CANCELLED
    assert not svc.uploading and svc.mission is mission and rec.commits == []
    assert send(svc, item_int(wire[1], 1), now_s=9.0) == []  # late item after the cancel


@pytest.mark.parametrize(
    "mission_type, item, result",
    [
        (0, MissionItem(16, x=95.0, y=149.0), mav.MAV_MISSION_INVALID_PARAM5_X),
        (0, MissionItem(16, x=-35.0, y=190.0), mav.MAV_MISSION_INVALID_PARAM6_Y),
        (1, MissionItem(16, x=-35.0, y=149.0), mav.MAV_MISSION_UNSUPPORTED),
        (2, MissionItem(5001, x=-35.0, y=149.0), mav.MAV_MISSION_UNSUPPORTED),
        (0, MissionItem(16, param1=float("inf"), x=-35.0, y=149.0), mav.MAV_MISSION_INVALID_PARAM1),
    ],
)
def test_an_invalid_item_refuses_the_upload_and_keeps_the_stored_mission(svc, rec, mission, mission_type, item, result):
    svc.mission = mission
    send(svc, mav.MAVLink_mission_count_message(1, 1, 2, mission_type))
    first = wire_items(mission, mission_type)[0]
    send(svc, item_int(first, 0, mission_type))
    ack = one(send(svc, item_int(item, 1, mission_type)), "MISSION_ACK")
    assert ack.type == result and svc.mission is mission and rec.commits == [] and not svc.uploading


def test_a_failing_commit_refuses_the_upload(svc, rec, mission):
    rec.fail = True
    ack = upload(svc, wire_items(mission, MissionType.MISSION))
    assert ack.type == mav.MAV_MISSION_ERROR and svc.mission.items == []


def test_too_many_items_is_no_space_and_unknown_type_unsupported(svc):
    ack = one(send(svc, mav.MAVLink_mission_count_message(1, 1, PARAMS.mission_max_items + 1, 0)), "MISSION_ACK")
    assert ack.type == mav.MAV_MISSION_NO_SPACE and not svc.uploading
    ack = one(send(svc, mav.MAVLink_mission_count_message(1, 1, 2, 7)), "MISSION_ACK")
    assert ack.type == mav.MAV_MISSION_UNSUPPORTED


def test_count_zero_and_clear_all(svc, rec, mission):
    svc.mission = mission
    ack = one(send(svc, mav.MAVLink_mission_count_message(1, 1, 0, MissionType.RALLY)), "MISSION_ACK")
    assert ack.type == mav.MAV_MISSION_ACCEPTED and svc.mission.rally == [] and len(svc.mission.fence) == 4
    ack = one(send(svc, mav.MAVLink_mission_clear_all_message(1, 1, MissionType.FENCE)), "MISSION_ACK")
    assert ack.type == mav.MAV_MISSION_ACCEPTED and svc.mission.fence == [] and len(svc.mission.items) == 5
    ack = one(send(svc, mav.MAVLink_mission_clear_all_message(1, 1, 255)), "MISSION_ACK")
    assert ack.type == mav.MAV_MISSION_ACCEPTED and ack.mission_type == 255
    assert svc.mission.items == [] and svc.count(MissionType.MISSION) == 1
    assert [t for _, t in rec.commits] == [MissionType.RALLY, MissionType.FENCE, 255]


def test_a_lost_final_ack_is_repeated_when_the_last_item_comes_again(svc, rec, mission):
    wire = wire_items(mission, MissionType.MISSION)
    upload(svc, wire)
    again = one(send(svc, item_int(wire[-1], len(wire) - 1)), "MISSION_ACK")
    assert again.type == mav.MAV_MISSION_ACCEPTED and len(rec.commits) == 1
    assert send(svc, item_int(wire[-1], len(wire) - 1), MAVSDK) == []


def test_set_current_answers_mission_current_or_a_warning(mission):
    asked = []
    svc = MissionService(mission, PARAMS, set_current=lambda seq: asked.append(seq) or seq != 3)
    current = one(send(svc, mav.MAVLink_mission_set_current_message(1, 1, 2)), "MISSION_CURRENT")
    assert current.seq == 2 and current.total == len(mission.items) and svc.current_seq == 2
    assert one(send(svc, mav.MAVLink_mission_set_current_message(1, 1, 3)), "STATUSTEXT").severity == mav.MAV_SEVERITY_WARNING
    assert one(send(svc, mav.MAVLink_mission_set_current_message(1, 1, 99)), "STATUSTEXT")
    assert asked == [2, 3] and svc.current_seq == 2
    reached = svc.item_reached(2)
    assert reached.get_type() == "MISSION_ITEM_REACHED" and reached.seq == 2


def test_messages_for_another_system_or_component_are_ignored(svc):
    assert send(svc, mav.MAVLink_mission_count_message(2, 1, 3, 0)) == []
    assert send(svc, mav.MAVLink_mission_request_list_message(1, 5, 0)) == []
    assert one(send(svc, mav.MAVLink_mission_request_list_message(0, 0, 0)), "MISSION_COUNT").count == 1


@pytest.mark.parametrize(
    "frame, x, y, wire",
    [(3, -35.3632615, 149.1652301, (-353632615, 1491652301)), (1, 1.25, -2.5, (12500, -25000)), (2, 3.0, 7.0, (3, 7))],
)
def test_coordinates_scale_by_frame(frame, x, y, wire):
    item = MissionItem(16, frame=frame, x=x, y=y)
    assert encode_xy(item) == wire
    assert decode_xy(frame, *wire) == pytest.approx((x, y), abs=1e-9)


def test_a_cancelled_upload_never_collects_the_previous_uploads_ack(svc, rec, mission):
    wire = wire_items(mission, MissionType.MISSION)
    upload(svc, wire)  # stored; its ACK could be repeated to a resent last item
    changed = [*wire[:-1], MissionItem(16, x=wire[-1].x, y=wire[-1].y, z=99.0)]
    send(svc, mav.MAVLink_mission_count_message(1, 1, len(changed), 0))
    for seq, item in enumerate(changed[:-1]):
        send(svc, item_int(item, seq))
    assert one(svc.tick(PARAMS.mission_upload_timeout_s), "MISSION_ACK").type == mav.MAV_MISSION_OPERATION_CANCELLED
    # the lost-ACK case of the cancelled upload: its last item comes late, and must not be ACCEPTED
    assert send(svc, item_int(changed[-1], len(changed) - 1)) == []
    assert send(svc, item_int(wire[-1], len(wire) - 1)) == []
    assert len(rec.commits) == 1


# ---- strangers on the GCS port: no disk work for nothing, no upload held for ever ----------------


def clear_all(mission_type: int):
    return mav.MAVLink_mission_clear_all_message(1, 1, mission_type)


def count(n: int, mission_type: int = 0):
    return mav.MAVLink_mission_count_message(1, 1, n, mission_type)


def test_a_clear_or_empty_upload_of_an_empty_list_is_accepted_without_a_commit(svc, rec, mission):
    before = svc.mission
    for mission_type in (MissionType.MISSION, MissionType.FENCE, MissionType.RALLY, 255):
        ack = one(send(svc, clear_all(mission_type)), "MISSION_ACK")
        assert ack.type == mav.MAV_MISSION_ACCEPTED and ack.mission_type == mission_type
    assert one(send(svc, count(0, MissionType.RALLY)), "MISSION_ACK").type == mav.MAV_MISSION_ACCEPTED
    assert rec.commits == [] and svc.mission is before  # the link tells the daemon nothing: no re-plan
    svc.mission = mission
    for _ in range(3):
        assert one(send(svc, clear_all(MissionType.FENCE)), "MISSION_ACK").type == mav.MAV_MISSION_ACCEPTED
        assert one(send(svc, clear_all(255)), "MISSION_ACK").type == mav.MAV_MISSION_ACCEPTED
    assert [t for _, t in rec.commits] == [MissionType.FENCE, 255]  # only the clears that changed something
    assert svc.mission.items == svc.mission.fence == svc.mission.rally == [] and svc.mission.home == mission.home


def test_repeated_counts_cannot_hold_an_upload_past_its_deadline(svc, rec, mission):
    deadline = svc.upload_budget_s(3)
    assert deadline == 3 * PARAMS.mission_upload_timeout_s + PARAMS.mission_upload_margin_s
    t = 0.0
    one(send(svc, count(3), MAVSDK, t), "MISSION_REQUEST_INT")  # a stranger starts an upload ...
    while t + 1.0 < deadline:
        t += 1.0
        assert one(send(svc, count(3), MAVSDK, t), "MISSION_REQUEST_INT").seq == 0  # ... and restarts it every second
        for msg in (clear_all(MissionType.MISSION), count(2)):
            assert one(send(svc, msg, MAVPROXY, t), "MISSION_ACK").type == mav.MAV_MISSION_DENIED
        assert svc.tick(t) == []
    cancelled = one(svc.tick(deadline), "MISSION_ACK")  # the restarts did not extend it
    assert cancelled.type == mav.MAV_MISSION_OPERATION_CANCELLED and cancelled.target_system == MAVSDK[0]
    assert not svc.uploading
    t = deadline + 0.1
    assert one(send(svc, count(3), MAVSDK, t), "MISSION_ACK").type == mav.MAV_MISSION_DENIED  # held off ...
    assert upload(svc, wire_items(mission, MissionType.MISSION), now_s=t).type == mav.MAV_MISSION_ACCEPTED  # ... the GCS gets in
    assert len(rec.commits) == 1
    later = t + PARAMS.mission_upload_holdoff_s
    assert one(send(svc, count(3), MAVSDK, later), "MISSION_REQUEST_INT")  # a hold-off, not a ban


def test_a_restart_past_the_deadline_does_not_revive_the_upload(svc):
    one(send(svc, count(2), MAVSDK, 0.0), "MISSION_REQUEST_INT")
    t = svc.upload_budget_s(2)
    send(svc, count(2), MAVSDK, t - 1.0)
    send(svc, count(2), MAVSDK, t)  # arrives with the deadline, before the loop's tick ...
    cancelled = one(svc.tick(t), "MISSION_ACK")  # ... which cancels it all the same
    assert cancelled.type == mav.MAV_MISSION_OPERATION_CANCELLED and not svc.uploading
    assert one(send(svc, count(2), MAVPROXY, t), "MISSION_REQUEST_INT").target_system == MAVPROXY[0]


def test_a_count_just_after_a_no_progress_cancel_is_a_restart_and_keeps_the_deadline(svc):
    deadline = svc.upload_budget_s(2)
    t = 0.0
    one(send(svc, count(2), MAVSDK, t), "MISSION_REQUEST_INT")
    while t + PARAMS.mission_upload_timeout_s < deadline:
        t += PARAMS.mission_upload_timeout_s  # no progress: cancelled ...
        assert one(svc.tick(t), "MISSION_ACK").type == mav.MAV_MISSION_OPERATION_CANCELLED
        t += 0.1  # ... and at once started again
        one(send(svc, count(2), MAVSDK, t), "MISSION_REQUEST_INT")
    assert one(svc.tick(deadline), "MISSION_ACK").type == mav.MAV_MISSION_OPERATION_CANCELLED  # progress < timeout ago
    assert one(send(svc, count(2), MAVSDK, deadline + 0.1), "MISSION_ACK").type == mav.MAV_MISSION_DENIED


def test_a_larger_upload_that_restarts_a_small_one_gets_the_larger_budget_from_the_first_count(svc, rec, mission):
    """A second `wp load` of a bigger mission: its deadline was the first COUNT's (2 items, 13 s),
    which cancelled a 300-item upload progressing at 20 items a second at seq 250."""
    wire = wire_items(mission, MissionType.MISSION)
    one(send(svc, count(2), MAVPROXY, 0.0), "MISSION_REQUEST_INT")
    t = svc.upload_budget_s(2) - 1.0
    one(send(svc, count(len(wire)), MAVPROXY, t), "MISSION_REQUEST_INT")
    step = 2.0 / len(wire)  # steady progress, ending 1 s past the small upload's deadline
    for seq, item in enumerate(wire):
        t += step
        assert all(r.get_type() == "MISSION_REQUEST_INT" for r in svc.tick(t)), (seq, t)
        reply = send(svc, item_int(item, seq), MAVPROXY, t)[0]
    assert reply.type == mav.MAV_MISSION_ACCEPTED and len(rec.commits) == 1
    assert svc.upload_budget_s(2) < t <= svc.upload_budget_s(len(wire))


def test_a_slow_upload_that_keeps_progressing_ends_within_its_deadline(svc, rec, mission):
    wire = wire_items(mission, MissionType.MISSION)
    t, step = 0.0, PARAMS.mission_upload_timeout_s - 0.01  # each item just before the no-progress timeout
    one(send(svc, count(len(wire)), MAVPROXY, t), "MISSION_REQUEST_INT")
    for seq, item in enumerate(wire):
        t += step
        assert all(r.get_type() == "MISSION_REQUEST_INT" for r in svc.tick(t))
        reply = send(svc, item_int(item, seq), MAVPROXY, t)[0]
    assert reply.type == mav.MAV_MISSION_ACCEPTED and len(rec.commits) == 1


def test_each_mission_type_is_its_own_transaction(svc, mission):
    wire = wire_items(mission, MissionType.MISSION)
    one(send(svc, count(len(wire)), MAVSDK), "MISSION_REQUEST_INT")  # one sender uploads the mission ...
    fence = wire_items(mission, MissionType.FENCE)
    assert upload(svc, fence, MissionType.FENCE).type == mav.MAV_MISSION_ACCEPTED  # ... another a fence meanwhile
    assert one(send(svc, clear_all(MissionType.RALLY)), "MISSION_ACK").type == mav.MAV_MISSION_ACCEPTED
    for intruder in (count(3), clear_all(MissionType.MISSION), clear_all(255), item_int(wire[0], 0)):
        assert one(send(svc, intruder), "MISSION_ACK").type == mav.MAV_MISSION_DENIED
    for seq, item in enumerate(wire):
        reply = send(svc, item_int(item, seq), MAVSDK)[0]
    assert reply.type == mav.MAV_MISSION_ACCEPTED
    assert len(svc.mission.items) == len(mission.items) and len(svc.mission.fence) == len(mission.fence)
