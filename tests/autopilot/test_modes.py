"""Every mode transition of the pure autopilot, accepted and refused (with the reason said), driven
in a closed loop with a kinematic rover: no sockets, no clock."""

from __future__ import annotations

import math

import pytest
from autopilot.harness import Bench, latlon, mission

from rover_ctl.autopilot.events import ArmRequest, ModeChanged, PlanMade
from rover_ctl.autopilot.modes import ModeContext, refusal, unsupported
from rover_ctl.vocabulary import RoverMode, mav

ALL = list(RoverMode)


def mode_names(bench: Bench) -> list[str]:
    return [e.mode.name for e in bench.of_type(ModeChanged)]


@pytest.mark.parametrize("target", ALL, ids=lambda m: m.name)
@pytest.mark.parametrize("start", ALL, ids=lambda m: m.name)
def test_every_transition_between_modes_is_accepted_with_a_position_and_a_mission(start, target):
    bench = Bench()
    bench.ready(mission((0.0, 20.0)))
    assert bench.request(bench.autopilot.set_mode(start)).accepted
    bench.run(0.2)
    reply = bench.request(bench.autopilot.set_mode(target))
    assert reply.accepted and bench.autopilot.mode == target
    bench.run(0.2)
    assert bench.autopilot.mode == target
    assert bench.autopilot.state().mode == target
    if start != target:
        change = bench.of_type(ModeChanged)[-1]
        assert (change.previous, change.mode, change.reason) == (start, target, "gcs")


@pytest.mark.parametrize("target", [RoverMode.AUTO, RoverMode.RTL, RoverMode.LOITER, RoverMode.GUIDED], ids=lambda m: m.name)
def test_driving_modes_are_refused_without_a_position_and_say_why(target):
    bench = Bench()
    reply = bench.request(bench.autopilot.set_mode(target))
    assert reply.result == mav.MAV_RESULT_FAILED and "position" in reply.reason
    assert bench.texts[-1:] == [f"Mode change refused: {target.name} needs a position"]
    assert bench.autopilot.mode == RoverMode.HOLD


@pytest.mark.parametrize("target", [RoverMode.MANUAL, RoverMode.HOLD], ids=lambda m: m.name)
def test_manual_and_hold_need_nothing(target):
    bench = Bench()
    assert bench.request(bench.autopilot.set_mode(target)).accepted


def test_auto_without_a_mission_is_refused_and_an_unknown_mode_denied():
    bench = Bench()
    bench.ready()
    reply = bench.request(bench.autopilot.set_mode(RoverMode.AUTO))
    assert reply.result == mav.MAV_RESULT_FAILED and bench.texts[-1] == "Mode change refused: AUTO needs a mission"
    reply = bench.request(bench.autopilot.mission_start())
    assert reply.result == mav.MAV_RESULT_FAILED and bench.texts[-1] == "Mission start refused: AUTO needs a mission"
    reply = bench.request(bench.autopilot.set_mode(99))
    assert reply.result == mav.MAV_RESULT_DENIED and bench.texts[-1] == "Mode change refused: mode 99 not supported"
    assert bench.autopilot.mode == RoverMode.HOLD


def test_refusal_rules():
    nothing = ModeContext(has_position=False, has_mission=False)
    assert refusal(RoverMode.MANUAL, nothing) is None and refusal(RoverMode.HOLD, nothing) is None
    assert refusal(RoverMode.RTL, nothing) == "RTL needs a position"
    assert refusal(RoverMode.AUTO, ModeContext(True, False)) == "AUTO needs a mission"
    assert refusal(RoverMode.AUTO, ModeContext(True, True)) is None
    assert unsupported(RoverMode.GUIDED) is None and unsupported(3) == "mode 3 not supported"


def test_manual_releases_the_channels_and_disarmed_is_neutral():
    bench = Bench()
    bench.home()
    bench.step()
    assert bench.neutral  # disarmed, HOLD
    bench.autopilot.set_mode(RoverMode.MANUAL)
    bench.step()
    assert bench.released
    bench.autopilot.set_mode(RoverMode.HOLD)
    bench.step()
    assert bench.neutral


