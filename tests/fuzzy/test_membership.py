"""Piecewise-linear sets at their breakpoints, shoulders, vertical edges and circular wrap."""

import math

import numpy as np
import pytest

from rover_ctl.fuzzy import FuzzySet, Variable

TRIANGLE = FuzzySet("t", (0.0, 7.5, 7.5, 15.0))
TRAPEZOID = FuzzySet("z", (1.0, 2.0, 4.0, 8.0))
NEAR = FuzzySet("near", (0.0, 0.0, 0.0, 7.5))  # the paper's: 1 at 0, 0 below it
FAR = FuzzySet("far", (7.5, 15.0, math.inf, math.inf))


@pytest.mark.parametrize(
    "fuzzy_set, x, expected",
    [
        (TRIANGLE, -1.0, 0.0), (TRIANGLE, 0.0, 0.0), (TRIANGLE, 3.75, 0.5), (TRIANGLE, 7.5, 1.0),
        (TRIANGLE, 11.25, 0.5), (TRIANGLE, 15.0, 0.0), (TRIANGLE, 16.0, 0.0),
        (TRAPEZOID, 1.5, 0.5), (TRAPEZOID, 2.0, 1.0), (TRAPEZOID, 3.0, 1.0), (TRAPEZOID, 4.0, 1.0), (TRAPEZOID, 6.0, 0.5),
        (NEAR, -0.001, 0.0), (NEAR, 0.0, 1.0), (NEAR, 7.5, 0.0), (NEAR, 3.0, 0.6),
        (FAR, 7.5, 0.0), (FAR, 11.25, 0.5), (FAR, 15.0, 1.0), (FAR, 1e9, 1.0), (FAR, math.inf, 1.0), (FAR, -5.0, 0.0),
    ],
)  # fmt: skip
def test_breakpoints_array_and_scalar_paths_agree(fuzzy_set, x, expected):
    assert fuzzy_set.membership(np.array([x]))[0] == pytest.approx(expected)
    assert fuzzy_set.membership_one(x) == pytest.approx(expected)


def test_peak_is_the_middle_of_the_core():
    assert TRIANGLE.peak == 7.5
    assert TRAPEZOID.peak == 3.0


DIRECTION = Variable(
    "target_direction",
    (
        FuzzySet("ahead", (-90.0, 0.0, 0.0, 90.0)),
        FuzzySet("left", (0.0, 90.0, 90.0, 180.0)),
        FuzzySet("behind", (90.0, 180.0, 180.0, 270.0)),
        FuzzySet("right", (180.0, 270.0, 270.0, 360.0)),
    ),
    0.0,
    360.0,
    "deg",
    period=360.0,
)


@pytest.mark.parametrize(
    "x, expected",
    [
        (0.0, [1, 0, 0, 0]), (360.0, [1, 0, 0, 0]), (720.0, [1, 0, 0, 0]), (-360.0, [1, 0, 0, 0]),
        (350.0, [80 / 90, 0, 0, 10 / 90]), (-10.0, [80 / 90, 0, 0, 10 / 90]), (10.0, [80 / 90, 10 / 90, 0, 0]),
        (45.0, [0.5, 0.5, 0, 0]), (180.0, [0, 0, 1, 0]), (315.0, [0.5, 0, 0, 0.5]), (270.0, [0, 0, 0, 1]),
    ],
)  # fmt: skip
def test_circular_universe_wraps(x, expected):
    assert DIRECTION.memberships(np.array([x]))[0] == pytest.approx(expected)
    assert DIRECTION.memberships_one(x) == pytest.approx(expected)


@pytest.mark.parametrize("x", [math.nan, math.inf, -math.inf])
def test_no_angle_fires_nothing(x):
    assert DIRECTION.memberships(np.array([x]))[0].tolist() == [0, 0, 0, 0]
    assert DIRECTION.memberships_one(x) == [0, 0, 0, 0]


def test_max_active_counts_overlapping_sets():
    assert DIRECTION.max_active() == 2
    triple = Variable("x", (FuzzySet("a", (0, 5, 5, 10)), FuzzySet("b", (1, 5, 5, 9)), FuzzySet("c", (2, 5, 5, 8))), 0, 10)
    assert triple.max_active() == 3
