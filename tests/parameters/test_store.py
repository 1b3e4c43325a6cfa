"""Parameters set from a ground station persist, atomically, beside the mission store; precedence
defaults < config file < stored < --set; a corrupt store is moved aside, never a crash."""

from __future__ import annotations

import os

import pytest

from rover_ctl.config import load_config
from rover_ctl.mavlink.params import ConfigParams
from rover_ctl.param_store import ParamStore, store_path


def config_in(tmp_path, toml: str = "", overrides: list[str] = ()):
    path = tmp_path / "rover.toml"
    path.write_text(toml)
    return load_config(path, [f"gcs.mission_store_path={tmp_path / 'state' / 'mission.json'}", *overrides])


def test_a_set_persists_across_a_restart(tmp_path):
    table = ConfigParams.persistent(config_in(tmp_path))
    assert table.set_param("WP_SPEED", 0.8) == (True, "")
    assert table.set_param("FS_ACTION", 2) == (True, "")
    assert table.set_param("WP_RADIUS", 500.0)[0] is False  # refused: not stored
    table.close()  # the daemon's shutdown: writes what the last gcs.param_save_s set
    stored = tmp_path / "state" / "params.parm"
    assert stored.read_text().splitlines()[1:] == ["WP_SPEED         0.8", "FS_ACTION        2"]
    restarted = config_in(tmp_path)
    ConfigParams.persistent(restarted)
    assert restarted.executor.cruise_speed_mps == 0.8 and restarted.failsafe.gcs_action == "hold"
    assert restarted.executor.acceptance_radius_m == 2.0


def test_precedence_defaults_file_stored_command_line(tmp_path):
    ParamStore(tmp_path / "state" / "params.parm").save({"WP_SPEED": 0.8, "WP_RADIUS": 3.0})
    config = config_in(tmp_path, "[executor]\ncruise_speed_mps = 1.0\nrtl_radius_m = 4.0\n", ["WP_RADIUS=5"])
    ConfigParams.persistent(config)
    assert config.executor.cruise_speed_mps == 0.8  # stored beats the file
    assert config.executor.rtl_radius_m == 4.0  # the file beats the default
    assert config.executor.acceptance_radius_m == 5.0  # --set beats what is stored


def test_no_store_when_the_mission_store_is_off(tmp_path):
    config = load_config(None, ["gcs.mission_store_path="])
    assert store_path(config) is None
    table = ConfigParams.persistent(config)
    assert table.store is None and table.set_param("WP_SPEED", 0.5) == (True, "")


@pytest.mark.parametrize("text", ["WP_SPEED 99\n", "garbage\n", "NOT_A_PARAM 1\n", "\xff\xfe bytes"])
def test_a_corrupt_store_is_moved_aside_with_one_line(tmp_path, text, caplog):
    stored = tmp_path / "state" / "params.parm"
    stored.parent.mkdir()
    stored.write_bytes(text.encode("latin-1"))
    config = config_in(tmp_path)
    table = ConfigParams.persistent(config)
    assert table.store_error is not None and "\n" not in table.store_error and "moved to" in table.store_error
    assert not stored.exists() and (tmp_path / "state" / "params.parm.corrupt").read_bytes() == text.encode("latin-1")
    assert config.executor.cruise_speed_mps == 1.2  # running on the config
    assert table.set_param("WP_SPEED", 0.7) == (True, "")  # and a new store starts
    assert "WP_SPEED" in stored.read_text()
    stored.write_text("junk\n")
    ConfigParams.persistent(config_in(tmp_path))
    assert (tmp_path / "state" / "params.parm.corrupt.1").exists()  # an earlier quarantine is kept


