"""A rule base's membership functions as a vector of numbers, and back, always valid.

The search moves *breakpoint values*, not sets: each variable's distinct finite breakpoints (over
all its sets) are its free parameters, and every set keeps referring to the same ranks. Where two
sets share a breakpoint (``near = [0, 0, 0.5, 1.2]`` ends where ``medium = [0.5, 1.2, ...]``
begins) they keep sharing it, so a partition stays a partition. A variable whose left/right
mirror (``obstacle_left`` / ``obstacle_right``, ``left_motor`` / ``right_motor``) has the very
same sets in the source shares its values with it (the robot is symmetric). The vector is short:
21 numbers for the default rule base's 117 breakpoints.

Fixed, never searched (the meaning of a variable, not its tuning):
- values at or beyond the universe's ends (``range``), and infinite shoulders;
- 0 of an output (``stop`` must stay a stop: zero wheel speed);
- on a circular input (``period``): 0, half the period and the period (dead ahead, behind).
  Only values strictly inside (0, period/2) are free; the rest are their mirror images
  (``period - v``) and wrapped copies (``-v``, ``period + v``), so left and right stay symmetric
  (the robot is) and a set crossing 0 stays one set. A circular input whose sets are not
  left/right symmetric is kept fixed.

``decode`` repairs any vector into a valid rule base: each free value is clipped into the open
segment between the fixed values around it (its universe), the values of a segment are sorted
and spread to at least ``MIN_GAP_FRACTION`` of the universe apart, then rounded to
``DECIMALS``. Sorting keeps every set's breakpoints ascending (a monotone map of the ranks), the
gap keeps every support non-zero, clipping keeps everything inside the universe:
``tests/tune/test_genome.py`` checks this on arbitrary vectors (Hypothesis).

Optionally (``scale_outputs``) one more number scales every output set and range about 0, within
``OUTPUT_SCALE_RANGE`` (off by default: the navigator scales the largest output peak to the top
wheel speed, so a common scale matters only where it meets a fixed output default; the scaled range
is widened to keep that default inside it, as the loader requires).
"""

from __future__ import annotations

import copy
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rover_ctl import inputfile
from rover_ctl.fuzzy import RuleBase, parse_rulebase
from rover_ctl.fuzzy.loader import resolve

MIN_GAP_FRACTION = 1e-3
"""Smallest distance between two free values, as a fraction of the universe (or half period)."""
DECIMALS = 4
"""Decimals of a breakpoint in a candidate (and in the tuned file)."""
MAX_STEP = 1e3
"""Vector entries are clipped to +-this (universes) before the repair: no overflow, same result."""
OUTPUT_SCALE_RANGE = (0.5, 1.5)
"""Bounds of the optional output scale."""


@dataclass(frozen=True)
class Gene:
    """One free value: which variable, its value in the source rule base, its segment."""

    kind: str
    """"inputs" or "outputs"."""
    variable: str
    value: float
    low: float
    high: float
    """The open segment it must stay inside (fixed values or universe ends around it)."""
    scale: float
    """The variable's universe width (half the period for a circular one): the search's unit."""


class GenomeError(ValueError):
    """A rule base the genome cannot describe (not TOML, or no free value at all)."""


def load_document(name_or_path: str | Path) -> tuple[dict[str, Any], str]:
    """The TOML document of a rule base (shipped name or path) and its file name."""
    path = resolve(name_or_path)
    if path.suffix.lower() != ".toml":
        raise GenomeError(f"{path}: only TOML rule bases can be tuned (write an FCL file as TOML first)")
    try:
        return tomllib.loads(inputfile.read_text(path)), path.name
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise GenomeError(f"{path}: cannot read: {exc}") from None


