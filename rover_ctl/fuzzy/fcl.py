"""IEC 61131-7 Fuzzy Control Language (FCL) import, for rule bases designed in other tools.

The supported subset maps one-to-one onto the TOML format and goes through the same checks:
``VAR_INPUT``/``VAR_OUTPUT`` (REAL), ``FUZZIFY``/``DEFUZZIFY`` blocks with ``TERM name := (x, mu)
...;`` point lists that describe a trapezoid, triangle or shoulder (values outside the points hold
the end values, as FCL says), ``RANGE := (low .. high);``, ``METHOD : COG | MM | AREA_CENTRE;``
(``AREA_CENTRE`` is this project's extension for the paper's defuzzifier), ``DEFAULT := value;``,
and one ``RULEBLOCK`` with ``AND : MIN | PROD;``, ``ACCU : MAX;``, ``ACT : MIN;`` and rules
``RULE n : IF a IS x AND b IS y THEN out IS z [, out2 IS w];``. Anything else (OR, NOT, WITH
weights, singleton terms, other methods) is refused with the line it is on, and so is a number
beyond the float range (``1e999``) in a TERM, RANGE or DEFAULT. FCL has no circular
variables: angle inputs need the TOML format.
"""

from __future__ import annotations

import math
import re
from typing import Any

from rover_ctl.fuzzy.rulebase import RuleBaseError

METHODS = {"COG": "centroid", "MM": "mean_of_maxima", "MOM": "mean_of_maxima", "AREA_CENTRE": "area_centre"}
ANDS = {"MIN": "min", "PROD": "product"}
NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
POINT = re.compile(rf"\(\s*({NUMBER})\s*,\s*({NUMBER})\s*\)")


def _points_to_trapezoid(points: list[tuple[float, float]], where: str) -> list[float]:
    """(x, mu) points of a trapezoid-shaped term -> [a, b, c, d] with infinite shoulders."""
    xs = [x for x, _ in points]
    mus = [mu for _, mu in points]
    if any(m not in (0.0, 1.0) for m in mus) or any(p > q for p, q in zip(xs, xs[1:])):
        raise RuleBaseError(f"{where}: term points must be ascending in x with memberships 0 or 1, got {points}")
    shapes = {
        (1, 0): lambda: [-math.inf, -math.inf, xs[0], xs[1]],
        (0, 1): lambda: [xs[0], xs[1], math.inf, math.inf],
        (0, 1, 0): lambda: [xs[0], xs[1], xs[1], xs[2]],
        (0, 1, 1, 0): lambda: [xs[0], xs[1], xs[2], xs[3]],
        (1, 1, 0): lambda: [-math.inf, -math.inf, xs[1], xs[2]],
        (0, 1, 1): lambda: [xs[0], xs[1], math.inf, math.inf],
    }
    shape = tuple(int(m) for m in mus)
    if shape not in shapes:
        raise RuleBaseError(f"{where}: term is not a trapezoid, triangle or shoulder: {points}")
    return shapes[shape]()


