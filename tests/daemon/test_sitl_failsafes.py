"""Each failsafe triggered by breaking its link or sensor in the emulator (SIM_* faults through
PARAM_SET on the emulator's second endpoint) or by the GCS going quiet, and each recovery."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from rover_ctl.estimation.frame import LocalFrame
from rover_ctl.app.report import read_jsonl
from rover_ctl.app.sim import SimOptions, SimRun
from rover_ctl.vocabulary import mav

ROOT = Path(__file__).resolve().parents[2]
LOOP = ROOT / "missions" / "cmac_loop.waypoints"

pytestmark = pytest.mark.sitl


OVERRIDES = [
    "failsafe.gcs_timeout_s=2.0",
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

        # Our heartbeat goes out at 1 Hz of wall time, as a ground station's does, while lockstep
        # runs several times faster: never late so far, since it is late only by both clocks.
        assert not any(t.startswith("FS GCS lost") for t in run.progress.texts)
        # The ground station stops its heartbeat: hold (failsafe.gcs_action), cleared when it is back.
        run.send_heartbeats = False
        assert said(run, "FS GCS lost: hold", sim_timeout_s=None, wall_timeout_s=10.0)
        run.send_heartbeats = True
        assert said(run, "FS GCS lost cleared", sim_timeout_s=None, wall_timeout_s=10.0)
        collisions = run.progress.collisions

    changes = [e["reasons"] for e in read_jsonl(out / "events.jsonl") if e["type"] == "failsafe"]
    assert {"rangefinder 6", "GPS lost", "GPS lost too long", "vehicle link", "GCS lost"} <= {r for c in changes for r in c}
    # It fired once, while our heartbeat was off.
    assert sum("GCS lost" in b and "GCS lost" not in a for a, b in zip([[]] + changes, changes)) == 1
    assert collisions == 0
    # While the vehicle link was quiet every override the daemon sent was neutral.
    rows = [line.split(",") for line in (out / "control.csv").read_text().splitlines()]
    header, rows = rows[0], rows[1:]
    fs, steer, thr = header.index("failsafe"), header.index("steering_us"), header.index("throttle_us")
    quiet = [r for r in rows if "vehicle link" in r[fs]]
    assert quiet and all(r[steer] == "1500" and r[thr] == "1500" for r in quiet)


BOULDER = ROOT / "missions" / "boulder_fence.plan"
BOULDER_WORLD = ROOT / "missions" / "worlds" / "boulder_fence.geojson"


def test_fenced_mission_avoids_the_exclusion_and_a_glitch_breaches_the_fence(tmp_path):
    from shapely.geometry import Point, Polygon

    from rover_ctl.estimation.frame import LocalFrame
    from rover_ctl.mission.files import load_mission

    out = tmp_path / "run"
    mission = load_mission(BOULDER).mission
    frame = LocalFrame(mission.home.lat_deg, mission.home.lon_deg)
    fence = mission.fence
    exclusion = Polygon([frame.to_enu(i.x, i.y) for i in fence if i.command == 5002])
    with SimRun(SimOptions(mission=BOULDER, out=out, world=BOULDER_WORLD, timeout_s=200.0,
                                config_overrides=["failsafe.recovery_s=1.0", "estimator.glitch_max_s=3.0"])) as run:
        run.arm()
        run.start_mission()
        assert run.wait_for(lambda p: 2 in p.reached or 3 in p.reached, sim_timeout_s=120.0)  # past the exclusion
        # A 40 m GPS jump west: gated first, then believed once glitch_max_s (shortened here) is
        # over (the filter resets): outside the fence.
        run.sitl_param("SIM_GPS_GLITCH_Y", -40.0)
        assert said(run, "FS fence breach: hold", sim_timeout_s=20.0)
        collisions = run.progress.collisions

    states = [r for r in read_jsonl(out / "truth.jsonl") if r["type"] == "state"]
    driven = [Point(frame.to_enu(s["lat_deg"], s["lon_deg"])) for s in states]
    assert min(exclusion.distance(p) for p in driven) > 0.2  # never entered the exclusion zone
    assert collisions == 0


def test_unhealthy_estimator_refuses_to_arm_and_holds_when_forced(tmp_path):
    """An estimator that never meets the health limit (set impossibly tight): the pre-arm check
    refuses with its reason; force-armed, the failsafe keeps the rover still."""
    out = tmp_path / "run"
    options = SimOptions(mission=ROOT / "missions" / "cmac_jump.waypoints", out=out, timeout_s=60.0,
                         config_overrides=["estimator.health_max_position_sigma_m=0.001"])  # fmt: skip
    with SimRun(options) as run:
        assert run.arming_answer(timeout_s=30.0) == mav.MAV_RESULT_FAILED
        assert run.wait_for(lambda p: "PreArm: estimator unhealthy" in p.texts, wall_timeout_s=5.0), run.progress.texts
        run.arm(force=True)
        run.start_mission()
        # The failsafe may trigger before our first heartbeat reaches the daemon (its STATUSTEXT is
        # then lost): the heartbeat's system status says it continuously.
        assert run.wait_for(lambda p: p.system_status == mav.MAV_STATE_CRITICAL, wall_timeout_s=5.0)
        assert run.wait_for(lambda p: False, sim_timeout_s=4.0) is False
    reasons = {r for e in read_jsonl(out / "events.jsonl") if e["type"] == "failsafe" for r in e["reasons"]}
    assert "estimator" in reasons
    states = [r for r in read_jsonl(out / "truth.jsonl") if r["type"] == "state"]
    assert max(abs(s["speed_mps"]) for s in states) < 0.05


def test_vehicle_gone_is_detected_on_the_wall_clock(tmp_path):
    """The emulator dies (its socket closes, no lockstep markers either): the daemon cannot measure
    the silence in vehicle time, so it does on the wall clock, and keeps serving the GCS."""
    out = tmp_path / "run"
    with SimRun(SimOptions(mission=ROOT / "missions" / "cmac_jump.waypoints", out=out, timeout_s=60.0)) as run:
        run.arm()
        run.start_mission()
        assert run.wait_for(lambda p: False, sim_timeout_s=2.0) is False
        run.sitl.kill()
        run.sitl.wait()
        run.sitl = None
        assert said(run, "FS vehicle link: motors neutral", sim_timeout_s=None, wall_timeout_s=5.0)
        assert run.wait_for(lambda p: p.system_status == mav.MAV_STATE_CRITICAL, wall_timeout_s=10.0)
        assert run.daemon.poll() is None
    assert not any(t.startswith("FS stuck") for t in run.progress.texts)


JUMP = ROOT / "missions" / "cmac_jump.waypoints"
FRONT_SENSORS_MASK = 1 | 16 | 32
"""Emulator rangefinder ids 0 (front), 4 (front-left) and 5 (front-right) as a SIM_RF_STUCK mask."""


def test_stuck_on_an_unseen_obstacle_backs_off_and_replans(tmp_path):
    """The front rangefinders stick at "nothing in range" (a failure they cannot report), so the
    rover drives into a drum on its first leg and stalls against it: the stuck failsafe backs off,
    the spot ahead is blocked, and the re-planned path goes around to finish the mission."""
    home = (-35.363261, 149.165230, 584.0)
    lat, lon = LocalFrame(*home).to_geodetic(0.5, 8.0)
    drum = {"type": "Feature", "geometry": {"type": "Point", "coordinates": [lon, lat]}, "properties": {"id": "drum", "radius_m": 0.5}}
    world = tmp_path / "drum.geojson"
    world.write_text(json.dumps({"type": "FeatureCollection", "home": [home[1], home[0], home[2], 0.0], "features": [drum]}))
    out = tmp_path / "run"
    options = SimOptions(mission=JUMP, out=out, world=world, timeout_s=240.0,
                         sitl_params=[f"SIM_RF_STUCK={FRONT_SENSORS_MASK}"])  # fmt: skip
    with SimRun(options) as run:
        run.arm()
        run.start_mission()
        assert run.wait_for(lambda p: p.complete, sim_timeout_s=200.0), run.progress.texts
        texts = run.progress.texts
    assert any(t.startswith("FS stuck: backing off") for t in texts), texts
    assert not any(t.startswith("FS stuck: gave up") for t in texts), texts
    events = read_jsonl(out / "events.jsonl")
    stuck_s = next(e["t_s"] for e in events if e["type"] == "failsafe" and "stuck" in e["reasons"])
    detours = [e for e in events if e["type"] == "plan" and e["t_s"] > stuck_s and e["goal_seq"] == 1]
    assert detours and len(detours[0]["path_en"]) > 2  # the re-plan goes around the blocked spot
