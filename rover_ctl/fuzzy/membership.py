"""Linguistic variables: a universe and its piecewise-linear fuzzy sets.

Every set is a trapezoid given by four breakpoints ``a <= b <= c <= d``::

    mu(x) = clip(min((x - a) / (b - a), 1, (d - x) / (d - c)), 0, 1)

A triangle is ``b == c``; a left shoulder has ``a == b = -inf`` (or ``a == b`` at the universe's
lower end: then ``mu = 1`` from ``a`` on and 0 below it, so inputs below the universe fire
nothing, as in the paper); a right shoulder has ``c == d = inf``. A vertical edge (``a == b`` or
``c == d``) belongs to the set: ``mu(a) = 1`` when ``a == b``.

A circular variable (an angle) has a ``period``: inputs are wrapped into ``[0, period)`` and a set
whose breakpoints cross 0 or the period (``ahead = [-90, 0, 0, 90]`` in degrees) is evaluated at
``x - period``, ``x`` and ``x + period``, the largest value counting.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class FuzzySet:
    """One named trapezoid ``points = (a, b, c, d)`` (see the module docstring)."""

    name: str
    points: tuple[float, float, float, float]

    @property
    def peak(self) -> float:
        """Middle of the core ``[b, c]``: the value the paper's defuzzifier weights by."""
        b, c = self.points[1], self.points[2]
        return (b + c) / 2.0

    def membership(self, x: np.ndarray) -> np.ndarray:
        """mu(x) for an array (no wrapping: that is the variable's job); NaN gives 0."""
        a, b, c, d = self.points
        x = np.asarray(x, dtype=np.float64)
        rising = (x - a) / (b - a) if b > a else np.where(x >= a, 1.0, 0.0)
        falling = (d - x) / (d - c) if d > c else np.where(x <= d, 1.0, 0.0)
        # fmin/fmax drop NaN in favour of the number: a NaN input ends at 0
        return np.fmin(np.fmax(np.fmin(rising, falling), 0.0), 1.0)

    def membership_one(self, x: float) -> float:
        """mu(x) for one float, without numpy (the control loop's path)."""
        a, b, c, d = self.points
        if x < a or x > d:
            return 0.0
        if x < b:
            return (x - a) / (b - a)
        if x > c:
            return (d - x) / (d - c)
        return 1.0


