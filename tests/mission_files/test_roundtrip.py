"""Round trips: file -> model -> same format -> model is equal (MissionItem.same_as), and WPL <->
.plan conversions keep items, home, fence and rally, on every real file in ../shared/missions/
and on the project's own missions."""

from __future__ import annotations

from pathlib import Path

import pytest

from rover_ctl.mission.files import load_mission, save_mission
from rover_ctl.mission.model import Mission

ROOT = Path(__file__).resolve().parents[2]
OWN = sorted(p for p in (ROOT / "missions").iterdir() if p.suffix in (".waypoints", ".plan", ".txt"))
SHARED_NAMES = [
    "ardupilot_rover1.txt",
    "ardupilot_rover_path_planning_fence.txt",
    "ardupilot_rover_path_planning_mission.txt",
    "ardupilot_rover_pause_continue.txt",
    "ardupilot_rover_rtl.txt",
    "ardupilot_rover_test_rally.txt",
    "px4_rover_mission_1.plan",
    "qgc_ce_geofence_home_base.plan",
    "sitlmodels_wildthumper_playpen_mission.txt",
]
# MAVProxy-written (tab-separated, %f) files that our writer reproduces byte for byte.
MAVPROXY_WRITTEN = [
    "ardupilot_rover1.txt",
    "ardupilot_rover_path_planning_fence.txt",
    "ardupilot_rover_path_planning_mission.txt",
    "ardupilot_rover_rtl.txt",
    "sitlmodels_wildthumper_playpen_mission.txt",
]


def same_content(a: Mission, b: Mission, home: bool = True) -> None:
    """What a WPL <-> .plan conversion must keep: items exactly, home, fence shapes, rally points."""
    assert len(a.items) == len(b.items) and all(x.same_as(y) for x, y in zip(a.items, b.items))
    if home:
        assert (a.home is None and b.home is None) or a.home.same_as(b.home)
    assert a.fence_polygons() == b.fence_polygons()
    assert a.fence_circles() == b.fence_circles()
    assert a.fence_return_point == b.fence_return_point
    assert [(p.lat_deg, p.lon_deg, p.alt_m) for p in a.rally] == [(p.lat_deg, p.lon_deg, p.alt_m) for p in b.rally]


def test_manifest_lists_the_files_tested(shared_dir):
    manifest = (shared_dir / "missions" / "MANIFEST.tsv").read_text().splitlines()
    listed = sorted(line.split("\t")[0] for line in manifest if line and not line.startswith("#"))
    assert listed == sorted(SHARED_NAMES)


@pytest.mark.parametrize("name", SHARED_NAMES)
def test_shared_file_round_trips(shared_dir, tmp_path, name):
    path = shared_dir / "missions" / name
    original = load_mission(path).mission
    assert original.items or original.fence or original.rally

    # same format (a legacy MAVProxy RALLY file comes back as a rally WPL, what MAVProxy writes today)
    again = tmp_path / f"again{path.suffix}"
    save_mission(original, again)
    assert load_mission(again).mission.same_as(original)

    converted = tmp_path / ("converted.txt" if path.suffix == ".plan" else "converted.plan")
    save_mission(original, converted)
    via = load_mission(converted).mission
    # a fence-only or rally-only WPL file has no home row
    keeps_home = bool(original.items) or converted.suffix == ".plan"
    same_content(original, via, home=keeps_home)
    back = tmp_path / f"back{path.suffix}"
    save_mission(via, back)
    same_content(original, load_mission(back).mission, home=keeps_home)


@pytest.mark.parametrize("name", MAVPROXY_WRITTEN)
def test_mavproxy_file_is_rewritten_byte_for_byte(shared_dir, tmp_path, name):
    path = shared_dir / "missions" / name
    out = tmp_path / name
    save_mission(load_mission(path).mission, out)
    assert out.read_text() == path.read_text()


@pytest.mark.parametrize("path", OWN, ids=lambda p: p.name)
def test_own_mission_round_trips(tmp_path, path):
    original = load_mission(path).mission
    for suffix in (".plan", ".waypoints"):
        if suffix == ".waypoints" and (original.fence or original.rally):
            continue
        out = tmp_path / f"x{suffix}"
        save_mission(original, out)
        loaded = load_mission(out).mission
        same_content(original, loaded)
        if suffix == path.suffix:
            assert loaded.same_as(original)
            assert out.read_text() == path.read_text()


def test_own_missions_are_present():
    assert {p.name for p in OWN} >= {"cmac_loop.waypoints", "cmac_jump.waypoints", "boulder_fence.plan"}
