"""Missions end to end: emulator and daemon as separate processes, lockstep, the test as the GCS."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import pytest
from pymavlink import mavutil

from rover_ctl.estimation.frame import LocalFrame
from rover_ctl.app.report import read_jsonl
from rover_ctl.app.sim import SimOptions, SimRun, simulate
from rover_ctl.vocabulary import MissionState, RoverMode

ROOT = Path(__file__).resolve().parents[2]
JUMP = ROOT / "missions" / "cmac_jump.waypoints"
HOME = (-35.363261, 149.165230, 584.0)
MODE_RTL = 11

pytestmark = pytest.mark.sitl


def world_with_circle(path: Path, east_m: float, north_m: float, radius_m: float) -> Path:
    frame = LocalFrame(*HOME)
    lat, lon = frame.to_geodetic(east_m, north_m)
    world = {
        "type": "FeatureCollection",
        "home": [HOME[1], HOME[0], HOME[2], 0.0],
        "features": [{"type": "Feature", "geometry": {"type": "Point", "coordinates": [lon, lat]},
                      "properties": {"id": "drum", "radius_m": radius_m}}],
    }  # fmt: skip
    path.write_text(json.dumps(world))
    return path


def truth_states(out: Path) -> list[dict]:
    return [r for r in read_jsonl(out / "truth.jsonl") if r["type"] == "state"]


def test_jump_mission_completes_around_an_obstacle(tmp_path):
    """cmac_jump: WP1, WP2, DO_JUMP back to WP1 once, WP4 home; a drum sits on the WP1-WP2 leg."""
    world = world_with_circle(tmp_path / "drum.geojson", 7.5, 15.0, 0.5)
    out = tmp_path / "run"
    metrics = simulate(SimOptions(mission=JUMP, out=out, world=world, timeout_s=150.0), plots=False)

    assert metrics["success"], metrics
    assert metrics["collisions"] == 0
    assert metrics["waypoints_reached"] == metrics["waypoints_total"] == 3
    events = read_jsonl(out / "events.jsonl")
    assert [e["seq"] for e in events if e["type"] == "reached"] == [1, 2, 1, 2, 4]  # the jump, taken once
    # Lockstep over TCP loses nothing, and the link health says so (the markers number apart).
    assert [e["lost"] for e in events if e["type"] == "link"][-1] == 0
    # The drum was on the way (the rover passed near it) and the rover went around it.
    frame = LocalFrame(*HOME)
    clearance = min(
        math.dist(frame.to_enu(s["lat_deg"], s["lon_deg"]), (7.5, 15.0)) for s in truth_states(out)
    )
    assert 0.5 < clearance < 3.0
    # Ended at home (the last waypoint), within the acceptance radius.
    last = truth_states(out)[-1]
    assert math.dist(frame.to_enu(last["lat_deg"], last["lon_deg"]), (0.0, 0.0)) < 2.5

    # Both links' telemetry logs read back with pymavlink.
    log = mavutil.mavlink_connection(str(out / "vehicle.tlog"))
    kinds = set()
    while (msg := log.recv_match()) is not None:
        kinds.add(msg.get_type())
    assert {"HEARTBEAT", "WHEEL_DISTANCE", "DISTANCE_SENSOR", "GPS_RAW_INT", "RC_CHANNELS_OVERRIDE", "TIMESYNC"} <= kinds
    gcs = mavutil.mavlink_connection(str(out / "gcs.tlog"))
    reached = [m.seq for m in iter(lambda: gcs.recv_match(type="MISSION_ITEM_REACHED"), None)]
    assert reached == [1, 2, 1, 2, 4]
    assert metrics["loop_latency_p99_ms"] is not None and metrics["path_length_m"] > 50


def download_params(run: SimRun, wall_timeout_s: float = 30.0) -> dict[str, float]:
    """What a ground station's parameter download (MAVProxy and QGC ask on connect) gets back."""
    run.gcs.conn.mav.param_request_list_send(*run.gcs.target)
    values: dict[str, float] = {}
    deadline = time.monotonic() + wall_timeout_s
    while time.monotonic() < deadline:
        msg = run.gcs.conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.2)
        if msg is not None:
            values[msg.param_id] = msg.param_value
            if len(values) == msg.param_count:
                break
    return values


