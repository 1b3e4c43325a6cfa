"""The odometry frame: dead reckoning, the link between it and the fused pose, and why the obstacle
map is kept in it (a wall seen while GPS fixes move the pose stays where it is against the rover)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st
from shapely.geometry import LineString, Polygon

from rover_ctl.config import ObstacleMapParams
from rover_ctl.navigation.obstacle_map import ObstacleMap
from rover_ctl.navigation.odometry import FrameLink, Odometry

coordinate = st.floats(-1e3, 1e3)
angle = st.floats(-math.pi, math.pi)


@given(coordinate, coordinate, angle, coordinate, coordinate, angle, coordinate, coordinate)
def test_a_point_taken_into_the_odometry_frame_and_back_is_the_same_point(pe, pn, ph, oe, on, oh, x, y):
    link = FrameLink((pe, pn), ph, (oe, on), oh)
    back = link.to_pose(link.to_odometry((x, y)))
    assert back == pytest.approx((x, y), abs=1e-6)


@given(coordinate, coordinate, angle, coordinate, coordinate, angle, st.floats(0.0, 50.0))
def test_the_link_lays_the_odometry_pose_onto_the_fused_one(pe, pn, ph, oe, on, oh, ahead_m):
    """The rover's position in each frame is the same place, and a point ahead along its heading
    in one frame is ahead along its heading in the other."""
    link = FrameLink((pe, pn), ph, (oe, on), oh)
    assert link.to_odometry((pe, pn)) == pytest.approx((oe, on), abs=1e-9)
    ahead = link.to_odometry((pe + ahead_m * math.cos(ph), pn + ahead_m * math.sin(ph)))
    assert ahead == pytest.approx((oe + ahead_m * math.cos(oh), on + ahead_m * math.sin(oh)), abs=1e-6)


def test_dead_reckoning_follows_the_wheels_along_the_gyros_heading_and_is_live_once_both_are_heard():
    odo = Odometry()
    assert not odo.live
    odo.on_wheels(5.0, 5.0)  # the first reading only sets where the wheels' counts start
    assert odo.position_en == (0.0, 0.0) and not odo.live
    odo.on_gyro(0.0, 0.0)
    assert odo.live
    odo.on_wheels(6.0, 6.0)  # 1 m straight on at heading 0
    odo.on_gyro(0.5, -math.pi / 2)  # NED clockwise rate: a quarter turn counter-clockwise over 1 s
    odo.on_gyro(1.0, -math.pi / 2)
    odo.on_gyro(2.0, 0.0)  # a reading after a gap over 0.5 s turns nothing (the rate between is unknown)
    odo.on_wheels(6.5, 6.5)
    assert odo.position_en == pytest.approx((1.0, 0.5))
    assert odo.heading_rad == pytest.approx(math.pi / 2)
    assert odo.yaw_rate_radps == 0.0


WALL_NORTH_M = 1.25
"""A wall along the rover's way, this far left of its line (the middle of a 0.5 m cell row)."""


def drive_along_a_wall(odometry_frame: bool, wander_m: float):
    """A rover driving east at 0.6 m/s for 12 m past a wall on its left, seen by its left and
    front-left beams at 20 Hz, while the fused pose wanders across the way by up to ``wander_m``
    (period 6 s) as GPS fixes come in; the odometry frame turned 0.4 rad against the pose's.
    The map is kept as the autopilot keeps it: in the odometry frame, or in the pose's. Returns
    the polygons handed to the planner, relative to the rover as the fused pose places it."""
    m = ObstacleMap(ObstacleMapParams())
    odo = Odometry()
    odo.on_gyro(0.0, 0.0)
    odo.on_wheels(0.0, 0.0)
    odo.east_m, odo.heading_rad = 3.1, 0.4
    t_s, x_m = 0.0, 0.0
    while x_m < 12.0:
        t_s, x_m = t_s + 0.05, x_m + 0.6 * 0.05
        odo.on_wheels(x_m, x_m)
        odo.on_gyro(t_s, 0.0)
        pose = (x_m + 0.1 * math.sin(t_s), wander_m * math.sin(2.0 * math.pi * t_s / 6.0))
        link = odo.link(pose, 0.0)
        for axis, range_m in ((math.pi / 2, WALL_NORTH_M), (math.pi / 4, WALL_NORTH_M * math.sqrt(2.0))):
            sensor = pose
            if odometry_frame:
                sensor, axis = link.to_odometry(pose), axis + link.turn_rad
            m.add(t_s, *sensor, axis, range_m, 4.0)
        if round(t_s / 0.5, 6).is_integer():
            m.update(t_s, link.to_odometry(pose) if odometry_frame else pose, 0.3)
    shapes = m.obstacles(link.to_odometry(pose) if odometry_frame else pose)
    if odometry_frame:
        shapes = tuple(tuple(map(link.to_pose, ring)) for ring in shapes)
    return [Polygon([(e - pose[0], n - pose[1]) for e, n in ring]) for ring in shapes]


def wall_covered(polygons) -> float:
    """Share of the wall's last 9 m (relative to the rover at the end) inside the polygons."""
    band = LineString([(-11.0, WALL_NORTH_M), (-2.0, WALL_NORTH_M)]).buffer(0.05)
    return sum(p.intersection(band).area for p in polygons) / band.area


@pytest.mark.parametrize("wander_m", [0.2, 0.4])
def test_in_the_odometry_frame_the_wall_handed_to_the_planner_does_not_move_with_the_pose(wander_m):
    """In the pose's frame, a pose wandering by 0.4 m spreads the wall's echoes over neighbouring
    cells and little of it becomes persistent; in the odometry frame the planner gets the same wall,
    where it is against the rover, however the pose wanders."""
    still = drive_along_a_wall(True, 0.0)
    assert wall_covered(still) >= 0.5
    moved = drive_along_a_wall(True, wander_m)
    assert len(moved) == len(still)
    for a, b in zip(still, moved):
        assert a.symmetric_difference(b).area < 1e-6
    assert wall_covered(drive_along_a_wall(False, 0.0)) >= 0.9  # the pose's frame, the pose still
    assert wall_covered(drive_along_a_wall(False, 0.4)) <= 0.3
