"""The held-out verdict (``rover_ctl.tuning.verdict``): paired tests, not raw rates."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import binomtest

from rover_ctl.tuning.episode import Outcome
from rover_ctl.tuning.verdict import BETTER, NOT_SHOWN, WORSE, binomial_tail, compare, overall, sentence


def outcome(seed: int, success: bool, duration_s: float = 60.0) -> Outcome:
    return Outcome("moving", seed, success, success, False, 0 if success else 1, 40.0, duration_s, duration_s + 3.0)


def runs(successes: list[bool], durations: list[float] | None = None) -> list[Outcome]:
    durations = durations or [60.0] * len(successes)
    return [outcome(seed, ok, d) for seed, (ok, d) in enumerate(zip(successes, durations), start=1)]


def test_the_same_outcomes_show_nothing():
    source = runs([True] * 9 + [False])
    v = compare("moving", source, source)
    assert v.verdict == NOT_SHOWN and (v.source_only, v.tuned_only) == (0, 0)
    assert v.p_success_better == v.p_success_worse == 1.0 and v.p_time_shorter == 1.0


def test_a_few_percent_more_collisions_at_scale_is_worse():
    """The fourth tuning run at 200 worlds: scattered 199 -> 183 successes."""
    source = runs([True] * 199 + [False])
    tuned = runs([True] * 183 + [False] * 17)
    v = compare("scattered", source, tuned)
    assert (v.source_only, v.tuned_only) == (16, 0) and v.p_success_worse < 1e-4
    assert v.verdict == WORSE and overall([v]) == WORSE


def test_one_world_lost_of_ten_is_not_shown_either_way_by_success():
    v = compare("scattered", runs([True] * 10), runs([True] * 9 + [False]))
    assert v.p_success_worse == 0.5 and v.verdict == NOT_SHOWN


def test_equal_success_and_shorter_times_is_better():
    source = runs([True] * 20, [60.0 + k for k in range(20)])
    tuned = runs([True] * 20, [55.0 + k for k in range(20)])
    v = compare("moving", source, tuned)
    assert v.verdict == BETTER and v.median_time_change_s == -5.0 and v.p_time_shorter < 0.001


def test_shorter_times_do_not_buy_fewer_successes():
    """Two more failures (not significant alone) and faster: not shown better."""
    source = runs([True] * 20, [60.0] * 20)
    tuned = runs([True] * 18 + [False] * 2, [50.0] * 20)
    assert compare("moving", source, tuned).verdict == NOT_SHOWN


def test_more_successes_when_significant_is_better_even_if_slower():
    source = runs([False] * 8 + [True] * 12, [60.0] * 20)
    tuned = runs([True] * 20, [65.0] * 20)
    v = compare("moving", source, tuned)
    assert v.tuned_only == 8 and v.p_success_better == 1 / 256 and v.verdict == BETTER


def test_overall_needs_every_scenario():
    better = compare("a", runs([False] * 8), runs([True] * 8))
    same = compare("b", runs([True] * 8), runs([True] * 8))
    assert overall([better]) == BETTER and overall([better, same]) == NOT_SHOWN and overall([]) == NOT_SHOWN
    assert "a: better" in sentence(better) and "0 -> 8 of 8" in sentence(better)
    assert "no world completed by both" in sentence(compare("c", runs([False] * 3), runs([False] * 3)))


def test_pairs_follow_the_seeds_not_the_order():
    source = runs([True, True, False], [50.0, 60.0, 70.0])
    v = compare("moving", source, list(reversed(source)))  # paired by position: one lost each way
    assert (v.source_only, v.tuned_only) == (0, 0) and v.median_time_change_s == 0.0


@pytest.mark.parametrize("tuned_seeds", [[1, 2], [1, 2, 4], [1, 2, 2]])
def test_outcomes_of_other_worlds_are_refused(tuned_seeds):
    source = runs([True, True, True])
    tuned = [outcome(seed, True) for seed in tuned_seeds]
    with pytest.raises(ValueError, match="not the same worlds"):
        compare("moving", source, tuned)


def test_longer_times_at_equal_success_are_worse():
    source = runs([True] * 20, [60.0 + k for k in range(20)])
    tuned = runs([True] * 20, [66.0 + k for k in range(20)])
    v = compare("moving", source, tuned)
    assert v.verdict == WORSE and v.median_time_change_s == 6.0


def test_worse_in_one_of_several_scenarios_needs_more_evidence():
    """Bonferroni: seven worlds lost and none won (p 1/128 = 0.0078) is worse alone, and in one
    of four scenarios (0.0078 < 0.05 / 4); five lost (p 0.031) is worse alone, not in one of two."""
    seven = compare("moving", runs([True] * 20), runs([True] * 13 + [False] * 7), scenarios=4)
    five = [compare("moving", runs([True] * 20), runs([True] * 15 + [False] * 5), scenarios=k) for k in (1, 2)]
    assert seven.verdict == WORSE and [v.verdict for v in five] == [WORSE, NOT_SHOWN]
    better = compare("a", runs([False] * 8), runs([True] * 8))
    assert overall([better, seven]) == WORSE


@pytest.mark.parametrize("n", [0, 1, 5, 16, 40])
def test_the_binomial_tail_is_scipys(n):
    for k in range(n + 1):
        assert math.isclose(binomial_tail(k, n), binomtest(k, n, 0.5, alternative="greater").pvalue if n else 1.0, rel_tol=1e-9)


pair = st.tuples(st.booleans(), st.floats(30.0, 90.0), st.booleans(), st.floats(30.0, 90.0))


@settings(max_examples=200, deadline=None)
@given(st.lists(pair, max_size=40))
def test_swapping_the_bases_swaps_the_verdict(pairs):
    source = [outcome(k, a, da) for k, (a, da, _, _) in enumerate(pairs)]
    tuned = [outcome(k, b, db) for k, (_, _, b, db) in enumerate(pairs)]
    forward, backward = compare("x", source, tuned).verdict, compare("x", tuned, source).verdict  # one scenario: symmetric
    assert {forward, backward} in ({NOT_SHOWN}, {BETTER, WORSE})
