"""Run the benchmarks and rewrite docs/BENCHMARKS.md.

Each benchmark is a module ``bench/bench_<name>.py`` with ``run(quick: bool) -> dict`` returning
``{"title": str, "markdown": str, ...figures}``. The dict is written to
``bench/results/<name>.json``; the markdown sections are joined into docs/BENCHMARKS.md in name
order. ``python -m bench [NAME ...] [--quick]`` runs some or all of them; sections of benchmarks not
run this time are kept from their last JSON. ``python -m bench navigation --only crossing,moving
--worlds 10`` runs some scenarios of the navigation benchmark on fewer worlds (its other rows are
kept from the last run, each row dated); ``--variants paper,default`` runs only those variants
(likewise keeping the other rows); ``--rulebase FILE`` compares a rule base file (a
``rover-ctl tune`` result) with default in a table of its own (``navigation_rulebase.json``);
``--scheduler tcp://HOST:8786`` runs the worlds as tasks on a Dask cluster whose workers run from
a checkout of this tree (docs/tuning.md, "On a cluster"). Ctrl-C or SIGTERM stops a run: the
benchmark in progress stops its emulators and daemons (the navigation benchmark's worlds run on
threads: ``SimRun.cancelled``) and nothing is written.

A result may carry ``"notes"``: paragraphs written by hand (what a row's figures were compared
with, why a row is older), each dated in its text. A rerun keeps them from the JSON it replaces and
they follow the benchmark's own text in docs/BENCHMARKS.md, so whoever re-runs a row reads them and
edits any that the new figures make untrue.
"""

from __future__ import annotations

import argparse
import importlib
import json
import signal
import sys
import time
from pathlib import Path

from bench import machine

ROOT = Path(__file__).resolve().parent
RESULTS = ROOT / "results"
DOC = ROOT.parent / "docs" / "BENCHMARKS.md"


def available() -> list[str]:
    return sorted(p.stem.removeprefix("bench_") for p in ROOT.glob("bench_*.py"))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench", description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help=f"benchmarks to run (default all: {', '.join(available())})")
    parser.add_argument("--quick", action="store_true", help="fewer repetitions, for a smoke run")
    parser.add_argument("--only", metavar="SCENARIO,...", help="navigation: run only these scenarios (the other rows are kept from the last run)")
    parser.add_argument("--worlds", type=int, metavar="N", help="navigation: N seeded worlds per scenario instead of the full counts")
    parser.add_argument("--variants", metavar="NAME,...", help="navigation: run only these variants (rule base + settings; the other rows are kept)")
    parser.add_argument("--rulebase", metavar="FILE", help="navigation: this rule base file against default, in a table of its own")
    parser.add_argument("--scheduler", metavar="ADDRESS", help="navigation: run the worlds as tasks on this Dask cluster (tcp://HOST:8786)")
    args = parser.parse_args(argv)
    # SIGTERM (a CI timeout, `timeout`) unwinds like Ctrl-C, so each benchmark stops its children;
    # the handler it replaces is put back (tests call main in their own process).
    previous = signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    try:
        return _run(parser, args)
    finally:
        signal.signal(signal.SIGTERM, previous)


def _run(parser: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    names = args.names or available()
    unknown = sorted(set(names) - set(available()))
    if unknown:
        parser.error(f"unknown benchmark(s): {', '.join(unknown)}")
    RESULTS.mkdir(exist_ok=True)
    for name in names:
        print(f"== bench {name}", flush=True)
        options = {k: v for k, v in (("only", args.only and args.only.split(",")), ("worlds", args.worlds),
                                     ("variants", args.variants and args.variants.split(",")), ("rulebase", args.rulebase),
                                     ("scheduler", args.scheduler)) if v}  # fmt: skip
        if options and name != "navigation":
            parser.error(f"--only, --worlds, --variants, --rulebase and --scheduler apply to the navigation benchmark, not {name}")
        module = importlib.import_module(f"bench.bench_{name}")
        unknown = sorted(set(options.get("only", ())) - set(getattr(module, "FULL_WORLDS", ())))
        if unknown:
            parser.error(f"unknown scenario(s) {', '.join(unknown)} (known: {', '.join(module.FULL_WORLDS)})")
        unknown = sorted(set(options.get("variants", ())) - set(getattr(module, "VARIANTS", ())))
        if unknown:
            parser.error(f"unknown variant(s) {', '.join(unknown)} (known: {', '.join(module.VARIANTS)})")
        reference_ms = machine.fresh_reference_ms()
        started = time.perf_counter()
        try:
            result = module.run(quick=args.quick, **options)
        except ValueError as exc:  # a bad --rulebase file, an unreachable --scheduler
            parser.error(str(exc))
        wall_s = time.perf_counter() - started
        result.setdefault("machine", machine.describe(reference_ms, machine.fresh_reference_ms()))
        result.setdefault("date", time.strftime("%Y-%m-%d"))
        result["wall_s"] = round(wall_s, 1)
        path = RESULTS / f"{result.get('name', name)}.json"
        if path.exists() and "notes" not in result:
            try:
                notes = json.loads(path.read_text()).get("notes")
            except (OSError, ValueError, AttributeError) as exc:  # never lose a finished run to the old file
                print(f"{path}: its notes could not be read ({exc}); writing without them", file=sys.stderr)
                notes = None
            if notes:
                result["notes"] = notes
        path.write_text(json.dumps(result, indent=2, default=float) + "\n")
        print(result.get("markdown", ""), flush=True)
    write_doc()
    return 0


def write_doc() -> None:
    parts = [
        "# Benchmarks\n",
        "Written by `python -m bench` (or `make bench`) from `bench/results/*.json`; every figure "
        "below was measured by the run named in its section, on the machine it names. Since 2026-11-27 "
        "that names the CPU and a reference time: the CPU time of a fixed pure-Python workload "
        "(`bench/machine.py`). This machine is a virtual machine whose host changes from day to day "
        "(the same tree ran the SITL benchmark 2.3-2.4 times slower on 2026-11-27 than on 2026-11-22): "
        "compare CPU times and real-time factors of two runs only with their reference times beside them.\n",
    ]
    for path in sorted(RESULTS.glob("*.json")):
        result = json.loads(path.read_text())
        parts.append(f"\n## {result.get('title', path.stem)}\n")
        parts.append(f"_`{result.get('command', f'python -m bench {path.stem}')}` on {result.get('date')}, {result.get('machine')}, {result.get('wall_s')} s._\n")
        parts.append("\n\n".join([result.get("markdown", ""), *result.get("notes", [])]) + "\n")
    DOC.write_text("\n".join(parts))


if __name__ == "__main__":
    sys.exit(main())
