"""``rover-ctl tune RULEBASE --scenarios NAME,...``: a rule base tuned by CMA-ES on Dask (docs/tuning.md)."""

from __future__ import annotations

import argparse
import math
import re
import signal
import sys
from pathlib import Path

from rover_ctl.cli import count, number_type

CMA_SEED = number_type(int, 1, 2**32 - 1, "a whole number", "in 1..4294967295 (cma's seed range; 0 would seed from the clock)")

SCHEDULER = re.compile(r"^(tcp|tls)://[^\s/:]+:(\d{1,5})$")


def _scheduler(text: str) -> str:
    match = SCHEDULER.match(text)
    if not match or not 1 <= int(match.group(2)) <= 65535:
        raise argparse.ArgumentTypeError(f"expected tcp://HOST:PORT (PORT in 1..65535), got {text!r}")
    return text


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("tune", help="tune a rule base's membership functions (CMA-ES on Dask)",
                                   description="Tune a rule base's membership functions by CMA-ES over seeded episodes, on a "
                                               "local or remote Dask cluster (docs/tuning.md).")  # fmt: skip
    parser.add_argument("rulebase", metavar="RULEBASE", help="shipped name (default, paper) or a .toml rule base")
    parser.add_argument("--scenarios", required=True, metavar="NAME,...",
                        help="open, scattered, walls, cul_de_sac, moving, crossing, head_on, overtaking, narrow_gap, "
                             "dense_clutter (comma-separated)")  # fmt: skip
    parser.add_argument("--worlds", type=count, default=4, metavar="N", help="training worlds per scenario (default 4)")
    parser.add_argument("--generations", type=count, default=30, metavar="G", help="CMA-ES generations (default 30)")
    parser.add_argument("--population", type=count, default=8, metavar="P", help="candidates per generation (default 8, at least 2)")
    parser.add_argument("--holdout", type=count, default=100, metavar="N", help="held-out worlds per scenario for the report and its verdict (default 100)")
    parser.add_argument("--seed", type=CMA_SEED, default=1, help="seed of CMA-ES and of the world seeds (default 1)")
    parser.add_argument("--scheduler", type=_scheduler, metavar="tcp://HOST:PORT", help="an existing Dask scheduler (default: a local cluster)")
    parser.add_argument("--workers", type=count, metavar="N", help="local cluster workers (default: one per core)")
    parser.add_argument("--scale-outputs", action="store_true", help="also search one scale of the output sets")
    parser.add_argument("--out", type=Path, metavar="DIR", help="run folder: checkpoint, tuned.toml, report (default runs/tune/<rulebase>); "
                                                             "an existing checkpoint there is resumed")  # fmt: skip
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE", help="daemon config override for the episodes (repeatable)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.live import Live
    from rich.table import Table

    from rover_ctl.app.tune import Progress, TuneError, TuneOptions, command_line, prepare, tune
    from rover_ctl.cli import UserError
    from rover_ctl.config import load_config
    from rover_ctl.tuning.verdict import HEADLINES

    if args.population < 2:
        raise UserError(f"--population {args.population}: CMA-ES needs at least 2 candidates")
    if args.workers is not None and args.scheduler:
        raise UserError("--workers sizes the local cluster; it does not apply with --scheduler")
    load_config(None, args.set)  # a bad --set is refused now
    scenarios = [s for s in args.scenarios.split(",") if s]
    out = args.out or Path("runs") / "tune" / Path(args.rulebase).stem
    options = TuneOptions(rulebase=args.rulebase, scenarios=scenarios, out=out, worlds=args.worlds, generations=args.generations,
                          population=args.population, holdout=args.holdout, seed=args.seed, scheduler=args.scheduler,
                          workers=args.workers, scale_outputs=args.scale_outputs, config_overrides=args.set,
                          command=command_line(sys.argv[1:]))  # fmt: skip
    console = Console(stderr=True)
    signal.signal(signal.SIGTERM, _interrupt)  # a service stop ends the run as Ctrl-C does: cluster closed, checkpoint kept

    def table(p: Progress) -> Table:
        t = Table(title=f"rover-ctl tune {args.rulebase}", show_header=False)
        t.add_row("generation", f"{p.generation}/{p.generations}" + (" (held-out check)" if p.phase != "search" else ""))
        t.add_row("episodes", f"{p.done}/{p.total}, {_num(p.episodes_per_s, '.2f')}/s, {_num(p.sim_x, '.0f')}x real time")
        t.add_row("workers", str(p.workers))
        t.add_row("score", f"best {_num(p.best, '.2f')}, median of generation {_num(p.median, '.2f')}")
        return t

    try:
        prepared = prepare(options)
        try:
            with Live(table(Progress(generations=args.generations)), console=console, refresh_per_second=2) as live:
                result = tune(options, lambda p: live.update(table(p)), prepared)
        finally:
            if not console.is_terminal:  # Live ends its last frame with a newline only on a terminal
                console.line()
    except TuneError as exc:
        raise UserError(str(exc)) from None
    for line in result["verdict_lines"]:
        console.print(line, markup=False, highlight=False, soft_wrap=True)
    console.print(f"verdict: {HEADLINES[result['verdict']]}", markup=False, highlight=False, soft_wrap=True)
    console.print(f"tuned rule base: {out / 'tuned.toml'} (use with --rulebase); report: {out / 'report.md'}")
    return 0


def _interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


def _num(value: float, spec: str) -> str:
    return "-" if value is None or math.isnan(value) else format(value, spec)
