"""The vehicle link against a scripted vehicle on a real UDP socket (same thread, own sockets)."""

from __future__ import annotations

import math
import os
import socket
import time

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from rover_ctl.config import LinkParams  # noqa: E402
from rover_ctl.mavlink.vehicle import (MAX_COMMAND_WAITERS, PARAM_READ_PERIOD_S, PARAM_READ_TRIES, CommandResult, FrameMarker,  # noqa: E402
                                      LinkError, StatusText as VehicleText, VehicleLink, VehicleParam, VehicleStatus,  # noqa: E402
                                      VehicleVersion, decode_range)  # noqa: E402
from rover_ctl.estimation.readings import Attitude, GpsFix, RangeReading, WheelDistance  # noqa: E402
from support import free_port  # noqa: E402

from rover_ctl.vocabulary import ARM_FORCE_MAGIC, mav  # noqa: E402  (not mavutil.mavlink: MAVLink 1's if another module imported mavutil first)


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def receive(conn, kind: str, timeout_s: float = 2.0):
    msg = conn.recv_match(type=kind, blocking=True, timeout=timeout_s)
    assert msg is not None, f"no {kind} within {timeout_s} s"
    return msg


def drain(link: VehicleLink, want: type, timeout_s: float = 2.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        link.wait_readable(0.05)
        for item in link.poll():
            if isinstance(item, want):
                return item
    raise AssertionError(f"no {want.__name__} within {timeout_s} s")


def send_version(vehicle, custom: bytes) -> None:
    vehicle.mav.autopilot_version_send(mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2, 0x04070000, 0, 0, 0, list(custom), [0] * 8, [0] * 8, 0, 0, 0)


@pytest.fixture
def pair():
    port = free_port(socket.SOCK_DGRAM)
    clock = FakeClock()
    link = VehicleLink(f"udpin:127.0.0.1:{port}", LinkParams(), command_timeout_s=0.5, command_retries=2, wall=clock)
    vehicle = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1, source_component=1, dialect="ardupilotmega")
    vehicle.mav.heartbeat_send(mav.MAV_TYPE_GROUND_ROVER, mav.MAV_AUTOPILOT_ARDUPILOTMEGA, mav.MAV_MODE_FLAG_SAFETY_ARMED, 0, 0)
    status = link.wait_vehicle(2.0)
    assert isinstance(status, VehicleStatus) and status.armed and status.custom_mode == 0
    # The link asks who the vehicle is; answered as ArduPilot does (its git hash as custom version).
    request = receive(vehicle, "COMMAND_LONG")
    assert (request.command, request.param1) == (mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    vehicle.mav.command_ack_send(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAV_RESULT_ACCEPTED)
    send_version(vehicle, b"64a9c787")
    assert drain(link, VehicleVersion).lockstep is False
    # The link heartbeats as a GCS from SYSID_MYGCS, once a period (udpin: now that it knows the peer).
    clock.t += LinkParams().heartbeat_period_s
    link.tick()
    hb = receive(vehicle, "HEARTBEAT")
    assert hb.type == mav.MAV_TYPE_GCS and hb.get_srcSystem() == 255
    yield link, vehicle, clock
    link.close()
    vehicle.close()


@pytest.mark.parametrize(
    "current_cm, max_cm, expected",
    [(150, 400, 1.5), (0, 400, math.inf), (65535, 400, math.inf), (401, 400, math.inf), (20, 400, 0.2)],
)
def test_range_decoding(current_cm, max_cm, expected):
    msg = mav.MAVLink_distance_sensor_message(1000, 20, max_cm, current_cm, 0, 3, 6, 0)
    reading = decode_range(msg, 1.0)
    assert reading.range_m == expected and reading.orientation == 6 and reading.max_range_m == 4.0


def test_sensor_messages_decode_to_readings(pair):
    link, vehicle, _ = pair
    vehicle.mav.attitude_send(2500, 0, 0, 1.2, 0, 0, -0.3)
    vehicle.mav.wheel_distance_send(2_520_000, 2, [1.5, 1.75] + [0.0] * 14)
    vehicle.mav.gps_raw_int_send(2_540_000, 3, -353632610, 1491652300, 584000, 65535, 65535, 120, 9000, 10)
    vehicle.mav.distance_sensor_send(2560, 20, 400, 0, 0, 0, 0, 0)
    got = {}
    deadline = time.monotonic() + 2.0
    while len(got) < 4 and time.monotonic() < deadline:
        link.wait_readable(0.05)
        for item in link.poll():
            got[type(item)] = item
    att = got[Attitude]
    assert (att.time_s, att.yaw_rad, att.yaw_rate_radps) == (2.5, pytest.approx(1.2), pytest.approx(-0.3))
    assert got[WheelDistance] == WheelDistance(2.52, 1.5, 1.75)
    fix = got[GpsFix]
    assert fix.has_fix and fix.lat_deg == pytest.approx(-35.363261) and math.isnan(fix.eph_m) and fix.speed_mps == 1.2
    assert got[RangeReading].range_m == math.inf  # 0 cm: nothing seen yet
    assert link.vehicle_time_s == pytest.approx(2.56)


def test_epoch_gps_time_is_put_on_the_vehicle_clock(pair):
    """A real GPS may stamp GPS_RAW_INT with UNIX time: the link uses the arrival time instead."""
    link, vehicle, _ = pair
    vehicle.mav.attitude_send(7000, 0, 0, 0.0, 0, 0, 0.0)
    vehicle.mav.gps_raw_int_send(1_763_800_000_000_000, 3, -353632610, 1491652300, 584000, 120, 65535, 0, 0, 10)
    fix = drain(link, GpsFix)
    assert fix.time_s == 7.0 and link.vehicle_time_s == 7.0


def test_garbage_is_counted_and_skipped(pair):
    link, vehicle, _ = pair
    vehicle.write(b"\xfd\x09\x00\x00\x07\x01\x01\x00\x00\x00garbage-bytes-that-are-no-frame")
    vehicle.mav.attitude_send(3000, 0, 0, 0.5, 0, 0, 0.0)
    assert drain(link, Attitude).time_s == 3.0
    assert link.garbage_frames >= 1


def test_command_is_retried_until_acknowledged(pair):
    link, vehicle, clock = pair
    results: list[CommandResult] = []
    link.arm_async(True, on_result=results.append)
    first = receive(vehicle, "COMMAND_LONG")
    assert (first.command, first.param1, first.confirmation) == (mav.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, 0)
    clock.t += 0.6  # no ACK within command_timeout_s: sent again with the next confirmation number
    link.tick()
    second = receive(vehicle, "COMMAND_LONG")
    assert second.confirmation == 1
    vehicle.mav.command_ack_send(mav.MAV_CMD_COMPONENT_ARM_DISARM, mav.MAV_RESULT_ACCEPTED)
    assert drain(link, CommandResult).accepted
    assert results and results[0].accepted


def test_a_repeated_command_waits_for_the_outstanding_one_instead_of_being_sent_again(pair):
    """A ground station repeating a disarm a thousand times put a thousand COMMAND_LONGs on the
    vehicle's link (a 57600 radio fills at some 140 a second)."""
    link, vehicle, _ = pair
    first: list[CommandResult] = []
    others = [[] for _ in range(12)]
    link.arm_async(False, on_result=first.append)
    for _ in range(1000):
        link.arm_async(False, on_result=first.append)  # the same waiter: joins once
    for results in others:
        link.arm_async(False, on_result=results.append)
    assert receive(vehicle, "COMMAND_LONG").param1 == 0.0
    assert vehicle.recv_match(type="COMMAND_LONG", blocking=True, timeout=0.3) is None
    vehicle.mav.command_ack_send(mav.MAV_CMD_COMPONENT_ARM_DISARM, mav.MAV_RESULT_ACCEPTED)
    assert drain(link, CommandResult).accepted
    assert len(first) == 1  # each waiter answered once; beyond MAX_COMMAND_WAITERS (8) not kept
    assert sum(len(r) for r in others) == MAX_COMMAND_WAITERS - 1
    link.arm_async(True, on_result=first.append)  # other parameters: a new request, sent
    assert receive(vehicle, "COMMAND_LONG").param1 == 1.0


def test_one_request_per_command_on_the_wire_so_an_ack_answers_the_right_one(pair):
    """A COMMAND_ACK names only the command: a disarm still being retried when an arm replaced it
    had its ACCEPTED taken as the arm's. The arm now waits for the disarm's answer."""
    link, vehicle, _ = pair
    disarm, arm, superseded = [], [], []
    link.arm_async(False, on_result=disarm.append)
    assert receive(vehicle, "COMMAND_LONG").param1 == 0.0
    link.arm_async(True, on_result=superseded.append)  # queued ...
    link.arm_async(True, on_result=superseded.append)  # (the same again joins it)
    link.command_async(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, float(ARM_FORCE_MAGIC), on_result=arm.append)  # ... replaced
    assert vehicle.recv_match(type="COMMAND_LONG", blocking=True, timeout=0.3) is None  # nothing while the disarm waits
    vehicle.mav.command_ack_send(mav.MAV_CMD_COMPONENT_ARM_DISARM, mav.MAV_RESULT_ACCEPTED)
    assert drain(link, CommandResult).accepted and [r.result for r in disarm] == [mav.MAV_RESULT_ACCEPTED] and arm == []
    sent = receive(vehicle, "COMMAND_LONG")  # then the arm goes
    assert (sent.param1, sent.param2) == (1.0, float(ARM_FORCE_MAGIC))
    vehicle.mav.command_ack_send(mav.MAV_CMD_COMPONENT_ARM_DISARM, mav.MAV_RESULT_DENIED)
    assert drain(link, CommandResult).result == mav.MAV_RESULT_DENIED and [r.result for r in arm] == [mav.MAV_RESULT_DENIED]
    assert superseded == [] and vehicle.recv_match(type="COMMAND_LONG", blocking=True, timeout=0.3) is None


def test_an_ack_addressed_to_another_ground_station_is_not_ours(pair):
    link, vehicle, _ = pair
    results: list[CommandResult] = []
    link.arm_async(True, on_result=results.append)
    receive(vehicle, "COMMAND_LONG")
    vehicle.mav.command_ack_send(mav.MAV_CMD_COMPONENT_ARM_DISARM, mav.MAV_RESULT_DENIED, 0, 0, 255, 230)  # MAVProxy's
    vehicle.mav.command_ack_send(mav.MAV_CMD_COMPONENT_ARM_DISARM, mav.MAV_RESULT_ACCEPTED, 0, 0, 255, 190)  # ours
    assert drain(link, CommandResult).accepted and [r.result for r in results] == [mav.MAV_RESULT_ACCEPTED]


def test_unanswered_command_fails_after_the_retries(pair):
    link, vehicle, clock = pair
    results: list[CommandResult] = []
    link.set_mode_async(0, on_result=results.append)
    for _ in range(3):
        receive(vehicle, "COMMAND_LONG")
        clock.t += 0.6
        link.tick()
    assert results == [CommandResult(mav.MAV_CMD_DO_SET_MODE, -1)]


def test_overrides_and_release(pair):
    link, vehicle, _ = pair
    link.send_override(1600, 1700)
    msg = receive(vehicle, "RC_CHANNELS_OVERRIDE")
    assert (msg.chan1_raw, msg.chan2_raw, msg.chan3_raw, msg.chan4_raw) == (1600, 0, 1700, 0)
    assert msg.get_srcSystem() == 255 and msg.target_system == 1
    link.release_override()
    msg = receive(vehicle, "RC_CHANNELS_OVERRIDE")
    assert (msg.chan1_raw, msg.chan3_raw) == (0, 0)


def test_timesync_probe_is_answered_and_is_not_a_marker(pair):
    """ArduPilot's latency probe, TIMESYNC(tc1=0, ts1=now) every 10 s: answered at once with our
    clock in tc1 and ts1 echoed (MAVLink spec); no frame, no lockstep."""
    link, vehicle, clock = pair
    vehicle.mav.timesync_send(0, 123_456_789)
    vehicle.mav.attitude_send(5020, 0, 0, 0.5, 0, 0, 0.0)
    items = []
    deadline = time.monotonic() + 2.0
    while not any(isinstance(i, Attitude) for i in items) and time.monotonic() < deadline:
        link.wait_readable(0.05)
        items += link.poll()
    assert not any(isinstance(i, FrameMarker) for i in items)
    answer = receive(vehicle, "TIMESYNC")
    assert (answer.tc1, answer.ts1) == (int(clock.t * 1e9), 123_456_789)
    assert link.probes_answered == 1 and link.lockstep_source is None


def test_markers_count_only_from_the_component_that_announced_lockstep(pair):
    link, vehicle, _ = pair
    send_version(vehicle, b"lockstep")
    assert drain(link, VehicleVersion).lockstep
    other = mavutil.mavlink_connection(f"udpout:127.0.0.1:{link.conn.port.getsockname()[1]}", source_system=1,
                                       source_component=mav.MAV_COMP_ID_ONBOARD_COMPUTER, dialect="ardupilotmega")  # fmt: skip
    other.mav.timesync_send(0, 7_000_000_000)  # same system, another component: a probe
    items = []
    deadline = time.monotonic() + 2.0
    while link.probes_answered == 0 and time.monotonic() < deadline:
        link.wait_readable(0.05)
        items += link.poll()
    assert link.probes_answered == 1 and not any(isinstance(i, FrameMarker) for i in items)
    other.close()


def test_lockstep_marker_is_a_frame_and_is_answered(pair):
    link, vehicle, _ = pair
    send_version(vehicle, b"lockstep")  # rover-sitl --lockstep announces itself so
    assert drain(link, VehicleVersion).lockstep
    vehicle.mav.wheel_distance_send(4_980_000, 2, [0.0] * 16)
    vehicle.mav.timesync_send(0, 5_000_000_000)
    vehicle.mav.attitude_send(5020, 0, 0, 0.5, 0, 0, 0.0)  # next frame: must not be in this poll
    seen = []
    deadline = time.monotonic() + 2.0
    while not any(isinstance(i, FrameMarker) for i in seen) and time.monotonic() < deadline:
        link.wait_readable(0.05)
        seen += link.poll()
    assert isinstance(seen[-1], FrameMarker) and seen[-1].time_s == 5.0
    assert not any(isinstance(i, Attitude) for i in seen)
    link.answer_marker(seen[-1])
    answer = receive(vehicle, "TIMESYNC")
    assert answer.ts1 == 5_000_000_000 and answer.tc1 != 0
    assert link.last_rx_vehicle_s == pytest.approx(4.98)  # markers are no sign of life
    assert drain(link, Attitude).time_s == 5.02


def test_no_vehicle_is_a_clear_error():
    port = free_port(socket.SOCK_DGRAM)
    link = VehicleLink(f"udpin:127.0.0.1:{port}", LinkParams())
    with pytest.raises(LinkError, match="no vehicle heartbeat within 0.2 s"):
        link.wait_vehicle(0.2)
    link.close()


def test_streams_are_asked_for_from_the_budget_and_nothing_else(pair):
    """Every stream off, EXTRA1 (WHEEL_DISTANCE) at its whole-hertz rate with the EXTRA1 messages
    the daemon does not read switched off, then one interval per other message."""
    from rover_ctl.config import Config
    from rover_ctl.mavlink import budget

    link, vehicle, _ = pair
    c = Config()
    plan = budget.plan(c.daemon, c.link, c.failsafe, "/dev/ttyUSB0,57600", 6)
    link.request_streams(plan)
    stop, extra1 = receive(vehicle, "REQUEST_DATA_STREAM"), receive(vehicle, "REQUEST_DATA_STREAM")
    assert (stop.req_stream_id, stop.start_stop) == (mav.MAV_DATA_STREAM_ALL, 0)
    assert (extra1.req_stream_id, extra1.req_message_rate, extra1.start_stop) == (mav.MAV_DATA_STREAM_EXTRA1, plan.rates_hz["EXTRA1"], 1)
    intervals = {}
    expected = {"GPS_RAW_INT", "DISTANCE_SENSOR", "SYS_STATUS", "ATTITUDE", *budget.EXTRA1_UNREAD}
    deadline = time.monotonic() + 5.0
    while not expected <= set(intervals) and time.monotonic() < deadline:
        msg = vehicle.recv_match(type="COMMAND_LONG", blocking=True, timeout=0.5)
        if msg is not None:
            assert msg.command == mav.MAV_CMD_SET_MESSAGE_INTERVAL
            intervals[mav.mavlink_map[int(msg.param1)].msgname] = msg.param2
    assert intervals["GPS_RAW_INT"] == pytest.approx(1e6 / plan.rates_hz["GPS_RAW_INT"])
    assert intervals["DISTANCE_SENSOR"] == pytest.approx(1e6 / plan.rates_hz["DISTANCE_SENSOR"])
    assert intervals["ATTITUDE"] == pytest.approx(1e6 / plan.rates_hz["EXTRA1"])
    assert all(intervals[name] == -1 for name in budget.EXTRA1_UNREAD)  # SIMSTATE included: no room on 57600
    assert "WHEEL_DISTANCE" not in intervals  # ArduPilot refuses it: it comes with EXTRA1


def test_link_health_counts_rates_bad_crcs_and_sequence_gaps(pair):
    link, vehicle, _ = pair
    for k in range(40):
        if k == 20:
            vehicle.mav.seq = (vehicle.mav.seq + 3) % 256  # three frames "lost" on the way
        vehicle.mav.attitude_send(1000 + 50 * k, 0, 0, 0.0, 0, 0, 0.0)
    good = vehicle.mav.attitude_encode(3000, 0, 0, 0.0, 0, 0, 0.0).pack(vehicle.mav)
    vehicle.write(good[:-1] + bytes([good[-1] ^ 0xFF]))  # a byte error in the CRC
    vehicle.mav.seq = (vehicle.mav.seq + 1) % 256  # the corrupted frame had its own sequence number
    vehicle.mav.attitude_send(3050, 0, 0, 0.0, 0, 0, 0.0)
    deadline = time.monotonic() + 2.0
    while link.vehicle_time_s < 3.05 and time.monotonic() < deadline:
        link.wait_readable(0.05)
        link.poll()
    stats = link.health.stats(link.vehicle_time_s)
    assert stats.crc_errors == 1 and stats.lost == 3 + 1  # the dropped frame left a gap too
    assert stats.rates_hz["ATTITUDE"] == pytest.approx(20.0, rel=0.1)


def test_radio_status_from_the_radio_is_read_whatever_its_system_id(pair):
    from rover_ctl.mavlink.vehicle import RadioStatus

    link, _, _ = pair
    port = link.conn.port.getsockname()[1]
    radio = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=51, source_component=68, dialect="ardupilotmega")
    radio.mav.radio_status_send(180, 170, 40, 20, 25, 3, 1)
    status = drain(link, RadioStatus)
    assert (status.rssi, status.remote_rssi, status.txbuf_pct, status.rx_errors) == (180, 170, 40, 3)
    radio.close()


