"""Persistent obstacles: echo evidence in a sparse ENU grid, cleared by free space and age, the
persistent places as a few polygons (rover_ctl.navigation.obstacle_map)."""

from __future__ import annotations

import functools
import math
from dataclasses import replace

from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Point, Polygon
from support import CONE_SECTORS, SURE_ECHOES

from rover_ctl.config import ObstacleMapParams
from rover_ctl.navigation.obstacle_map import JOIN_FRACTION, ObstacleMap

PARAMS = ObstacleMapParams()
BODY_M = 0.3
MAX_RANGE_M = 4.0


def look_at_wall(m: ObstacleMap, t0: float, seconds: float, rover=(0.0, 0.0), wall_north_m=3.0, half_m=2.0, rate_hz=20.0,
                 moving=(), ident=0) -> float:  # fmt: skip
    """A rover at ``rover`` sweeping its beam over a wall along y = wall_north_m, |x| <= half_m."""
    t = t0
    for k in range(round(seconds * rate_hz)):
        t = t0 + k / rate_hz
        axis = math.pi / 2 + 0.5 * math.sin(k * 0.3)
        r = (wall_north_m - rover[1]) / math.sin(axis)
        hit = abs(rover[0] + r * math.cos(axis)) <= half_m and r <= MAX_RANGE_M
        m.add(t, rover[0], rover[1], axis, r if hit else math.inf, MAX_RANGE_M, ident)
        if k % 10 == 9:
            m.update(t, rover, BODY_M, moving)
    return t


def covered(polygons, point, slack_m) -> bool:
    return any(Polygon(p).buffer(slack_m).covers(Point(point)) for p in polygons)


def test_a_wall_seen_repeatedly_becomes_one_polygon_and_not_before_min_span():
    m = ObstacleMap(PARAMS)
    look_at_wall(m, 0.0, PARAMS.min_span_s * 0.6)
    assert not m.persistent, "seen for less than min_span_s"
    look_at_wall(m, PARAMS.min_span_s * 0.6, 3.0)
    obstacles = m.obstacles((0.0, 0.0))
    assert len(obstacles) == 1 and len(obstacles[0]) <= 8, obstacles
    # The wall's seen stretch lies inside the polygon (up to the simplification).
    for x in (-1.0, 0.0, 1.0):
        assert covered(obstacles, (x, 3.0), PARAMS.simplify_m + 1e-6)
    assert not covered(obstacles, (0.0, 0.0), 0.0)


def test_a_point_near_a_persistent_wall_is_on_its_face():
    """The cells of a wall along y = 3 (0.5 m cells: rows 3.0-3.5), within a distance measured to
    the cells' squares; no distance, or no persistent cell, is never on a wall."""
    m = ObstacleMap(PARAMS)
    assert not m.near_persistent(0.0, 3.0, 1.0)
    look_at_wall(m, 0.0, 3.0)
    assert m.near_persistent(0.2, 3.2, 0.5) and m.near_persistent(0.2, 2.6, 0.5)
    assert not m.near_persistent(0.2, 2.4, 0.5) and m.near_persistent(0.2, 2.4, 0.7)
    assert not m.near_persistent(0.2, 3.2, 0.0)
    assert not m.near_persistent(8.0, 3.2, 0.5)  # past the wall's end




@functools.cache
def _small_cell_wall() -> ObstacleMap:
    m = ObstacleMap(replace(PARAMS, cell_m=0.1))  # small cells: a wall of some 30 of them
    look_at_wall(m, 0.0, 30.0)
    return m

@settings(max_examples=200, deadline=None)
@given(east=st.floats(-6.0, 6.0), north=st.one_of(st.floats(2.7, 3.4), st.floats(-3.0, 9.0)),
       distance=st.one_of(st.floats(0.01, 0.2), st.floats(0.01, 10.0)))
