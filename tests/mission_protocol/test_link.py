"""GcsLink over real UDP sockets: heartbeat, commands, the mission service, the store (params: tests/parameters)."""

from __future__ import annotations

import random
import select
import time

import pytest
from mission_protocol.helpers import HOME, MAVPROXY, MAVSDK, LinkThread, expect, gcs
from pymavlink.dialects.v20 import ardupilotmega as mav

from rover_ctl.config import GcsParams
from rover_ctl.mavlink.commands import CAPABILITIES
from rover_ctl.mavlink.gcs import DefaultHandlers, GcsLink
from rover_ctl.mavlink.telemetry import StatusTextAssembler
from rover_ctl.vocabulary import RoverMode
from rover_ctl.mavlink.mission_client import MissionClient, MissionClientError
from rover_ctl.mission.model import Mission
from rover_ctl.mission.store import MissionStore

FAST = GcsParams(client_retry_s=0.2, client_retries=10, heartbeat_period_s=0.2)


@pytest.fixture
def url(udp_port: int) -> str:
    return f"udpin:127.0.0.1:{udp_port}"


def client(port: int, sender=MAVPROXY) -> MissionClient:
    return MissionClient(f"udpout:127.0.0.1:{port}", FAST, *sender)


def command(conn, cmd: int, *params: float):
    p = list(params) + [0.0] * (7 - len(params))
    conn.mav.command_long_send(1, 1, cmd, 0, *p)
    return expect(conn, "COMMAND_ACK", command=cmd)


def test_heartbeat_is_a_rover_autopilot_from_1_1(url, udp_port):
    with LinkThread(url, params=FAST):
        conn = gcs(udp_port)
        conn.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        hb = expect(conn, "HEARTBEAT")
        assert (hb.get_srcSystem(), hb.get_srcComponent()) == (1, 1)
        assert hb.type == mav.MAV_TYPE_GROUND_ROVER and hb.autopilot == mav.MAV_AUTOPILOT_ARDUPILOTMEGA
        assert hb.custom_mode == RoverMode.HOLD and hb.base_mode & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        assert not hb.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED
        assert hb.get_msgbuf()[0] == 0xFD  # MAVLink 2 start byte


@pytest.mark.parametrize("ground_station_id, counted", [(255, {255}), (245, {245}), (0, {255, 245, 17})])
def test_only_the_ground_stations_heartbeat_holds_off_the_gcs_failsafe(url, udp_port, ground_station_id, counted):
    """As ArduPilot's MAV_GCS_SYSID: a heartbeat from any other system (a stranger on an unsigned
    link) does not hide a lost ground station; every GCS is still answered."""
    params = GcsParams(heartbeat_period_s=0.2, ground_station_system_id=ground_station_id)
    with LinkThread(url, params=params) as lt:
        for sysid in (17, 245, 255):
            conn = gcs(udp_port, (sysid, 190))
            before = lt.link.last_gcs_heartbeat_s
            conn.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            expect(conn, "HEARTBEAT")  # answered either way; a new address only after its frame was read
            assert (lt.link.last_gcs_heartbeat_s != before) == (sysid in counted), sysid