def test_auto_runs_the_mission_then_holds_and_reports_progress_on_the_wire():
    bench = Bench()
    bench.ready(mission((0.0, 8.0), (6.0, 8.0)))
    assert bench.request(bench.autopilot.set_mode(RoverMode.AUTO)).accepted
    assert bench.autopilot.state().mission_state.name == "ACTIVE"
    assert bench.run(90.0, until=lambda b: b.autopilot.mode == RoverMode.HOLD)
    assert bench.autopilot.state().mission_state.name == "COMPLETE"
    assert mode_names(bench) == ["AUTO", "HOLD"] and bench.of_type(ModeChanged)[-1].reason == "mission complete"
    assert math.dist(bench.position_en, (6.0, 8.0)) < bench.config.executor.acceptance_radius_m + 0.5
    assert any(isinstance(e, PlanMade) and e.goal_seq == 2 for e in bench.events)
    bench.run(3.0)
    assert abs(bench.speed_mps) < 0.05 and bench.neutral  # stopped, then neutral


def test_hold_stops_a_driving_rover_by_braking():
    bench = Bench()
    bench.ready(mission((0.0, 30.0)))
    bench.autopilot.set_mode(RoverMode.AUTO)
    bench.run(6.0)
    assert bench.speed_mps > 0.5
    bench.autopilot.set_mode(RoverMode.HOLD)
    out = bench.step()
    assert out.command.left_out < 0.3 and out.command.right_out < 0.3  # braking towards zero speed
    bench.run(1.5)
    assert abs(bench.speed_mps) < 0.05
    assert bench.autopilot.state().mission_state.name == "PAUSED"


def test_rtl_drives_home_and_holds_there():
    bench = Bench()
    bench.ready(mission((0.0, 30.0)))
    bench.autopilot.set_mode(RoverMode.AUTO)
    bench.run(60.0, until=lambda b: b.north_m > 12.0)
    assert bench.request(bench.autopilot.return_to_launch()).accepted
    assert "RTL: returning home" in bench.texts
    assert bench.run(60.0, until=lambda b: "RTL: reached home" in b.texts)
    assert math.dist(bench.position_en, (0.0, 0.0)) <= bench.config.executor.rtl_radius_m + 0.3
    bench.run(3.0)
    assert abs(bench.speed_mps) < 0.05 and bench.autopilot.mode == RoverMode.RTL


def test_loiter_holds_its_point_and_drives_back_when_pushed_away():
    bench = Bench()
    bench.ready()
    bench.east_m, bench.north_m = 5.0, 5.0
    bench.step()
    assert bench.request(bench.autopilot.set_mode(RoverMode.LOITER)).accepted
    bench.run(2.0)
    assert bench.neutral and math.dist(bench.position_en, (5.0, 5.0)) < 0.1
    bench.east_m += 1.5  # pushed, but within loiter_radius_m (2 m): stays put
    bench.run(2.0)
    assert bench.neutral and math.dist(bench.position_en, (6.5, 5.0)) < 0.1
    bench.east_m += 3.0  # pushed 4.5 m off: drives back to within half the radius
    assert bench.run(30.0, until=lambda b: math.dist(b.position_en, (5.0, 5.0)) <= 1.0)
    bench.run(3.0)
    assert abs(bench.speed_mps) < 0.05 and math.dist(bench.position_en, (5.0, 5.0)) < 2.0


def test_guided_drives_to_the_target_with_the_planner_then_keeps_station():
    bench = Bench()
    bench.ready()
    assert bench.request(bench.autopilot.set_mode(RoverMode.GUIDED)).accepted
    bench.run(1.0)
    assert bench.neutral  # no target yet: keeps station where it entered
    lat, lon = latlon(-6.0, 12.0)
    assert bench.request(bench.autopilot.guided_target(lat, lon)).accepted
    assert bench.run(60.0, until=lambda b: "Reached destination" in b.texts)
    assert math.dist(bench.position_en, (-6.0, 12.0)) <= bench.config.executor.acceptance_radius_m + 0.3
    assert any(isinstance(e, PlanMade) and e.goal_seq == 0 for e in bench.events)
    bench.run(3.0)
    assert abs(bench.speed_mps) < 0.05 and bench.autopilot.mode == RoverMode.GUIDED


