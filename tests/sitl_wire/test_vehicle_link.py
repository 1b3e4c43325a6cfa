"""The emulator's vehicle side over a real TCP socket, in lockstep (sim-time rates, no wall-clock waits)."""

from __future__ import annotations

import json
import math

import pytest
from support.sitl import collect, lockstep_client, of_type, rover_sitl

from sitl.endpoints import mavlink

pytestmark = pytest.mark.sitl

HOME = (-35.363261, 149.165230)
M_PER_DEG_LAT = 111_320.0


@pytest.fixture
def client():
    with rover_sitl("--lockstep", "--seed", "7") as sitl:
        c = lockstep_client(sitl.url)
        yield c
        c.close()


def north_east_m(simstate) -> tuple[float, float]:
    north = (simstate.lat / 1e7 - HOME[0]) * M_PER_DEG_LAT
    east = (simstate.lng / 1e7 - HOME[1]) * M_PER_DEG_LAT * math.cos(math.radians(HOME[0]))
    return north, east


def test_heartbeat_identity_and_modes(client) -> None:
    beats = of_type(collect(client, 1.0), "HEARTBEAT")
    assert beats, "no HEARTBEAT in 1 sim second"
    hb = beats[-1]
    assert (hb.type, hb.autopilot, hb.custom_mode) == (mavlink.MAV_TYPE_GROUND_ROVER, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0)
    assert hb.base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED and not hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED

    custom = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert client.command(mavlink.MAV_CMD_DO_SET_MODE, custom, 4) == mavlink.MAV_RESULT_ACCEPTED
    assert of_type(collect(client, 1.1), "HEARTBEAT")[-1].custom_mode == 4
    assert client.command(mavlink.MAV_CMD_DO_SET_MODE, custom, 10) == mavlink.MAV_RESULT_FAILED  # AUTO: not emulated
    client.conn.mav.set_mode_send(1, custom, 0)
    received = collect(client, 1.1)
    assert [a.result for a in of_type(received, "COMMAND_ACK") if a.command == mavlink.MAVLINK_MSG_ID_SET_MODE] == [0]
    assert of_type(received, "HEARTBEAT")[-1].custom_mode == 0
    assert client.command(mavlink.MAV_CMD_NAV_LOITER_UNLIM) == mavlink.MAV_RESULT_UNSUPPORTED


def test_arming_refused_without_gps_fix_then_forced() -> None:
    with rover_sitl("--lockstep", "--param", "SIM_GPS_DISABLE=1") as sitl:
        c = lockstep_client(sitl.url)
        assert c.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_FAILED
        received = collect(c, 1.1)
        assert any(t.text.startswith("PreArm") for t in of_type(received, "STATUSTEXT"))
        assert not of_type(received, "HEARTBEAT")[-1].base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        c.arm(force=True)
        assert of_type(collect(c, 1.1), "HEARTBEAT")[-1].base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        assert c.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0) == mavlink.MAV_RESULT_ACCEPTED
        c.close()


def test_sensor_rates_and_plausibility(client) -> None:
    client.arm()
    received = collect(client, 4.0)
    arming_s = received[0][0]  # the frames stepped while arming come with the first one: left out
    received = [(t_s, m) for t_s, m in received if t_s > arming_s]
    seconds = 4.0
    counts = {kind: len(of_type(received, kind)) for kind in
              ("ATTITUDE", "WHEEL_DISTANCE", "GPS_RAW_INT", "SERVO_OUTPUT_RAW", "SIMSTATE", "HEARTBEAT", "SYS_STATUS")}
    expected_hz = {"ATTITUDE": 50, "WHEEL_DISTANCE": 50, "GPS_RAW_INT": 5, "SERVO_OUTPUT_RAW": 10, "SIMSTATE": 10,
                   "HEARTBEAT": 1, "SYS_STATUS": 1}
    for kind, hz in expected_hz.items():
        assert abs(counts[kind] - hz * seconds) <= 1, (kind, counts[kind])
    ranges = of_type(received, "DISTANCE_SENSOR")
    by_sensor = {}
    for r in ranges:
        by_sensor.setdefault(r.id, []).append(r)
    assert sorted({r.orientation for r in ranges}) == [0, 1, 2, 4, 6, 7]
    for readings in by_sensor.values():
        assert abs(len(readings) - 20 * seconds) <= 1
        assert all(r.min_distance <= r.current_distance <= r.max_distance + 1 for r in readings)

    gps = of_type(received, "GPS_RAW_INT")
    assert all(g.fix_type >= 3 for g in gps[1:])
    for g in gps:
        if g.fix_type >= 3:
            assert abs(g.lat / 1e7 - HOME[0]) * M_PER_DEG_LAT < 10 and abs(g.lon / 1e7 - HOME[1]) * M_PER_DEG_LAT < 10
    times = [t for t, m in received if m.get_type() == "GPS_RAW_INT"]
    assert [g.time_usec for g in gps] == [round(t * 1e6) for t in times]  # time_usec is sim time
    yaws = [a.yaw for a in of_type(received, "ATTITUDE")]
    assert max(abs(y) for y in yaws) < math.radians(10)  # home heading 0 = north
    wheels = of_type(received, "WHEEL_DISTANCE")
    assert wheels[-1].count == 2 and abs(wheels[-1].distance[0]) < 0.05  # standing still
    assert of_type(received, "SYS_STATUS")[-1].voltage_battery > 10_000


