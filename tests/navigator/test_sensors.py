"""Rangefinder configuration as data: what the rule base reads vs what the rover has."""

from __future__ import annotations

import math

import pytest

from rover_ctl.config import Config
from rover_ctl.navigation.navigator import Navigator
from rover_ctl.navigation.sensors import SensorSetupError, plan_rangefinders

DEFAULT_READS = [0, 7, 1, 6, 2]
PAPER_READS = [6, 0, 2, 4]


def test_no_rangefinders_is_gps_only_with_every_side_clear():
    plan = plan_rangefinders(DEFAULT_READS, set())
    assert not plan.avoidance and plan.required == frozenset()
    assert plan.inputs({}, DEFAULT_READS) == dict.fromkeys(DEFAULT_READS, math.inf)
    assert "Avoidance off" in plan.describe()


def test_downward_rangefinders_do_not_count():
    assert not plan_rangefinders(DEFAULT_READS, {25}).avoidance


def test_six_rangefinders_default_rule_base_requires_what_it_reads_only():
    plan = plan_rangefinders(DEFAULT_READS, {0, 1, 2, 4, 6, 7})
    assert plan.avoidance and plan.required == {0, 1, 2, 6, 7} and not plan.substitutes


def test_missing_diagonals_read_the_nearer_neighbour():
    """The issue's bug 3: the paper's four with the default rule base no longer read 0 m diagonals."""
    plan = plan_rangefinders(DEFAULT_READS, {0, 2, 4, 6})
    assert plan.required == {0, 2, 6} and plan.substitutes == {1: (0, 2), 7: (0, 6)}
    got = plan.inputs({0: 3.0, 2: 1.5, 4: math.inf, 6: math.inf}, DEFAULT_READS)
    assert got == {0: 3.0, 7: 3.0, 1: 1.5, 6: math.inf, 2: 1.5}


def test_a_silent_neighbour_leaves_the_substitute_missing_so_blocked():
    plan = plan_rangefinders(DEFAULT_READS, {0, 2, 6})
    assert 1 not in plan.inputs({0: 3.0, 6: 2.0}, DEFAULT_READS)


def test_a_side_the_rule_base_needs_and_the_rover_lacks_is_refused_in_one_line():
    with pytest.raises(SensorSetupError, match=r"obstacle_back \(4\).*it has front \(0\), right \(2\), left \(6\)") as err:
        plan_rangefinders(PAPER_READS, {0, 2, 6})
    assert "\n" not in str(err.value)


def test_navigator_without_rangefinders_drives_to_the_target():
    config = Config()
    nav = Navigator("default", config.navigator, config.robot.max_wheel_rpm)
    blocked = nav.step(0, 0, 0, 10, 0, {})
    nav.rangefinders = plan_rangefinders(nav.orientations, set())
    clear = nav.step(0, 0, 0, 10, 0, {})
    assert clear.left_rpm > 0 and clear.right_rpm > 0  # straight ahead, forwards
    assert (blocked.left_rpm, blocked.right_rpm) != (clear.left_rpm, clear.right_rpm)
