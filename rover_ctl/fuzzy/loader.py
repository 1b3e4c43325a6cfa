"""Rule-base files (TOML, documented in docs/fuzzy.md) to checked ``RuleBase`` objects.

Every problem is one ``RuleBaseError`` line naming the file and the variable or rule:
unknown keys, variables or set names, breakpoints that are not four (or three, a triangle)
ascending numbers, infinite output sets, malformed rule text, conflicting rules. Every number is
finite and within +-``MAX_MAGNITUDE``, except an input set's shoulder (``a = b = -inf`` or
``c = d = inf``); an output's default lies in its range; a period is positive and a circular
input's sets lie within ``-period .. 2 period``. Input combinations no rule covers are not errors
but are listed in ``RuleBase.warnings``.
"""

from __future__ import annotations

import math
import re
import tomllib
from pathlib import Path
from typing import Any

from rover_ctl import inputfile
from rover_ctl.fuzzy.fcl import parse_fcl
from rover_ctl.fuzzy.membership import FuzzySet, Variable
from rover_ctl.fuzzy.rulebase import Rule, RuleBase, RuleBaseError

SHIPPED_DIR = Path(__file__).resolve().parent / "rulebases"
MIN_RESOLUTION = 11
MAX_RESOLUTION = 1_000_001
"""Samples of the sampled defuzzifiers: beyond this a rule base would only cost memory and time."""
MAX_MAGNITUDE = 1e12
"""Largest |number| in a rule base (breakpoints, ranges, defaults, periods): far beyond any unit a
rover uses, and small enough that the defuzzifiers' products (area x peak) stay finite."""
TOP_KEYS = {"name", "description", "and", "defuzzifier", "resolution", "inputs", "outputs", "rules"}
VARIABLE_KEYS = {"unit", "range", "period", "default", "sets", "description"}
CLAUSE = re.compile(r"^\s*(\w+)\s+is\s+(\w+)\s*$")


class _Overflow(str):
    """A TOML float literal beyond the float range (``1e400``), which tomllib would read as inf."""


def _toml_float(text: str) -> float | _Overflow:
    value = float(text)
    return _Overflow(text) if math.isinf(value) and text.lstrip("+-") != "inf" else value


def shipped() -> list[str]:
    """Names of the rule bases shipped in the package."""
    return sorted(p.stem for p in SHIPPED_DIR.glob("*.toml"))


def resolve(name_or_path: str | Path) -> Path:
    """A shipped name (``paper``, ``default``) or a path to a file."""
    candidate = Path(name_or_path)
    if candidate.suffix == "" and (SHIPPED_DIR / f"{candidate.name}.toml").is_file() and not candidate.exists():
        return SHIPPED_DIR / f"{candidate.name}.toml"
    if not candidate.is_file():
        raise RuleBaseError(f"{name_or_path}: no such rule base file or shipped name (shipped: {', '.join(shipped())})")
    return candidate


def load_rulebase(name_or_path: str | Path) -> RuleBase:
    """Load and check a rule base by shipped name or path (TOML, or FCL for a ``.fcl`` file)."""
    path = resolve(name_or_path)
    try:
        text = inputfile.read_text(path)
    except (OSError, UnicodeDecodeError) as exc:
        raise RuleBaseError(f"{path}: cannot read: {exc}") from None
    if path.suffix.lower() == ".fcl":
        return parse_rulebase(parse_fcl(text, path.name), path.name)
    try:
        data = tomllib.loads(text, parse_float=_toml_float)
    except (ValueError, RecursionError) as exc:  # TOMLDecodeError, a 5000-digit number, nesting
        raise RuleBaseError(f"{path}: invalid TOML: {str(exc).splitlines()[0] or type(exc).__name__}") from None
    return parse_rulebase(data, path.name)


