"""The parameter protocol over real UDP sockets (a GcsLink in its own thread, a raw pymavlink GCS)."""

from __future__ import annotations

import pytest
from mission_protocol.helpers import LinkThread, expect, gcs
from pymavlink.dialects.v20 import ardupilotmega as mav

from rover_ctl.config import Config, GcsParams, load_config
from rover_ctl.mavlink.gcs import DefaultHandlers
from rover_ctl.mavlink.params import LIST_BURST, ConfigParams, ParamService
from rover_ctl.parameters import BY_NAME, MAVLINK, values

FAST = GcsParams(heartbeat_period_s=0.2, param_send_rate_hz=1000.0)


@pytest.fixture
def link(udp_port):
    config = Config()
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=FAST, handlers=DefaultHandlers(config)):
        yield config, gcs(udp_port)


def test_list_has_every_parameter_with_count_index_and_type(link):
    config, conn = link
    conn.mav.param_request_list_send(1, 1)
    got = {}
    while len(got) < len(MAVLINK):
        p = expect(conn, "PARAM_VALUE")
        got[p.param_id] = p
    assert list(got) == [p.name for p in MAVLINK]  # in table order
    assert {p.param_count for p in got.values()} == {len(MAVLINK)}
    assert [p.param_index for p in got.values()] == list(range(len(MAVLINK)))
    assert all(got[p.name].param_type == p.mav_type for p in MAVLINK)
    assert got["WP_RADIUS"].param_value == config.executor.acceptance_radius_m and got["RNG_PRESENT"].param_value == -1


def test_read_by_name_and_by_index(link):
    _, conn = link
    conn.mav.param_request_read_send(1, 1, b"WP_SPEED", -1)
    p = expect(conn, "PARAM_VALUE")
    assert (p.param_id, p.param_index, p.param_type) == ("WP_SPEED", MAVLINK.index(BY_NAME["WP_SPEED"]), mav.MAV_PARAM_TYPE_REAL32)
    assert p.param_value == pytest.approx(1.2)
    conn.mav.param_request_read_send(1, 1, b"", len(MAVLINK))  # no such index: no answer
    conn.mav.param_request_read_send(1, 1, b"NO_SUCH_PARAM", -1)  # no such name: no answer
    conn.mav.param_request_read_send(1, 1, b"", 0)
    first = expect(conn, "PARAM_VALUE")  # the next answer is the one to the good request
    assert (first.param_id, first.param_index) == (MAVLINK[0].name, 0)


def test_set_in_range_echoes_and_applies(link):
    config, conn = link
    conn.mav.param_set_send(1, 1, b"WP_SPEED", 0.75, mav.MAV_PARAM_TYPE_REAL32)
    p = expect(conn, "PARAM_VALUE", param_id="WP_SPEED")
    assert p.param_value == pytest.approx(0.75) and p.param_index == MAVLINK.index(BY_NAME["WP_SPEED"])
    assert config.executor.cruise_speed_mps == pytest.approx(0.75)
    conn.mav.param_set_send(1, 1, b"FS_ACTION", 2, mav.MAV_PARAM_TYPE_INT8)
    assert expect(conn, "PARAM_VALUE", param_id="FS_ACTION").param_value == 2
    conn.mav.param_set_send(1, 1, b"LOIT_RADIUS", 3.5, mav.MAV_PARAM_TYPE_REAL32)
    assert expect(conn, "PARAM_VALUE", param_id="LOIT_RADIUS").param_value == 3.5
    assert config.failsafe.gcs_action == "hold" and config.autopilot.loiter_radius_m == 3.5