def test_a_serial_line_at_the_wrong_baud_rate_is_a_clear_error():
    """A radio at 57600 opened at 115200 delivers bytes that never make a frame: say so, early."""
    import pty as ptymod

    master, slave = ptymod.openpty()
    device = os.ttyname(slave)
    link = VehicleLink(f"{device},115200", LinkParams())
    try:
        os.write(master, bytes(range(256)) * 20)  # what a mismatched UART reads: noise
        with pytest.raises(LinkError, match=r"not one MAVLink frame at 115200 baud: wrong baud rate"):
            link.wait_vehicle(5.0)
    finally:
        link.close()
        os.close(master)
        os.close(slave)


def test_a_read_holding_only_part_of_a_frame_is_no_error(pair):
    """On a serial line a read can end mid-frame (or hold only bytes a byte error broke): poll
    returns what is whole and keeps the rest for the next read."""
    link, vehicle, _ = pair
    frame = vehicle.mav.attitude_encode(4000, 0, 0, 0.25, 0, 0, 0.0).pack(vehicle.mav)
    vehicle.mav.seq = (vehicle.mav.seq + 1) % 256
    vehicle.write(frame[:10])
    link.wait_readable(0.5)
    assert [i for i in link.poll() if isinstance(i, Attitude)] == []
    vehicle.write(frame[10:])
    assert drain(link, Attitude).time_s == 4.0


