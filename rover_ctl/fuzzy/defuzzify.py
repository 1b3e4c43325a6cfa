"""Defuzzifiers: per-output-set strengths ``mu`` (rows x sets) to crisp values.

Each returns NaN for a row where no set fired; the rule base replaces that by the output's
documented default, so the control loop never sees NaN.

- ``area_centre`` (the paper's): each set clipped at its strength ``mu_k`` is a trapezoid of area
  ``A_k = 0.5 mu_k (bottom_k + top_k(mu_k))``; the output is ``sum(A_k peak_k) / sum(A_k)``.
  For a trapezoid ``(a, b, c, d)``: ``bottom = d - a``, ``top(mu) = (c - b) + (1 - mu)((b - a) + (d - c))``.
- ``centroid``: the centre of gravity of ``max_k min(mu_k, set_k(x))`` over the output range,
  integrated with the trapezoid rule on ``resolution`` evenly spaced points. The aggregate is
  piecewise linear, so the error comes only from kinks between samples and is far below the
  sample spacing ``(high - low) / (resolution - 1)``.
- ``mean_of_maxima``: the mean of the sampled x where the aggregate reaches its maximum (the
  length-weighted middle of the plateau), exact to within half the sample spacing.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from rover_ctl.fuzzy.membership import Variable

ROWS_PER_SAMPLED_CHUNK = 512
"""Rows aggregated at once by the sampled defuzzifiers (rows x sets x samples floats in memory)."""


def area_centre(mu: np.ndarray, output: Variable, resolution: int) -> np.ndarray:
    # A_k = 0.5 mu (bottom + core + (1 - mu) slopes) = mu (alpha - beta mu), expanded once
    points = np.array([s.points for s in output.sets])
    a, b, c, d = points.T
    slopes = (b - a) + (d - c)
    alpha, beta = 0.5 * ((d - a) + (c - b) + slopes), 0.5 * slopes
    areas = mu * (alpha - beta * mu)
    total = areas.sum(axis=-1)
    moment = areas @ ((b + c) / 2.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0.0, moment / total, np.nan)


def _sampled(mu: np.ndarray, output: Variable, resolution: int, reduce: Callable) -> np.ndarray:
    xs = np.linspace(output.low, output.high, resolution)
    shapes = output.memberships(xs).T  # sets x samples
    result = np.empty(mu.shape[0])
    for start in range(0, mu.shape[0], ROWS_PER_SAMPLED_CHUNK):
        chunk = mu[start : start + ROWS_PER_SAMPLED_CHUNK]
        aggregate = np.minimum(chunk[:, :, None], shapes[None, :, :]).max(axis=1)
        result[start : start + ROWS_PER_SAMPLED_CHUNK] = reduce(aggregate, xs)
    return result


def _trapezoid(y: np.ndarray, xs: np.ndarray) -> np.ndarray:
    """The trapezoid rule along each row (scipy.integrate.trapezoid's formula, without importing
    scipy.integrate, which loads scipy.optimize, into the daemon)."""
    return ((y[:, 1:] + y[:, :-1]) * np.diff(xs)).sum(axis=1) / 2.0


def _centre_of_gravity(aggregate: np.ndarray, xs: np.ndarray) -> np.ndarray:
    area = _trapezoid(aggregate, xs)
    moment = _trapezoid(aggregate * xs, xs)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(area > 0.0, moment / area, np.nan)


def _mean_of_maxima(aggregate: np.ndarray, xs: np.ndarray) -> np.ndarray:
    height = aggregate.max(axis=1, keepdims=True)
    at_max = aggregate >= height - 1e-12
    count = at_max.sum(axis=1)
    mean = (at_max * xs).sum(axis=1) / count
    return np.where(height[:, 0] > 0.0, mean, np.nan)


def centroid(mu: np.ndarray, output: Variable, resolution: int) -> np.ndarray:
    return _sampled(mu, output, resolution, _centre_of_gravity)


def mean_of_maxima(mu: np.ndarray, output: Variable, resolution: int) -> np.ndarray:
    return _sampled(mu, output, resolution, _mean_of_maxima)


DEFUZZIFIERS: dict[str, Callable[[np.ndarray, Variable, int], np.ndarray]] = {
    "area_centre": area_centre,
    "centroid": centroid,
    "mean_of_maxima": mean_of_maxima,
}