class Genome:
    """The free values of one rule-base document; ``decode(x)`` -> (document, RuleBase)."""

    def __init__(self, document: dict[str, Any], where: str = "<rule base>", scale_outputs: bool = False) -> None:
        parse_rulebase(document, where)  # the source must itself be valid
        self.document = document
        self.where = where
        self.scale_outputs = scale_outputs
        self.genes: list[Gene] = []
        self.twin_of: dict[tuple[str, str], str] = {}
        """(kind, variable) -> the variable whose values it shares (its left/right mirror)."""
        for kind in ("inputs", "outputs"):
            for name, spec in document[kind].items():
                twin = _mirror_name(name)
                if twin != name and _same_sets(document[kind].get(twin), spec) and (kind, twin) not in self.twin_of:
                    self.twin_of[(kind, name)] = twin
                    continue
                self.genes += _genes(kind, name, spec)
        if not self.genes:
            raise GenomeError(f"{where}: no membership-function value can move (all at universe ends)")

    @property
    def size(self) -> int:
        return len(self.genes) + (1 if self.scale_outputs else 0)

    def start(self) -> np.ndarray:
        """The source rule base's vector (the search's mean at generation 0): all zeros, since a
        vector is the offset of each value from the source, in units of ``Gene.scale``."""
        return np.zeros(self.size)

    def values(self, x: np.ndarray) -> dict[tuple[str, str], dict[float, float]]:
        """Repaired values: (kind, variable) -> {source value: new value}."""
        x = np.asarray(x, dtype=float)
        if x.shape != (self.size,):
            raise ValueError(f"expected a vector of {self.size} numbers, got shape {x.shape}")
        x = np.clip(np.where(np.isnan(x), 0.0, x), -MAX_STEP, MAX_STEP)  # NaN: the source value; inf: the far end
        raw = [g.value + xi * g.scale for g, xi in zip(self.genes, x[: len(self.genes)])]
        groups: dict[tuple[str, str, float, float], list[int]] = {}
        for i, g in enumerate(self.genes):
            groups.setdefault((g.kind, g.variable, g.low, g.high), []).append(i)
        out: dict[tuple[str, str], dict[float, float]] = {}
        for (kind, variable, low, high), members in groups.items():
            scale = self.genes[members[0]].scale
            repaired = _spread(sorted(raw[i] for i in members), low, high, max(MIN_GAP_FRACTION * scale, 10.0 ** -(DECIMALS - 1)))
            mapping = out.setdefault((kind, variable), {})
            for i, value in zip(sorted(members, key=lambda i: self.genes[i].value), repaired):
                mapping[self.genes[i].value] = value
        return out

    def repaired(self, x: np.ndarray) -> np.ndarray:
        """The vector of the rule base ``x`` decodes to (``x`` itself when no repair was needed)."""
        moved = self.values(x)
        out = [(moved[(g.kind, g.variable)][g.value] - g.value) / g.scale for g in self.genes]
        if self.scale_outputs:
            out.append(self.output_scale(x) - 1.0)
        return np.array(out)

    def output_scale(self, x: np.ndarray) -> float:
        if not self.scale_outputs:
            return 1.0
        low, high = OUTPUT_SCALE_RANGE
        return round(float(np.clip(1.0 + float(np.nan_to_num(x[-1])), low, high)), DECIMALS)

    def decode_document(self, x: np.ndarray) -> dict[str, Any]:
        """The candidate's TOML document (a deep copy of the source with new breakpoints)."""
        doc = copy.deepcopy(self.document)
        moved = self.values(x)
        scale = self.output_scale(x)
        for kind in ("inputs", "outputs"):
            for name, spec in doc[kind].items():
                mapping = moved.get((kind, self.twin_of.get((kind, name), name)), {})
                period = spec.get("period")
                scaled = kind == "outputs" and scale != 1.0
                for set_name, points in spec["sets"].items():
                    new = [_map(float(p), mapping, period) for p in points]
                    if scaled:
                        new = [round(p * scale, DECIMALS) for p in new]
                    spec["sets"][set_name] = [float(p) for p in new]
                if scaled:  # the universe with its sets (the sampled defuzzifiers sample the range)
                    low, high = (round(float(v) * scale, DECIMALS) for v in spec["range"])
                    default = float(spec.get("default", 0.0))  # fixed, and the loader wants it in range
                    spec["range"] = [min(low, default), max(high, default)]
        return doc

    def decode(self, x: np.ndarray) -> tuple[dict[str, Any], RuleBase]:
        """Candidate document and its checked rule base (RuleBaseError would be a bug in the repair)."""
        doc = self.decode_document(x)
        return doc, parse_rulebase(doc, self.where)

    def describe(self) -> str:
        per_variable: dict[str, int] = {}
        for g in self.genes:
            per_variable[g.variable] = per_variable.get(g.variable, 0) + 1
        text = ", ".join(f"{name} {count}" for name, count in per_variable.items())
        if self.twin_of:
            text += "; shared with the mirror: " + ", ".join(f"{a} = {b}" for (_k, a), b in self.twin_of.items())
        return f"{self.size} parameters ({text}{', output scale 1' if self.scale_outputs else ''})"


