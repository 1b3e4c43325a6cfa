"""Sensors as data in the autopilot: rangefinders learnt or configured, arming waits for them, a
rule base the rover cannot serve and a reversed wheel map refuse arming and stop driving."""

from __future__ import annotations

import math

from autopilot.harness import Bench, mission

from rover_ctl.config import Config
from rover_ctl.estimation.readings import Attitude, WheelDistance
from rover_ctl.fuzzy import load_rulebase
from rover_ctl.vocabulary import RoverMode, mav


def learning(orientations: tuple[int, ...], rulebase: str = "default") -> Bench:
    """A bench whose autopilot learns the rangefinders (the default ``link.rangefinders = [-1]``)."""
    config = Config()
    bench = Bench(config, ranges_m=dict.fromkeys(orientations, math.inf))
    if rulebase != "default":
        from rover_ctl.autopilot.autopilot import Autopilot

        bench.autopilot = Autopilot(config, load_rulebase(rulebase))
    return bench


def test_arming_waits_for_the_rangefinders_then_plans_from_what_reported():
    bench = learning((0, 1, 2, 4, 6, 7))
    bench.home(mission((0.0, 10.0)))
    bench.step()
    reply = bench.request(bench.autopilot.arm(True))
    assert reply.result == mav.MAV_RESULT_TEMPORARILY_REJECTED and "rangefinders" in reply.reason
    bench.run(bench.autopilot.config.link.rangefinder_discovery_s + 0.1)
    plan = bench.autopilot.rangefinder_plan
    assert plan is not None and plan.avoidance and plan.required == {0, 1, 2, 6, 7}
    assert bench.autopilot.failsafes.used_rangefinders == plan.required
    assert bench.request(bench.autopilot.arm(True)).accepted


def test_no_rangefinders_is_gps_only_and_the_rover_drives():
    bench = learning(())
    bench.home(mission((0.0, 8.0)))
    bench.run(bench.autopilot.config.link.rangefinder_discovery_s + 0.1)
    assert not bench.autopilot.rangefinder_plan.avoidance
    assert any(t.startswith("Avoidance off") for t in bench.texts)
    assert bench.request(bench.autopilot.arm(True)).accepted
    bench.step()
    assert bench.request(bench.autopilot.set_mode(RoverMode.AUTO)).accepted
    assert bench.run(30.0, until=lambda b: b.autopilot.executor.complete)


def test_paper_four_feed_the_diagonals_from_their_neighbours():
    bench = learning((0, 2, 4, 6))
    bench.home(mission((0.0, 10.0)))
    bench.run(bench.autopilot.config.link.rangefinder_discovery_s + 0.1)
    plan = bench.autopilot.rangefinder_plan
    assert plan.substitutes == {1: (0, 2), 7: (0, 6)} and plan.required == {0, 2, 6}


def test_a_side_the_rule_base_reads_and_the_rover_lacks_refuses_arming_even_forced():
    bench = learning((0, 2, 6), rulebase="paper")  # the paper's rule base reads the back one
    bench.home(mission((0.0, 10.0)))
    bench.run(bench.autopilot.config.link.rangefinder_discovery_s + 0.1)
    assert bench.autopilot.rangefinder_plan is None and "back" in bench.autopilot.sensor_error
    for force in (False, True):
        reply = bench.request(bench.autopilot.arm(True, force))
        assert reply.result == mav.MAV_RESULT_DENIED and "back" in reply.reason


def test_a_reversed_wheel_map_stops_the_mission_and_refuses_arming():
    bench = Bench()
    bench.ready(mission((0.0, 30.0)))
    assert bench.request(bench.autopilot.set_mode(RoverMode.AUTO)).accepted
    # Wheels that say "turning left" while the gyro says right, for a full radian of turn.
    t_s, left_m, right_m = bench.t_s, 0.0, 0.0
    for _ in range(200):
        t_s += 0.04
        left_m, right_m = left_m + 0.01, right_m + 0.03  # counter-clockwise by the wheels
        bench.autopilot.on_attitude(Attitude(t_s, 0.0, 0.5))  # clockwise by the gyro (ATTITUDE yawspeed, NED)
        bench.autopilot.on_wheels(WheelDistance(t_s, left_m, right_m))
    assert bench.autopilot.wheel_map.verdict == "reversed"
    bench.collect(bench.autopilot.drain())
    assert bench.autopilot.mode == RoverMode.HOLD
    assert any("wheel map reversed" in t for t in bench.texts)
    bench.autopilot.on_vehicle(False)
    reply = bench.request(bench.autopilot.arm(True, True))
    assert reply.result == mav.MAV_RESULT_DENIED and "wheel map" in reply.reason
