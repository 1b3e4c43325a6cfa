"""The files we write, read by other tools' own parsers: pymavlink's mavwp loaders (what MAVProxy's
``wp load``, ``fence load`` and ``rally load`` use) for WPL, and MAVSDK's
``import_qgroundcontrol_mission`` (QGroundControl's .plan reader in C++) for .plan. Each must see
exactly the items of our model."""

from __future__ import annotations

import asyncio
import math
import os
import threading
from pathlib import Path

import pytest

os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil, mavwp  # noqa: E402

from rover_ctl.mission.files import load_mission, save_mission  # noqa: E402
from rover_ctl.mission.model import Mission, MissionItem  # noqa: E402
from rover_ctl.mission.wpl import format_wpl  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
OWN = sorted(p for p in (ROOT / "missions").iterdir() if p.suffix in (".waypoints", ".plan"))
SHARED = [
    "ardupilot_rover1.txt",
    "ardupilot_rover_path_planning_fence.txt",
    "ardupilot_rover_test_rally.txt",
    "px4_rover_mission_1.plan",
    "qgc_ce_geofence_home_base.plan",
    "sitlmodels_wildthumper_playpen_mission.txt",
]
FLOAT32_REL = 1e-6
HEARTBEAT_PERIOD_S = 0.1
AUTOPILOT_WAIT_S = 5.0


def close(a: float, b: float) -> bool:
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    return math.isclose(a, b, rel_tol=FLOAT32_REL, abs_tol=1e-6)


def assert_same(ours: MissionItem, theirs, latlon_scale: float) -> None:
    """``theirs`` is a MISSION_ITEM(_INT)-like object; lat/lon are divided by ``latlon_scale``."""
    assert (theirs.command, theirs.frame, bool(theirs.autocontinue)) == (ours.command, ours.frame, ours.autocontinue)
    for name in ("param1", "param2", "param3", "param4"):
        assert close(getattr(theirs, name), getattr(ours, name)), name
    assert abs(theirs.x / latlon_scale - ours.x) <= 1e-7 and abs(theirs.y / latlon_scale - ours.y) <= 1e-7
    assert close(theirs.z, ours.z)


def wpl_lists(mission: Mission) -> list[tuple[int, list[MissionItem]]]:
    return [(t, mission.of_type(t)) for t in (0, 1, 2) if mission.of_type(t)] or [(0, [])]


@pytest.mark.parametrize("source", [*OWN, *SHARED], ids=lambda s: getattr(s, "name", s))
def test_mavproxy_loaders_read_our_wpl(shared_dir, tmp_path, source):
    path = source if isinstance(source, Path) else shared_dir / "missions" / source
    mission = load_mission(path).mission
    for mission_type, items in wpl_lists(mission):
        out = tmp_path / f"list{mission_type}.waypoints"
        out.write_text(format_wpl(items, mission_type, mission.home))
        loader = {0: mavwp.MAVWPLoader, 1: mavwp.MissionItemProtocol_Fence, 2: mavwp.MissionItemProtocol_Rally}[mission_type]()
        loader.load(str(out))
        theirs = [loader.wp(i) for i in range(loader.count())]
        if mission_type == 0:
            home = theirs.pop(0)
            assert (home.x, home.y) == ((mission.home.lat_deg, mission.home.lon_deg) if mission.home else (0.0, 0.0))
        assert len(theirs) == len(items)
        for ours, their in zip(items, theirs):
            assert_same(ours, their, latlon_scale=1.0)


def heartbeat_autopilot(port: int, stop: threading.Event) -> None:
    """A bare autopilot (sysid 1, comp 1) so MAVSDK has a system to attach MissionRaw to."""
    link = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1, source_component=1)
    try:
        while not stop.is_set():
            link.mav.heartbeat_send(
                mavutil.mavlink.MAV_TYPE_GROUND_ROVER, mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0
            )
            stop.wait(HEARTBEAT_PERIOD_S)
    finally:
        link.close()


async def mavsdk_import(port: int, plans: list[Path]) -> list:
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync

    sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        await sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        system = await sdk.first_autopilot(AUTOPILOT_WAIT_S)
        assert system is not None, "MAVSDK saw no autopilot heartbeat"
        mission_raw = MissionRawAsync(system)
        return [await mission_raw.import_qgroundcontrol_mission(str(plan)) for plan in plans]
    finally:
        sdk.destroy()


@pytest.mark.interop
def test_mavsdk_imports_our_plans(shared_dir, tmp_path, udp_port):
    sources = [*OWN, *(shared_dir / "missions" / name for name in SHARED)]
    missions, plans = [], []
    for index, source in enumerate(sources):
        mission = load_mission(source).mission
        plan = tmp_path / f"{index}_{source.stem}.plan"
        save_mission(mission, plan)
        missions.append(mission)
        plans.append(plan)

    stop = threading.Event()
    autopilot = threading.Thread(target=heartbeat_autopilot, args=(udp_port, stop), daemon=True)
    autopilot.start()
    try:
        imported = asyncio.run(mavsdk_import(udp_port, plans))
    finally:
        stop.set()
        autopilot.join()

    for mission, plan, data in zip(missions, plans, imported):
        home, *items = data.mission_items
        if mission.home is not None:
            assert abs(home.x / 1e7 - mission.home.lat_deg) <= 1e-7 and abs(home.y / 1e7 - mission.home.lon_deg) <= 1e-7
        for ours, theirs, name in ((mission.items, items, "mission"), (mission.fence, data.geofence_items, "fence"), (mission.rally, data.rally_items, "rally")):
            assert len(theirs) == len(ours), f"{plan.name}: {name}"
            for our_item, their_item in zip(ours, theirs):
                assert_same(our_item, their_item, latlon_scale=1e7)