def parse_rulebase(data: dict[str, Any], where: str) -> RuleBase:
    """Build a rule base from the parsed TOML document (``where`` names it in errors)."""
    _no_unknown(data, TOP_KEYS, where)
    inputs = _variables(data.get("inputs"), "inputs", where, output=False)
    outputs = _variables(data.get("outputs"), "outputs", where, output=True)
    clash = {v.name for v in inputs} & {v.name for v in outputs}
    if clash:
        raise RuleBaseError(f"{where}: {', '.join(sorted(clash))} is both an input and an output")
    rules_table = data.get("rules")
    if not isinstance(rules_table, dict) or not isinstance(rules_table.get("list"), list) or not rules_table["list"]:
        raise RuleBaseError(f"{where}: [rules] needs a non-empty list = [\"if ... then ...\", ...]")
    _no_unknown(rules_table, {"list"}, f"{where} [rules]")
    rules = tuple(
        _rule(text, inputs, outputs, f"{where} rule {n}") for n, text in enumerate(rules_table["list"], start=1)
    )
    resolution = data.get("resolution", 1001)
    if not isinstance(resolution, int) or not MIN_RESOLUTION <= resolution <= MAX_RESOLUTION:
        raise RuleBaseError(
            f"{where}: resolution must be a whole number {MIN_RESOLUTION}-{MAX_RESOLUTION}, got {str(resolution)[:40]}"
        )
    return RuleBase(
        name=str(data.get("name", where)),
        description=str(data.get("description", "")),
        inputs=inputs,
        outputs=outputs,
        rules=rules,
        and_method=str(data.get("and", "min")),
        defuzzifier=str(data.get("defuzzifier", "area_centre")),
        resolution=resolution,
        source=where,
    )


def _no_unknown(table: dict[str, Any], known: set[str], where: str) -> None:
    unknown = sorted(set(table) - known)
    if unknown:
        raise RuleBaseError(f"{where}: unknown key(s) {', '.join(unknown)} (known: {', '.join(sorted(known))})")


def _number(value: Any, where: str, infinite: bool = False) -> float:
    """A finite number within +-MAX_MAGNITUDE (or +-inf if ``infinite``), else a RuleBaseError."""
    if isinstance(value, _Overflow):
        raise RuleBaseError(f"{where}: {value[:40]} is beyond the float range")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise RuleBaseError(f"{where}: expected a number, got {str(value)[:40]!r}")
    if isinstance(value, float) and math.isnan(value):
        raise RuleBaseError(f"{where}: expected a number, got {value!r}")
    if isinstance(value, float) and math.isinf(value):
        if not infinite:
            raise RuleBaseError(f"{where}: expected a finite number, got {value!r}")
        return value
    if abs(value) > MAX_MAGNITUDE:  # an int is compared exactly: a 400-digit one does not overflow
        shown = f"{value:g}" if isinstance(value, float) else str(value)[:40]
        raise RuleBaseError(f"{where}: expected a number within +-{MAX_MAGNITUDE:g}, got {shown}")
    return float(value)


def _variables(table: Any, kind: str, where: str, output: bool) -> tuple[Variable, ...]:
    if not isinstance(table, dict) or not table:
        raise RuleBaseError(f"{where}: needs at least one variable under [{kind}.<name>]")
    variables = []
    for name, spec in table.items():
        here = f"{where} [{kind}.{name}]"
        if not isinstance(spec, dict):
            raise RuleBaseError(f"{here}: expected a table")
        _no_unknown(spec, VARIABLE_KEYS if output else VARIABLE_KEYS - {"default"}, here)
        span = spec.get("range")
        if not isinstance(span, list) or len(span) != 2:
            raise RuleBaseError(f"{here}: range must be [low, high]")
        low, high = (_number(v, f"{here} range") for v in span)
        if not low < high:
            raise RuleBaseError(f"{here}: range must be finite with low < high, got {span!r}")
        period = spec.get("period")
        if period is not None:
            period = _number(period, f"{here} period")
            if output or period <= 0.0:
                raise RuleBaseError(f"{here}: period must be positive and only inputs can be circular")
        sets_spec = spec.get("sets")
        if not isinstance(sets_spec, dict) or not sets_spec:
            raise RuleBaseError(f"{here}: sets must be a table name = [a, b, c, d] (or [a, peak, c])")
        sets = []
        for set_name, points in sets_spec.items():
            if set_name in ("any", "none"):
                raise RuleBaseError(f"{here}: '{set_name}' is reserved and cannot name a set")
            sets.append(FuzzySet(set_name, _points(points, f"{here} set {set_name}", output, period)))
        default = _number(spec.get("default", 0.0), f"{here} default")
        if output and not low <= default <= high:
            given = "" if "default" in spec else " (the value when none is given: set one)"
            raise RuleBaseError(f"{here}: default {default:g}{given} is outside range [{low:g}, {high:g}]")
        variables.append(
            Variable(name, tuple(sets), low, high, str(spec.get("unit", "")), period, default)
        )
    return tuple(variables)