def test_on_a_face_is_the_distance_to_the_nearest_persistent_square(east, north, distance):
    """Whichever way it looks (the cells around the point, or every persistent cell when there are
    fewer of them), the answer is the distance to the nearest persistent cell's square."""
    m = _small_cell_wall()
    cell = m.params.cell_m
    def to_square(i, j):
        return math.hypot(max(i * cell - east, 0.0, east - (i + 1) * cell), max(j * cell - north, 0.0, north - (j + 1) * cell))
    assert len(m.persistent) > 25  # a 0.2 m look's window (5 x 5 cells) is the smaller set
    assert m.near_persistent(east, north, distance) == any(to_square(i, j) <= distance for i, j in m.persistent)

def test_a_brief_echo_is_not_persistent():
    m = ObstacleMap(PARAMS)
    for k in range(10):  # half a second of echoes at one place: a pedestrian walking through
        m.add(k * 0.05, 0.0, 0.0, math.pi / 2, 2.0, MAX_RANGE_M)
    m.update(0.5, (0.0, 0.0), BODY_M)
    assert m.cells and not m.persistent


def test_free_space_clears_an_obstacle_that_has_gone():
    m = ObstacleMap(PARAMS)
    t = look_at_wall(m, 0.0, 3.0)
    assert m.obstacles((0.0, 0.0))  # handed to the planner
    for k in range(1, 200):  # the same beams now see nothing: the wall was a parked cart
        axis = math.pi / 2 + 0.5 * math.sin(k * 0.3)
        m.add(t + k * 0.05, 0.0, 0.0, axis, math.inf, MAX_RANGE_M)
    assert m.update(t + 10.0, (0.0, 0.0), BODY_M) > 0  # the planner's obstacles changed
    assert not m.persistent
    assert m.obstacles((0.0, 0.0)) == ()


def test_a_beam_stopping_at_the_obstacle_does_not_clear_it():
    m = ObstacleMap(PARAMS)
    t = look_at_wall(m, 0.0, 3.0)
    before = m.persistent
    look_at_wall(m, t, 5.0)
    assert m.persistent >= before


def test_cells_not_seen_for_ttl_are_forgotten():
    params = replace(PARAMS, ttl_s=10.0)
    m = ObstacleMap(params)
    t = look_at_wall(m, 0.0, 3.0)
    m.update(t + 9.0, (0.0, -20.0), BODY_M)
    assert m.persistent
    m.update(t + 10.5, (0.0, -20.0), BODY_M)
    assert not m.cells


def test_echoes_of_tracks_yielded_to_are_left_out():
    m = ObstacleMap(PARAMS)
    look_at_wall(m, 0.0, 3.0, moving={7}, ident=7)
    assert not m.cells
    look_at_wall(m, 3.0, 3.0, moving={7}, ident=8)
    assert m.persistent


def test_clusters_are_bounded_and_the_nearest_come_first():
    params = replace(PARAMS, max_obstacles=3)
    m = ObstacleMap(params)
    drums = [(4.0 * i, 3.0) for i in range(6)]
    for k in range(60):
        for x, y in drums:  # a beam from 2 m south of each drum
            m.add(k * 0.05, x, y - 2.0, math.pi / 2, 2.0, MAX_RANGE_M)
        if k % 10 == 9:
            m.update(k * 0.05, (-10.0, 0.0), BODY_M)
    obstacles = m.obstacles((-10.0, 0.0))
    assert len(obstacles) == 3
    assert [round(Polygon(p).centroid.x) for p in obstacles] == [0, 4, 8]


def test_a_new_cell_size_starts_a_new_grid():
    params = replace(PARAMS)
    m = ObstacleMap(params)
    t = look_at_wall(m, 0.0, 3.0)
    params.cell_m = 0.25
    m.update(t, (0.0, 0.0), BODY_M)
    assert not m.cells


def test_a_cleared_map_holds_nothing_persistent_and_hands_the_planner_the_empty_set():
    """The autopilot clears the map when its frame changes: what it held was placed in the other
    frame, so not even the on-wall test of tracks may read it before the next update."""
    m = ObstacleMap(PARAMS)
    t = look_at_wall(m, 0.0, 3.0)
    assert m.near_persistent(0.0, 3.0, 0.3)
    assert m.obstacles((0.0, 0.0))
    handed_cells = len(m.persistent)
    m.clear()
    assert not m.persistent and not m.near_persistent(0.0, 3.0, 0.3)
    assert m.update(t + 0.5, (0.0, 0.0), BODY_M) == handed_cells
    assert not m.obstacles((0.0, 0.0))


