"""Garbage and hostile frames against a real daemon process (``rover-ctl run`` against
``rover-sitl``, real sockets): it stays up, keeps heartbeating, its stored mission is unchanged
and the rover does not move: the vehicle stays disarmed in HOLD and every RC override the daemon
sent is neutral. The frames are bench/soak.py's mix without the well-formed commands (those take
effect by design: the soak bench reports them)."""

from __future__ import annotations

import csv
import json
import os

import pytest
from fuzz.frames import well_formed_effects
from mission_protocol.helpers import sample_mission

from bench.soak import soak
from rover_ctl.mission.store import to_json

FRAMES = int(os.environ.get("ROVER_FUZZ_DAEMON_FRAMES", "3000"))


@pytest.mark.sitl
def test_hostile_frames_never_stop_the_daemon_or_move_the_rover(tmp_path):
    store_text = json.dumps(to_json(sample_mission()), indent=1)
    result = soak(FRAMES, seed=7, workdir=tmp_path, keep=lambda msg: not well_formed_effects(msg), store_text=store_text)
    assert result["crashes"] == 0 and result["daemon_alive"], result
    assert result["handler_exceptions_caught"] == 0 and result["tracebacks_in_log"] == 0, (tmp_path / "daemon.log").read_text()[-3000:]
    assert result["longest_heartbeat_gap_s"] < 2.5, result
    assert set(result["heartbeat_states"]) == {"disarmed HOLD"}, result
    assert not result["store_changed"] and (tmp_path / "mission.json").read_text() == store_text
    assert result["changed_params"] == []
    harmless = {"REQUEST_MESSAGE", "GET_HOME_POSITION", "SET_MESSAGE_INTERVAL", "REQUEST_AUTOPILOT_CAPABILITIES"}
    assert set(result["accepted_commands"]) <= harmless, result["accepted_commands"]
    with open(tmp_path / "logs" / "control.csv", newline="") as fh:
        overrides = {(row["steering_us"], row["throttle_us"]) for row in csv.DictReader(fh)}
    assert overrides and overrides <= {("1500", "1500"), ("", "")}, overrides
