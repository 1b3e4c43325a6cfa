"""Pre-arm checks (each refusal says why, force-arming skips them) and mission progress as the
wire reports it: MISSION_CURRENT's mission_state and MISSION_ITEM_REACHED per item."""

from __future__ import annotations

from dataclasses import replace

import pytest
from autopilot.harness import Bench, mission, waypoint

from rover_ctl.autopilot import prearm
from rover_ctl.autopilot.events import ArmRequest, ItemReached, MissionComplete, MissionCurrent
from rover_ctl.mission.model import Mission
from rover_ctl.navigation.planner import Circle, Fence
from rover_ctl.vocabulary import Cmd, MissionState, RoverMode, mav

OK = prearm.ArmingInputs(position_en=(0.0, 0.0), estimator_healthy=True, range_ages_s={0: 0.1, 2: 0.1, 4: 0.1, 6: 0.1},
                         needed_orientations=(0, 2, 4, 6), first_waypoint_en=(10.0, 10.0), max_distance_m=1000.0)  # fmt: skip
SQUARE = ((-50.0, -50.0), (50.0, -50.0), (50.0, 50.0), (-50.0, 50.0))


@pytest.mark.parametrize(
    "change, reason",
    [
        ({"position_en": None}, "no position (waiting for GPS)"),
        ({"estimator_healthy": False}, "estimator unhealthy"),
        ({"gps_ok": False}, "no recent GPS fix"),
        ({"range_ages_s": {0: 0.1, 2: 0.1, 4: 3.0}}, "rangefinder missing: back, left"),
        ({"fence": Fence(inclusion_polygons=(SQUARE,)), "position_en": (60.0, 0.0)}, "outside the inclusion fence"),
        ({"fence": Fence(exclusion_circles=(Circle((1.0, 0.0), 3.0),))}, "inside a fence exclusion zone"),
        ({"first_waypoint_en": (3000.0, 4000.0)}, "first waypoint 5000 m from home"),
        ({"fence": Fence(exclusion_circles=(Circle((0.0, 12000.0), 5.0),))}, "fence 11995 m from home"),
        ({"fence_error": "fence item 0: circle radius 0"}, "fence unusable: fence item 0: circle radius 0"),
        ({"sensor_rates_hz": {"ATTITUDE": 10.0, "WHEEL_DISTANCE": 2.5}, "min_sensor_rate_hz": 4.0},
         "link too slow: WHEEL_DISTANCE 2.5 Hz < 4 Hz"),
        ({"planner_nodes": 2560, "max_planner_nodes": 800}, "fence too complex to plan: 2560 nodes, max 800 (PLN_CIRCLE_SEGS)"),
        ({"vehicle_params": {"PILOT_STEER_TYPE": 0.0}}, "vehicle PILOT_STEER_TYPE 0 reverses steering in reverse: set 3"),
        ({"vehicle_params": {"PILOT_STEER_TYPE": 2.0}}, "vehicle PILOT_STEER_TYPE 2 reverses steering in reverse: set 3"),
        ({"vehicle_params": {"PILOT_STEER_TYPE": 1.0}}, "vehicle PILOT_STEER_TYPE 1 reads steering and throttle as two paddles: set 3"),
    ],
)
def test_each_check_names_its_reason(change, reason):
    assert prearm.failures(OK) == []
    assert prearm.failures(replace(OK, **change)) == [reason]


def test_a_fence_around_home_is_not_far_and_several_failures_are_all_listed():
    assert prearm.failures(replace(OK, fence=Fence(inclusion_polygons=(SQUARE,)))) == []
    both = prearm.failures(replace(OK, estimator_healthy=False, range_ages_s={}))
    assert both == ["estimator unhealthy", "rangefinder missing: front, right, back, left"]


def test_arming_refused_says_prearm_and_force_skips_the_checks():
    bench = Bench()
    reply = bench.request(bench.autopilot.arm(True))
    assert reply.result == mav.MAV_RESULT_FAILED and reply.reason == "no position (waiting for GPS)"
    assert bench.texts[0] == "PreArm: no position (waiting for GPS)" and not bench.of_type(ArmRequest)
    bench.home(Mission(items=[waypoint(0.0, 2000.0)]))
    bench.step()
    reply = bench.request(bench.autopilot.arm(True))
    assert not reply.accepted and bench.texts[-1] == "PreArm: first waypoint 2000 m from home"
    assert bench.request(bench.autopilot.arm(True, force=True)).accepted
    assert bench.of_type(ArmRequest) == [ArmRequest(True, True)]


def test_arming_needs_the_rangefinders_the_rule_base_reads():
    bench = Bench()
    del bench.ranges_m[4]  # the default rule base has no input for the back: not needed
    bench.home()
    bench.step()
    assert bench.autopilot.navigator.orientations == [0, 7, 1, 6, 2]
    assert bench.request(bench.autopilot.arm(True)).accepted
    bench.request(bench.autopilot.arm(False))
    bench.step()
    del bench.ranges_m[6]
    bench.run(1.0)
    assert not bench.request(bench.autopilot.arm(True)).accepted
    assert bench.texts[-1] == "PreArm: rangefinder missing: left"


