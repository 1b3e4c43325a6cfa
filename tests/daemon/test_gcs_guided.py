"""The GCS link's GUIDED entry points on a real UDP socket (the in-memory handlers stand for the
autopilot): every message form MAVProxy and QGroundControl use, and where each is refused."""

from __future__ import annotations

import time

from mission_protocol.helpers import MAVPROXY, LinkThread, expect, gcs
from pymavlink.dialects.v20 import ardupilotmega as mav

from rover_ctl.config import GcsParams
from rover_ctl.mavlink.gcs import DefaultHandlers
from rover_ctl.vocabulary import RoverMode

FAST = GcsParams(client_retry_s=0.2, client_retries=10, heartbeat_period_s=0.2)
LAT, LON = -35.3631, 149.1653
POSITION_ONLY = 0b110111111000
"""type_mask: x, y, z used; velocity, acceleration, yaw ignored."""


def wait_for(predicate, timeout_s: float = 2.0) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.01)  # polling another thread's state, not standing in for a protocol reply
    return False


def test_guided_messages(udp_port):
    handlers = DefaultHandlers()
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=FAST, handlers=handlers):
        conn = gcs(udp_port, MAVPROXY)
        # Outside GUIDED: a current=2 item is refused with MISSION_ACK ERROR, DO_REPOSITION without
        # CHANGE_MODE is DENIED, a position target is ignored.
        conn.mav.mission_item_int_send(1, 1, 0, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, mav.MAV_CMD_NAV_WAYPOINT, 2, 0,
                                       0, 0, 0, 0, int(LAT * 1e7), int(LON * 1e7), 0)  # fmt: skip
        assert expect(conn, "MISSION_ACK").type == mav.MAV_MISSION_ERROR
        conn.mav.command_long_send(1, 1, mav.MAV_CMD_DO_REPOSITION, 0, -1, 0, 0, 0, LAT, LON, 0)
        assert expect(conn, "COMMAND_ACK", command=mav.MAV_CMD_DO_REPOSITION).result == mav.MAV_RESULT_DENIED
        assert handlers.guided is None and handlers.custom_mode == RoverMode.HOLD

        # DO_REPOSITION as QGroundControl sends it (COMMAND_INT, frame GLOBAL, CHANGE_MODE) -> GUIDED.
        conn.mav.command_int_send(1, 1, mav.MAV_FRAME_GLOBAL, mav.MAV_CMD_DO_REPOSITION, 0, 0, -1,
                                  mav.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE, 0, float("nan"), int(LAT * 1e7), int(LON * 1e7), 584)  # fmt: skip
        assert expect(conn, "COMMAND_ACK", command=mav.MAV_CMD_DO_REPOSITION).result == mav.MAV_RESULT_ACCEPTED
        assert handlers.custom_mode == RoverMode.GUIDED and handlers.guided == (LAT, LON)

        # In GUIDED: a position target moves the destination, a velocity-only one does not.
        conn.mav.set_position_target_global_int_send(0, 1, 1, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, POSITION_ONLY,
                                                     int((LAT + 1e-4) * 1e7), int(LON * 1e7), 0, 0, 0, 0, 0, 0, 0, 0, 0)  # fmt: skip
        assert wait_for(lambda: handlers.guided is not None and abs(handlers.guided[0] - (LAT + 1e-4)) < 1e-9)
        conn.mav.set_position_target_global_int_send(0, 1, 1, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0b110111000111,
                                                     int(LAT * 1e7), int(LON * 1e7), 0, 1.0, 0, 0, 0, 0, 0, 0, 0)  # fmt: skip
        conn.mav.command_long_send(1, 1, mav.MAV_CMD_GET_HOME_POSITION, 0, 0, 0, 0, 0, 0, 0, 0)  # handled after it
        expect(conn, "COMMAND_ACK", command=mav.MAV_CMD_GET_HOME_POSITION)
        assert abs(handlers.guided[0] - (LAT + 1e-4)) < 1e-9
        # ...and the guided-WP item is accepted in GUIDED; a legacy MISSION_ITEM carries degrees.
        conn.mav.mission_item_send(1, 1, 0, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, mav.MAV_CMD_NAV_WAYPOINT, 2, 0,
                                   0, 0, 0, 0, LAT - 1e-4, LON, 0)  # fmt: skip
        assert expect(conn, "MISSION_ACK").type == mav.MAV_MISSION_ACCEPTED
        assert abs(handlers.guided[0] - (LAT - 1e-4)) < 1e-5  # float32 degrees: ~0.1 m
        # A current=2 item is not an upload: the stored mission is untouched.
        assert not handlers.mission.items