def test_hold_stops_quickly_and_rtl_returns_home(tmp_path):
    out = tmp_path / "run"
    with SimRun(SimOptions(mission=JUMP, out=out, timeout_s=120.0)) as run:
        params = download_params(run)
        assert {"SYSID_THISMAV", "WP_RADIUS"} <= params.keys() and params["SYSID_THISMAV"] == 1
        run.arm()
        run.start_mission()
        assert run.wait_for(lambda p: 1 in p.reached, sim_timeout_s=60.0)
        # Up to speed on the next leg, 15 m east: past the corner's pivot turn, 3 m along it.
        assert run.wait_for(lambda p: p.position_en is not None and p.position_en[0] > 3.0, sim_timeout_s=30.0)
        assert run.set_mode(RoverMode.HOLD) == mavutil.mavlink.MAV_RESULT_ACCEPTED
        assert run.wait_for(lambda p: p.mode == RoverMode.HOLD, wall_timeout_s=10.0)  # heartbeats are 1 Hz wall
        assert run.wait_for(lambda p: False, sim_timeout_s=2.0) is False
        assert run.set_mode(MODE_RTL) == mavutil.mavlink.MAV_RESULT_ACCEPTED
        home = LocalFrame(*HOME)
        # Home is reached within rtl_radius_m (2 m) of the daemon's home, its first GPS fix, by its
        # estimate: each of the two is about a metre off the truth.
        near_home_m = 4.0
        assert run.wait_for(lambda p: p.position_en is not None and math.dist(p.position_en, (0, 0)) < near_home_m, sim_timeout_s=60.0)
        assert run.wait_for(lambda p: False, sim_timeout_s=3.0) is False  # settles at home
        # MANUAL: the daemon hands the RC channels back to the radio and stops overriding.
        assert run.set_mode(RoverMode.MANUAL) == mavutil.mavlink.MAV_RESULT_ACCEPTED
        assert run.wait_for(lambda p: False, sim_timeout_s=2.0) is False

    events = read_jsonl(out / "events.jsonl")
    hold_s = next(e["t_s"] for e in events if e["type"] == "mode" and e["name"] == "HOLD")
    states = truth_states(out)
    before = [s["speed_mps"] for s in states if hold_s - 0.5 <= s["t_s"] <= hold_s]
    after = [s["speed_mps"] for s in states if hold_s + 0.5 <= s["t_s"] <= hold_s + 2.0]
    assert max(before) > 0.5  # it was driving
    assert max(abs(v) for v in after) < 0.05  # and stood still from 0.5 s of sim time after HOLD
    last = states[-1]
    # RTL stops within rtl_radius_m of the daemon's home (its first fix) by its estimate, which
    # follows the GPS's slowly wandering bias: compare where the GPS, less its white noise, puts
    # the rover with that home. (The truth alone drifts with the bias: 3.1 m in 340 s of sim time,
    # and how much sim time passes depends on how fast lockstep runs while the ground station's
    # parameter download and mode changes take their wall time.)
    first_fix = next(e for e in events if e["type"] == "frame")
    daemon_home_en = home.to_enu(first_fix["lat_deg"], first_fix["lon_deg"])
    bias = [r for r in read_jsonl(out / "truth.jsonl") if r["type"] == "gps"][-1]
    east, north = home.to_enu(last["lat_deg"], last["lon_deg"])
    seen_en = (east + bias["err_bias_e_m"], north + bias["err_bias_n_m"])
    assert math.dist(seen_en, daemon_home_en) < 2.0 + 1.0  # RTL_RADIUS, and the estimate's own error
    assert abs(last["speed_mps"]) < 0.05
    log = mavutil.mavlink_connection(str(out / "vehicle.tlog"))
    overrides = [(m.chan1_raw, m.chan3_raw) for m in iter(lambda: log.recv_match(type="RC_CHANNELS_OVERRIDE"), None)]
    # Released once, then silent until the stop's single neutral.
    assert overrides[-2:] == [(0, 0), (1500, 1500)] and overrides.count((0, 0)) == 1


def test_the_ground_station_hears_the_vehicles_answer_to_arming(tmp_path):
    """Arming that passes the daemon's checks goes on to the vehicle, whose own checks decide:
    rover-sitl refuses without a 3D fix (ARMING_CHECK 1), ArduPilot on its pre-arm checks. The
    ground station's COMMAND_ACK is the vehicle's answer (it was ACCEPTED as soon as the daemon
    forwarded the request, and the rover stayed disarmed in AUTO with nothing to retry on); with
    the fix back the same command arms. The daemon's own GPS check is given a long window here so
    that the vehicle's check is the one that decides."""
    from rover_ctl.vocabulary import mav
    from sitl.mavlink_vehicle import GPS_TIMEOUT_S

    options = SimOptions(mission=JUMP, out=tmp_path / "run", timeout_s=60.0, config_overrides=["estimator.gps_timeout_s=60"])
    with SimRun(options) as run:
        assert run.wait_for(lambda p: p.position_en is not None, wall_timeout_s=30.0)
        assert run.wait_for(lambda p: False, sim_timeout_s=3.0) is False  # the rangefinders known
        run.sitl_param("SIM_GPS_DISABLE", 1)
        # The vehicle's fix is gone once its last one is older than ArduPilot's GPS timeout.
        assert run.wait_for(lambda p: False, sim_timeout_s=GPS_TIMEOUT_S + 1.0) is False
        assert run.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mav.MAV_RESULT_FAILED
        assert any(t.startswith("Vehicle refused arming") for t in run.progress.texts)
        # The vehicle's own reason is passed on (CRITICAL, as ArduPilot sends its PreArm texts).
        assert run.wait_for(lambda p: "PreArm: GPS 1: Bad fix" in p.texts, wall_timeout_s=5.0)
        run.sitl_param("SIM_GPS_DISABLE", 0)
        assert run.wait_for(lambda p: False, sim_timeout_s=1.0) is False
        assert run.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mav.MAV_RESULT_ACCEPTED
        assert run.wait_for(lambda p: p.armed, wall_timeout_s=10.0)