def test_override_drives_forward_and_turns(client) -> None:
    client.arm()
    start = north_east_m(of_type(collect(client, 0.2), "SIMSTATE")[-1])
    received = collect(client, 3.0, lambda t: (1800, 1500))
    north, east = north_east_m(of_type(received, "SIMSTATE")[-1])
    assert north - start[0] > 1.5 and abs(east - start[1]) < 0.3  # heading 0: straight north
    assert of_type(received, "SERVO_OUTPUT_RAW")[-1].servo1_raw == 1785
    wheel = of_type(received, "WHEEL_DISTANCE")[-1]
    assert wheel.distance[0] > 1.5 and wheel.distance[1] > 1.5

    def mean_yaw_rate_dps(steering_us: int) -> float:
        rates = [a.yawspeed for a in of_type(collect(client, 1.0, lambda t: (1700, steering_us)), "ATTITUDE")]
        return math.degrees(sum(rates[25:]) / len(rates[25:]))  # after the motors settle

    assert mean_yaw_rate_dps(1650) > 20  # steering right: clockwise, NED yaw rate positive
    assert mean_yaw_rate_dps(1350) < -20


def test_override_times_out_and_needs_sysid_mygcs(client) -> None:
    client.arm()
    received = collect(client, 2.0, lambda t: (1800, 1500) if t < 0.1 else None)
    servo = [(t, m.servo1_raw) for t, m in received if m.get_type() == "SERVO_OUTPUT_RAW"]
    assert any(pwm == 1785 for t, pwm in servo if t < 0.9)
    assert all(pwm == 1500 for t, pwm in servo if t > 1.2)  # 1 s RC_OVERRIDE_TIME, then neutral
    speed = of_type(collect(client, 1.0), "WHEEL_DISTANCE")
    assert abs(speed[-1].distance[0] - speed[0].distance[0]) < 0.02  # stopped

    client.conn.mav.srcSystem = 254  # not SYSID_MYGCS: ignored
    received = collect(client, 1.0, lambda t: (1900, 1500))
    assert all(m.servo1_raw == 1500 for m in of_type(received, "SERVO_OUTPUT_RAW"))


def test_rc_override_time_minus_1_never_times_out_and_0_turns_overrides_off(client) -> None:
    """ArduPilot's meanings of the two special values (scripts set -1 to drive without refreshing)."""
    client.arm()
    client.set_param("RC_OVERRIDE_TIME", -1)
    received = collect(client, 2.0, lambda t: (1800, 1500) if t < 0.1 else None)
    assert all(m.servo1_raw == 1785 for t, m in received if m.get_type() == "SERVO_OUTPUT_RAW" and t > 0.2)
    client.set_param("RC_OVERRIDE_TIME", 0)
    received = collect(client, 1.0, lambda t: (1800, 1500))
    assert all(m.servo1_raw == 1500 for t, m in received if m.get_type() == "SERVO_OUTPUT_RAW" and t > 0.2)


def test_hold_and_disarm_stop_the_motors(client) -> None:
    client.arm()
    assert of_type(collect(client, 0.5, lambda t: (1800, 1500)), "SERVO_OUTPUT_RAW")[-1].servo3_raw == 1785
    client.command(mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4)
    assert of_type(collect(client, 0.5, lambda t: (1800, 1500)), "SERVO_OUTPUT_RAW")[-1].servo3_raw == 1500


def test_message_intervals_and_streams(client) -> None:
    assert client.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_ATTITUDE, 100_000) == 0
    assert client.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_WHEEL_DISTANCE, 100_000) \
        == mavlink.MAV_RESULT_FAILED  # ArduPilot: only via the EXTRA1 stream
    client.conn.mav.request_data_stream_send(1, 1, mavlink.MAV_DATA_STREAM_EXTRA1, 4, 1)
    client.conn.mav.request_data_stream_send(1, 1, mavlink.MAV_DATA_STREAM_EXTRA3, 0, 0)
    collect(client, 0.3)
    received = collect(client, 2.0)
    assert abs(len(of_type(received, "WHEEL_DISTANCE")) - 8) <= 1
    assert abs(len(of_type(received, "ATTITUDE")) - 8) <= 1  # EXTRA1 also carries ATTITUDE, now 4 Hz
    assert not of_type(received, "DISTANCE_SENSOR")
    assert client.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION) == 0
    assert of_type(collect(client, 0.1), "AUTOPILOT_VERSION")


