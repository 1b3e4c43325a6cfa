"""Every failsafe action as the autopilot applies it (rover_ctl.autopilot.failsafe decides, the
autopilot acts): NEUTRAL, HOLD, RTL, BACK_OFF with the re-plan, GCS loss, fence breach, GPS loss
and dead reckoning, silent rangefinders, an unhealthy estimator. Closed loop, no sockets."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest
from autopilot.harness import Bench, mission, waypoint

from rover_ctl.autopilot.events import FailsafeChanged, ModeChanged, StatusText
from rover_ctl.autopilot.failsafe import Action
from rover_ctl.config import Config
from autopilot.harness import rover_config
from rover_ctl.mission.model import Mission
from rover_ctl.navigation.sensors import FRONT, LEFT, RIGHT
from rover_ctl.vocabulary import Cmd, RoverMode, Severity, mav


def driving(config: Config | None = None, points=((0.0, 40.0),), fence=None) -> Bench:
    bench = Bench(config or rover_config())
    bench.ready(mission(*points, fence=fence))
    assert bench.request(bench.autopilot.set_mode(RoverMode.AUTO)).accepted
    bench.run(4.0)
    assert bench.speed_mps > 0.5
    return bench


def action(bench: Bench) -> Action:
    return bench.autopilot.decision.action


def test_vehicle_link_silent_sends_neutral_and_resumes():
    bench = driving()
    bench.vehicle_age_s = 1.5
    bench.step()
    assert action(bench) == Action.NEUTRAL and bench.neutral
    assert "FS vehicle link: motors neutral" in bench.texts
    assert bench.autopilot.state().system_status == mav.MAV_STATE_CRITICAL
    bench.run(6.0)
    assert all(o.command.throttle_us == 1500 for o in bench.outputs[-100:])
    assert not any(t.startswith("FS stuck") for t in bench.texts)  # not driven: not stuck
    bench.vehicle_age_s = 0.0
    assert bench.run(5.0, until=lambda b: "FS vehicle link cleared" in b.texts)
    bench.run(2.0)
    assert bench.speed_mps > 0.3 and bench.autopilot.mode == RoverMode.AUTO  # the mission goes on


@pytest.mark.parametrize("gcs_action, expected", [("continue", Action.NONE), ("hold", Action.HOLD), ("rtl", Action.RTL)])
def test_gcs_loss_actions(gcs_action, expected):
    config = rover_config()
    config.failsafe.gcs_action = gcs_action
    bench = driving(config)
    bench.gcs_age_s = 0.5
    bench.run(1.0)
    assert action(bench) == Action.NONE
    bench.gcs_age_s = config.failsafe.gcs_timeout_s + 0.1
    bench.step()
    assert "GCS lost" in bench.autopilot.decision.reasons and action(bench) == expected
    assert f"FS GCS lost: {gcs_action}" in bench.texts
    bench.run(3.0)
    if expected == Action.HOLD:
        assert abs(bench.speed_mps) < 0.05 and bench.autopilot.mode == RoverMode.AUTO
    elif expected == Action.RTL:
        assert bench.autopilot.mode == RoverMode.RTL and bench.of_type(ModeChanged)[-1].reason == "failsafe"
    else:
        assert bench.speed_mps > 0.5
    bench.gcs_age_s = 0.0
    assert bench.run(5.0, until=lambda b: "FS GCS lost cleared" in b.texts)
    # RTL stays (ArduPilot's failsafe mode change); HOLD lets the mission go on.
    assert bench.autopilot.mode == (RoverMode.RTL if expected == Action.RTL else RoverMode.AUTO)


def test_no_ground_station_ever_is_no_gcs_failsafe():
    bench = driving()
    bench.gcs_age_s = math.inf
    bench.run(10.0)
    assert "GCS lost" not in bench.autopilot.decision.reasons


def square(half_m: float, command: int = Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION) -> list:
    corners = [(-half_m, -half_m), (half_m, -half_m), (half_m, half_m), (-half_m, half_m)]
    return [replace(waypoint(e, n, command), param1=4) for e, n in corners]


@pytest.mark.parametrize("fence_action", ["hold", "rtl"])
def test_fence_breach(fence_action):
    config = rover_config()
    config.failsafe.fence_action = fence_action
    bench = driving(config, fence=square(50.0))
    bench.north_m = 51.0  # a GPS jump puts the estimate outside the inclusion fence
    bench.step()
    assert "fence breach" in bench.autopilot.decision.reasons
    assert f"FS fence breach: {fence_action}" in bench.texts
    assert bench.autopilot.state().system_status == (mav.MAV_STATE_CRITICAL if fence_action == "hold" else mav.MAV_STATE_ACTIVE)
    if fence_action == "hold":
        bench.run(3.0)
        assert abs(bench.speed_mps) < 0.05
    else:
        assert bench.autopilot.mode == RoverMode.RTL
        assert bench.run(60.0, until=lambda b: "RTL: reached home" in b.texts)


def test_gps_loss_dead_reckons_then_holds():
    config = rover_config()
    config.failsafe.dead_reckoning_max_s = 3.0
    bench = driving(config)
    bench.gps_age_s = config.failsafe.gps_timeout_s + 0.1
    bench.step()
    decision = bench.autopilot.decision
    assert decision.dead_reckoning and decision.action == Action.NONE and "FS GPS lost: dead reckoning" in bench.texts
    bench.run(1.0)
    assert bench.speed_mps > 0.5  # driving on the dead-reckoned pose
    bench.gps_age_s = config.failsafe.gps_timeout_s + 3.1
    bench.step()
    assert action(bench) == Action.HOLD and "FS GPS lost too long: hold" in bench.texts
    bench.run(2.0)
    assert abs(bench.speed_mps) < 0.05
    bench.gps_age_s = 0.0
    assert bench.run(5.0, until=lambda b: "FS GPS lost too long cleared" in b.texts)


def test_silent_rangefinder_not_required_blocks_its_side_and_slows_down():
    config = rover_config()
    config.failsafe.required_rangefinders = [2, 6]  # the front one may fail: go on carefully
    bench = driving(config)
    del bench.ranges_m[0]  # the front rangefinder stops reporting (its last reading: nothing in range)
    bench.run(config.failsafe.rangefinder_timeout_s + 0.1)
    assert 0 in bench.autopilot.decision.blocked_orientations and "FS rangefinder 0: silent, side blocked" in bench.texts
    assert bench.autopilot.decision.speed_limit_mps == config.failsafe.degraded_speed_mps
    assert bench.outputs[-1].log_row["range_front_m"] == math.inf  # logged as last heard...
    bench.run(2.0)
    assert bench.speed_mps < 0.3  # ...but the navigator treats the front as blocked: no more driving ahead
    bench.ranges_m[0] = math.inf
    assert bench.run(5.0, until=lambda b: "FS rangefinder 0 cleared" in b.texts)
    bench.run(3.0)
    assert bench.speed_mps > 0.5


def test_silent_required_rangefinder_holds_within_a_second_and_resumes():
    bench = driving()  # FS_RNG_MASK -1: every rangefinder the rule base reads is required
    silent_from = bench.t_s
    for orientation in list(bench.ranges_m):
        del bench.ranges_m[orientation]  # every rangefinder fails
    assert bench.run(1.0, until=lambda b: action(b) == Action.HOLD)
    assert bench.t_s - silent_from <= 1.0 and "FS rangefinder 0: silent, hold" in bench.texts
    bench.run(2.0)
    assert abs(bench.speed_mps) < 0.05 and bench.autopilot.mode == RoverMode.AUTO  # held, mission kept
    bench.ranges_m.update(dict.fromkeys((0, 1, 2, 4, 6, 7), math.inf))
    assert bench.run(5.0, until=lambda b: action(b) == Action.NONE)
    bench.run(3.0)
    assert bench.speed_mps > 0.5


def test_estimator_unhealthy_holds_after_its_delay():
    bench = driving()
    bench.healthy = False
    bench.step()
    assert action(bench) == Action.NONE  # a blip shorter than estimator_unhealthy_s is ignored
    bench.run(0.6)
    assert action(bench) == Action.HOLD and "FS estimator: unhealthy, hold" in bench.texts
    bench.run(2.0)
    assert abs(bench.speed_mps) < 0.05
    bench.healthy = True
    assert bench.run(5.0, until=lambda b: b.autopilot.decision.action == Action.NONE)


def test_stuck_backs_off_then_replans_around_the_spot_ahead():
    bench = driving(points=((0.0, 40.0),))
    bench.frozen = True  # against something no rangefinder sees
    assert bench.run(10.0, until=lambda b: b.autopilot.decision.action == Action.BACK_OFF)
    assert bench.texts[-1] == "FS stuck: backing off (1/3)"
    out = bench.step()
    assert out.log_row["left_set_rpm"] < 0 and out.log_row["right_set_rpm"] < 0  # reversing
    blocked_before = len(bench.autopilot.planner._blocked)
    bench.frozen = False
    assert bench.run(5.0, until=lambda b: b.autopilot.decision.action == Action.NONE)
    assert len(bench.autopilot.planner._blocked) == blocked_before + 1  # the spot ahead, avoided
    bench.step()
    plans = [e for e in bench.events if type(e).__name__ == "PlanMade"]
    assert len(plans[-1].path_en) > 2  # the new path goes around it


def test_backing_off_stops_short_of_something_behind():
    """Backing off blind drove a rover stuck in a cul-de-sac's corner into the wall behind it
    (in-process runner, cul_de_sac seed 97 with the map on): with the back rangefinder within
    ``back_off_clear_m`` the wheels are held instead."""
    bench = driving(points=((0.0, 40.0),))
    bench.frozen = True
    assert bench.run(10.0, until=lambda b: b.autopilot.decision.action == Action.BACK_OFF)
    out = bench.step()
    assert out.log_row["left_set_rpm"] < 0 and out.log_row["right_set_rpm"] < 0  # nothing behind: reversing
    bench.ranges_m[4] = 0.25  # something 0.25 m behind
    bench.step()
    out = bench.step()
    assert bench.autopilot.decision.action == Action.BACK_OFF
    assert out.log_row["left_set_rpm"] == 0.0 and out.log_row["right_set_rpm"] == 0.0
    bench.autopilot.config.failsafe.back_off_clear_m = 0.0  # 0: back off blind
    out = bench.step()
    assert out.log_row["left_set_rpm"] < 0 and out.log_row["right_set_rpm"] < 0


def test_stuck_gives_up_and_holds_after_its_tries():
    config = rover_config()
    config.failsafe.stuck_max_tries = 1
    bench = driving(config)
    bench.frozen = True
    assert bench.run(40.0, until=lambda b: "FS stuck: gave up, hold" in b.texts)
    assert action(bench) == Action.HOLD
    bench.autopilot.set_mode(RoverMode.HOLD)  # leaving the driving modes forgets it
    bench.step()
    assert "stuck" not in bench.autopilot.decision.reasons


def test_failsafe_changes_are_events_for_the_log():
    bench = driving()
    bench.vehicle_age_s = 2.0
    bench.step()
    change = bench.of_type(FailsafeChanged)[-1]
    assert change.reasons == ("vehicle link",) and change.action == "NEUTRAL"
    text = [e for e in bench.events if isinstance(e, StatusText)][-1]
    assert text.severity == Severity.CRITICAL


def test_a_fence_the_planner_cannot_use_is_ignored_and_refuses_arming():
    bench = Bench()
    bad = [replace(waypoint(0, 0, Cmd.NAV_FENCE_CIRCLE_INCLUSION), param1=0.0)]  # zero radius
    bench.home(Mission(items=[waypoint(0.0, 10.0)], fence=bad))
    bench.step()
    assert bench.texts[0].startswith("Fence part ignored:")
    assert not bench.request(bench.autopilot.arm(True)).accepted
    assert any(t.startswith("PreArm: fence unusable") for t in bench.texts)


def test_a_rover_parked_by_its_rule_base_backs_off_and_replans():
    """Obstacles ahead and on both sides: the rule base turns in place and crawls (under
    stuck_min_command_mps) without getting anywhere. After parked_window_s the stuck failsafe
    backs it off and plans around the spot ahead, as for a stalled rover. (The bench's ranges turn
    with the rover, so its memory fills the circle with echoes; with the front and back sectors
    across the rover's width, ``proximity.edge_sectors``, the rule base then creeps backwards
    instead, 0.48 m in 19 s, which the parked rule takes for progress: the memory's sectors are
    the cones here.)"""
    config = rover_config()
    config.proximity.edge_sectors = False
    bench = Bench(config)
    bench.ranges_m.update({FRONT: 0.6, LEFT: 0.5, RIGHT: 0.5})
    bench.ready(mission((0.0, 30.0)))
    assert bench.request(bench.autopilot.set_mode(RoverMode.AUTO)).accepted
    start_s = bench.t_s
    assert bench.run(20.0, until=lambda b: b.autopilot.decision.action == Action.BACK_OFF)
    assert bench.texts[-1] == "FS stuck: backing off (1/3)"
    assert bench.t_s - start_s >= bench.config.failsafe.parked_window_s
    bench.ranges_m.update({FRONT: math.inf, LEFT: math.inf, RIGHT: math.inf})
    assert bench.run(5.0, until=lambda b: b.autopilot.decision.replan)