def _points(points: Any, where: str, finite: bool, period: float | None = None) -> tuple[float, float, float, float]:
    if not isinstance(points, list) or len(points) not in (3, 4):
        raise RuleBaseError(f"{where}: expected [a, b, c, d] (trapezoid) or [a, peak, c] (triangle), got {points!r}")
    values = [_number(v, where, infinite=True) for v in points]
    if len(values) == 3:
        values.insert(2, values[1])
    if any(p > q for p, q in zip(values, values[1:])):
        raise RuleBaseError(f"{where}: breakpoints must be ascending, got {points!r}")
    if values[0] == values[3]:
        raise RuleBaseError(f"{where}: a set needs a support of non-zero width, got {points!r}")
    if finite and not all(math.isfinite(v) for v in values):
        raise RuleBaseError(f"{where}: output sets must be finite (the defuzzifier integrates them), got {points!r}")
    a, b, c, d = values
    left_shoulder, right_shoulder = a == b == -math.inf, c == d == math.inf
    finite_left, finite_right = math.isfinite(a) and math.isfinite(b), math.isfinite(c) and math.isfinite(d)
    if not (left_shoulder or finite_left) or not (right_shoulder or finite_right):
        raise RuleBaseError(f"{where}: only a shoulder can be infinite (a = b = -inf or c = d = inf), got {points!r}")
    if left_shoulder and right_shoulder:
        raise RuleBaseError(f"{where}: a set cannot be a shoulder on both sides (it would cover every value), got {points!r}")
    if period is not None and not -period <= a <= d <= 2.0 * period:
        raise RuleBaseError(
            f"{where}: a circular input's breakpoints must lie within -period..2 x period "
            f"({-period:g}..{2.0 * period:g}: it is evaluated at x - period, x, x + period), got {points!r}"
        )
    return a, b, c, d


def _clauses(text: str, variables: tuple[Variable, ...], kind: str, where: str) -> tuple[int | None, ...]:
    chosen: list[int | None] = [None] * len(variables)
    names = [v.name for v in variables]
    for clause in re.split(r"\s+and\s+", text.strip()):
        match = CLAUSE.match(clause)
        if not match:
            raise RuleBaseError(f"{where}: cannot read {clause.strip()!r} (expected '<{kind}> is <set>')")
        var_name, set_name = match.groups()
        if var_name not in names:
            raise RuleBaseError(f"{where}: unknown {kind} {var_name!r} (known: {', '.join(names)})")
        i = names.index(var_name)
        if chosen[i] is not None:
            raise RuleBaseError(f"{where}: {var_name} appears twice")
        if set_name == "any" and kind == "input":
            continue
        try:
            chosen[i] = variables[i].set_index(set_name)
        except KeyError:
            raise RuleBaseError(
                f"{where}: unknown set {set_name!r} of {var_name} (known: {', '.join(variables[i].set_names)})"
            ) from None
    return tuple(chosen)


def _rule(text: Any, inputs: tuple[Variable, ...], outputs: tuple[Variable, ...], where: str) -> Rule:
    if not isinstance(text, str):
        raise RuleBaseError(f"{where}: expected a string 'if ... then ...', got {text!r}")
    match = re.match(r"^\s*if\s+(.+?)\s+then\s+(.+?)\s*$", text, flags=re.IGNORECASE)
    if not match:
        raise RuleBaseError(f"{where}: expected 'if <input> is <set> and ... then <output> is <set> and ...'")
    antecedent = _clauses(match.group(1), inputs, "input", where)
    consequent = _clauses(match.group(2), outputs, "output", where)
    if all(k is None for k in consequent):
        raise RuleBaseError(f"{where}: concludes nothing")
    return Rule(antecedent, consequent, " ".join(text.split()), where)
