"""Faults survived, measured in lockstep against the emulator's truth: the vehicle link going
quiet, every rangefinder failing, one rangefinder failing that is not required, and the daemon
killed and started again mid-mission. docs/failsafes.md quotes the figures these tests print."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from rover_ctl.app.report import read_jsonl
from rover_ctl.app.sim import SimOptions, SimRun
from rover_ctl.vocabulary import MissionState, RoverMode

ROOT = Path(__file__).resolve().parents[2]
LOOP = ROOT / "missions" / "cmac_loop.waypoints"
ALL_RANGEFINDERS = 0b111111
"""SIM_RF_FAIL mask of the emulator's six rangefinders (sensor ids 0-5)."""
LEFT_RANGEFINDER = 0b100
"""Sensor id 2: orientation 6 (left)."""
NEUTRAL_WITHIN_S = 0.5
HOLD_WITHIN_S = 1.0

pytestmark = pytest.mark.sitl


def fault_start(out: Path, name: str) -> float:
    return next(r["t_s"] for r in read_jsonl(out / "truth.jsonl") if r["type"] == "fault" and r["name"] == name and r["active"])


def control_rows(out: Path) -> list[dict]:
    with open(out / "control.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def truth_speeds(out: Path, start_s: float, end_s: float) -> list[float]:
    return [r["speed_mps"] for r in read_jsonl(out / "truth.jsonl") if r["type"] == "state" and start_s <= r["t_s"] <= end_s]


def test_vehicle_link_quiet_sends_neutral_within_half_a_second(tmp_path):
    out = tmp_path / "run"
    with SimRun(SimOptions(mission=LOOP, out=out, timeout_s=300.0)) as run:
        run.arm()
        run.start_mission()
        assert run.wait_for(lambda p: 1 in p.reached, sim_timeout_s=60.0)
        run.sitl_param("SIM_LINK_QUIET", 1, confirm=False)
        assert run.wait_for(lambda p: any(t.startswith("FS vehicle link: motors neutral") for t in p.texts), sim_timeout_s=10.0)
        run.sitl_param("SIM_LINK_QUIET", 0)
        assert run.wait_for(lambda p: p.complete, sim_timeout_s=250.0), run.progress
    quiet_s = fault_start(out, "SIM_LINK_QUIET")
    neutral = [r for r in control_rows(out) if float(r["t_s"]) >= quiet_s and "vehicle link" in r["failsafe"]]
    delay_s = float(neutral[0]["t_s"]) - quiet_s
    print(f"vehicle link quiet at {quiet_s:.2f} s: neutral after {delay_s:.2f} s")
    assert delay_s <= NEUTRAL_WITHIN_S and (neutral[0]["steering_us"], neutral[0]["throttle_us"]) == ("1500", "1500")


def test_every_rangefinder_failing_holds_within_a_second_and_names_them(tmp_path):
    out = tmp_path / "run"
    with SimRun(SimOptions(mission=LOOP, out=out, timeout_s=300.0)) as run:
        run.arm()
        run.start_mission()
        assert run.wait_for(lambda p: 1 in p.reached, sim_timeout_s=60.0)
        run.sitl_param("SIM_RF_FAIL", ALL_RANGEFINDERS)
        assert run.wait_for(lambda p: False, sim_timeout_s=5.0) is False
        # Held in AUTO, not switched out of it; heartbeats are 1 Hz of wall time (a few s of lockstep).
        assert run.wait_for(lambda p: p.mode == RoverMode.AUTO, wall_timeout_s=10.0) and 2 not in run.progress.reached
        held_texts = [t for t in run.progress.texts if t.endswith("silent, hold")]
        run.sitl_param("SIM_RF_FAIL", 0)
        assert run.wait_for(lambda p: p.complete, sim_timeout_s=250.0), run.progress
    failed_s = fault_start(out, "SIM_RF_FAIL")
    held = [r for r in control_rows(out) if float(r["t_s"]) >= failed_s and "rangefinder" in r["failsafe"]]
    delay_s = float(held[0]["t_s"]) - failed_s
    speeds = truth_speeds(out, failed_s + 3.0, failed_s + 5.0)
    print(f"all rangefinders failed at {failed_s:.2f} s: hold after {delay_s:.2f} s, speed 3-5 s later <= {max(speeds):.3f} m/s")
    assert delay_s <= HOLD_WITHIN_S and max(speeds) < 0.05
    assert {t.split(":")[0] for t in held_texts} >= {"FS rangefinder 0", "FS rangefinder 6", "FS rangefinder 2"}


def test_a_rangefinder_not_required_failing_slows_the_rover_and_it_goes_on(tmp_path):
    out = tmp_path / "run"
    options = SimOptions(mission=LOOP, out=out, timeout_s=300.0,
                         config_overrides=["failsafe.required_rangefinders=0", "failsafe.degraded_speed_mps=0.5"])  # fmt: skip
    with SimRun(options) as run:
        run.arm()
        run.start_mission()
        assert run.wait_for(lambda p: 1 in p.reached, sim_timeout_s=60.0)
        run.sitl_param("SIM_RF_FAIL", LEFT_RANGEFINDER)
        assert run.wait_for(lambda p: False, sim_timeout_s=6.0) is False
        run.sitl_param("SIM_RF_FAIL", 0)
        assert run.wait_for(lambda p: p.complete, sim_timeout_s=250.0), run.progress
        assert not any(t.endswith("silent, hold") for t in run.progress.texts)
    failed_s = fault_start(out, "SIM_RF_FAIL")
    speeds = truth_speeds(out, failed_s + 1.0, failed_s + 6.0)
    print(f"left rangefinder failed at {failed_s:.2f} s: speed {min(speeds):.2f}-{max(speeds):.2f} m/s while degraded")
    assert max(speeds) <= 0.5 + 0.1 and sum(speeds) / len(speeds) > 0.2  # slower, still driving


@pytest.mark.parametrize("restart", [0, 1], ids=["resume", "start-over"])
def test_daemon_killed_mid_mission_keeps_the_rover_stopped_then_resumes_as_mis_restart_says(tmp_path, restart):
    out = tmp_path / "run"
    options = SimOptions(mission=LOOP, out=out, timeout_s=400.0, mission_store=tmp_path / "state" / "mission.json",
                         config_overrides=[f"autopilot.mission_restart={restart}"])  # fmt: skip
    with SimRun(options) as run:
        run.arm()
        run.start_mission()
        assert run.wait_for(lambda p: 2 in p.reached and p.current_seq == 3, sim_timeout_s=120.0)
        killed_s = run.progress.sim_time_s
        run.restart_daemon(tmp_path / "after")
        run.progress.reached.clear()
        # The new daemon reports the stored mission, holds, and says where AUTO would go on.
        assert run.wait_for(lambda p: p.mission_state == MissionState.NOT_STARTED and p.current_seq == (3 if restart == 0 else 1)
                            and p.position_en is not None, wall_timeout_s=60.0), run.progress  # fmt: skip
        assert run.wait_for(lambda p: p.mode == RoverMode.HOLD, wall_timeout_s=10.0)  # the new daemon's heartbeat (1 Hz wall)
        assert run.wait_for(lambda p: False, sim_timeout_s=3.0) is False
        stopped_s = run.progress.sim_time_s
        assert run.set_mode(RoverMode.AUTO) == 0
        assert run.wait_for(lambda p: p.complete, sim_timeout_s=300.0), run.progress
        reached = sorted(run.progress.reached)
    speeds = truth_speeds(out, stopped_s - 1.0, stopped_s)
    print(f"MIS_RESTART {restart}: killed at {killed_s:.1f} s, speed before AUTO <= {max(speeds):.3f} m/s, reached after {reached}")
    assert max(speeds) < 0.05
    assert reached[0] == (3 if restart == 0 else 1) and reached[-1] == 5