def _same_sets(a: dict[str, Any] | None, b: dict[str, Any]) -> bool:
    return a is not None and all(a.get(key) == b.get(key) for key in ("sets", "range", "period"))


def _mirror_name(name: str) -> str:
    """``obstacle_left`` <-> ``obstacle_right``, ``left_motor`` <-> ``right_motor``."""
    return name.replace("left", "\0").replace("right", "left").replace("\0", "right")


def _genes(kind: str, name: str, spec: dict[str, Any]) -> list[Gene]:
    low, high = (float(v) for v in spec["range"])
    period = spec.get("period")
    values = sorted({float(p) for points in spec["sets"].values() for p in points if math.isfinite(float(p))})
    if period is not None:
        period = float(period)
        half = period / 2.0
        wrapped = {round(v % period, 9) for v in values}
        if any(round((period - v) % period, 9) not in wrapped for v in wrapped):
            return []  # not left/right symmetric: the mirror parametrisation does not apply, kept fixed
        free = [v for v in values if 0.0 < v < half]
        fixed = [0.0, half]
        scale = half
    else:
        fixed = [low, high] + ([0.0] if kind == "outputs" and low < 0.0 < high else [])
        free = [v for v in values if low < v < high and v not in fixed]
        scale = high - low
    fixed = sorted(set(fixed))
    genes = []
    for v in free:
        below = max(f for f in fixed if f < v)
        above = min(f for f in fixed if f > v)
        genes.append(Gene(kind, name, v, below, above, scale))
    return genes


def _spread(values: list[float], low: float, high: float, gap: float) -> list[float]:
    """Sorted ``values`` clipped into the open (low, high), at least ``gap`` apart, rounded."""
    n = len(values)
    gap = min(gap, (high - low) / (n + 1))
    out = [min(max(v, low + gap), high - gap) for v in values]
    for i in range(1, n):  # push up from the left...
        out[i] = max(out[i], out[i - 1] + gap)
    for i in range(n - 1, -1, -1):  # ...and down from the right, inside the segment
        ceiling = (high - gap) if i == n - 1 else out[i + 1] - gap
        out[i] = min(out[i], ceiling)
    rounded = [round(v, DECIMALS) for v in out]
    if any(b <= a for a, b in zip(rounded, rounded[1:])) or (rounded and (rounded[0] <= low or rounded[-1] >= high)):
        return out  # a segment too narrow for the rounding: keep the exact spread
    return rounded


def _map(p: float, mapping: dict[float, float], period: float | None) -> float:
    """A source breakpoint's new value (fixed values and infinities unchanged)."""
    if not math.isfinite(p):
        return p
    if p in mapping:
        return mapping[p]
    if period is None:
        return p
    period = float(period)
    half = period / 2.0
    # A circular breakpoint outside (0, half): the mirror (period - v) or a wrapped copy of a free one.
    for shift, sign in ((0.0, -1.0), (period, -1.0), (period, 1.0), (-period, 1.0)):
        # p = shift + sign * v  <=>  v = (p - shift) * sign
        v = (p - shift) * sign
        if v in mapping and 0.0 < v < half:
            return round(shift + sign * mapping[v], DECIMALS)
    return p