def test_guided_target_refusals_say_why():
    bench = Bench()
    lat, lon = latlon(0.0, 10.0)
    reply = bench.request(bench.autopilot.guided_target(lat, lon, change_mode=True))
    assert reply.result == mav.MAV_RESULT_DENIED and bench.texts[-1] == "Guided target refused: no position yet"
    bench.ready()
    reply = bench.request(bench.autopilot.guided_target(lat, lon))  # HOLD, no CHANGE_MODE flag
    assert reply.result == mav.MAV_RESULT_DENIED and bench.texts[-1] == "Guided target refused: not in GUIDED mode"
    for bad in ((math.nan, lon), (91.0, lon), (0.0, 0.0)):
        assert bench.request(bench.autopilot.guided_target(*bad, change_mode=True)).result == mav.MAV_RESULT_DENIED
        assert bench.texts[-1] == "Guided target refused: invalid location"
    assert bench.autopilot.mode == RoverMode.HOLD
    # DO_REPOSITION's CHANGE_MODE flag switches to GUIDED and drives there.
    assert bench.request(bench.autopilot.guided_target(lat, lon, change_mode=True)).accepted
    assert bench.autopilot.mode == RoverMode.GUIDED and bench.of_type(ModeChanged)[-1].reason == "guided target"


def test_arming_and_disarming_go_to_the_vehicle():
    bench = Bench()
    bench.home()
    bench.step()
    assert bench.request(bench.autopilot.arm(True)).accepted
    assert bench.of_type(ArmRequest)[-1] == ArmRequest(True, False)
    bench.step()
    assert bench.autopilot.state().armed
    assert bench.request(bench.autopilot.arm(True)).accepted  # already armed: nothing more to ask
    assert len(bench.of_type(ArmRequest)) == 1
    assert bench.request(bench.autopilot.arm(False)).accepted
    assert bench.of_type(ArmRequest)[-1] == ArmRequest(False, False)


def test_a_new_mission_stops_auto_and_rtl_goes_on():
    bench = Bench()
    bench.ready(mission((0.0, 30.0)))
    bench.autopilot.set_mode(RoverMode.AUTO)
    bench.run(2.0)
    bench.autopilot.mission_changed(mission((5.0, 5.0)), 0)
    bench.collect(bench.autopilot.drain())
    assert bench.autopilot.mode == RoverMode.HOLD and bench.of_type(ModeChanged)[-1].reason == "mission changed"
    assert bench.autopilot.state().mission_state.name == "NOT_STARTED"
    bench.autopilot.set_mode(RoverMode.RTL)
    bench.autopilot.mission_changed(mission((1.0, 1.0)), 0)
    assert bench.autopilot.mode == RoverMode.RTL
    bench.run(1.0)
    assert bench.outputs[-1].log_row["goal_east_m"] == 0.0  # still driving home


def test_set_current_moves_the_mission_and_refuses_a_bad_seq():
    bench = Bench()
    bench.ready(mission((0.0, 5.0), (5.0, 5.0), (5.0, 0.0)))
    assert bench.autopilot.set_current(3)
    bench.collect(bench.autopilot.drain())
    assert bench.autopilot.state().current_seq == 3
    assert not bench.autopilot.set_current(7)
    bench.collect(bench.autopilot.drain())
    assert bench.texts[-1].startswith("mission seq 7 does not exist")


def test_guided_target_outside_the_fence_is_refused():
    from dataclasses import replace

    from autopilot.harness import waypoint

    from rover_ctl.mission.model import Mission
    from rover_ctl.vocabulary import Cmd

    bench = Bench()
    zone = [replace(waypoint(0.0, 20.0, Cmd.NAV_FENCE_CIRCLE_EXCLUSION), param1=5.0)]
    bench.ready(Mission(fence=zone))
    reply = bench.request(bench.autopilot.guided_target(*latlon(0.0, 21.0), change_mode=True))
    assert reply.result == mav.MAV_RESULT_DENIED
    assert bench.texts[-1] == "Guided target refused: target inside a fence exclusion zone"
    assert bench.request(bench.autopilot.guided_target(*latlon(0.0, 30.0), change_mode=True)).accepted
