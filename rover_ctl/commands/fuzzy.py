"""``rover-ctl fuzzy eval|show``: rule bases for controller designers.

* ``eval --rulebase NAME|FILE [--input CSV] [--output CSV] [--explain]``: evaluate every row of a
  CSV whose header names the rule base's inputs (other columns are kept); the output repeats the
  input columns and appends one column per output (and, with ``--explain``, a ``rules`` column of
  ``#<rule number>=<strength>`` for the rules that fired). stdin/stdout by default.
* ``show NAME|FILE [--plot FILE.png]``: variables, sets, rule summary and coverage warnings;
  ``--plot`` draws the membership functions, one panel per variable, as the paper's figures do.
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import sys
import importlib.util
from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING

from rover_ctl import inputfile
from rover_ctl.cli import UserError

if TYPE_CHECKING:  # numpy and the engine load when a subcommand runs, not for --help
    import numpy as np

    from rover_ctl.fuzzy import RuleBase


def shipped_names() -> list[str]:
    """``rover_ctl.fuzzy.shipped()`` without importing the engine (and numpy) for the help text:
    the rule base files in the package's folder, found without running its ``__init__``."""
    folder = Path(importlib.util.find_spec("rover_ctl.fuzzy").submodule_search_locations[0]) / "rulebases"
    return sorted(p.stem for p in folder.glob("*.toml"))


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("fuzzy", help="evaluate or inspect fuzzy rule bases")
    sub = parser.add_subparsers(dest="fuzzy_command", metavar="ACTION", required=True)
    names = ", ".join(shipped_names())

    evaluate = sub.add_parser("eval", help="evaluate a rule base on the rows of a CSV")
    evaluate.add_argument("--rulebase", required=True, metavar="NAME|FILE", help=f"shipped ({names}) or a .toml or .fcl file")
    evaluate.add_argument("--input", metavar="CSV", help="input rows (default stdin)")
    evaluate.add_argument("--output", metavar="CSV", help="where to write (default stdout)")
    evaluate.add_argument("--explain", action="store_true", help="add a column with the rules that fired")
    evaluate.set_defaults(func=cmd_eval)

    show = sub.add_parser("show", help="print a rule base's variables and rule summary")
    show.add_argument("rulebase", metavar="NAME|FILE", help=f"shipped ({names}) or a .toml or .fcl file")
    show.add_argument("--plot", metavar="FILE.png", help="draw the membership functions to this image")
    show.set_defaults(func=cmd_show)


def _load(name: str) -> RuleBase:
    from rover_ctl.fuzzy import RuleBaseError, load_rulebase

    try:
        return load_rulebase(name)
    except RuleBaseError as exc:
        raise UserError(str(exc)) from None


def _read_rows(args: argparse.Namespace, rb: RuleBase) -> tuple[list[str], list[list[str]], dict[str, np.ndarray]]:
    import numpy as np

    where = args.input or "<stdin>"
    try:
        text = inputfile.read_text(args.input) if args.input else sys.stdin.read()
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"{where}: cannot read: {exc}") from None
    text = text.removeprefix("\ufeff")  # the byte-order mark spreadsheet programs put before the header
    reader = csv.reader(io.StringIO(text))
    try:
        header = [h.strip() for h in next(reader, [])]
        missing = [n for n in rb.input_names if n not in header]
        if missing:
            raise UserError(f"{where}: missing input column(s) {', '.join(missing)} (header: {','.join(header) or 'empty'})")
        rows = [row for row in reader if row]
    except csv.Error as exc:  # e.g. a field over the csv module's 128 KB limit
        raise UserError(f"{where} line {reader.line_num}: not CSV: {exc}") from None
    columns = {n: np.empty(len(rows)) for n in rb.input_names}
    for line, row in enumerate(rows, start=2):
        if len(row) != len(header):
            raise UserError(f"{where} line {line}: {len(row)} fields, the header has {len(header)}")
        for name in rb.input_names:
            value = row[header.index(name)].strip()
            try:
                number = float(value)
            except ValueError:
                number = math.nan
            if math.isnan(number):
                raise UserError(f"{where} line {line} column {name}: not a number: {value!r}")
            columns[name][line - 2] = number
    return header, rows, columns


