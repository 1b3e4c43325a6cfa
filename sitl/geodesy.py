"""Geodetic lat/lon <-> local east/north metres about a home point: the world's truth frame.

The frame is pyproj's azimuthal equidistant projection centred on home on the WGS84 ellipsoid:
distances and bearings from home are exact, and over a rover's few hundred metres it agrees with a
local tangent plane (ENU) to well under a millimetre.
"""

from __future__ import annotations

from functools import lru_cache

from pyproj import Geod, Transformer

WORLD_EXTENT_M = 10_000.0
"""How far a world reaches: a rover's mission spans metres to a few kilometres, so an obstacle
larger than this (a circle's radius, a polygon's or a motion path's reach from its first point) or
a GPS glitch farther than this is a mistake in the file, not a scenario (a radius of 1e300 m
overflowed shapely and ran with a garbage obstacle)."""
_GEOD = Geod(ellps="WGS84")


def distances_m(lon0_deg: float, lat0_deg: float, lonlats) -> list[float]:
    """Geodesic distances on WGS84 from (lon0, lat0) to each [lon, lat] of ``lonlats``."""
    lons, lats = [p[0] for p in lonlats], [p[1] for p in lonlats]
    return list(_GEOD.inv([lon0_deg] * len(lons), [lat0_deg] * len(lats), lons, lats)[2])


@lru_cache(maxsize=16)
def _aeqd(lat0_deg: float, lon0_deg: float) -> Transformer:
    """WGS84 (lon, lat) <-> the azimuthal equidistant plane about home, in metres. One per home:
    building one takes PROJ about 7 ms, and the in-process episode runner builds worlds about the
    same home for every episode (pyproj's Transformer is thread-safe since 3.1)."""
    return Transformer.from_crs("EPSG:4326", f"+proj=aeqd +lat_0={lat0_deg!r} +lon_0={lon0_deg!r} +ellps=WGS84 +units=m",
                                always_xy=True)  # fmt: skip


class LocalFrame:
    """East/north metres about (lat0_deg, lon0_deg)."""

    def __init__(self, lat0_deg: float, lon0_deg: float) -> None:
        self.lat0_deg = lat0_deg
        self.lon0_deg = lon0_deg
        self._forward = _aeqd(lat0_deg, lon0_deg)

    def to_en(self, lat_deg, lon_deg):
        """(east_m, north_m) of a point, or of arrays of points."""
        return self._forward.transform(lon_deg, lat_deg)

    def to_latlon(self, east_m, north_m):
        """(lat_deg, lon_deg) of a local point, or of arrays of points."""
        lon, lat = self._forward.transform(east_m, north_m, direction="INVERSE")
        return lat, lon