@pytest.mark.parametrize(
    "name, value, why",
    [
        ("WP_SPEED", 99.0, "WP_SPEED: 99 is out of range 0 .. 20 m/s"),
        ("WP_RADIUS", float("nan"), "WP_RADIUS: nan is not a finite number"),
        ("FS_ACTION", 7.0, "FS_ACTION: 7 is not one of"),
        ("SYSID_THISMAV", 7.0, "SYSID_THISMAV is read-only: set at start"),
    ],
)
def test_a_refused_set_keeps_the_value_and_says_why(link, name, value, why):
    config, conn = link
    before = values(config)
    conn.mav.param_set_send(1, 1, name.encode(), value, mav.MAV_PARAM_TYPE_REAL32)
    text = expect(conn, "STATUSTEXT")
    assert text.text.startswith(why[:50]) and text.severity == mav.MAV_SEVERITY_WARNING
    echo = expect(conn, "PARAM_VALUE", param_id=name)
    assert echo.param_value == pytest.approx(before[name])  # as float32 on the wire
    assert values(config) == before


def test_an_unknown_name_is_ignored(link):
    _, conn = link
    conn.mav.param_set_send(1, 1, b"NO_SUCH_PARAM", 1.0, mav.MAV_PARAM_TYPE_REAL32)
    conn.mav.param_request_read_send(1, 1, b"WP_RADIUS", -1)
    assert expect(conn, "PARAM_VALUE").param_id == "WP_RADIUS"  # nothing came before it


class Recorder:
    """A pymavlink connection stand-in that keeps what is sent."""

    def __init__(self):
        self.sent = []
        self.mav = self

    def param_value_send(self, *fields):
        self.sent.append(fields)


def test_a_list_goes_out_at_the_configured_pace():
    conn, handlers = Recorder(), DefaultHandlers()
    service = ParamService(conn, handlers, rate_hz=lambda: 20.0)
    service.handle(mav.MAVLink_param_request_list_message(1, 1))
    assert conn.sent == []  # sent from the loop's tick, not inside the handler
    service.tick(100.0)
    assert len(conn.sent) == LIST_BURST
    service.tick(100.5)  # 0.5 s at 20 per second
    assert len(conn.sent) == LIST_BURST + 10
    for k in range(1, 200):
        service.tick(100.5 + k)
    assert [s[0].decode() for s in conn.sent] == [p.name for p in MAVLINK]
    service.handle(mav.MAVLink_param_request_list_message(1, 1))  # a new request starts over
    service.tick(500.0)
    assert conn.sent[-1][0].decode() == MAVLINK[LIST_BURST - 1].name


def test_a_request_while_the_list_goes_out_does_not_start_it_over():
    """A stream of PARAM_REQUEST_LIST (one per loop turn) used to restart the list every time, so
    no ground station's fetch ever finished."""
    conn, handlers = Recorder(), DefaultHandlers()
    service = ParamService(conn, handlers, rate_hz=lambda: 20.0)
    request = mav.MAVLink_param_request_list_message(1, 1)
    service.handle(request)
    now_s = 100.0
    for _ in range(10 * len(MAVLINK)):
        service.tick(now_s)
        if not service.listing:
            break
        service.handle(request)
        now_s += 0.05
    assert [s[0].decode() for s in conn.sent] == [p.name for p in MAVLINK]  # each once, in order: it finished


def test_alternating_sets_are_answered_at_once_and_written_once_per_interval(tmp_path):
    config = load_config(None, [f"gcs.mission_store_path={tmp_path / 'state' / 'mission.json'}"])
    handlers = DefaultHandlers(config)
    handlers.table = ConfigParams.persistent(config, clock=lambda: 0.0)  # what the daemon does
    conn = Recorder()
    service = ParamService(conn, handlers)
    for k in range(100):
        value = 0.5 if k % 2 else 0.8
        service.handle(mav.MAVLink_param_set_message(1, 1, b"WP_SPEED", value, mav.MAV_PARAM_TYPE_REAL32))
        name, echoed = conn.sent[-1][:2]
        assert name == b"WP_SPEED" and echoed == pytest.approx(value)  # the answer carries the new value
    assert handlers.table.writes == 1 and handlers.table.unsaved
