"""The obstacle memory: echoes kept in ENU, folded into each sensor's sector."""

from __future__ import annotations

import math

import pytest

from rover_ctl.config import ProximityParams
from rover_ctl.navigation.proximity import ObstacleMemory

FRONT, FRONT_RIGHT, RIGHT, BACK, LEFT, FRONT_LEFT = 0, 1, 2, 4, 6, 7
CLEAR = {o: math.inf for o in (FRONT, FRONT_RIGHT, RIGHT, BACK, LEFT, FRONT_LEFT)}


@pytest.fixture
def memory() -> ObstacleMemory:
    return ObstacleMemory(ProximityParams(memory_s=1.5, sector_half_deg=22.5), footprint_length_m=0.4, footprint_width_m=0.4)


def test_an_obstacle_that_left_the_beam_stays_in_its_sector(memory):
    # Facing east at the origin, the front sensor (at x = 0.2) sees an echo 2 m ahead.
    memory.add(0.0, 0.0, 0.0, 0.0, FRONT, 2.0)
    # 0.5 s later the rover has turned 15 degrees left: the narrow beam now misses the obstacle,
    # but it is still 15 degrees right of the axis, inside the front sector.
    ranges = memory.ranges(0.5, 0.0, 0.0, math.radians(15.0), CLEAR)
    expected = math.hypot(2.2 - 0.2 * math.cos(math.radians(15)), 0.2 * math.sin(math.radians(15)))
    assert ranges[FRONT] == pytest.approx(expected, abs=1e-6)
    assert ranges[LEFT] == math.inf and ranges[BACK] == math.inf
    # Turned 40 degrees: the echo now belongs to the front-right sector only.
    ranges = memory.ranges(0.5, 0.0, 0.0, math.radians(40.0), CLEAR)
    assert ranges[FRONT] == math.inf and ranges[FRONT_RIGHT] < 2.2


def test_echoes_are_forgotten_and_never_lengthen_a_reading(memory):
    memory.add(0.0, 0.0, 0.0, 0.0, FRONT, 2.0)
    assert memory.ranges(1.0, 0.0, 0.0, 0.0, {FRONT: 0.8})[FRONT] == 0.8  # the nearer wins
    assert memory.ranges(1.6, 0.0, 0.0, 0.0, CLEAR)[FRONT] == math.inf  # older than memory_s


def test_no_echo_adds_nothing_and_missing_sensors_stay_missing(memory):
    memory.add(0.0, 0.0, 0.0, 0.0, FRONT, math.inf)
    assert memory.ranges(0.1, 0.0, 0.0, 0.0, CLEAR) == CLEAR
    memory.add(0.0, 0.0, 0.0, 0.0, LEFT, 1.0)
    assert set(memory.ranges(0.1, 0.0, 0.0, 0.0, {FRONT: math.inf})) == {FRONT}  # a silent sensor is not invented