def _finite(text: str, where: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise RuleBaseError(f"{where}: {text[:40]} is not a finite number")
    return value


def parse_fcl(text: str, where: str) -> dict[str, Any]:
    """FCL text -> the document structure ``parse_rulebase`` takes (see the module docstring)."""
    text = re.sub(r"\(\*.*?\*\)", lambda m: "\n" * m.group(0).count("\n"), text, flags=re.S)
    text = re.sub(r"//[^\n]*", "", text)
    data: dict[str, Any] = {"inputs": {}, "outputs": {}, "rules": {"list": []}}
    block: tuple[str, str] | None = None  # (kind, variable name)
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip().rstrip(";").strip()
        here = f"{where} line {number}"
        if not line:
            continue
        head = line.split()[0].upper()
        if head == "FUNCTION_BLOCK":
            data["name"] = line.split()[1] if len(line.split()) > 1 else where
        elif head in ("VAR_INPUT", "VAR_OUTPUT"):
            block = (head, "")
        elif head in ("END_VAR", "END_FUZZIFY", "END_DEFUZZIFY", "END_RULEBLOCK", "END_FUNCTION_BLOCK"):
            block = None
        elif head in ("FUZZIFY", "DEFUZZIFY"):
            if len(line.split()) < 2:
                raise RuleBaseError(f"{here}: {head} needs the name of a variable")
            name = line.split()[1]
            table = data["inputs" if head == "FUZZIFY" else "outputs"]
            if name not in table:
                raise RuleBaseError(f"{here}: {name} is not declared in {'VAR_INPUT' if head == 'FUZZIFY' else 'VAR_OUTPUT'}")
            block = (head, name)
        elif head == "RULEBLOCK":
            block = ("RULEBLOCK", "")
        elif block and block[0] in ("VAR_INPUT", "VAR_OUTPUT"):
            match = re.fullmatch(r"(\w+)\s*:\s*REAL", line, flags=re.I)
            if not match:
                raise RuleBaseError(f"{here}: expected '<name> : REAL;'")
            table = data["inputs" if block[0] == "VAR_INPUT" else "outputs"]
            table[match.group(1)] = {"sets": {}}
        elif block and block[0] in ("FUZZIFY", "DEFUZZIFY"):
            _variable_line(line, data["inputs" if block[0] == "FUZZIFY" else "outputs"][block[1]], data, here)
        elif block and block[0] == "RULEBLOCK":
            _ruleblock_line(line, data, here)
        else:
            raise RuleBaseError(f"{here}: unexpected {raw.strip()!r}")
    for kind in ("inputs", "outputs"):
        for name, spec in data[kind].items():
            finite = [p for points in spec["sets"].values() for p in points if math.isfinite(p)]
            if "range" not in spec and finite:
                spec["range"] = [min(finite), max(finite)]
    return data


def _variable_line(line: str, spec: dict[str, Any], data: dict[str, Any], here: str) -> None:
    if match := re.fullmatch(r"TERM\s+(\w+)\s*:=\s*(.+)", line, flags=re.I):
        term = f"{here} TERM {match.group(1)}"
        if POINT.sub(" ", match.group(2)).replace(",", " ").strip():  # e.g. (inf, 0): not skipped
            raise RuleBaseError(f"{term}: expected (x, mu) points with x and mu numbers, got {match.group(2)[:60]!r}")
        points = [(_finite(x, term), _finite(mu, term)) for x, mu in POINT.findall(match.group(2))]
        if len(points) < 2:
            raise RuleBaseError(f"{here}: TERM {match.group(1)} needs (x, mu) points")
        spec["sets"][match.group(1)] = _points_to_trapezoid(points, term)
    elif match := re.fullmatch(rf"RANGE\s*:=\s*\(\s*({NUMBER})\s*\.\.\s*({NUMBER})\s*\)", line, flags=re.I):
        spec["range"] = [_finite(match.group(1), f"{here} RANGE"), _finite(match.group(2), f"{here} RANGE")]
    elif match := re.fullmatch(r"METHOD\s*:\s*(\w+)", line, flags=re.I):
        method = match.group(1).upper()
        if method not in METHODS:
            raise RuleBaseError(f"{here}: METHOD {method} not supported (supported: {', '.join(METHODS)})")
        data["defuzzifier"] = METHODS[method]
    elif match := re.fullmatch(rf"DEFAULT\s*:=\s*({NUMBER})", line, flags=re.I):
        spec["default"] = _finite(match.group(1), f"{here} DEFAULT")
    else:
        raise RuleBaseError(f"{here}: unexpected {line!r} (TERM, RANGE, METHOD, DEFAULT supported)")


def _ruleblock_line(line: str, data: dict[str, Any], here: str) -> None:
    if match := re.fullmatch(r"(AND|ACCU|ACT)\s*:\s*(\w+)", line, flags=re.I):
        key, value = match.group(1).upper(), match.group(2).upper()
        supported = (key == "AND" and value in ANDS) or (key == "ACCU" and value == "MAX") or (key == "ACT" and value == "MIN")
        if not supported:
            raise RuleBaseError(f"{here}: {key} : {value} not supported (AND MIN|PROD, ACCU MAX, ACT MIN)")
        if key == "AND":
            data["and"] = ANDS[value]
    elif match := re.fullmatch(r"RULE\s+\w+\s*:\s*IF\s+(.+?)\s+THEN\s+(.+)", line, flags=re.I):
        condition, conclusion = match.groups()
        if re.search(r"\b(OR|NOT|WITH)\b", line, flags=re.I):
            raise RuleBaseError(f"{here}: OR, NOT and WITH are not supported")
        conclusion = re.sub(r"\s*,\s*", " and ", conclusion)
        text = f"if {condition} then {conclusion}"
        data["rules"]["list"].append(re.sub(r"\b(IS|AND)\b", lambda m: m.group(1).lower(), text, flags=re.I))
    else:
        raise RuleBaseError(f"{here}: unexpected {line!r} in RULEBLOCK")