def test_commands_are_dispatched_and_acked_to_the_sender(url, udp_port):
    handlers = DefaultHandlers(home=HOME)
    with LinkThread(url, params=FAST, handlers=handlers) as lt:
        conn = gcs(udp_port, MAVSDK)
        ack = command(conn, mav.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        assert ack.result == mav.MAV_RESULT_ACCEPTED and (ack.target_system, ack.target_component) == MAVSDK
        expect(conn, "HEARTBEAT", custom_mode=RoverMode.HOLD)
        hb = expect(conn, "HEARTBEAT")
        assert hb.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED
        assert command(conn, mav.MAV_CMD_DO_SET_MODE, 1, RoverMode.GUIDED).result == mav.MAV_RESULT_ACCEPTED
        assert command(conn, mav.MAV_CMD_DO_SET_MODE, 1, 99).result == mav.MAV_RESULT_DENIED
        assert command(conn, mav.MAV_CMD_MISSION_START).result == mav.MAV_RESULT_DENIED  # no mission
        assert command(conn, mav.MAV_CMD_NAV_RETURN_TO_LAUNCH).result == mav.MAV_RESULT_ACCEPTED
        assert handlers.custom_mode == RoverMode.RTL
        assert command(conn, mav.MAV_CMD_DO_FLIGHTTERMINATION, 1).result == mav.MAV_RESULT_UNSUPPORTED
        conn.mav.set_mode_send(1, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, RoverMode.MANUAL)
        expect(conn, "HEARTBEAT", custom_mode=RoverMode.MANUAL)
        conn.mav.command_int_send(1, 1, 0, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 0, 0, 0, 0, 0, 0, 0)
        assert expect(conn, "COMMAND_ACK", command=mav.MAV_CMD_COMPONENT_ARM_DISARM).result == mav.MAV_RESULT_ACCEPTED
        assert not lt.link.handlers.state().armed


def test_autopilot_version_and_home_position_on_request(url, udp_port):
    with LinkThread(url, params=FAST, handlers=DefaultHandlers(home=HOME)):
        conn = gcs(udp_port)
        assert command(conn, mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION).result == mav.MAV_RESULT_ACCEPTED
        version = expect(conn, "AUTOPILOT_VERSION")
        assert version.capabilities == CAPABILITIES
        for flag in ("MISSION_INT", "MISSION_FENCE", "MISSION_RALLY", "COMMAND_INT", "MAVLINK2"):
            assert version.capabilities & getattr(mav, f"MAV_PROTOCOL_CAPABILITY_{flag}")
        assert not version.capabilities & mav.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
        for request in ((mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_HOME_POSITION), (mav.MAV_CMD_GET_HOME_POSITION,)):
            assert command(conn, *request).result == mav.MAV_RESULT_ACCEPTED
            home = expect(conn, "HOME_POSITION")
            assert (home.latitude, home.longitude, home.altitude) == (-353632610, 1491652300, 584000)
        assert command(conn, mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_BATTERY_STATUS).result == mav.MAV_RESULT_UNSUPPORTED


def test_home_position_fails_without_a_home(url, udp_port):
    with LinkThread(url, params=FAST):
        conn = gcs(udp_port)
        assert command(conn, mav.MAV_CMD_GET_HOME_POSITION).result == mav.MAV_RESULT_FAILED


def test_garbage_on_the_link_is_survived(url, udp_port, mission):
    rng = random.Random(7)
    with LinkThread(url, params=FAST) as lt, client(udp_port) as c:
        c.connect()
        for size in (1, 7, 40, 280, 1000):
            c.conn.write(bytes([0xFD]) + rng.randbytes(size))  # a MAVLink 2 start byte, then noise
        c.upload(mission)
        assert lt.link.service.mission.same_as(mission)


def test_upload_download_clear_and_mission_changed(url, udp_port, mission):
    handlers = DefaultHandlers()
    with LinkThread(url, params=FAST, handlers=handlers) as lt, client(udp_port, MAVSDK) as c:
        assert c.connect() == (1, 1)
        assert c.upload(mission) == [0, 1, 2]
        assert lt.link.service.mission.same_as(mission) and handlers.mission.same_as(mission)
        assert c.download().same_as(mission)
        c.clear(1)
        assert lt.link.service.mission.fence == [] and handlers.mission.fence == []
        c.clear(255)
        assert c.download().same_as(Mission(home=mission.home))


@pytest.mark.parametrize("link_side, client_side", [("udpout", "udpin"), ("tcpin", "tcp")])
def test_other_connection_kinds(link_side, client_side, udp_port, tcp_port, mission):
    port = tcp_port if link_side == "tcpin" else udp_port
    with LinkThread(f"{link_side}:127.0.0.1:{port}", params=FAST) as lt, MissionClient(
        f"{client_side}:127.0.0.1:{port}", FAST
    ) as c:
        c.upload(mission)
        assert lt.link.service.mission.same_as(mission) and c.download().same_as(mission)


def test_mission_start_and_set_current(url, udp_port, mission):
    handlers = DefaultHandlers()
    with LinkThread(url, params=FAST, handlers=handlers) as lt, client(udp_port) as c:
        c.connect()
        c.upload(mission)
        conn = c.conn
        ack = command(conn, mav.MAV_CMD_MISSION_START)
        assert ack.result == mav.MAV_RESULT_ACCEPTED and handlers.custom_mode == RoverMode.AUTO
        conn.mav.mission_set_current_send(1, 1, 3)
        assert expect(conn, "MISSION_CURRENT", seq=3).total == len(mission.items)
        assert handlers.current_seq == 3
        assert command(conn, mav.MAV_CMD_DO_SET_MISSION_CURRENT, 2).result == mav.MAV_RESULT_ACCEPTED
        assert command(conn, mav.MAV_CMD_DO_SET_MISSION_CURRENT, 40).result == mav.MAV_RESULT_DENIED
        assert lt.link.service.current_seq == 2


def test_a_restarted_link_keeps_its_mission(url, udp_port, mission, tmp_path):
    store = MissionStore(tmp_path / "state" / "mission.json")
    with LinkThread(url, params=FAST, store=store), client(udp_port) as c:
        c.upload(mission)
    assert store.load().same_as(mission)
    handlers = DefaultHandlers()
    with LinkThread(url, params=FAST, store=store, handlers=handlers), client(udp_port) as c:
        assert handlers.mission.same_as(mission)  # the daemon is told at start
        assert c.download().same_as(mission)


def test_a_corrupt_store_is_moved_aside_and_the_link_starts_empty(tmp_path, url):
    path = tmp_path / "mission.json"
    path.write_text('{"format": "rover_ctl-mission-store", "version": 1, "items": [', encoding="utf-8")
    link = GcsLink(url, FAST, store=MissionStore(path))
    try:
        assert link.service.mission.same_as(Mission())
        assert "corrupt mission store" in link.store_error and "mission.json.corrupt" in link.store_error
        assert (tmp_path / "mission.json.corrupt").read_text().endswith('"items": [')
        assert not path.exists()
    finally:
        link.close()


def test_a_store_that_cannot_be_written_refuses_the_upload(tmp_path, url, udp_port, mission):
    blocker = tmp_path / "not_a_dir"
    blocker.write_text("")
    with LinkThread(url, params=FAST, store=MissionStore(blocker / "mission.json")) as lt, client(udp_port) as c:
        with pytest.raises(MissionClientError, match="mission upload refused by the vehicle: MAV_MISSION_ERROR"):
            c.upload(mission)
        assert lt.link.service.mission.same_as(Mission())


def test_data_stream_and_message_interval_set_telemetry_rates(url):
    link = GcsLink(url, FAST)
    try:
        assert link.send_global_position_int(0.0, -35.0, 149.0, 584.0, 0.0, 0.0, 0.0, 90.0, 0)
        assert not link.send_global_position_int(0.1, -35.0, 149.0, 584.0, 0.0, 0.0, 0.0, 90.0, 100)  # 4 Hz default
        assert link.send_global_position_int(0.25, -35.0, 149.0, 584.0, 0.0, 0.0, 0.0, 90.0, 250)
        link.telemetry.set_interval(mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 50_000)  # 20 Hz
        assert link.send_global_position_int(0.31, -35.0, 149.0, 584.0, 0.0, 0.0, 0.0, 90.0, 310)
        link.telemetry.set_interval(mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, -1)
        assert not link.send_global_position_int(9.0, -35.0, 149.0, 584.0, 0.0, 0.0, 0.0, 90.0, 9000)
        assert link.telemetry.set_interval(mav.MAVLINK_MSG_ID_BATTERY_STATUS, 1000) == mav.MAV_RESULT_DENIED
    finally:
        link.close()


def test_request_data_stream_over_the_wire(url, udp_port):
    with LinkThread(url, params=FAST) as lt:
        conn = gcs(udp_port)
        conn.mav.request_data_stream_send(1, 1, mav.MAV_DATA_STREAM_EXTRA1, 25, 1)
        conn.mav.request_data_stream_send(1, 1, mav.MAV_DATA_STREAM_POSITION, 0, 0)
        conn.mav.command_long_send(1, 1, mav.MAV_CMD_SET_MESSAGE_INTERVAL, 0, mav.MAVLINK_MSG_ID_SYS_STATUS, 200_000, 0, 0, 0, 0, 0)
        expect(conn, "COMMAND_ACK", command=mav.MAV_CMD_SET_MESSAGE_INTERVAL, result=mav.MAV_RESULT_ACCEPTED)
        rates = lt.link.telemetry.rates.interval_s
        assert rates[mav.MAVLINK_MSG_ID_ATTITUDE] == pytest.approx(0.04)
        assert rates[mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT] is None
        assert rates[mav.MAVLINK_MSG_ID_SYS_STATUS] == pytest.approx(0.2)


def connected(url: str, udp_port: int):
    """An unthreaded GcsLink that has heard a ground station (so it knows where to send)."""
    link = GcsLink(url, FAST)
    conn = gcs(udp_port)
    conn.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    end = time.monotonic() + 3.0
    while not link.peers:  # a frame that passed makes its sender a peer (rover_ctl.mavlink.peers)
        assert time.monotonic() < end, "the link never heard the ground station"
        link.poll(time.monotonic())
    while conn.recv_match(blocking=True, timeout=0.2) is not None:  # what that poll sent (HEARTBEAT, MISSION_CURRENT)
        pass
    return link, conn


def test_mission_current_and_item_reached_as_the_executor_reports(url, udp_port, mission):
    link, conn = connected(url, udp_port)
    try:
        link.service.mission = mission
        link.send_mission_current(3)
        current = expect(conn, "MISSION_CURRENT")
        assert (current.seq, current.total, current.mission_state) == (3, len(mission.items), mav.MISSION_STATE_ACTIVE)
        link.send_mission_item_reached(3)
        assert expect(conn, "MISSION_ITEM_REACHED").seq == 3
        assert link.service.current_seq == 3
    finally:
        link.close()


def test_long_statustext_is_chunked(url, udp_port):
    link, conn = connected(url, udp_port)
    try:
        text = "obstacle ahead " * 7
        link.send_statustext(text, mav.MAV_SEVERITY_WARNING)
        chunks = [expect(conn, "STATUSTEXT") for _ in range(3)]
        assert len({c.id for c in chunks}) == 1 and chunks[0].id > 0
        assert [c.chunk_seq for c in chunks] == [0, 1, 2]
        assert "".join(c.text for c in chunks) == text
        assembler = StatusTextAssembler()
        assert [assembler.add(c) for c in chunks] == [None, None, text]
        link.send_statustext("a" * 50, mav.MAV_SEVERITY_INFO)  # one full message, id 0: whole as it is
        assert assembler.add(expect(conn, "STATUSTEXT")) == "a" * 50
        link.send_statustext("b" * 100, mav.MAV_SEVERITY_INFO)  # two full chunks and an empty one to end
        assert [assembler.add(expect(conn, "STATUSTEXT")) for _ in range(3)] == [None, None, "b" * 100]
    finally:
        link.close()


def test_the_assembler_keeps_a_bounded_number_of_unfinished_texts():
    assembler = StatusTextAssembler(pending=2)
    chunk = lambda text_id, text: mav.MAVLink_statustext_message(mav.MAV_SEVERITY_INFO, text.encode(), text_id, 0)  # noqa: E731
    for text_id in (1, 2, 3):  # never ended
        assert assembler.add(chunk(text_id, "x" * 50)) is None
    assert assembler.add(chunk(1, "end")) == "end"  # id 1, the oldest, was given up
    assert assembler.add(chunk(3, "end")) == "x" * 50 + "end"



def test_sys_status_health_follows_ardupilot(url, udp_port):
    """Healthy unless failed, and the GEOFENCE bit healthy while not breached (MAVProxy says
    "fence breach" when it is clear)."""
    link, conn = connected(url, udp_port)
    try:
        gps, fence = mav.MAV_SYS_STATUS_SENSOR_GPS, mav.MAV_SYS_STATUS_GEOFENCE
        assert link.send_sys_status(0.0, 12.1, 80, present=gps)
        status = expect(conn, "SYS_STATUS")
        assert status.onboard_control_sensors_health & (gps | fence) == gps | fence
        assert status.voltage_battery == 12100 and status.battery_remaining == 80
        assert link.send_sys_status(10.0, 12.0, 79, present=gps | fence, failed=gps | fence)
        status = expect(conn, "SYS_STATUS")
        assert status.onboard_control_sensors_present & fence and not status.onboard_control_sensors_health & (gps | fence)
    finally:
        link.close()


def test_pose_due_tells_without_taking_the_slot(url):
    link = GcsLink(url, FAST)
    try:
        assert link.pose_due(0.0) and link.pose_due(0.0)  # asking twice takes nothing
        assert link.send_global_position_int(0.0, -35.0, 149.0, 584.0, 0.0, 0.0, 0.0, 90.0, 0)
        assert link.send_attitude(0.0, 0.0, 0.0, 0)
        assert not link.pose_due(0.01)  # both just went out
        assert link.pose_due(10.0)
    finally:
        link.close()


def test_a_poll_told_the_socket_is_empty_reads_only_what_the_parser_holds(url, udp_port):
    """``poll(readable=False)`` (the daemon's select found nothing on the socket) hands over the
    frames already read, from a datagram that held more than one poll takes, and does not call
    recv for nothing; the frame that arrives meanwhile waits for a readable poll."""
    link = GcsLink(url, GcsParams(max_messages_per_poll=1))
    ground = gcs(udp_port)
    try:
        heartbeat = mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)
        ground.write(heartbeat.pack(ground.mav) + heartbeat.pack(ground.mav))  # two frames, one datagram
        reads = []
        recv = link.conn.recv
        link.conn.recv = lambda n=None: reads.append(n) or recv(n)
        deadline = time.monotonic() + 2.0
        while link.last_gcs_heartbeat_s is None and time.monotonic() < deadline:
            link.poll(time.monotonic())
        first = link.last_gcs_heartbeat_s
        assert first is not None and link.conn.mav.buf_len() > 0  # the second frame waits in the parser
        before = len(reads)
        link.poll(time.monotonic() + 0.01, readable=False)
        assert link.last_gcs_heartbeat_s != first  # the held frame was handled
        ground.write(heartbeat.pack(ground.mav))
        assert select.select([link.conn.port], [], [], 2.0)[0]  # it is there to be read
        link.poll(time.monotonic() + 0.02, readable=False)
        # One recv in the two polls: the first one's, which DatagramFraming answers with no bytes
        # so that the parser hands over the frame it holds; none for the socket.
        assert len(reads) == before + 1
        handled = link.last_gcs_heartbeat_s
        link.poll(time.monotonic() + 0.03)
        assert link.last_gcs_heartbeat_s != handled  # read once told the socket is readable
    finally:
        link.close()
        ground.close()