def test_params_and_gps_disable_fault(client) -> None:
    client.conn.mav.param_request_list_send(1, 1)
    names = {p.param_id for p in of_type(collect(client, 0.2), "PARAM_VALUE")}
    assert {"SYSID_MYGCS", "RC_OVERRIDE_TIME", "SIM_GPS_DISABLE", "SIM_LINK_LOSS"} <= names
    assert all(g.fix_type >= 3 for g in of_type(collect(client, 1.0), "GPS_RAW_INT")[1:])
    client.set_param("SIM_GPS_DISABLE", 1)
    received = collect(client, 1.0)
    assert [p.param_value for p in of_type(received, "PARAM_VALUE")] == [1.0]
    assert any("SIM_GPS_DISABLE" in t.text for t in of_type(received, "STATUSTEXT"))
    assert all(g.fix_type < 3 for g in of_type(collect(client, 1.0), "GPS_RAW_INT"))
    client.set_param("SIM_LINK_LOSS", 250)  # out of range: refused, value unchanged
    received = collect(client, 0.2)
    assert [p.param_value for p in of_type(received, "PARAM_VALUE")] == [0.0]
    client.set_param("SIM_GPS_GLITCH_X", 1e6)  # farther than a world reaches: refused as a world file's glitch is
    received = collect(client, 0.2)
    assert [p.param_value for p in of_type(received, "PARAM_VALUE")] == [0.0]
    assert any("SIM_GPS_GLITCH_X" in t.text for t in of_type(received, "STATUSTEXT"))


def test_nan_and_out_of_range_values_are_refused_and_the_emulator_lives_on(client) -> None:
    """Each of these raised in the emulator (int() of NaN or inf) and ended it."""
    client.set_param("SYSID_MYGCS", math.nan)
    received = collect(client, 0.2)
    assert [p.param_value for p in of_type(received, "PARAM_VALUE")] == [255.0]  # refused, old value echoed
    assert any("SYSID_MYGCS" in t.text for t in of_type(received, "STATUSTEXT"))
    custom = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert client.command(mavlink.MAV_CMD_DO_SET_MODE, custom, math.nan) == mavlink.MAV_RESULT_FAILED
    assert client.command(mavlink.MAV_CMD_REQUEST_MESSAGE, math.inf) == mavlink.MAV_RESULT_FAILED
    assert client.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_ATTITUDE, math.nan) == mavlink.MAV_RESULT_FAILED
    assert client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, math.nan) == mavlink.MAV_RESULT_ACCEPTED
    assert of_type(collect(client, 1.1), "HEARTBEAT")


def test_collision_reported_on_link_and_in_truth_log(tmp_path) -> None:
    lat = HOME[0] + 2.5 / M_PER_DEG_LAT
    world = {"type": "FeatureCollection", "home": [HOME[1], HOME[0], 584.0, 0.0], "features": [
        {"type": "Feature", "geometry": {"type": "Point", "coordinates": [HOME[1], lat]},
         "properties": {"id": "post", "radius_m": 0.4}}]}
    (tmp_path / "w.geojson").write_text(json.dumps(world))
    truth_path = tmp_path / "truth.jsonl"
    with rover_sitl("--lockstep", "--world", str(tmp_path / "w.geojson"), "--truth-log", str(truth_path)) as sitl:
        c = lockstep_client(sitl.url)
        c.arm()
        received = collect(c, 5.0, lambda t: (1800, 1500))
        c.close()
    assert any(t.text == "Collision with post" for t in of_type(received, "STATUSTEXT"))
    front = [r.current_distance for r in of_type(received, "DISTANCE_SENSOR") if r.orientation == 0]
    assert min(front) < 100  # the front rangefinder saw it coming
    records = [json.loads(line) for line in truth_path.read_text().splitlines()]
    collisions = [r for r in records if r["type"] == "collision"]
    assert len(collisions) == 1 and collisions[0]["obstacle"] == "post"
    assert {"state", "gps"} <= {r["type"] for r in records}


def _scripted_truth(tmp_path, name: str) -> str:
    truth_path = tmp_path / name
    with rover_sitl("--lockstep", "--seed", "11", "--truth-log", str(truth_path)) as sitl:
        c = lockstep_client(sitl.url)
        c.arm()
        collect(c, 4.0, lambda t: (1750, 1500) if t < 2 else (1600, 1900))
        c.close()
    assert sitl.returncode == 0
    return truth_path.read_text()


def test_lockstep_runs_are_deterministic(tmp_path) -> None:
    first = _scripted_truth(tmp_path, "a.jsonl")
    assert first == _scripted_truth(tmp_path, "b.jsonl")
    assert '"type":"state"' in first and len(first.splitlines()) > 60