def test_an_ardupilot_vehicle_is_asked_for_its_steering_type_until_it_answers(pair):
    link, vehicle, clock = pair
    request = receive(vehicle, "PARAM_REQUEST_READ")  # sent with the first heartbeat's tick
    assert (request.param_id, request.param_index, request.target_system) == ("PILOT_STEER_TYPE", -1, 1)
    clock.t += PARAM_READ_PERIOD_S
    link.tick()
    receive(vehicle, "PARAM_REQUEST_READ")  # not answered: asked again a period later
    vehicle.mav.param_value_send(b"SOMETHING_ELSE", 1.0, mav.MAV_PARAM_TYPE_REAL32, 900, 1)  # another GCS's
    vehicle.mav.param_value_send(b"PILOT_STEER_TYPE", 0.0, mav.MAV_PARAM_TYPE_INT8, 900, 2)
    assert drain(link, VehicleParam) == VehicleParam("PILOT_STEER_TYPE", 0.0)
    clock.t += PARAM_READ_PERIOD_S
    link.tick()
    assert vehicle.recv_match(type="PARAM_REQUEST_READ", blocking=True, timeout=0.3) is None  # answered: no more


def test_an_unanswered_parameter_read_stops_after_its_tries(pair):
    link, vehicle, clock = pair
    asked = 0
    for _ in range(PARAM_READ_TRIES + 3):
        while vehicle.recv_match(type="PARAM_REQUEST_READ", blocking=True, timeout=0.1) is not None:
            asked += 1
        clock.t += PARAM_READ_PERIOD_S
        link.tick()
    assert asked == PARAM_READ_TRIES


