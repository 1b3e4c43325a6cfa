"""World files, obstacle motion, ray casting and the scatter generator."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from shapely.geometry import LineString, Point, Polygon

from sitl.geodesy import LocalFrame
from sitl.world import Home, LocalObstacle, LocalWorld, World, WorldError, load_world, parse_world, scatter_obstacles

ROOT = Path(__file__).resolve().parents[2]
HOME = Home(-35.363261, 149.165230, 584.0, 0.0)
FRAME = LocalFrame(HOME.lat_deg, HOME.lon_deg)


def lonlat(east, north):
    lat, lon = FRAME.to_latlon(east, north)
    return [float(lon), float(lat)]


def circle_feature(east, north, radius, **props):
    return {"type": "Feature", "geometry": {"type": "Point", "coordinates": lonlat(east, north)},
            "properties": {"radius_m": radius, **props}}


def square_feature(east, north, half, **props):
    ring = [lonlat(east + a, north + b) for a, b in ((-half, -half), (half, -half), (half, half), (-half, half), (-half, -half))]
    return {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [ring]}, "properties": props}


def collection(*features, **members):
    return {"type": "FeatureCollection", "features": list(features), **members}


def write(tmp_path, doc) -> Path:
    path = tmp_path / "world.geojson"
    path.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return path


def test_geodesy_round_trip_and_scale():
    east, north = FRAME.to_en(*FRAME.to_latlon(30.0, -55.0))
    assert (east, north) == pytest.approx((30.0, -55.0), abs=1e-6)
    lat, _ = FRAME.to_latlon(0.0, 111.0)
    assert lat - HOME.lat_deg == pytest.approx(0.001, rel=0.01)  # ~111 km per degree of latitude


@pytest.mark.parametrize("name", ["cmac_loop", "boulder_fence", "playground"])
def test_bundled_worlds_load_and_round_trip(name):
    world = load_world(ROOT / "missions" / "worlds" / f"{name}.geojson")
    assert world.obstacles and world.home is not None
    assert parse_world(json.loads(json.dumps(world.to_geojson()))) == world


def test_cmac_loop_world_has_a_moving_obstacle_and_passable_gaps():
    world = load_world(ROOT / "missions" / "worlds" / "cmac_loop.geojson")
    assert 5 <= len(world.obstacles) <= 8
    assert sum(o.motion is not None for o in world.obstacles) == 1
    local = world.local(LocalFrame(world.home.lat_deg, world.home.lon_deg))
    shapes = [o.shape(0.0) for o in local.obstacles]
    for i, a in enumerate(shapes):
        for b in shapes[i + 1:]:
            assert a.distance(b) >= 2.0
    legs = LineString([(0, 0), (0, 40), (30, 55), (55, 30), (35, 5), (0, 0)])
    assert sum(shape.distance(legs) < 1.0 for shape in shapes) >= 4, "obstacles sit on or near the legs"
    for waypoint in [(0, 0), (0, 40), (30, 55), (55, 30), (35, 5)]:
        assert all(shape.distance(Point(waypoint)) > 3.0 for shape in shapes)


@pytest.mark.parametrize("doc, message", [
    ("{ not json", "not valid JSON"),
    (collection({"type": "Feature", "geometry": {"type": "LineString", "coordinates": [[0, 0], [1, 1]]}}),
     "feature 0: unsupported geometry 'LineString'"),
    (collection(square_feature(0, 5, 1), {"type": "Feature", "geometry": {"type": "Point", "coordinates": [149.1, -35.3]},
                                          "properties": {}}), "feature 1: a Point obstacle needs properties.radius_m"),
    (collection(circle_feature(0, 5, -1)), "feature 0: radius_m must be > 0"),
    (collection({"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [[[0, 0], [1, 1], [1, 0], [0, 1], [0, 0]]]}}),
     "feature 0: Polygon is self-intersecting"),
    (collection({"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [[[0, 0], [1, 1], [0, 0]]]}}),
     "feature 0: a Polygon needs at least 3 distinct vertices"),
    (collection({"type": "Feature", "geometry": {"type": "Point", "coordinates": [200, 10]}, "properties": {"radius_m": 1}}),
     "feature 0: Point [200.0, 10.0] is not a [lon, lat] position"),
    (collection(circle_feature(0, 5, 1, motion={"type": "teleport"})), "feature 0: unknown motion type 'teleport'"),
    (collection(circle_feature(0, 5, 1, motion={"type": "velocity", "velocity_mps": [1e308, 0]})), "feature 0: motion velocity_mps 1e+308 m/s is over 50"),
    (collection(circle_feature(0, 5, 1, motion={"type": "waypoints", "path": [lonlat(0, 0), lonlat(1, 0)], "speed_mps": 1e308})),
     "feature 0: motion speed_mps must be > 0 and <= 50, got 1e+308"),
    (collection(circle_feature(0, 5, 1, motion={"type": "waypoints", "path": [lonlat(0, 0)], "speed_mps": 1})),
     "feature 0: motion path must list at least 2"),
    (collection(circle_feature(0, 5, 1, id="a"), circle_feature(0, 9, 1, id="a")), "obstacle id 'a' is used twice"),
    (collection(faults=[{"name": "gps_outage", "start_s": 1}]), "faults[0]: gps_outage: 'duration_s' must be a number"),
    (collection(faults=[{"name": "meteor", "start_s": 1, "duration_s": 1}]), "faults[0]: unknown fault 'meteor'"),
    (collection(faults=[{"name": "gps_outage", "start_s": 1e308, "duration_s": 1e308}]), "faults[0]: gps_outage: start_s must be"),
    (collection(home=[149.1, -35.3, 584]), "home: expected [lon, lat, alt_m, heading_deg]"),
    (collection(home=[149.1, -35.3, 584, 1e300]), "home: need"),  # the heading --home takes: 0 <= heading < 360
    (collection(home=[149.1, -35.3, 584, -90]), "home: need"),
    (collection(home=[149.1, -35.3, 1e7, 0]), "home: need"),
    ({"type": "Feature"}, "expected a GeoJSON FeatureCollection"),
    (json.dumps(collection(circle_feature(0, 5, 1))).replace('"radius_m": 1', '"radius_m": ' + "9" * 400),
     "feature 0: radius_m must be a finite number"),
    (json.dumps(collection(circle_feature(0, 5, 1))).replace('"coordinates": [', '"coordinates": [' + "9" * 400 + ", ", 1),
     "feature 0: Point longitude must be a finite number"),
    (json.dumps(collection(faults=[{"name": "gps_outage", "start_s": 1, "duration_s": 1}])).replace('"start_s": 1', '"start_s": ' + "9" * 5000),
     "faults[0]: gps_outage: 'start_s' must be a number"),
    ("[" * 100_000 + "]" * 100_000, "not a world file: JSON nested too deeply"),
    # sizes within a world's extent (10 km): a radius of 1e300 m ran with a garbage obstacle after a shapely overflow
    (collection(circle_feature(0, 5, 1e300)), "feature 0: radius_m must be > 0 and <= 10000 m (a world's extent), got 1e+300"),
    (collection(circle_feature(0, 5, 10_001)), "feature 0: radius_m must be > 0 and <= 10000 m"),
    (collection(square_feature(0, 5, 1), {"type": "Feature", "properties": {}, "geometry": {"type": "Polygon", "coordinates": [
        [lonlat(0, 0), lonlat(0, 20_000), lonlat(10, 10), lonlat(0, 0)]]}}), "feature 1: vertex 1 is 20000 m from vertex 0, over 10000 m"),
    (collection(circle_feature(0, 5, 1, motion={"type": "waypoints", "path": [lonlat(0, 5), lonlat(0, 10), [-30.83, 35.36]], "speed_mps": 1})),
     "feature 0: motion path point 2 is 2000"),  # the antipode
    (collection(faults=[{"name": "gps_glitch", "start_s": 1, "duration_s": 1, "north_m": 1e300, "east_m": 0}]),
     "faults[0]: SIM_GPS_GLITCH_X: 1e+300 is outside -10000..10000"),
])
def test_bad_world_files_give_one_line_errors_naming_file_and_feature(tmp_path, doc, message):
    path = write(tmp_path, doc)
    with pytest.raises(WorldError) as err:
        load_world(path)
    text = str(err.value)
    assert text.startswith(f"{path}: ")
    assert message in text
    assert "\n" not in text


def test_missing_file_is_a_world_error(tmp_path):
    with pytest.raises(WorldError, match="cannot read"):
        load_world(tmp_path / "absent.geojson")


@pytest.mark.parametrize("kind", ["device", "fifo", "directory"])
def test_a_file_that_is_not_regular_is_refused_unread(tmp_path, kind):
    """/dev/zero was read forever; a FIFO without a writer blocks in open()."""
    import os

    path = {"device": Path("/dev/zero"), "fifo": tmp_path / "world.fifo", "directory": tmp_path}[kind]
    if kind == "fifo":
        os.mkfifo(path)
    with pytest.raises(WorldError) as err:
        load_world(path)
    assert str(err.value) == f"{path}: not a regular file (a device, FIFO or directory is not a world file)"


def test_a_file_over_the_size_limit_is_refused_after_reading_the_limit(tmp_path):
    from sitl.world import MAX_WORLD_BYTES

    doc = json.dumps(collection(circle_feature(0, 5, 1)))
    path = write(tmp_path, doc + " " * (MAX_WORLD_BYTES - len(doc)))
    assert len(load_world(path).obstacles) == 1  # at the limit: read
    with path.open("a") as file:
        file.write(" ")
    with pytest.raises(WorldError, match=r"larger than 4 MiB, the most a world file may be"):
        load_world(path)


def test_obstacle_motion_velocity_and_waypoint_loops():
    doc = collection(
        circle_feature(0, 10, 0.5, id="v", motion={"type": "velocity", "velocity_mps": [1.0, -0.5]}),
        circle_feature(0, 0, 0.5, id="loop", motion={"type": "waypoints", "path": [lonlat(0, 0), lonlat(10, 0), lonlat(10, 10)],
                                                     "speed_mps": 2.0, "loop": True}),
        circle_feature(0, 0, 0.5, id="once", motion={"type": "waypoints", "path": [lonlat(0, 0), lonlat(4, 0)],
                                                     "speed_mps": 1.0, "loop": False}),
    )
    local = {o.id: o for o in parse_world(doc).local(FRAME).obstacles}
    assert local["v"].ref_at(4.0) == pytest.approx((4.0, 8.0), abs=1e-6)
    assert local["loop"].ref_at(2.5) == pytest.approx((5.0, 0.0), abs=1e-6)
    assert local["loop"].ref_at(7.5) == pytest.approx((10.0, 5.0), abs=1e-6)
    perimeter = 20 + math.hypot(10, 10)
    assert local["loop"].ref_at(perimeter / 2.0) == pytest.approx((0.0, 0.0), abs=1e-6)  # closed back to the start
    assert local["once"].ref_at(100.0) == pytest.approx((4.0, 0.0), abs=1e-6)
    assert local["loop"].shape(2.5).centroid.x == pytest.approx(5.0, abs=1e-3)


def test_a_motion_may_start_when_the_rover_first_arms():
    doc = collection(
        circle_feature(0, 10, 0.5, id="armed", motion={"type": "velocity", "velocity_mps": [1.0, 0.0], "start": "armed"}),
        circle_feature(0, 0, 0.5, id="boot", motion={"type": "velocity", "velocity_mps": [1.0, 0.0]}),
    )
    world = parse_world(doc)
    assert world == parse_world(world.to_geojson())  # "start" written back as read
    local = world.local(FRAME)
    armed, boot = local.obstacles
    assert armed.ref_at(5.0) == pytest.approx((0.0, 10.0), abs=1e-6)  # waits, drawn where it is
    assert boot.ref_at(5.0) == pytest.approx((5.0, 0.0), abs=1e-6)
    local.armed(5.0)
    local.armed(9.0)  # only the first arming counts
    assert armed.ref_at(7.0) == pytest.approx((2.0, 10.0), abs=1e-6)
    assert local.ray_cast((2.0, 0.0), math.pi / 2, 20.0, 7.0)[1] == "armed"
    with pytest.raises(WorldError, match="motion start"):
        parse_world(collection(circle_feature(0, 0, 0.5, motion={"type": "velocity", "velocity_mps": [1, 0], "start": "later"})))


def test_ray_casting_against_circles_and_polygons():
    world = parse_world(collection(circle_feature(0, 10, 1.0, id="c"), square_feature(10, 0, 1.0, id="p"))).local(FRAME)
    north, east = math.pi / 2, 0.0
    assert world.ray_cast((0, 0), north, 20.0, 0.0) == pytest.approx((9.0, "c"), abs=1e-6)
    assert world.ray_cast((0, 0), east, 20.0, 0.0) == pytest.approx((9.0, "p"), abs=1e-6)
    assert world.ray_cast((0, 0), north, 8.0, 0.0) is None  # beyond max range
    assert world.ray_cast((0, 0), -north, 20.0, 0.0) is None  # behind
    # Grazing the circle 0.5 m off its centre: chord geometry.
    assert world.ray_cast((0.5, 0), north, 20.0, 0.0)[0] == pytest.approx(10 - math.sqrt(0.75), abs=1e-6)
    assert world.ray_cast((1.2, 0), north, 20.0, 0.0) is None
    # Oblique hit on the square's west face (x = 9) from the origin.
    angle = math.atan2(0.5, 9.0)
    assert world.ray_cast((0, 0), angle, 20.0, 0.0)[0] == pytest.approx(math.hypot(9.0, 0.5), abs=1e-6)
    assert world.ray_cast((0, 10), north, 20.0, 0.0)[0] == 0.0  # from inside the circle


def test_ray_casting_sees_a_moving_obstacle_where_it_is():
    obstacle = LocalObstacle("m", "circle", (0.0, 10.0), 1.0, [], None, (0.0, -1.0), 0.0, True)
    world = LocalWorld([obstacle])
    assert world.ray_cast((0, 0), math.pi / 2, 20.0, 3.0)[0] == pytest.approx(6.0, abs=1e-9)


def test_scatter_keeps_gaps_and_clear_waypoints_and_is_seeded():
    legs = [(-35.363261, 149.165230), *(tuple(reversed(lonlat(e, n))) for e, n in [(0, 40), (30, 55), (55, 30)])]
    world = scatter_obstacles(legs, 12, seed=7)
    assert len(world.obstacles) == 12
    assert world == scatter_obstacles(legs, 12, seed=7)
    assert world != scatter_obstacles(legs, 12, seed=8)
    local = world.local(FRAME)
    shapes = [o.shape(0.0) for o in local.obstacles]
    for i, a in enumerate(shapes):
        assert all(a.distance(b) >= 2.0 for b in shapes[i + 1:])
    waypoints = [Point(0, 0), Point(0, 40), Point(30, 55), Point(55, 30)]
    polyline = LineString([(p.x, p.y) for p in waypoints])
    for shape in shapes:
        assert min(shape.distance(w) for w in waypoints) >= 4.0 - 1e-6
        assert shape.centroid.distance(polyline) <= 2.5 + 0.9  # centre within lateral_m, plus its size
    assert {o.kind for o in world.obstacles} == {"circle", "polygon"}
    assert parse_world(world.to_geojson()) == world


def test_scatter_refuses_an_impossible_request():
    legs = [(-35.363261, 149.165230), tuple(reversed(lonlat(0, 12)))]
    with pytest.raises(WorldError, match="placed only"):
        scatter_obstacles(legs, 30, seed=1, max_tries=500)


def test_world_without_obstacles_is_valid():
    assert parse_world(collection()) == World()
    assert World().local(FRAME).near((0, 0), 10.0, 0.0) == []


def test_boulder_world_fits_the_bundled_plan():
    """Obstacles inside the plan's inclusion fence, clear of its exclusion zone and waypoints."""
    plan = json.loads((ROOT / "missions" / "boulder_fence.plan").read_text())
    world = load_world(ROOT / "missions" / "worlds" / "boulder_fence.geojson")
    home = plan["mission"]["plannedHomePosition"]
    assert (world.home.lat_deg, world.home.lon_deg) == pytest.approx(tuple(home[:2]))
    frame = LocalFrame(world.home.lat_deg, world.home.lon_deg)
    shapes = [o.shape(0.0) for o in world.local(frame).obstacles]

    def local_polygon(points):
        return Polygon([frame.to_en(lat, lon) for lat, lon in points])

    fences = plan["geoFence"]["polygons"]
    inclusion = [local_polygon(f["polygon"]) for f in fences if f["inclusion"]]
    exclusion = [local_polygon(f["polygon"]) for f in fences if not f["inclusion"]]
    waypoints = [Point(frame.to_en(i["params"][4], i["params"][5])) for i in plan["mission"]["items"] if i.get("command") == 16]
    assert inclusion and exclusion and waypoints
    for shape in shapes:
        assert all(zone.contains(shape) for zone in inclusion)
        assert all(shape.distance(zone) > 2.0 for zone in exclusion)
        assert all(shape.distance(w) > 3.0 for w in waypoints)