def test_an_accepted_arming_drives_at_once_not_at_the_next_heartbeat(tmp_path):
    """In AUTO, disarmed, then armed: the vehicle's ACCEPTED answer means it has armed, so the
    daemon drives from that frame on. It used to wait for the vehicle's next HEARTBEAT (1 Hz)
    saying so, up to a second later, a delay that also moved a lockstep run's encounter with an
    obstacle that starts moving at arming by up to a second of its walk."""
    import csv

    from rover_ctl.vocabulary import mav

    with SimRun(SimOptions(mission=JUMP, out=tmp_path / "run", timeout_s=60.0)) as run:
        assert run.wait_for(lambda p: p.position_en is not None, wall_timeout_s=30.0)
        assert run.wait_for(lambda p: False, sim_timeout_s=3.0) is False  # the rangefinders known
        run.start_mission()
        run.arm()
        assert run.wait_for(lambda p: False, sim_timeout_s=3.0) is False
    out = tmp_path / "run"
    tlog = mavutil.mavlink_connection(str(out / "vehicle.tlog"))
    offset_s = ack_s = armed_heartbeat_s = None
    while (msg := tlog.recv_match()) is not None:  # in lockstep, tlog stamps are vehicle time plus one offset
        if msg.get_srcSystem() != 1:
            continue
        kind = msg.get_type()
        if kind == "ATTITUDE" and ack_s is None:
            offset_s = msg._timestamp - msg.time_boot_ms / 1e3
        elif kind == "COMMAND_ACK" and msg.command == mav.MAV_CMD_COMPONENT_ARM_DISARM and msg.result == mav.MAV_RESULT_ACCEPTED:
            ack_s = msg._timestamp
        elif kind == "HEARTBEAT" and ack_s is not None and msg.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED:
            armed_heartbeat_s = msg._timestamp
            break
    assert None not in (offset_s, ack_s, armed_heartbeat_s), (offset_s, ack_s, armed_heartbeat_s)
    ack_s, armed_heartbeat_s = ack_s - offset_s, armed_heartbeat_s - offset_s
    rows = list(csv.DictReader((out / "control.csv").open()))
    armed_s = next(float(r["t_s"]) for r in rows if r["armed"] == "1")
    throttle = next(r for r in rows if float(r["t_s"]) >= armed_s and r["throttle_us"])
    assert ack_s - 0.02 <= armed_s <= ack_s + 0.1, (ack_s, armed_s, armed_heartbeat_s)
    assert float(throttle["t_s"]) <= ack_s + 0.1 and int(throttle["throttle_us"]) > 1500, throttle


@pytest.mark.parametrize("arm", [True, False])
def test_an_accepted_arming_is_taken_in_stream_order_with_the_heartbeats_read_with_it(arm):
    """The ACK's callback runs while the link decodes, before the items read with it are handled:
    a heartbeat the vehicle sent just before it armed (or disarmed), read in the same batch, undid
    the ACCEPTED until the next heartbeat, a second later. Now the ACK's own item applies it."""
    from rover_ctl.app.daemon import Daemon
    from rover_ctl.config import Config
    from rover_ctl.mavlink.vehicle import CommandResult, VehicleStatus
    from rover_ctl.vocabulary import mav

    from types import SimpleNamespace

    daemon = Daemon(Config())
    answered = []
    daemon.gcs = SimpleNamespace(command_result=lambda command, result: answered.append(result))  # no GCS link
    daemon.autopilot.on_vehicle(not arm)
    accepted = CommandResult(mav.MAV_CMD_COMPONENT_ARM_DISARM, mav.MAV_RESULT_ACCEPTED)
    daemon._arm_results[arm](accepted)  # the link decoded the ACK: items [heartbeat before it, ACK]
    for item in (VehicleStatus(0.0, not arm, RoverMode.HOLD, 3), accepted):
        daemon._on_item(item)
    assert daemon.autopilot.armed is arm
    daemon._on_item(VehicleStatus(1.0, arm, RoverMode.HOLD, 3))  # the next heartbeat agrees; nothing left over
    daemon._on_item(CommandResult(mav.MAV_CMD_COMPONENT_ARM_DISARM, mav.MAV_RESULT_ACCEPTED))
    assert daemon.autopilot.armed is arm and daemon._arm_accepted is None and answered == [mav.MAV_RESULT_ACCEPTED]


