"""Geodetic lat/lon <-> local east/north metres about a home point: the world's truth frame.

The frame is pyproj's azimuthal equidistant projection centred on home on the WGS84 ellipsoid:
distances and bearings from home are exact, and over a rover's few hundred metres it agrees with a
local tangent plane (ENU) to well under a millimetre.
"""

from __future__ import annotations

from pyproj import Transformer


class LocalFrame:
    """East/north metres about (lat0_deg, lon0_deg)."""

    def __init__(self, lat0_deg: float, lon0_deg: float) -> None:
        self.lat0_deg = lat0_deg
        self.lon0_deg = lon0_deg
        local = f"+proj=aeqd +lat_0={lat0_deg!r} +lon_0={lon0_deg!r} +ellps=WGS84 +units=m"
        self._forward = Transformer.from_crs("EPSG:4326", local, always_xy=True)

    def to_en(self, lat_deg, lon_deg):
        """(east_m, north_m) of a point, or of arrays of points."""
        return self._forward.transform(lon_deg, lat_deg)

    def to_latlon(self, east_m, north_m):
        """(lat_deg, lon_deg) of a local point, or of arrays of points."""
        lon, lat = self._forward.transform(east_m, north_m, direction="INVERSE")
        return lat, lon
