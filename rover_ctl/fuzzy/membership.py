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
        """mu(x) for an array (no wrapping: that is the variable's job)."""
        a, b, c, d = self.points
        x = np.asarray(x, dtype=np.float64)
        rising = (x - a) / (b - a) if b > a else np.where(x >= a, 1.0, 0.0)
        falling = (d - x) / (d - c) if d > c else np.where(x <= d, 1.0, 0.0)
        return np.clip(np.minimum(rising, falling), 0.0, 1.0)

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
        if self.period is None:
            columns = [s.membership(x) for s in self.sets]
        else:
            wrapped = np.mod(x, self.period)
            shifts = (-self.period, 0.0, self.period)
            columns = [np.maximum.reduce([s.membership(wrapped + k) for k in shifts]) for s in self.sets]
        mu = np.stack(columns, axis=-1)
        return np.nan_to_num(mu, nan=0.0)

    def memberships_one(self, x: float) -> list[float]:
        """Membership of every set for one float (pure Python)."""
        if math.isnan(x):
            return [0.0] * len(self.sets)
        if self.period is None:
            return [s.membership_one(x) for s in self.sets]
        wrapped = math.fmod(x, self.period)
        if wrapped < 0.0:
            wrapped += self.period
        low, high = wrapped - self.period, wrapped + self.period
        return [max(s.membership_one(low), s.membership_one(wrapped), s.membership_one(high)) for s in self.sets]

    def max_active(self) -> int:
        """Most sets that are non-zero at one point of the universe (exact for piecewise-linear sets).

        Checked at every breakpoint and between neighbouring breakpoints, wrapped for a circular
        variable; the compiled evaluator enumerates only that many sets per input.
        """
        points = sorted({p for s in self.sets for p in s.points if math.isfinite(p)} | {self.low, self.high})
        probes = list(points)
        probes += [(p + q) / 2.0 for p, q in zip(points, points[1:])]
        probes += [points[0] - 1.0, points[-1] + 1.0]
        if self.period is not None:
            probes += [p % self.period for p in probes]
        mu = self.memberships(np.array(probes))
        return int((mu > 0.0).sum(axis=1).max())
