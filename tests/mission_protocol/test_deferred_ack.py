"""A command whose answer is not the daemon's to give yet (arming: the vehicle decides) is
acknowledged once the answer comes, to each ground station that asked, and only once each."""

from __future__ import annotations

import os

os.environ.setdefault("MAVLINK20", "1")

from rover_ctl.mavlink.commands import ACK_LATER, MAX_WAITING_SENDERS, CommandService  # noqa: E402
from rover_ctl.vocabulary import mav  # noqa: E402

ARM = mav.MAV_CMD_COMPONENT_ARM_DISARM


class Sent:
    def __init__(self) -> None:
        self.messages: list = []
        self.mav = self

    def send(self, msg) -> None:
        self.messages.append(msg)


class LaterHandlers:
    def arm(self, arm: bool, force: bool) -> int:
        return ACK_LATER

    def return_to_launch(self) -> int:
        return mav.MAV_RESULT_ACCEPTED


def arm_from(system: int, component: int = 190):
    msg = mav.MAVLink_command_long_message(1, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0)
    msg._header = mav.MAVLink_header(msg.id, srcSystem=system, srcComponent=component)
    return msg


def acks(conn: Sent) -> list[tuple[int, int, int, int]]:
    return [(m.command, m.result, m.target_system, m.target_component) for m in conn.messages if m.get_type() == "COMMAND_ACK"]


def test_the_ack_waits_for_the_answer_and_reaches_every_sender_once():
    conn = Sent()
    service = CommandService(conn, LaterHandlers(), mission=None, telemetry=None, home=lambda: None)
    service.handle(arm_from(255))
    service.handle(arm_from(255))  # a retransmission: the same sender waits once
    service.handle(arm_from(250))
    assert acks(conn) == []
    service.answer(ARM, mav.MAV_RESULT_FAILED)
    assert acks(conn) == [(ARM, mav.MAV_RESULT_FAILED, 255, 190), (ARM, mav.MAV_RESULT_FAILED, 250, 190)]
    service.answer(ARM, mav.MAV_RESULT_ACCEPTED)  # nobody waits any more (an arming of the autopilot's own)
    assert len(acks(conn)) == 2


def test_the_waiting_senders_are_bounded():
    conn = Sent()
    service = CommandService(conn, LaterHandlers(), mission=None, telemetry=None, home=lambda: None)
    for system in range(1, 101):
        service.handle(arm_from(system))
    service.answer(ARM, mav.MAV_RESULT_ACCEPTED)
    assert [a[2] for a in acks(conn)] == list(range(101 - MAX_WAITING_SENDERS, 101))
