"""The project's bundled missions (missions/*.waypoints, *.plan), defined in metres east/north of
home and converted to latitude/longitude in the daemon's own local frame (``rover_ctl.estimation.frame``).

``python tests/mission_files/bundled.py`` rewrites the files with ``save_mission``;
``test_bundled.py`` checks that the committed files are exactly what these definitions give.
Coordinates are rounded to 1e-7 degrees (the MAVLink wire precision, about 1 cm) so that the
files, the uploaded mission and a download of it are identical.
"""

from __future__ import annotations

import sys
from pathlib import Path

from rover_ctl.estimation.frame import LocalFrame
from rover_ctl.mission.files import save_mission
from rover_ctl.mission.model import FRAME_GLOBAL, FRAME_GLOBAL_RELATIVE_ALT, FRAME_MISSION, Cmd, Home, Mission, MissionItem

MISSIONS = Path(__file__).resolve().parents[2] / "missions"
WIRE_DECIMALS = 7
SPEED_TYPE_GROUND = 1.0
"""DO_CHANGE_SPEED param1: ground speed."""
THROTTLE_UNCHANGED = -1.0

CMAC_HOME = Home(-35.363261, 149.165230, 584.0)
BOULDER_HOME = Home(40.071377, -105.229790, 1584.0)


def _latlon(frame: LocalFrame, east_m: float, north_m: float) -> tuple[float, float]:
    lat_deg, lon_deg = frame.to_geodetic(east_m, north_m)
    return round(lat_deg, WIRE_DECIMALS), round(lon_deg, WIRE_DECIMALS)


def waypoint(frame: LocalFrame, east_m: float, north_m: float) -> MissionItem:
    lat_deg, lon_deg = _latlon(frame, east_m, north_m)
    return MissionItem(Cmd.NAV_WAYPOINT, FRAME_GLOBAL_RELATIVE_ALT, x=lat_deg, y=lon_deg)


def fence_polygon(frame: LocalFrame, corners_en: list[tuple[float, float]], inclusion: bool) -> list[MissionItem]:
    command = Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION if inclusion else Cmd.NAV_FENCE_POLYGON_VERTEX_EXCLUSION
    return [
        MissionItem(command, FRAME_GLOBAL, param1=float(len(corners_en)), x=lat, y=lon, autocontinue=False)
        for lat, lon in (_latlon(frame, e, n) for e, n in corners_en)
    ]


def cmac_loop() -> Mission:
    """Four legs around the CMAC field and back home (the demo mission)."""
    frame = LocalFrame(CMAC_HOME.lat_deg, CMAC_HOME.lon_deg, CMAC_HOME.alt_m)
    legs = [waypoint(frame, e, n) for e, n in ((0, 40), (30, 55), (55, 30), (35, 5))]
    return Mission(items=[*legs, MissionItem(Cmd.NAV_RETURN_TO_LAUNCH, FRAME_MISSION)], home=CMAC_HOME)


def cmac_jump() -> Mission:
    """Two short legs repeated once by DO_JUMP, then back to the start point (for tests)."""
    frame = LocalFrame(CMAC_HOME.lat_deg, CMAC_HOME.lon_deg, CMAC_HOME.alt_m)
    first, second, last = (waypoint(frame, e, n) for e, n in ((0, 15), (15, 15), (0, 0)))
    jump = MissionItem(Cmd.DO_JUMP, FRAME_MISSION, param1=1.0, param2=1.0)  # to seq 1 (first), repeat once
    return Mission(items=[first, second, jump, last], home=CMAC_HOME)


def boulder_fence() -> Mission:
    """Three waypoints at the SparkFun AVC lot inside an inclusion fence, with an exclusion zone
    across the straight line between the first two, and one rally point."""
    frame = LocalFrame(BOULDER_HOME.lat_deg, BOULDER_HOME.lon_deg, BOULDER_HOME.alt_m)
    speed = MissionItem(Cmd.DO_CHANGE_SPEED, FRAME_MISSION, param1=SPEED_TYPE_GROUND, param2=1.2, param3=THROTTLE_UNCHANGED)
    legs = [waypoint(frame, e, n) for e, n in ((10, 25), (60, 25), (60, -10))]
    rtl = MissionItem(Cmd.NAV_RETURN_TO_LAUNCH, FRAME_MISSION)
    fence = fence_polygon(frame, [(-15, -25), (80, -25), (80, 45), (-15, 45)], inclusion=True)
    fence += fence_polygon(frame, [(31, 20), (39, 20), (39, 30), (31, 30)], inclusion=False)
    rally_lat, rally_lon = _latlon(frame, -5, -10)
    rally = [MissionItem(Cmd.NAV_RALLY_POINT, FRAME_GLOBAL_RELATIVE_ALT, x=rally_lat, y=rally_lon, autocontinue=False)]
    return Mission(items=[speed, *legs, rtl], home=BOULDER_HOME, fence=fence, rally=rally)


BUNDLED = {
    "cmac_loop.waypoints": cmac_loop,
    "cmac_jump.waypoints": cmac_jump,
    "boulder_fence.plan": boulder_fence,
}


def main() -> int:
    for name, build in BUNDLED.items():
        save_mission(build(), MISSIONS / name)
        print(f"wrote {MISSIONS / name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
