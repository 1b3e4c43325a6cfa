"""Every defuzzifier against values computed by hand."""

import math

import numpy as np
import pytest

from rover_ctl.fuzzy import FuzzySet, Variable
from rover_ctl.fuzzy.defuzzify import area_centre, centroid, mean_of_maxima

OUT = Variable(
    "y",
    (FuzzySet("a", (0.0, 2.0, 2.0, 4.0)), FuzzySet("b", (6.0, 8.0, 8.0, 10.0)), FuzzySet("c", (0.0, 0.0, 0.0, 4.0))),
    0.0,
    10.0,
)
RESOLUTION = 2001


def strengths(a=0.0, b=0.0, c=0.0):
    return np.array([[a, b, c]])


def test_area_centre_paper_formula():
    # A_a = 0.5*0.5*(4 + 4*0.5) = 1.5 at peak 2; A_b = 0.5*1*(4 + 0) = 2 at peak 8.
    assert area_centre(strengths(a=0.5, b=1.0), OUT, RESOLUTION)[0] == pytest.approx((1.5 * 2 + 2 * 8) / 3.5)
    assert area_centre(strengths(a=0.3), OUT, RESOLUTION)[0] == pytest.approx(2.0)


def test_centroid_of_a_clipped_shoulder():
    # c = 1 - x/4 on [0, 4], clipped at 0.5: area 1.5, moment 1 + 4/3 = 7/3 -> 14/9.
    assert centroid(strengths(c=0.5), OUT, RESOLUTION)[0] == pytest.approx(14 / 9, abs=2e-3)
    # unclipped right triangle: centroid at a third of its base
    assert centroid(strengths(c=1.0), OUT, RESOLUTION)[0] == pytest.approx(4 / 3, abs=2e-3)
    # two symmetric triangles with equal strength: the midpoint
    assert centroid(strengths(a=0.7, b=0.7), OUT, RESOLUTION)[0] == pytest.approx(5.0, abs=2e-3)


def test_mean_of_maxima():
    # c clipped at 0.5 is flat on [0, 2]; a and c overlap below it but never exceed 0.5
    assert mean_of_maxima(strengths(c=0.5), OUT, RESOLUTION)[0] == pytest.approx(1.0, abs=5e-3)
    # the strongest set wins alone: b at full strength peaks at 8
    assert mean_of_maxima(strengths(a=0.4, b=0.9), OUT, RESOLUTION)[0] == pytest.approx(8.0, abs=5e-3)


@pytest.mark.parametrize("defuzz", [area_centre, centroid, mean_of_maxima])
def test_nothing_fired_is_nan_for_the_caller_to_replace(defuzz):
    assert math.isnan(defuzz(strengths(), OUT, RESOLUTION)[0])
