"""``rover-ctl sim MISSION``: the emulator and the daemon, a mission run end to end, a report."""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import time
from pathlib import Path

from rover_ctl.cli import number_type, positive, seed
from sitl.clock import MIN_SPEEDUP


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("sim", help="run a mission against the emulator and write a report", description="Run a mission against the emulator end to end and write a report (docs/daemon.md).")
    parser.add_argument("mission", type=Path, metavar="MISSION", help="mission file (.waypoints, .txt or .plan)")
    world = parser.add_mutually_exclusive_group()
    world.add_argument("--world", type=Path, metavar="GEOJSON", help="emulator world (obstacles, faults)")
    world.add_argument("--obstacles", type=int, metavar="N", help="N seeded random obstacles along the mission legs")
    parser.add_argument("--seed", type=seed, default=1, help="seed of the emulator's random draws (default 1)")
    parser.add_argument("--rulebase", default="default", metavar="NAME|FILE", help="fuzzy rule base (default: default)")
    timing = parser.add_mutually_exclusive_group()
    timing.add_argument("--lockstep", action="store_true", help="lockstep with the emulator (default; deterministic, as fast as possible)")
    timing.add_argument("--speedup", type=number_type(float, MIN_SPEEDUP, math.inf, "a number", f">= {MIN_SPEEDUP:g}"), metavar="X",
                        help="free-running emulator at X times real time ('inf': as fast as it goes)")
    parser.add_argument("--out", type=Path, metavar="DIR", help="each sim writes a new numbered run folder here, with its logs and report, and DIR/latest (default runs/<mission>)")
    parser.add_argument("--json", action="store_true", help="print the metrics JSON on stdout (progress goes to stderr)")
    parser.add_argument("--timeout-s", type=positive, metavar="S",
                        help="sim-time budget of the mission (default: twice its route at cruise speed plus its holds, at least 300)")  # fmt: skip
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE", help="daemon config override (repeatable)")
    parser.add_argument("--signing-key", metavar="PASSPHRASE|@FILE",
                        help="MAVLink 2 signing on the GCS link: the daemon and this ground station use this key (as `rover-ctl mission`)")  # fmt: skip
    parser.add_argument("--sitl-param", action="append", default=[], metavar="NAME=VALUE", help="emulator parameter, e.g. a SIM_* fault (repeatable)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # SIGTERM (a service manager, `timeout`) unwinds like Ctrl-C: the run stops its daemon and
    # emulator on the way out instead of leaving them running.
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum))
    try:
        return _run(args)
    finally:
        signal.signal(signal.SIGTERM, previous)


def _run(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.live import Live
    from rich.table import Table

    from rover_ctl.app.logs import LogDirError, new_run_folder
    from rover_ctl.app.report import ReportError
    from rover_ctl.app.sim import Progress, SimError, SimOptions, boot_altitude_m, simulate
    from rover_ctl.cli import UserError
    from rover_ctl.config import load_config
    from rover_ctl.mission.files import MissionFileError, load_mission

    if args.obstacles is not None and args.obstacles < 0:
        raise UserError(f"--obstacles {args.obstacles}: expected a count >= 0")
    if args.world is not None and not args.world.is_file():
        raise UserError(f"--world {args.world}: no such file")
    from rover_ctl.mavlink.signing import SigningError, client_key

    try:
        signing_key = client_key(args.signing_key)
    except SigningError as exc:
        raise UserError(str(exc)) from None
    budget_mb = load_config(None, args.set).daemon.log_max_total_mb  # also refuses a bad --set now
    from rover_ctl.config import NavigatorParams
    from rover_ctl.fuzzy import RuleBaseError
    from rover_ctl.navigation.navigator import Navigator
    from sitl.world import WorldError, load_world

    try:  # the daemon's and the emulator's own checks, before a run folder is made for them
        Navigator(args.rulebase, NavigatorParams(), 1.0)
    except (RuleBaseError, OSError, ValueError) as exc:
        raise UserError(f"--rulebase {args.rulebase}: {exc}") from None
    try:
        if args.world is not None:
            load_world(args.world)
    except WorldError as exc:
        raise UserError(str(exc)) from None
    from sitl.main import parse_param

    for item in args.sitl_param:
        try:
            parse_param(item)
        except argparse.ArgumentTypeError as exc:
            raise UserError(f"--sitl-param {item}: {exc}") from None
    try:
        boot_altitude_m(load_mission(args.mission).mission)
        out = new_run_folder(args.out or Path("runs") / args.mission.stem, budget_mb)
    except (MissionFileError, LogDirError) as exc:
        raise UserError(str(exc)) from None
    except WorldError as exc:
        raise UserError(f"{args.mission}: home: the emulator cannot boot there: {exc}") from None
    options = SimOptions(
        mission=args.mission, out=out, world=args.world, obstacles=args.obstacles, seed=args.seed,
        rulebase=args.rulebase, lockstep=args.speedup is None, speedup=args.speedup or 1.0,
        timeout_s=args.timeout_s, config_overrides=args.set, sitl_params=args.sitl_param, signing_key=signing_key,
    )  # fmt: skip
    console = Console(stderr=args.json)

    def table(p: Progress) -> Table:
        t = Table(title=f"rover-ctl sim {args.mission.name}", show_header=False)
        driving = p.current_seq and len(p.reached) < p.waypoints_total
        t.add_row("waypoints", f"{len(p.reached)} of {p.waypoints_total} reached" + (f", heading for #{p.current_seq}" if driving else ""))
        t.add_row("to the waypoint", f"{p.distance_left_m:.1f} m" if driving and not math.isnan(p.distance_left_m) else "-")
        t.add_row("elapsed", f"sim {p.elapsed_sim_s:.1f} s, wall {p.elapsed_wall_s:.1f} s")
        t.add_row("collisions", str(p.collisions))
        t.add_row("status", p.last_text or "-")
        if p.gcs_url:
            t.add_row("watch with", f"mavproxy.py --master {p.gcs_url}")
        return t

    try:
        try:
            with Live(table(Progress()), console=console, refresh_per_second=4, transient=False) as live:
                last, latest = [0.0], [None]

                def on_tick(p: Progress) -> None:
                    latest[0] = p
                    if time.monotonic() - last[0] > 0.25:
                        last[0] = time.monotonic()
                        live.update(table(p))

                metrics = simulate(options, on_tick)
                if latest[0] is not None:  # the last tick, not the last one shown (shown at most 4 times a second)
                    live.update(table(latest[0]), refresh=True)
        finally:
            if not console.is_terminal:  # Live ends its last frame with a newline only on a terminal
                console.line()
    except MissionFileError as exc:
        raise UserError(str(exc)) from None
    except (SimError, ReportError) as exc:
        raise UserError(str(exc)) from None
    if args.json:
        print(json.dumps(metrics, indent=2))
    else:
        verdict = "[green]success[/]" if metrics["success"] else "[red]failed[/]"
        console.print(
            f"{verdict}: {metrics['waypoints_reached']}/{metrics['waypoints_total']} waypoints, "
            f"{metrics['collisions']} collisions, {metrics['path_length_m']} m driven in {metrics['duration_s']} s"
        )
        console.print(f"report: {out}/ (metrics.json, map.png, motors.png, tracking.png, vehicle.tlog, control.csv); {out.parent / 'latest'} points to it")
    return 0 if metrics["success"] else 1
