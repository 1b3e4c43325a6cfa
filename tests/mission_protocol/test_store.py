"""The mission store: atomic, lossless, loud about corruption."""

from __future__ import annotations

import json
import os

import pytest

from rover_ctl.mission.model import Mission, MissionItem
from rover_ctl.mission.store import MissionStore, StoreError


def test_missing_store_is_an_empty_mission(tmp_path):
    assert MissionStore(tmp_path / "none.json").load().same_as(Mission())


def test_round_trip_is_lossless_including_nan_params(tmp_path, mission):
    store = MissionStore(tmp_path / "sub" / "m.json")
    odd = Mission(items=[*mission.items, MissionItem(16, param4=float("nan"), x=1.0, y=2.0)], fence=mission.fence)
    store.save(odd)
    assert store.load().same_as(odd)
    assert [p.name for p in store.path.parent.iterdir()] == ["m.json"]  # no temp file left


def test_a_failed_save_keeps_the_old_store_and_leaves_no_temp_file(tmp_path, mission, monkeypatch):
    store = MissionStore(tmp_path / "m.json")
    store.save(mission)

    def no_rename(src, dst):
        raise OSError("simulated crash before the rename")

    monkeypatch.setattr(os, "replace", no_rename)
    with pytest.raises(OSError, match="simulated"):
        store.save(Mission())
    monkeypatch.undo()
    assert store.load().same_as(mission)
    assert [p.name for p in tmp_path.iterdir()] == ["m.json"]


@pytest.mark.parametrize(
    "text, message",
    [
        ('{"format": "rover_ctl-mission-store", "version": 1, "items": [', "corrupt mission store"),
        ('{"items": []}', "not a rover_ctl mission store"),
        ('{"format": "rover_ctl-mission-store", "version": 9}', "unsupported store version 9"),
        ('{"format": "rover_ctl-mission-store", "version": 1, "items": {}, "fence": [], "rally": []}', '"items" must be a list'),
        ('{"format": "rover_ctl-mission-store", "version": 1, "items": [{"command": 16, "x": "north"}], "fence": [], "rally": []}',
         "items[0]: x has the wrong type"),
        ('{"format": "rover_ctl-mission-store", "version": 1, "items": [{"cmd": 16}], "fence": [], "rally": []}', "items[0]: "),
        ('{"format": "rover_ctl-mission-store", "version": 1, "home": {"lat_deg": "x", "lon_deg": 1}, "items": [], "fence": [], "rally": []}',
         "home: coordinates must be numbers"),
    ],
)  # fmt: skip
def test_a_bad_store_is_a_one_line_error_naming_the_file(tmp_path, text, message):
    path = tmp_path / "m.json"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(StoreError) as info:
        MissionStore(path).load()
    assert str(info.value).startswith(f"{path}: ") and message in str(info.value) and "\n" not in str(info.value)


def test_quarantine_never_overwrites_an_earlier_one(tmp_path):
    store = MissionStore(tmp_path / "m.json")
    for n in range(3):
        store.path.write_text(f"garbage {n}")
        store.quarantine()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.json.corrupt", "m.json.corrupt.1", "m.json.corrupt.2"]
    assert (tmp_path / "m.json.corrupt.2").read_text() == "garbage 2"
    assert store.quarantine() is None  # nothing left to move


def test_the_store_is_plain_json(tmp_path, mission):
    store = MissionStore(tmp_path / "m.json")
    store.save(mission)
    data = json.loads(store.path.read_text())
    assert data["format"] == "rover_ctl-mission-store" and len(data["items"]) == len(mission.items)