def test_a_long_vehicle_text_in_chunks_is_one_text(pair):
    link, vehicle, _ = pair
    text = "PreArm: Hardware safety switch; Battery 1 below minimum arming voltage"
    data = text.encode()
    vehicle.mav.statustext_send(mav.MAV_SEVERITY_CRITICAL, data[:50], 7, 0)
    vehicle.mav.statustext_send(mav.MAV_SEVERITY_CRITICAL, data[50:], 7, 1)
    item = drain(link, VehicleText)
    assert (item.text, item.severity) == (text, mav.MAV_SEVERITY_CRITICAL)


def test_a_tcp_read_that_comes_back_short_ends_the_poll():
    """A byte stream read short has nothing more waiting: the poll does not read again only to
    find it empty (a system call and pymavlink's EAGAIN exception every loop turn)."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    link = VehicleLink(f"tcp:127.0.0.1:{server.getsockname()[1]}", LinkParams())
    peer, _ = server.accept()
    try:
        vehicle = mav.MAVLink(None, srcSystem=1, srcComponent=1)
        frames = [vehicle.attitude_encode(1000 + k, 0.0, 0.0, 0.1 * k, 0.0, 0.0, 0.0).pack(vehicle) for k in range(3)]
        peer.sendall(b"".join(frames))
        link.wait_readable(2.0)  # one short sendall on loopback: one segment, all of it there
        reads = []
        recv = link.conn.recv
        link.conn.recv = lambda n=None: reads.append(n) or recv(n)
        items = link.poll()
        assert [type(i) for i in items] == [Attitude] and items[0].yaw_rad == pytest.approx(0.2)  # coalesced: the newest
        assert len(reads) == 1
        assert link.poll() == [] and len(reads) == 2  # the next turn reads again
    finally:
        link.close()
        peer.close()
        server.close()
