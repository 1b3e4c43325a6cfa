"""The mission's progress beside the stored mission (MIS_RESTART 0 resumes there after a restart)."""

from __future__ import annotations

from rover_ctl.mission.model import Mission, MissionItem
from rover_ctl.mission.store import MissionStore
from rover_ctl.vocabulary import Cmd


def mission(lat: float) -> Mission:
    return Mission(items=[MissionItem(Cmd.NAV_WAYPOINT, x=lat, y=149.0), MissionItem(Cmd.NAV_WAYPOINT, x=lat + 1e-4, y=149.0)])


def test_progress_belongs_to_its_mission(tmp_path):
    store = MissionStore(tmp_path / "mission.json")
    assert store.load_progress(mission(-35.0)) is None
    store.save_progress(mission(-35.0), 2)
    assert store.load_progress(mission(-35.0)) == 2
    assert store.load_progress(mission(-36.0)) is None  # another mission: start from its first item


def test_a_damaged_progress_file_is_no_progress(tmp_path):
    store = MissionStore(tmp_path / "mission.json")
    for text in ("", "{", "[]", '{"mission": 1, "seq": "x"}', "\xff"):
        store.progress_path.write_text(text)
        assert store.load_progress(mission(-35.0)) is None
