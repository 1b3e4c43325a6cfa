"""The obstacle memory: echoes kept in ENU, folded into each sensor's sector."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from rover_ctl.config import ProximityParams
from rover_ctl.navigation.proximity import ORIENTATION_RAD, ObstacleMemory

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


def _remembered_ahead(memory: ObstacleMemory, ahead_m: float, left_m: float, heading_deg: float = 0.0) -> dict[int, float]:
    """One point ``ahead_m`` beyond the front edge (x = 0.2) and ``left_m`` left of the axis of
    a rover at the origin facing east, remembered, then read with the rover turned ``heading_deg``."""
    memory.add(0.0, ahead_m - 1.0, left_m, 0.0, FRONT, 1.0)  # from 1 m behind, the beam straight at it
    return memory.ranges(0.1, 0.0, 0.0, math.radians(heading_deg), CLEAR)


@pytest.mark.parametrize("left_m", [-0.19, -0.1, 0.1, 0.19])
def test_an_echo_ahead_of_the_bumper_reads_in_front_across_its_whole_width(memory, left_m):
    # 0.15 m ahead of the edge and 0.1 m aside: outside the front cone (+-0.06 m there), and
    # every diagonal sector starts at its corner 22.5 degrees out: it was in no sector at all.
    ranges = _remembered_ahead(memory, 0.15, left_m)
    assert ranges[FRONT] == pytest.approx(0.15)  # its distance from the edge: what the bumper meets
    assert all(ranges[o] == math.inf for o in CLEAR if o != FRONT)
    cones = ObstacleMemory(ProximityParams(edge_sectors=False), footprint_length_m=0.4, footprint_width_m=0.4)
    assert _remembered_ahead(cones, 0.15, left_m) == CLEAR


def test_beyond_the_edges_end_the_widened_sector_meets_the_diagonal(memory):
    # Ahead of the left corner (0.2, 0.2), within 22.5 degrees of straight ahead: front, at its
    # distance from the corner; past 22.5 degrees: the front-left diagonal's.
    ranges = _remembered_ahead(memory, 0.3, 0.2 + 0.3 * math.tan(math.radians(20.0)))
    assert ranges[FRONT] == pytest.approx(0.3 / math.cos(math.radians(20.0)))
    assert ranges[FRONT_LEFT] == math.inf
    memory = ObstacleMemory(ProximityParams(), footprint_length_m=0.4, footprint_width_m=0.4)
    ranges = _remembered_ahead(memory, 0.3, 0.2 + 0.3 * math.tan(math.radians(25.0)))
    assert ranges[FRONT] == math.inf
    assert ranges[FRONT_LEFT] == pytest.approx(0.3 / math.cos(math.radians(25.0)))


def test_inside_the_sensors_cone_the_distance_is_still_from_the_sensor(memory):
    ranges = _remembered_ahead(memory, 1.0, 0.3)  # 16.7 degrees off the axis: the cone's
    assert ranges[FRONT] == pytest.approx(math.hypot(1.0, 0.3))
    memory = ObstacleMemory(ProximityParams(), footprint_length_m=0.4, footprint_width_m=0.4)
    memory.add(0.0, 0.7, 0.15, math.pi, FRONT, 1.0)  # 0.3 m behind the back edge, 0.15 m aside
    assert memory.ranges(0.1, 0.0, 0.0, 0.0, CLEAR)[BACK] == pytest.approx(0.3)  # the back edge works the same way


def test_echoes_are_forgotten_and_never_lengthen_a_reading(memory):
    memory.add(0.0, 0.0, 0.0, 0.0, FRONT, 2.0)
    assert memory.ranges(1.0, 0.0, 0.0, 0.0, {FRONT: 0.8})[FRONT] == 0.8  # the nearer wins
    assert memory.ranges(1.6, 0.0, 0.0, 0.0, CLEAR)[FRONT] == math.inf  # older than memory_s


def test_no_echo_adds_nothing_and_missing_sensors_stay_missing(memory):
    memory.add(0.0, 0.0, 0.0, 0.0, FRONT, math.inf)
    assert memory.ranges(0.1, 0.0, 0.0, 0.0, CLEAR) == CLEAR
    memory.add(0.0, 0.0, 0.0, 0.0, LEFT, 1.0)
    assert set(memory.ranges(0.1, 0.0, 0.0, 0.0, {FRONT: math.inf})) == {FRONT}  # a silent sensor is not invented


PREDICTING = ProximityParams(horizon_s=2.0, track_beam_half_deg=0.0)
"""Prediction, with echoes as sure across their beam as along it: ``_watch`` keeps the beam on the
obstacle, so its echoes are exact."""


def _watch(memory: ObstacleMemory, start_en, velocity_en, seconds: float) -> float:
    """A rover at the origin points its front beam at an obstacle moving from ``start_en`` at
    ``velocity_en`` every 0.1 s (sensor at the centre); returns the time of the last echo."""
    t = 0.0
    for k in range(int(round(seconds / 0.1)) + 1):
        t = 0.1 * k
        e, n = start_en[0] + velocity_en[0] * t, start_en[1] + velocity_en[1] * t
        memory.add(t, 0.0, 0.0, math.atan2(n, e), FRONT, math.hypot(e, n))
    return t


@pytest.mark.parametrize("horizon_s", [0.0, 2.0])
def test_a_pedestrian_about_to_cross_ahead_reads_ahead_only_with_prediction(horizon_s):
    memory = ObstacleMemory(replace(PREDICTING, horizon_s=horizon_s), 0.0, 0.0)
    t = _watch(memory, (2.0, -2.5), (0.0, 1.0), 1.0)  # now at (2, -1.5), 37 deg right, walking north
    ranges = memory.ranges(t, 0.0, 0.0, 0.0, CLEAR)  # facing east
    if horizon_s:
        assert ranges[FRONT] == pytest.approx(2.0, abs=0.05)  # where it will cross, within 2 s
        # front-right: the nearest point of its path still in that sector, at its -22.5 deg edge
        assert ranges[FRONT_RIGHT] == pytest.approx(2.0 / math.cos(math.radians(22.5)), abs=0.1)
    else:
        assert ranges[FRONT] == math.inf
        assert ranges[FRONT_RIGHT] == pytest.approx(2.5, abs=0.05)


def test_a_crossed_obstacle_leaves_no_trail_with_prediction():
    # Walked across the rover's front and is now at (2, 1.1), 29 deg left: out of the front sector.
    without, with_ = ObstacleMemory(ProximityParams(), 0.0, 0.0), ObstacleMemory(PREDICTING, 0.0, 0.0)
    for memory in (without, with_):
        t = _watch(memory, (2.0, -0.4), (0.0, 1.0), 1.5)
    assert without.ranges(t, 0.0, 0.0, 0.0, CLEAR)[FRONT] == pytest.approx(2.0, abs=0.05)  # its trail
    assert with_.ranges(t, 0.0, 0.0, 0.0, CLEAR)[FRONT] == math.inf


def test_a_closing_obstacle_reads_nearer_one_walking_away_does_not():
    closing, leaving = ObstacleMemory(PREDICTING, 0.0, 0.0), ObstacleMemory(PREDICTING, 0.0, 0.0)
    t = _watch(closing, (4.5, 0.0), (-1.0, 0.0), 1.0)  # head-on at 1 m/s, now 3.5 m ahead
    assert closing.ranges(t, 0.0, 0.0, 0.0, CLEAR)[FRONT] == pytest.approx(1.5, abs=0.15)
    t = _watch(leaving, (1.5, 0.0), (1.0, 0.0), 1.0)  # now 2.5 m ahead, walking away
    assert leaving.ranges(t, 0.0, 0.0, 0.0, CLEAR)[FRONT] == pytest.approx(2.5, abs=0.05)


def test_a_static_world_reads_the_same_with_prediction():
    """A rover driving at 1 m/s beside a wall and towards a post; each sensor's narrow beam
    (+-7.5 deg) echoes off the nearest point of them in it, with 2 cm noise: the side echoes slide
    along the wall with the rover, and still no track moves and the ranges are those without
    prediction. (Passing close beside the post, a diagonal beam's echo sweeps over its surface
    and does read as moving: the limit in rover_ctl.navigation.tracks.)"""
    rng = np.random.default_rng(5)
    wall = [(x, 1.5) for x in np.arange(-1.0, 8.0, 0.05)]
    post = [(8.0 + 0.2 * math.cos(a), 0.0 + 0.2 * math.sin(a)) for a in np.linspace(0, math.tau, 24)]
    obstacles = np.array(wall + post)
    without, with_ = ObstacleMemory(ProximityParams(), 0.0, 0.0), ObstacleMemory(PREDICTING, 0.0, 0.0)
    for k in range(60):
        t, pose = 0.1 * k, (0.1 * k, 0.0, 0.0)
        for orientation in (FRONT, FRONT_RIGHT, RIGHT, LEFT, FRONT_LEFT):
            axis = pose[2] + ORIENTATION_RAD[orientation]
            d = obstacles - pose[:2]
            bearing = np.abs(np.remainder(np.arctan2(d[:, 1], d[:, 0]) - axis + math.pi, math.tau) - math.pi)
            seen = np.hypot(d[:, 0], d[:, 1])[bearing < math.radians(7.5)]
            noisy = float(seen.min()) + rng.normal(0, 0.02) if len(seen) and seen.min() < 4.0 else math.inf
            without.add(t, *pose, orientation, noisy)
            with_.add(t, *pose, orientation, noisy)
        assert with_.ranges(t, *pose, CLEAR, speed_mps=1.0) == without.ranges(t, *pose, CLEAR, speed_mps=1.0)
    assert with_.tracker.moving(t, (1.0, 0.0)) == []
