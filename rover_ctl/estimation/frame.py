"""The local frame: geodetic latitude/longitude <-> metres east/north of home, and heading
conventions.

The frame is PROJ's ellipsoidal azimuthal equidistant projection (``+proj=aeqd``, WGS84) centred
on home. It is a local ENU (east, north) plane tangent at home in which the distance and the
bearing *from home* of every point are the exact WGS84 geodesic ones (PROJ solves the geodesic
with Karney's algorithm), so

* along a radius from home the scale is exactly 1, and across it the scale is
  ``(d/R) / sin(d/R) ~ 1 + d^2 / (6 R^2)``: a relative length error of 1e-7 at 5 km
  (0.5 mm over 5 km) and 1e-5 at 50 km; a rover mission of a few kilometres is exact to well
  under a millimetre, far below GPS noise;
* the round trip geodetic -> ENU -> geodetic is exact to ~1e-9 m at any distance used here;
* longitudes are differenced on the ellipsoid, so home and points on either side of the
  antimeridian (179.99 and -179.99) are metres apart, not a planet apart.

Altitude does not enter the horizontal frame (a GPS altitude error of tens of metres moves a
point by ``h * d / R``, millimetres at mission range), so ``to_enu`` accepts an ``alt_m`` for
callers holding one but does not use it.

Headings: the wire (ATTITUDE yaw, GPS course, mission yaw) is compass/NED: 0 north, clockwise
positive. Inside the daemon headings are ENU: 0 east, counter-clockwise positive. The two are
related by ``heading_enu = pi/2 - yaw_ned``, an involution (the same formula maps back).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from pyproj import Transformer


@lru_cache(maxsize=16)
def _aeqd(lat_deg: float, lon_deg: float) -> Transformer:
    """WGS84 (lon, lat) <-> the azimuthal equidistant plane about (lat, lon), in metres. One per
    home: building one takes PROJ about 7 ms, and the episode runner builds a frame about the
    same home for every episode (pyproj's Transformer is thread-safe since 3.1)."""
    # always_xy: the transformer takes (lon, lat) in and gives (east, north) out.
    return Transformer.from_crs("EPSG:4326", f"+proj=aeqd +lat_0={lat_deg!r} +lon_0={lon_deg!r} +ellps=WGS84 +units=m +no_defs",
                                always_xy=True)  # fmt: skip


class LocalFrame:
    """East/north metres relative to a home point (``lat_deg``, ``lon_deg``, ``alt_m``)."""

    def __init__(self, lat_deg: float, lon_deg: float, alt_m: float = 0.0) -> None:
        if not (math.isfinite(lat_deg) and -90.0 <= lat_deg <= 90.0):
            raise ValueError(f"LocalFrame: home latitude {lat_deg!r} is not within [-90, 90] degrees")
        if not (math.isfinite(lon_deg) and -180.0 <= lon_deg <= 360.0):
            raise ValueError(f"LocalFrame: home longitude {lon_deg!r} is not within [-180, 360] degrees")
        if not math.isfinite(alt_m):
            raise ValueError(f"LocalFrame: home altitude {alt_m!r} is not a finite number")
        self.lat_deg = float(lat_deg)
        self.lon_deg = float(lon_deg)
        self.alt_m = float(alt_m)
        self._proj = _aeqd(self.lat_deg, self.lon_deg)

    def __repr__(self) -> str:
        return f"LocalFrame(lat_deg={self.lat_deg!r}, lon_deg={self.lon_deg!r}, alt_m={self.alt_m!r})"

    def to_enu(self, lat_deg, lon_deg, alt_m=None):
        """(east_m, north_m) of geodetic point(s); scalars in, floats out; arrays in, arrays out.
        ``alt_m`` is accepted and ignored: the horizontal frame does not depend on height."""
        del alt_m
        east_m, north_m = self._proj.transform(lon_deg, lat_deg)
        return _same_kind(east_m, lat_deg), _same_kind(north_m, lat_deg)

    def to_geodetic(self, east_m, north_m):
        """(lat_deg, lon_deg) of local point(s); longitude in [-180, 180)."""
        lon_deg, lat_deg = self._proj.transform(east_m, north_m, direction="INVERSE")
        lon_deg = (np.asarray(lon_deg, dtype=float) + 180.0) % 360.0 - 180.0
        return _same_kind(lat_deg, east_m), _same_kind(lon_deg, east_m)

    def bearing_distance(self, from_en: tuple[float, float], to_en: tuple[float, float]) -> tuple[float, float]:
        """ENU heading (rad) and planar distance (m) from one local point to another."""
        de = to_en[0] - from_en[0]
        dn = to_en[1] - from_en[1]
        return math.atan2(dn, de), math.hypot(de, dn)


def _same_kind(value, like):
    """A Python float when the caller passed a scalar, else a float numpy array."""
    if np.ndim(like) == 0:
        return float(np.asarray(value))
    return np.asarray(value, dtype=float)


def wrap_pi(angle_rad):
    """Angle(s) wrapped to [-pi, pi); works on floats and numpy arrays alike."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def compass_to_enu_rad(yaw_ned_rad):
    """NED/compass yaw (0 north, clockwise) -> ENU heading (0 east, counter-clockwise), wrapped."""
    return wrap_pi(math.pi / 2.0 - yaw_ned_rad)


def enu_to_compass_rad(heading_rad):
    """ENU heading -> compass yaw in [0, 2 pi) (0 north, clockwise), as MAVLink reports yaw."""
    return (math.pi / 2.0 - heading_rad) % (2.0 * math.pi)