def test_ready_to_arm_says_what_an_arming_request_would_meet_and_says_nothing():
    """SYS_STATUS's pre-arm bit: the daemon's checks as arm() makes them, without their texts."""
    bench = Bench()
    assert not bench.autopilot.ready_to_arm()  # no position yet
    bench.home(Mission(items=[waypoint(0.0, 2000.0)]))
    bench.step()
    assert not bench.autopilot.ready_to_arm()  # first waypoint 2000 m from home
    bench.home(Mission(items=[waypoint(0.0, 20.0)]))
    bench.step()
    assert bench.autopilot.ready_to_arm() and not bench.texts
    bench.gps_ok = False
    bench.step()
    assert not bench.autopilot.ready_to_arm()  # no recent GPS fix
    bench.gps_ok = True
    bench.step()
    assert bench.request(bench.autopilot.arm(True)).accepted
    bench.autopilot.on_vehicle(True)
    bench.gps_ok = False
    bench.step()
    assert bench.autopilot.ready_to_arm()  # armed: ready, as ArduPilot reports it


def test_arming_waits_for_a_fresh_gps_fix():
    bench = Bench()
    bench.home()
    bench.gps_ok = False  # a dropout after home was set: the estimator still has a position
    bench.step()
    reply = bench.request(bench.autopilot.arm(True))
    assert reply.result == mav.MAV_RESULT_FAILED and reply.reason == "no recent GPS fix"
    assert bench.texts[-1] == "PreArm: no recent GPS fix" and not bench.of_type(ArmRequest)
    bench.gps_ok = True
    bench.step()
    assert bench.request(bench.autopilot.arm(True)).accepted


def test_arming_inside_an_exclusion_zone_is_refused():
    bench = Bench()
    zone = [replace(waypoint(0.0, 1.0, Cmd.NAV_FENCE_CIRCLE_EXCLUSION), param1=5.0)]
    bench.home(Mission(fence=zone))
    bench.step()
    assert not bench.request(bench.autopilot.arm(True)).accepted
    assert bench.texts[-1] == "PreArm: inside a fence exclusion zone"


def states(bench: Bench) -> list[tuple[int, str]]:
    return [(e.seq, e.state.name) for e in bench.of_type(MissionCurrent)]


def test_mission_state_through_a_mission():
    bench = Bench()
    bench.home()
    assert bench.autopilot.state().mission_state == MissionState.NO_MISSION
    bench.ready(mission((0.0, 6.0), (0.0, 12.0)))
    assert bench.autopilot.state().mission_state == MissionState.NOT_STARTED
    assert bench.request(bench.autopilot.mission_start()).accepted
    bench.run(2.0)
    bench.autopilot.set_mode(RoverMode.HOLD)
    bench.step()
    assert bench.autopilot.state().mission_state == MissionState.PAUSED
    bench.autopilot.set_mode(RoverMode.AUTO)
    assert bench.run(60.0, until=lambda b: b.autopilot.state().mission_state == MissionState.COMPLETE)
    assert [e.seq for e in bench.of_type(ItemReached)] == [1, 2]
    assert [e.seq for e in bench.of_type(MissionComplete)] == [2]
    seen = states(bench)
    assert seen[0] == (0, "NO_MISSION")
    for expected in [(1, "NOT_STARTED"), (1, "ACTIVE"), (1, "PAUSED"), (2, "ACTIVE"), (2, "COMPLETE")]:
        assert expected in seen
    assert seen.index((1, "PAUSED")) < seen.index((2, "COMPLETE"))
    assert bench.autopilot.mode == RoverMode.HOLD
    # AUTO again restarts a completed mission; clearing it reports NO_MISSION.
    bench.autopilot.set_mode(RoverMode.AUTO)
    bench.step()
    assert bench.autopilot.state().mission_state == MissionState.ACTIVE and bench.autopilot.state().current_seq == 1
    bench.autopilot.mission_changed(Mission(), 0)
    bench.collect(bench.autopilot.drain())
    assert states(bench)[-1] == (0, "NO_MISSION")


def test_mission_current_is_emitted_on_change_not_every_step():
    bench = Bench()
    bench.ready(mission((0.0, 30.0)))
    bench.autopilot.mission_start()
    bench.run(5.0)
    currents = [(e.seq, e.state) for e in bench.of_type(MissionCurrent)]
    assert currents[-1] == (1, MissionState.ACTIVE)
    assert all(a != b for a, b in zip(currents, currents[1:])) and len(currents) <= 4  # 125 steps, no repeats


def test_mission_resumes_at_the_stored_item_after_a_restart():
    """MIS_RESTART 0: a daemon started again resumes at the item the stored mission was on."""
    bench = Bench()
    bench.autopilot.mission_changed(mission((0.0, 6.0), (0.0, 12.0), (0.0, 18.0)), 0)
    bench.autopilot.resume_from(2)  # before home: applied once the executor exists
    bench.ready()
    assert bench.autopilot.mode == RoverMode.HOLD and bench.autopilot.executor.current_seq == 2
    assert bench.request(bench.autopilot.set_mode(RoverMode.AUTO)).accepted
    assert bench.run(60.0, until=lambda b: b.autopilot.state().mission_state == MissionState.COMPLETE)
    assert [e.seq for e in bench.of_type(ItemReached)] == [2, 3]  # item 1 was done before the restart


def test_mis_restart_1_starts_over_on_entering_auto():
    bench = Bench()
    bench.config.autopilot.mission_restart = 1
    bench.autopilot.mission_changed(mission((0.0, 6.0), (0.0, 12.0)), 0)
    bench.autopilot.resume_from(2)  # ignored: MIS_RESTART 1
    bench.ready()
    assert bench.autopilot.executor.current_seq == 1
    bench.autopilot.executor.set_current(2)
    assert bench.request(bench.autopilot.set_mode(RoverMode.AUTO)).accepted
    assert bench.autopilot.executor.current_seq == 1
