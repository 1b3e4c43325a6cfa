"""Each failsafe triggered by breaking its link or sensor in the emulator (SIM_* faults through
PARAM_SET on the emulator's second endpoint) or by the GCS going quiet, and each recovery."""

from __future__ import annotations

from pathlib import Path

import pytest

from rover_ctl.report import read_jsonl
from rover_ctl.sim import SimOptions, SimRun

ROOT = Path(__file__).resolve().parents[2]
LOOP = ROOT / "missions" / "cmac_loop.waypoints"

pytestmark = pytest.mark.sitl

OVERRIDES = [
    "failsafe.gcs_timeout_s=1.0",
    "failsafe.gcs_action=hold",
    "failsafe.dead_reckoning_max_s=3.0",
    "failsafe.recovery_s=1.0",
]


def said(run: SimRun, text: str, sim_timeout_s: float = 10.0, wall_timeout_s: float | None = None) -> bool:
    """Wait until the daemon's STATUSTEXTs include one starting with ``text``."""
    return run.wait_for(lambda p: any(t.startswith(text) for t in p.texts), sim_timeout_s=sim_timeout_s, wall_timeout_s=wall_timeout_s)


def test_failsafes_trigger_and_clear(tmp_path):
    out = tmp_path / "run"
    with SimRun(SimOptions(mission=LOOP, out=out, timeout_s=300.0, config_overrides=OVERRIDES)) as run:
        run.arm()
        run.start_mission()
        assert run.wait_for(lambda p: False, sim_timeout_s=3.0) is False

        # Left rangefinder (sensor id 2, orientation 6) silent: that side counts as blocked.
        run.sitl_param("SIM_RF_FAIL", 4)
        assert said(run, "FS rangefinder 6: silent")
        run.sitl_param("SIM_RF_FAIL", 0)
        assert said(run, "FS rangefinder 6 cleared")

        # GPS outage: dead reckoning, then hold when it lasts too long; cleared when fixes return.
        run.sitl_param("SIM_GPS_DISABLE", 1)
        assert said(run, "FS GPS lost: dead reckoning")
        assert said(run, "FS GPS lost too long: hold")
        run.sitl_param("SIM_GPS_DISABLE", 0)
        assert said(run, "FS GPS lost too long cleared")

        # The vehicle goes quiet (lockstep markers still come): motors neutral, then back.
        run.sitl_param("SIM_LINK_QUIET", 1, confirm=False)
        assert said(run, "FS vehicle link: motors neutral")
        run.sitl_param("SIM_LINK_QUIET", 0)
        assert said(run, "FS vehicle link cleared")

        # The ground station stops its heartbeat: hold (failsafe.gcs_action), cleared when it is back.
        run.send_heartbeats = False
        assert said(run, "FS GCS lost: hold", sim_timeout_s=None, wall_timeout_s=10.0)
        run.send_heartbeats = True
        assert said(run, "FS GCS lost cleared", sim_timeout_s=None, wall_timeout_s=10.0)
        collisions = run.progress.collisions

    reasons = {r for e in read_jsonl(out / "events.jsonl") if e["type"] == "failsafe" for r in e["reasons"]}
    assert {"rangefinder 6", "GPS lost", "GPS lost too long", "vehicle link", "GCS lost"} <= reasons
    assert collisions == 0
    # While the vehicle link was quiet every override the daemon sent was neutral.
    rows = [line.split(",") for line in (out / "control.csv").read_text().splitlines()]
    header, rows = rows[0], rows[1:]
    fs, steer, thr = header.index("failsafe"), header.index("steering_us"), header.index("throttle_us")
    quiet = [r for r in rows if "vehicle link" in r[fs]]
    assert quiet and all(r[steer] == "1500" and r[thr] == "1500" for r in quiet)
