"""The local frame against pyproj's geodesic, and the heading conventions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pyproj import Geod

from rover_ctl.estimation.frame import LocalFrame, compass_to_enu_rad, enu_to_compass_rad, wrap_pi

WGS84 = Geod(ellps="WGS84")


def geodesic_enu(frame: LocalFrame, lat_deg: float, lon_deg: float) -> tuple[float, float]:
    """East/north of a point from the geodesic distance and azimuth from home."""
    azimuth_deg, _, distance_m = WGS84.inv(frame.lon_deg, frame.lat_deg, lon_deg, lat_deg)
    return distance_m * math.sin(math.radians(azimuth_deg)), distance_m * math.cos(math.radians(azimuth_deg))


def test_home_is_origin_and_small_offsets_are_metres():
    frame = LocalFrame(-35.363261, 149.165230, 584.0)
    assert frame.to_enu(-35.363261, 149.165230) == pytest.approx((0.0, 0.0), abs=1e-9)
    # 40 m north along the meridian: the geodesic says how many degrees that is.
    lon, lat, _ = WGS84.fwd(149.165230, -35.363261, 0.0, 40.0)
    east_m, north_m = frame.to_enu(lat, lon)
    assert east_m == pytest.approx(0.0, abs=1e-6) and north_m == pytest.approx(40.0, abs=1e-6)


@pytest.mark.parametrize("azimuth_deg", [0.0, 37.0, 90.0, 200.0, 300.0])
def test_five_km_from_home_matches_geodesic(azimuth_deg):
    frame = LocalFrame(40.071377, -105.229790, 1584.0)
    lon, lat, _ = WGS84.fwd(frame.lon_deg, frame.lat_deg, azimuth_deg, 5000.0)
    east_m, north_m = frame.to_enu(lat, lon)
    assert (east_m, north_m) == pytest.approx(geodesic_enu(frame, lat, lon), abs=1e-6)
    assert math.hypot(east_m, north_m) == pytest.approx(5000.0, abs=1e-6)
    assert frame.to_geodetic(east_m, north_m) == pytest.approx((lat, lon), abs=1e-10)


def test_distances_between_two_far_points_are_exact_to_a_millimetre():
    frame = LocalFrame(-35.363261, 149.165230)
    a = frame.to_geodetic(3000.0, 4000.0)
    b = frame.to_geodetic(-2000.0, 3500.0)
    _, _, geodesic_m = WGS84.inv(a[1], a[0], b[1], b[0])
    assert math.dist((3000.0, 4000.0), (-2000.0, 3500.0)) == pytest.approx(geodesic_m, abs=1e-3)


def test_antimeridian_points_are_metres_apart():
    frame = LocalFrame(-16.5, 179.9995)  # Fiji, 50 m west of the antimeridian
    east_m, north_m = frame.to_enu(-16.5, -179.9995)
    assert (east_m, north_m) == pytest.approx(geodesic_enu(frame, -16.5, -179.9995), abs=1e-6)
    assert 100.0 < east_m < 110.0 and abs(north_m) < 0.01
    lat, lon = frame.to_geodetic(east_m, north_m)
    assert lat == pytest.approx(-16.5, abs=1e-10) and lon == pytest.approx(-179.9995, abs=1e-10)
    lat, lon = frame.to_geodetic(-30.0, 0.0)
    assert lon == pytest.approx(179.9995 - 30.0 / 106.7e3, abs=2e-6)


def test_arrays_round_trip_and_scalars_stay_scalars():
    frame = LocalFrame(51.5, -0.12)
    rng = np.random.default_rng(4)
    east = rng.uniform(-5000, 5000, 200)
    north = rng.uniform(-5000, 5000, 200)
    lat, lon = frame.to_geodetic(east, north)
    assert isinstance(lat, np.ndarray) and lat.shape == (200,)
    back_e, back_n = frame.to_enu(lat, lon, alt_m=np.full(200, 30.0))
    assert np.max(np.abs(back_e - east)) < 1e-6 and np.max(np.abs(back_n - north)) < 1e-6
    assert isinstance(frame.to_enu(51.5, -0.12)[0], float)
    assert isinstance(frame.to_geodetic(1.0, 2.0)[1], float)


@pytest.mark.parametrize("bad", [(91.0, 0.0, 0.0), (math.nan, 0.0, 0.0), (0.0, math.inf, 0.0), (0.0, 0.0, math.nan)])
def test_bad_home_is_refused_with_a_message(bad):
    with pytest.raises(ValueError, match="LocalFrame: home"):
        LocalFrame(*bad)


def test_heading_conventions():
    assert compass_to_enu_rad(0.0) == pytest.approx(math.pi / 2)  # north
    assert compass_to_enu_rad(math.pi / 2) == pytest.approx(0.0)  # east
    assert compass_to_enu_rad(math.pi) == pytest.approx(-math.pi / 2)  # south
    assert enu_to_compass_rad(math.pi) == pytest.approx(3 * math.pi / 2)  # west
    angles = np.linspace(-3.0, 3.0, 13)
    assert np.allclose(compass_to_enu_rad(enu_to_compass_rad(angles)), angles)
    assert np.all((enu_to_compass_rad(angles) >= 0) & (enu_to_compass_rad(angles) < 2 * math.pi))
    assert wrap_pi(3 * math.pi) == pytest.approx(-math.pi)
    assert np.allclose(wrap_pi(np.array([4.0, -4.0])), [4.0 - 2 * math.pi, 2 * math.pi - 4.0])


def test_bearing_distance():
    frame = LocalFrame(0.0, 0.0)
    bearing, distance = frame.bearing_distance((1.0, 1.0), (1.0, 4.0))
    assert bearing == pytest.approx(math.pi / 2) and distance == pytest.approx(3.0)