def test_a_failed_write_keeps_the_old_file_and_says_so(tmp_path, monkeypatch):
    now = [0.0]
    table = ConfigParams.persistent(config_in(tmp_path), clock=lambda: now[0])
    assert table.set_param("WP_SPEED", 0.8) == (True, "")
    before = (tmp_path / "state" / "params.parm").read_text()

    def no_space(*args):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", no_space)
    now[0] += table.config.gcs.param_save_s  # a write is due: the set writes at once
    assert table.set_param("WP_SPEED", 0.9) == (True, "WP_SPEED set but not saved")
    assert table.config.executor.cruise_speed_mps == 0.9  # in force for this run
    assert (tmp_path / "state" / "params.parm").read_text() == before
    assert [p.name for p in (tmp_path / "state").iterdir()] == ["params.parm"]  # no temporary file left


def test_rover_ctl_params_leaves_a_corrupt_store_where_it_is(tmp_path, capsys):
    """Showing, exporting or importing parameters only looks at the store: it moved a corrupt one
    aside (and printed the reason twice) before refusing."""
    from rover_ctl.cli import main

    stored = tmp_path / "state" / "params.parm"
    stored.parent.mkdir()
    stored.write_text("WP_SPEED 999\n")
    store_flag = ["--mission-store", str(tmp_path / "state" / "mission.json")]
    assert main(["params", *store_flag]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "fix or remove it" in err[0], err
    parm = tmp_path / "in.parm"
    parm.write_text("WP_SPEED 1.0\n")
    assert main(["params", "import", str(parm), *store_flag]) == 2
    capsys.readouterr()
    assert stored.read_text() == "WP_SPEED 999\n" and sorted(p.name for p in stored.parent.iterdir()) == ["params.parm"]


def test_writes_are_coalesced_while_every_value_is_in_force_at_once(tmp_path):
    """A stream of PARAM_SETs (here 100 alternating values) is one write per gcs.param_save_s,
    the first at once; the last value is written when the interval has passed."""
    now = [0.0]
    table = ConfigParams.persistent(config_in(tmp_path), clock=lambda: now[0])
    stored = tmp_path / "state" / "params.parm"
    for k in range(100):
        value = 0.5 if k % 2 else 0.8
        assert table.set_param("WP_SPEED", value) == (True, "")
        assert table.config.executor.cruise_speed_mps == value  # in force at once
        now[0] += 0.001
    assert table.writes == 1 and table.unsaved and "WP_SPEED         0.8" in stored.read_text()
    table.flush()  # the daemon's loop turn, still within the interval: nothing
    assert table.writes == 1
    now[0] += table.config.gcs.param_save_s
    table.flush()
    assert table.writes == 2 and not table.unsaved
    restarted = config_in(tmp_path)
    ConfigParams.persistent(restarted)  # a crash now would lose nothing
    assert restarted.executor.cruise_speed_mps == 0.5
    table.close()
    assert table.writes == 2  # nothing left to write


def test_shutdown_writes_what_the_interval_held_back(tmp_path):
    table = ConfigParams.persistent(config_in(tmp_path), clock=lambda: 0.0)
    table.set_param("WP_SPEED", 0.8)
    table.set_param("WP_SPEED", 0.6)
    assert table.unsaved
    table.close()
    restarted = config_in(tmp_path)
    ConfigParams.persistent(restarted)
    assert restarted.executor.cruise_speed_mps == 0.6


def test_a_deferred_write_that_fails_is_logged_and_tried_again(tmp_path, monkeypatch, caplog):
    now = [0.0]
    table = ConfigParams.persistent(config_in(tmp_path), clock=lambda: now[0])
    table.set_param("WP_SPEED", 0.8)
    table.set_param("WP_SPEED", 0.9)  # held back
    stored = tmp_path / "state" / "params.parm"
    before = stored.read_text()

    def no_space(*args):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", no_space)
    now[0] += table.config.gcs.param_save_s
    table.flush()
    assert "cannot save parameters" in caplog.text and table.unsaved and stored.read_text() == before
    monkeypatch.undo()
    table.flush()  # not before another interval
    assert stored.read_text() == before
    now[0] += table.config.gcs.param_save_s
    table.flush()
    assert not table.unsaved and "WP_SPEED         0.9" in stored.read_text()
