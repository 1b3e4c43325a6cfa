"""ArduPilot's own Rover firmware vs rover-sitl: the bundled mission, each rangefinder layout.

For each configuration the daemon flies missions/cmac_loop.waypoints twice: against the firmware
(``rover_ctl.app.firmware``, stock parameters plus the documented encoders and rangefinders, the
wheel map ArduPilot needs, free running at the speed-up given) and against rover-sitl in lockstep
with the matching layout and rule base. Rows side by side: success, mission time, path driven
(truth), cross-track max and RMS (the daemon's own estimate against its planned path) and the
control loop's rate in vehicle time (target 25 Hz).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from rover_ctl.app.firmware import FirmwareOptions, firmware_path, simulate_firmware
from rover_ctl.app.sim import ARM_AT_S, SimOptions, SimRun

ROOT = Path(__file__).resolve().parent.parent
MISSION = ROOT / "missions" / "cmac_loop.waypoints"
WHEELS = ["link.wheel_left_index=1", "link.wheel_right_index=0"]
CONFIGS = [
    # (label, firmware layout, rover-sitl --rangefinders, rule base, firmware speed-up)
    ("six rangefinders, default rules", "six", "default", "default", 10),
    ("paper's four, paper rules", "paper", "paper", "paper", 10),
    ("no rangefinders, default rules", "none", "default", "default", 10),
    ("no rangefinders, default rules", "none", "default", "default", 50),
    ("no rangefinders, default rules", "none", "default", "default", 1),
]
FIELDS = ("success", "duration_s", "path_length_m", "cross_track_max_m", "cross_track_rms_m", "control_rate_hz")


class _PaperLayoutRun(SimRun):
    """rover-sitl with the paper's four rangefinders (SimOptions has no layout field)."""

    def _sitl_command(self) -> list[str]:
        return super()._sitl_command() + ["--rangefinders", "paper"]


def _emulator(out: Path, layout: str, rulebase: str) -> dict:
    """The same mission in rover-sitl, lockstep. There is no rangefinder-less emulator layout: the
    reference for "none" is the default six in an empty world (they never see anything)."""
    from rover_ctl.app.report import write_report

    # Armed at ARM_AT_S of sim time, as `rover-ctl sim` does: a run whose arming time followed the
    # wall clock took 142.3-144.6 s (14 runs of 7 trees of 2026-11-27); this one is the same every time.
    options = SimOptions(mission=MISSION, out=out, rulebase=rulebase, timeout_s=400, arm_at_s=ARM_AT_S)
    with (_PaperLayoutRun if layout == "paper" else SimRun)(options) as sim_run:
        complete = sim_run.run_mission()
    return write_report(out, None, timed_out=not complete, plots=False)


def run(quick: bool) -> dict:
    if firmware_path() is None:
        raise SystemExit("bench firmware: ../shared/ardupilot/ardurover is absent")
    rows, results = [], []
    configs = CONFIGS[:1] if quick else CONFIGS
    with tempfile.TemporaryDirectory() as tmp:
        for n, (label, fw_layout, sitl_layout, rulebase, speedup) in enumerate(configs):
            fw = simulate_firmware(FirmwareOptions(mission=MISSION, out=Path(tmp) / f"fw{n}", lockstep=False, speedup=speedup,
                                                   timeout_s=400 if speedup <= 10 else 1500, rulebase=rulebase, rangefinders=fw_layout,
                                                   config_overrides=list(WHEELS)))  # fmt: skip
            em = _emulator(Path(tmp) / f"em{n}", sitl_layout, rulebase)
            results.append({"config": label, "speedup": speedup, "firmware": {k: fw.get(k) for k in FIELDS},
                            "emulator": {k: em.get(k) for k in FIELDS}})  # fmt: skip
            cells = [f"{fw.get(k)} / {em.get(k)}" for k in FIELDS]
            rows.append(f"| {label} | {speedup:g}x / lockstep | " + " | ".join(cells) + " |")
    markdown = "\n".join([
        "_`python -m bench firmware`._ Each cell: **firmware / emulator**.\n",
        "| configuration | time base | success | time s | path m | cross-track max m | cross-track RMS m | control rate Hz |",
        "|---|---|---|---|---|---|---|---|",
        *rows,
        "",
        "Firmware: ArduPilot Rover 4.7-dev SITL `rover-skid`, stock parameters + PILOT_STEER_TYPE 3 + WENC/RNGFND (docs/ardupilot.md), "
        "free running at the speed-up shown; the daemon follows its timestamps. Emulator: rover-sitl in lockstep. "
        "Control rate is control steps per second of vehicle time during the mission (target 25 Hz); below it the "
        "daemon could not keep up with the firmware at that speed-up on this machine (2 cores shared with the firmware "
        "and the ground station); there it limits the speed to 0.25 m per control step (SCHED_STEP_TRVL) and says so, "
        "so a slow loop makes a slow mission (budget: 1500 s of the firmware's time at 50x, 400 s otherwise).",
    ])  # fmt: skip
    return {"title": "ArduPilot firmware vs rover-sitl (cmac_loop)", "markdown": markdown, "runs": results}