def cmd_eval(args: argparse.Namespace) -> int:
    import numpy as np

    rb = _load(args.rulebase)
    header, rows, columns = _read_rows(args, rb)
    outputs = rb.evaluate(columns) if rows else {n: np.empty(0) for n in rb.output_names}
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header + list(rb.output_names) + (["rules"] if args.explain else []))
    for i, row in enumerate(rows):
        extra = [f"{outputs[n][i]:.4f}" for n in rb.output_names]
        if args.explain:
            fired = rb.explain(**{n: columns[n][i] for n in rb.input_names})
            extra.append(" ".join(f"#{index + 1}={strength:.3f}" for index, strength, _ in fired))
        writer.writerow(row + extra)
    if args.output:
        try:
            Path(args.output).write_text(buffer.getvalue(), encoding="utf-8")
        except OSError as exc:
            raise UserError(f"{args.output}: cannot write: {exc.strerror}") from None
    else:
        sys.stdout.write(buffer.getvalue())
    return 0


def _fmt(value: float) -> str:
    return "inf" if value == math.inf else "-inf" if value == -math.inf else f"{value:g}"


def cmd_show(args: argparse.Namespace) -> int:
    rb = _load(args.rulebase)
    print(f"rule base {rb.name} ({rb.source}): {rb.description}")
    print(f"  AND {rb.and_method}, aggregation max, defuzzifier {rb.defuzzifier}, {len(rb.rules)} rules")
    for kind, variables in (("input", rb.inputs), ("output", rb.outputs)):
        for v in variables:
            extra = f", circular period {_fmt(v.period)}" if v.period else ""
            extra += f", default {_fmt(v.default)}" if kind == "output" else ""
            print(f"  {kind} {v.name} [{v.unit}] range {_fmt(v.low)}..{_fmt(v.high)}{extra}")
            for s in v.sets:
                print(f"    {s.name:16s} {' '.join(_fmt(p) for p in s.points)}")
    for o, output in enumerate(rb.outputs):
        counts = Counter(output.sets[r.consequent[o]].name for r in rb.rules if r.consequent[o] is not None)
        print(f"  rules concluding {output.name}: " + ", ".join(f"{name} {counts[name]}" for name in output.set_names if counts[name]))
    for warning in rb.warnings:
        print(f"  warning: {warning}")
    if args.plot:
        print(f"  membership functions drawn to {_plot(rb, args.plot)}")
    return 0


def _plot(rb: RuleBase, path: str) -> Path:
    """Draw the membership functions to ``path`` (``.png`` added without a suffix, as matplotlib
    does); the file written."""
    import matplotlib
    import numpy as np

    if Path(path).is_dir():
        raise UserError(f"--plot {path}: is a folder; give a file name, e.g. {Path(path) / 'sets.png'}")
    target = Path(path) if Path(path).suffix else Path(path).with_suffix(".png")

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    variables = rb.inputs + rb.outputs
    cols = 2
    rows = math.ceil(len(variables) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(10, 2.4 * rows), squeeze=False)
    for ax, v in zip(axes.flat, variables):
        xs = np.linspace(v.low, v.high, 801)
        mu = v.memberships(xs)
        for k, s in enumerate(v.sets):
            ax.plot(xs, mu[:, k], label=s.name)
        ax.set_title(f"{v.name} [{v.unit}]", fontsize=9)
        ax.set_ylim(-0.05, 1.1)
        ax.legend(fontsize=7, loc="center right")
    for ax in axes.flat[len(variables) :]:
        ax.axis("off")
    fig.tight_layout()
    try:
        fig.savefig(target, dpi=90)
    except (OSError, ValueError) as exc:
        raise UserError(f"{target}: cannot write the plot: {exc}") from None
    finally:
        plt.close(fig)
    return target