def test_the_daemon_refuses_arming_without_a_recent_fix(tmp_path):
    """The daemon's own pre-arm check: after a GPS dropout its estimator still has a position
    (dead reckoning), but arming now would start the mission blind; refused with its reason,
    without asking the vehicle. Its SYS_STATUS pre-arm bit (a ground station's "ready" light)
    says so before anyone tries."""
    from rover_ctl.vocabulary import mav

    with SimRun(SimOptions(mission=JUMP, out=tmp_path / "run", timeout_s=60.0)) as run:
        assert run.wait_for(lambda p: p.position_en is not None, wall_timeout_s=30.0)
        # SYS_STATUS comes at its wall-clock rate (1 Hz), many sim seconds apart in lockstep
        assert run.wait_for(lambda p: p.ready_to_arm, wall_timeout_s=5.0)  # the rangefinders known, the fix recent
        run.sitl_param("SIM_GPS_DISABLE", 1)
        assert run.wait_for(lambda p: p.ready_to_arm is False, wall_timeout_s=5.0)  # past gps_timeout_s (1 s)
        assert run.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mav.MAV_RESULT_FAILED
        assert run.wait_for(lambda p: "PreArm: no recent GPS fix" in p.texts, wall_timeout_s=5.0)
        assert not any(t.startswith("Vehicle refused arming") for t in run.progress.texts)


def test_cancelling_stops_runs_on_other_threads_and_their_children(tmp_path):
    """A program running several simulations on threads (the navigation benchmark) gets Ctrl-C or
    SIGTERM on its main thread only: SimRun.cancelled makes every run give up at its next check
    and stop its emulator and daemon (they outlived a killed benchmark)."""
    import threading

    runs: list[SimRun] = []
    errors: list[Exception] = []

    def drive() -> None:
        try:
            with SimRun(SimOptions(mission=JUMP, out=tmp_path / "run", timeout_s=600.0)) as run:
                runs.append(run)
                run.arm()
                run.start_mission()
                run.wait_for(lambda p: p.mission_state == MissionState.COMPLETE, wall_timeout_s=60.0)
        except Exception as exc:  # noqa: BLE001 - the test looks at it
            errors.append(exc)

    worker = threading.Thread(target=drive)
    worker.start()
    try:
        deadline = time.monotonic() + 30.0
        while not runs and time.monotonic() < deadline:
            time.sleep(0.05)
        assert runs, "the run did not start"
        SimRun.cancelled.set()
        worker.join(30.0)
    finally:
        SimRun.cancelled.clear()
    assert not worker.is_alive()
    assert [str(e) for e in errors] == ["cancelled"]
    assert runs[0].sitl.poll() is not None and runs[0].daemon.poll() is not None


def test_emulator_ports_taken_before_it_binds_them_are_replaced(tmp_path):
    """The same race for the emulator's ports (vehicle link and watcher): it exits 69 and the run
    starts it again on new ones."""
    import socket

    run = SimRun(SimOptions(mission=JUMP, out=tmp_path / "run", timeout_s=60.0))
    taken = run.vehicle_port, run.watch_port
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as vehicle_thief, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as watch_thief:  # fmt: skip
        vehicle_thief.bind(("127.0.0.1", taken[0]))
        vehicle_thief.listen(1)
        watch_thief.bind(("127.0.0.1", taken[1]))
        with run:
            assert run.vehicle_port != taken[0] and run.watch_port != taken[1]
            assert run.sitl.poll() is None and run.daemon.poll() is None
            assert "SYSID_THISMAV" in download_params(run)  # the mission went up and the daemon answers


def test_a_gcs_port_taken_before_the_daemon_binds_it_is_replaced(tmp_path):
    """`rover-ctl sim` picks the daemon's GCS port free, then the daemon binds it: a process beside
    it (a second simulation) can take it in between. The daemon then exits 69 (a link could not be
    opened) and the run starts it again on another port, instead of failing."""
    import socket

    run = SimRun(SimOptions(mission=JUMP, out=tmp_path / "run", timeout_s=60.0))
    taken = run.gcs_port
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as thief:
        thief.bind(("127.0.0.1", taken))
        with run:
            assert run.gcs_port != taken and run.gcs_url.endswith(f":{run.gcs_port}")
            assert run.daemon.poll() is None
            assert "SYSID_THISMAV" in download_params(run)  # the mission went up (start) and the daemon answers