@dataclass(frozen=True)
class Variable:
    """A linguistic variable: name, unit, universe ``[low, high]``, its sets, optional period."""

    name: str
    sets: tuple[FuzzySet, ...]
    low: float
    high: float
    unit: str = ""
    period: float | None = None
    """Circular universe: inputs wrap modulo ``period`` (360 for degrees)."""
    default: float = 0.0
    """Outputs only: the crisp value when no rule fires for this output."""

    def set_index(self, name: str) -> int:
        for index, fuzzy_set in enumerate(self.sets):
            if fuzzy_set.name == name:
                return index
        raise KeyError(name)

    @property
    def set_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.sets)

    def memberships(self, x: np.ndarray) -> np.ndarray:
        """Membership of every set, shape ``x.shape + (len(sets),)``; NaN inputs fire nothing."""
        x = np.asarray(x, dtype=np.float64)
        return np.moveaxis(self.membership_rows(x.ravel()).reshape((len(self.sets),) + x.shape), 0, -1)

    def membership_rows(self, x: np.ndarray) -> np.ndarray:
        """Membership of every set for a 1-D array, shape ``(len(sets), len(x))``."""
        rows = np.empty((len(self.sets), x.size))
        if self.period is None:
            for k, fuzzy_set in enumerate(self.sets):
                rows[k] = fuzzy_set.membership(x)
            return rows
        with np.errstate(invalid="ignore"):  # an infinite angle wraps to NaN: fires nothing
            wrapped = np.mod(x, self.period)
        for k, fuzzy_set in enumerate(self.sets):
            a, _, _, d = fuzzy_set.points
            rows[k] = fuzzy_set.membership(wrapped)
            # only a set reaching past 0 or the period needs the shifted copies
            if a < 0.0:
                np.fmax(rows[k], fuzzy_set.membership(wrapped - self.period), out=rows[k])
            if d > self.period:
                np.fmax(rows[k], fuzzy_set.membership(wrapped + self.period), out=rows[k])
        return rows

    def memberships_one(self, x: float) -> list[float]:
        """Membership of every set for one float (pure Python)."""
        if math.isnan(x) or (self.period is not None and math.isinf(x)):  # no angle: nothing fires
            return [0.0] * len(self.sets)
        if self.period is None:
            return [s.membership_one(x) for s in self.sets]
        wrapped = math.fmod(x, self.period)
        if wrapped < 0.0:
            wrapped += self.period
        low, high = wrapped - self.period, wrapped + self.period
        memberships = []
        for fuzzy_set in self.sets:
            a, _, _, d = fuzzy_set.points
            # The copies a period away are 0 (x < a, x > d) unless the set reaches below 0
            # (low < 0) or to the period (high >= period): computed only then.
            mu_low = fuzzy_set.membership_one(low) if a < 0.0 else 0.0
            mu_high = fuzzy_set.membership_one(high) if d >= self.period else 0.0
            memberships.append(max(mu_low, fuzzy_set.membership_one(wrapped), mu_high))
        return memberships

    def _probes(self) -> np.ndarray:
        """Every breakpoint, the middle between neighbouring ones and a point beyond each end
        (wrapped too for a circular variable): piecewise-linear sets are linear between them, so
        which sets are non-zero anywhere is decided at these points."""
        points = sorted({p for s in self.sets for p in s.points if math.isfinite(p)} | {self.low, self.high})
        probes = list(points)
        probes += [(p + q) / 2.0 for p, q in zip(points, points[1:])]
        probes += [points[0] - 1.0, points[-1] + 1.0]
        if self.period is not None:
            probes += [p % self.period for p in probes]
        return np.array(probes)

    def max_active(self) -> int:
        """Most sets that are non-zero at one point of the universe (exact for piecewise-linear sets);
        the compiled evaluator enumerates only that many sets per input."""
        return int((self.memberships(self._probes()) > 0.0).sum(axis=1).max())

    def chain_peaks(self) -> np.ndarray | None:
        """The sets' peaks if the variable is a chain, else None.

        A chain lists its sets in order of strictly increasing peaks (within one period for a
        circular variable), and at any x only the pair ``(j, j + 1)`` of sets whose peaks bracket
        x can be non-zero (``(n - 1, 0)`` across the wrap of a circular variable; the end pair
        beyond the outer peaks of a linear one). The batch evaluator then needs only the pair's
        lower index per input (``pair_index``) instead of sorting memberships.
        """
        peaks = np.array([s.peak for s in self.sets])
        if len(peaks) < 2 or np.any(np.diff(peaks) <= 0.0):
            return None
        if self.period is not None and (peaks[0] < 0.0 or peaks[-1] >= self.period):
            return None
        probes = self._probes()
        lower = self.pair_index(probes, peaks)
        upper = (lower + 1) % len(peaks)
        outside = self.memberships(probes) > 0.0
        rows = np.arange(len(probes))
        outside[rows, lower] = False
        outside[rows, upper] = False
        return None if outside.any() else peaks

    def pair_index(self, x: np.ndarray, peaks: np.ndarray) -> np.ndarray:
        """Lower index of the pair of neighbouring sets that may be non-zero at each x (chains)."""
        n = len(peaks)
        if self.period is None:
            return np.clip(np.searchsorted(peaks, x, side="right") - 1, 0, n - 2)
        with np.errstate(invalid="ignore"):
            wrapped = np.mod(x, self.period)
        return (np.searchsorted(peaks, wrapped, side="right") - 1) % n
