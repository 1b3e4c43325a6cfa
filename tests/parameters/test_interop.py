"""MAVProxy's parameter commands against a GcsLink whose table persists, as a ground-station user
would use them: fetch, show, set out of range (refused, reason at the prompt, value unchanged),
set in range (kept across a restart of the link)."""

from __future__ import annotations

import re

import pytest
from mission_protocol.helpers import LinkThread
from mission_protocol.test_interop import MavProxy

from rover_ctl.config import load_config
from rover_ctl.mavlink.gcs import DefaultHandlers
from rover_ctl.mavlink.params import ConfigParams
from rover_ctl.parameters import MAVLINK

pytestmark = pytest.mark.interop


def shown(line: str, name: str) -> float:
    """The value in a ``param show`` line (after any prompt MAVProxy prints before it)."""
    return float(re.search(rf"{name}\s+(\S+)", line).group(1))


def handlers_with_store(tmp_path):
    config = load_config(None, [f"gcs.mission_store_path={tmp_path / 'state' / 'mission.json'}", "gcs.heartbeat_period_s=0.2",
                                "gcs.param_send_rate_hz=500"])  # fmt: skip
    handlers = DefaultHandlers(config)
    handlers.table = ConfigParams.persistent(config)  # what the daemon does
    return config, handlers


def test_mavproxy_fetch_show_set_refused_and_persisted(udp_port, tmp_path):
    config, handlers = handlers_with_store(tmp_path)
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=config.gcs, handlers=handlers):
        mp = MavProxy(udp_port, tmp_path, modules="param")
        try:
            mp.wait_for("Detected vehicle 1:1")
            mp.send("param fetch")
            mp.wait_for(f"Received {len(MAVLINK)} parameters")
            mp.send("param show WP_SPEED")
            assert shown(mp.wait_for("WP_SPEED "), "WP_SPEED") == pytest.approx(1.2)
            mp.send("param set WP_SPEED 99")
            mp.wait_for("WP_SPEED: 99 is out of range 0 .. 20 m/s")  # the STATUSTEXT at the prompt
            mp.wait_for("Failed to set WP_SPEED to 99")  # MAVProxy saw the old value echoed
            assert config.executor.cruise_speed_mps == 1.2
            mp.send("param set WP_SPEED 1.5")
            for _ in range(5):  # MAVProxy sends the set from its idle loop: read back until it went through
                mp.send("param fetch WP_SPEED")
                if shown(mp.wait_for("WP_SPEED = "), "WP_SPEED =") == pytest.approx(1.5):
                    break
            else:
                pytest.fail("MAVProxy's set of WP_SPEED to 1.5 never showed")
        finally:
            mp.close()
    assert config.executor.cruise_speed_mps == pytest.approx(1.5)

    config, handlers = handlers_with_store(tmp_path)  # a restart: a new table from the same state
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=config.gcs, handlers=handlers):
        mp = MavProxy(udp_port, tmp_path, modules="param")
        try:
            mp.wait_for("Detected vehicle 1:1")
            mp.send("param fetch")
            mp.wait_for(f"Received {len(MAVLINK)} parameters")
            mp.send("param show WP_SPEED")
            assert shown(mp.wait_for("WP_SPEED "), "WP_SPEED") == pytest.approx(1.5)
        finally:
            mp.close()
