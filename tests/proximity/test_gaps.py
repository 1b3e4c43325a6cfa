"""Narrow passages: finding a gap in the remembered echoes, looking through it, passing it."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from rover_ctl.config import PassageParams
from rover_ctl.navigation.gaps import Gap, Passage, find_gap, seen_open_m, spread_m

PARAMS = replace(PassageParams(), enabled=True)
WIDTH = 0.40


def wall_echoes(gap_centre_e: float, gap_m: float, wall_n: float = 3.0, spacing_m: float = 0.05, range_m: float = 1.0):
    """Echoes on a wall across y = wall_n from x = -3 to 3, with an opening, seen head-on at ``range_m``."""
    xs = np.arange(-3.0, 3.0, spacing_m)
    xs = xs[np.abs(xs - gap_centre_e) >= gap_m / 2.0]
    points = np.column_stack((xs, np.full(len(xs), wall_n)))
    return points, np.full(len(xs), range_m), np.full(len(xs), math.pi / 2.0)


def test_an_opening_of_one_and_a_half_widths_in_a_wall_is_found_where_it_is():
    gap = find_gap(*wall_echoes(0.8, 0.6), (0.0, 0.0), (0.0, 10.0), WIDTH, PARAMS)
    assert gap is not None
    assert gap.centre_en == pytest.approx((0.8, 3.0), abs=0.05)
    assert gap.axis_en == pytest.approx((0.0, 1.0), abs=1e-6)
    # Upper bound: the hole between the echoes plus each edge's beam spread (1 m * tan 7.5 deg).
    assert gap.width_m == pytest.approx(0.6 + 2 * math.tan(math.radians(7.5)), abs=0.06)


def test_a_wall_without_opening_or_with_one_too_narrow_has_no_gap():
    assert find_gap(*wall_echoes(0.8, 0.0), (0.0, 0.0), (0.0, 10.0), WIDTH, PARAMS) is None
    assert find_gap(*wall_echoes(0.8, 0.2, range_m=0.3), (0.0, 0.0), (0.0, 10.0), WIDTH, PARAMS) is None


def test_an_opening_wide_enough_for_the_rule_base_is_left_to_it():
    assert find_gap(*wall_echoes(0.0, 1.6), (0.0, 0.0), (0.0, 10.0), WIDTH, PARAMS) is None


def test_obstacles_one_behind_the_other_are_no_opening():
    points = np.array([[-0.3, 2.0], [0.3, 3.5]])
    assert find_gap(points, np.ones(2), np.full(2, math.pi / 2), (0.0, 0.0), (0.0, 10.0), WIDTH, PARAMS) is None


def test_spread_is_the_beam_width_across_the_way():
    assert spread_m(np.array([2.0]), np.array([math.pi / 2]), math.pi / 2, 7.5)[0] == pytest.approx(2 * math.tan(math.radians(7.5)))
    assert spread_m(np.array([2.0]), np.array([0.0]), math.pi / 2, 7.5)[0] == pytest.approx(0.0, abs=1e-12)


GAP = Gap((0.0, 3.0), (0.0, 1.0), 0.7, ((-0.3, 3.0), (0.3, 3.0)))


def test_a_beam_through_the_gap_shows_its_cone_free():
    # From 2.3 m before the line, head-on: the cone is 2 * 2.3 * tan(7.5 deg) = 0.61 m wide there.
    beams = np.array([[0.0, 0.7, math.pi / 2, 4.0]])
    assert seen_open_m(GAP, beams, 7.5, 0.6) == pytest.approx(0.6, abs=1e-9)  # clipped to the segment
    near = np.array([[0.0, 2.0, math.pi / 2, 4.0]])
    assert seen_open_m(GAP, near, 7.5, 0.6) == pytest.approx(2 * math.tan(math.radians(7.5)), abs=1e-9)


def test_a_beam_that_stops_at_the_line_or_misses_it_shows_nothing():
    assert seen_open_m(GAP, np.array([[0.0, 0.7, math.pi / 2, 2.3]]), 7.5, 0.6) == 0.0  # echo on the line: a post
    assert seen_open_m(GAP, np.array([[2.0, 0.7, math.pi / 2, 4.0]]), 7.5, 0.6) == 0.0  # passes beside
    assert seen_open_m(GAP, np.empty((0, 4)), 7.5, 0.6) == 0.0


def test_overlapping_beams_are_counted_once():
    beams = np.array([[0.0, 2.0, math.pi / 2, 4.0], [0.0, 2.0, math.pi / 2, 4.0], [0.1, 2.0, math.pi / 2, 4.0]])
    assert seen_open_m(GAP, beams, 7.5, 0.6) == pytest.approx(2 * math.tan(math.radians(7.5)) + 0.1, abs=1e-9)


def passage() -> Passage:
    return Passage(PARAMS, lambda: 1.5, lambda: 0.45, lambda: WIDTH)


def test_a_candidate_is_lined_up_for_then_passed_with_its_edges_set_aside():
    p = passage()
    echoes = wall_echoes(0.8, 0.6)
    step = p.update(0.0, (0.0, 0.0), math.pi / 2, (0.0, 10.0), echoes)
    assert step is not None and not step.confirmed and step.ignore is None
    assert step.target_en[1] <= 3.0 - PARAMS.verify_m + 1e-9  # the look-through point, on the centre line
    assert step.speed_limit_mps == PARAMS.speed_mps
    # Lined up 2.3 m before the line, the front beam passes: confirmed.
    p.beam(0.1, (0.8, 0.7), math.pi / 2, math.inf, 4.0)
    step = p.update(0.1, (0.8, 0.5), math.pi / 2, (0.0, 10.0), echoes)
    assert step.confirmed and step.ignore is not None
    # The posts' echoes beside the strip are set aside; one in the strip is not.
    posts = np.array([[0.8 - 0.32, 3.0], [0.8 + 0.32, 3.0], [0.8, 3.0]])
    mask = step.ignore(posts, np.full(3, 0.5), np.full(3, math.pi / 2))
    assert mask.tolist() == [True, True, False]
    # Through: the passage ends.
    assert p.update(5.0, (0.8, 3.6), math.pi / 2, (0.0, 10.0), echoes) is None
    assert p.events[-1] == "Narrow passage: through"


def test_a_passage_never_seen_through_is_given_up_and_not_tried_again():
    p = passage()
    echoes = wall_echoes(0.8, 0.6)
    assert p.update(0.0, (0.0, 0.0), math.pi / 2, (0.0, 10.0), echoes) is not None
    assert p.update(PARAMS.timeout_s + 1.0, (0.0, 0.0), math.pi / 2, (0.0, 10.0), echoes) is None
    assert p.events[-1] == "Narrow passage: given up"
    assert p.update(PARAMS.timeout_s + 2.0, (0.0, 0.0), math.pi / 2, (0.0, 10.0), echoes) is None


def test_off_by_default():
    p = Passage(PassageParams(), lambda: 1.5, lambda: 0.45, lambda: WIDTH)
    assert p.update(0.0, (0.0, 0.0), math.pi / 2, (0.0, 10.0), wall_echoes(0.8, 0.6)) is None
