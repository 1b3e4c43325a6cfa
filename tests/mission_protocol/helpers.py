"""Helpers for the mission-protocol tests (import as ``mission_protocol.helpers``): messages as they arrive from a given sender."""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as mav

from rover_ctl.mission.model import Home, Mission, MissionItem

HOME = Home(-35.363261, 149.165230, 584.0)
MAVPROXY = (255, 230)
MAVSDK = (245, 190)


def from_sender(msg, sender: tuple[int, int] = MAVPROXY):
    """``msg`` packed by ``sender`` and parsed back, as the service receives it."""
    tx = mav.MAVLink(None, srcSystem=sender[0], srcComponent=sender[1])
    rx = mav.MAVLink(None)
    return rx.decode(bytearray(msg.pack(tx)))


def sample_mission(n: int = 4) -> Mission:
    """``n`` waypoints north of CMAC home, one DO_CHANGE_SPEED, a fence and a rally point."""
    items = [MissionItem(16, x=HOME.lat_deg + 1e-4 * (i + 1), y=HOME.lon_deg + 5e-5 * i, z=0.0) for i in range(n)]
    items.insert(1, MissionItem(178, frame=2, param1=1.0, param2=1.5, param3=-1.0))
    fence = [MissionItem(5001, frame=0, param1=4.0, x=HOME.lat_deg + dy, y=HOME.lon_deg + dx)
             for dy, dx in ((-1e-3, -1e-3), (1e-3, -1e-3), (1e-3, 1e-3), (-1e-3, 1e-3))]  # fmt: skip
    rally = [MissionItem(5100, x=HOME.lat_deg, y=HOME.lon_deg + 2e-4, z=5.0)]
    return Mission(items=items, home=HOME, fence=fence, rally=rally)