@settings(max_examples=60, deadline=None)
@given(
    st.floats(-20, 20),
    st.floats(-20, 20),
    st.floats(-math.pi, math.pi),
    st.lists(st.tuples(st.floats(0.0, 1.2), st.floats(-math.pi, math.pi)), min_size=1, max_size=12),
)
def test_the_rover_is_never_inside_a_persistent_obstacle(east, north, heading, echoes):
    """Echoes anywhere around the rover, even under it (noise, its own wheels), seen long enough
    to persist: no polygon handed to the planner contains the rover's position."""
    m = ObstacleMap(PARAMS)
    for k in range(80):
        for range_m, bearing in echoes:
            m.add(k * 0.05, east, north, heading + bearing, range_m, MAX_RANGE_M)
        if k % 10 == 9:
            m.update(k * 0.05, (east, north), BODY_M)
    for polygon in m.obstacles((east, north)):
        assert not Polygon(polygon).contains(Point(east, north))
        assert Polygon(polygon).distance(Point(east, north)) >= BODY_M - PARAMS.simplify_m - PARAMS.cell_m * JOIN_FRACTION - 1e-9


def test_an_echo_where_a_beam_just_saw_free_space_adds_no_evidence():
    """A drum crossing a stopped rover's front beam: the beam saw the place free, then the drum's
    echo stood on the axis for 2 s. Something moved in: not a place to plan around, unless
    ``free_memory_s`` is 0 (the rule off)."""
    for memory_s, persistent in ((PARAMS.free_memory_s, False), (0.0, True)):
        m = ObstacleMap(replace(PARAMS, free_memory_s=memory_s))
        for k in range(10):  # half a second of nothing within 4 m
            m.add(k * 0.05, 0.0, 0.0, math.pi / 2, math.inf, MAX_RANGE_M)
        m.update(0.5, (0.0, 0.0), BODY_M)
        for k in range(40):  # then 2 s of echoes 2 m ahead
            m.add(0.5 + k * 0.05, 0.0, 0.0, math.pi / 2, 2.0, MAX_RANGE_M)
        m.update(2.5, (0.0, 0.0), BODY_M)
        assert bool(m.persistent) is persistent, memory_s


def test_a_wall_seen_free_long_before_is_persistent_again():
    """The rule forgets: after ``free_memory_s`` the echoes count (a parked cart becomes an obstacle)."""
    m = ObstacleMap(PARAMS)
    m.add(0.0, 0.0, 0.0, math.pi / 2, math.inf, MAX_RANGE_M)
    m.update(0.0, (0.0, 0.0), BODY_M)
    for k in range(80):
        m.add(PARAMS.free_memory_s + 0.1 + k * 0.05, 0.0, 0.0, math.pi / 2, 2.0, MAX_RANGE_M)
    m.update(PARAMS.free_memory_s + 4.2, (0.0, 0.0), BODY_M)
    assert m.persistent


def test_a_drum_crossing_a_stopped_rovers_beam_is_not_planned_around():
    """In-process runner, moving seed 93 with the map on: the rover stopped to let the crossing drum
    pass; the drum's echo stood still on the front beam's axis for 1.8 s (a track of its own, not
    the one yielded to), the cell became persistent and the re-plan around it led the rover into
    the walker coming down the leg. With the free-space rule it is never persistent. (The tracker of
    ``SURE_ECHOES`` and the memory's ``CONE_SECTORS``, the case's; pivot turns off and the map in the
    fused pose's frame, as when it was found: they move the encounter.)"""
    from rover_ctl.fuzzy import load_rulebase
    from rover_ctl.tuning.episode import Episode, episode_config

    def run(memory_s: float):
        config = episode_config(["obstacle_map.enabled=1", f"obstacle_map.free_memory_s={memory_s}", "pivot.angle_deg=0", "obstacle_map.odometry_frame=0",
                                *SURE_ECHOES, *CONE_SECTORS])  # fmt: skip
        return Episode(load_rulebase("default"), "moving", 93, config, start_s=30.0).run()

    assert run(PARAMS.free_memory_s).success
    assert not run(0.0).success
