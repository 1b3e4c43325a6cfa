"""A stranger on the GCS port, through a real socket: a flood of clears of an empty list writes
nothing, and resending MISSION_COUNT cannot keep a ground station out of the upload."""

from __future__ import annotations

import time

from mission_protocol.helpers import MAVPROXY, LinkThread, expect, gcs, sample_mission
from pymavlink.dialects.v20 import ardupilotmega as mav

from rover_ctl.config import GcsParams
from rover_ctl.mavlink.gcs import DefaultHandlers
from rover_ctl.mission.store import MissionStore

FAST = GcsParams(heartbeat_period_s=0.2)
STRANGER = (77, 1)


class CountingStore(MissionStore):
    def __init__(self, path) -> None:
        super().__init__(path)
        self.saves = 0

    def save(self, mission) -> None:
        self.saves += 1
        super().save(mission)


class CountingHandlers(DefaultHandlers):
    def __init__(self) -> None:
        super().__init__()
        self.changes: list[int] = []

    def mission_changed(self, mission, mission_type: int) -> None:
        self.changes.append(mission_type)
        super().mission_changed(mission, mission_type)


def send_as(conn, sender: tuple[int, int], msg) -> None:
    conn.mav.srcSystem, conn.mav.srcComponent = sender
    conn.mav.send(msg)


def test_a_flood_of_clears_of_an_empty_list_writes_nothing_and_plans_nothing(tmp_path, udp_port):
    store = CountingStore(tmp_path / "mission.json")
    MissionStore(store.path).save(sample_mission())
    handlers = CountingHandlers()
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=FAST, handlers=handlers, store=store) as lt:
        conn = gcs(udp_port)
        conn.mav.mission_clear_all_send(1, 1, mav.MAV_MISSION_TYPE_ALL)  # a real clear: one write
        assert expect(conn, "MISSION_ACK").type == mav.MAV_MISSION_ACCEPTED
        assert store.saves == 1 and handlers.changes == [mav.MAV_MISSION_TYPE_ALL] * 2  # at start, and the clear
        written = store.path.stat()
        for n in range(100):
            conn.mav.mission_clear_all_send(1, 1, (mav.MAV_MISSION_TYPE_MISSION, mav.MAV_MISSION_TYPE_FENCE,
                                                   mav.MAV_MISSION_TYPE_RALLY, mav.MAV_MISSION_TYPE_ALL)[n % 4])  # fmt: skip
        for _ in range(100):
            assert expect(conn, "MISSION_ACK").type == mav.MAV_MISSION_ACCEPTED
        after = store.path.stat()
        assert store.saves == 1 and (after.st_ino, after.st_mtime_ns) == (written.st_ino, written.st_mtime_ns)
        assert len(handlers.changes) == 2  # no re-plan either
        assert not lt.link.service.mission.items and lt.link.service.mission.home is not None


def test_a_stranger_resending_counts_loses_the_upload_at_its_deadline(udp_port):
    params = GcsParams(heartbeat_period_s=0.2, mission_item_retry_s=0.05, mission_upload_timeout_s=0.3,
                       mission_upload_margin_s=0.5, mission_upload_holdoff_s=2.0)  # fmt: skip
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=params):
        conn = gcs(udp_port)  # one socket, two senders: the link answers the address it last heard from
        results: list[int] = []
        cancelled = False
        end = time.monotonic() + 10.0  # far beyond the deadline (0.8 s): only a bound for a failing test
        while mav.MAV_MISSION_ACCEPTED not in results and time.monotonic() < end:
            send_as(conn, STRANGER, mav.MAVLink_mission_count_message(1, 1, 1, mav.MAV_MISSION_TYPE_MISSION))
            send_as(conn, MAVPROXY, mav.MAVLink_mission_clear_all_message(1, 1, mav.MAV_MISSION_TYPE_MISSION))
            while (ack := conn.recv_match(type="MISSION_ACK", blocking=True, timeout=0.1)) is not None:
                if ack.target_system == MAVPROXY[0]:
                    results.append(ack.type)
                elif ack.type == mav.MAV_MISSION_OPERATION_CANCELLED:
                    cancelled = True
        assert results[0] == mav.MAV_MISSION_DENIED  # the stranger held the upload ...
        assert results[-1] == mav.MAV_MISSION_ACCEPTED and cancelled  # ... until its deadline, not for ever
