"""Whether a tuned rule base beats its source on held-out worlds: issue 13's measure, with chance
taken out.

Pure: outcomes in, a verdict out. The measure is "higher success, or equal success with a shorter
time", per scenario, on worlds the search never saw. Both rule bases run the same worlds, so the
comparison is paired, and on a finite sample "higher" and "shorter" must mean more than a draw
would give:

- **success**, the exact McNemar test: of the worlds exactly one base completed without a
  collision, ``b`` went to the source only and ``c`` to the tuned base only. With no difference
  between the bases each such world is a fair coin, so ``p_better = P(X >= c)`` and
  ``p_worse = P(X >= b)`` for ``X ~ Binomial(b + c, 1/2)`` (one-sided);
- **time**, the Wilcoxon signed-rank test on the mission times of the worlds both completed,
  one-sided each way (scipy's normal approximation with its tie and zero corrections: mission
  times fall on a grid, so ties are common, and the approximation gives the same p on every
  scipy the project allows, where ``method="auto"`` changed between versions).

A scenario's verdict, with ``alpha`` = ``VerdictParams.alpha`` and ``alpha_w = alpha / k`` for
``k`` scenarios judged together:

- ``better``: ``c > b`` with ``p_better < alpha``; or the success difference not significant
  either way, ``c >= b``, and the tuned base faster with ``p < alpha``;
- ``worse``: the mirror image at ``alpha_w`` (``b > c`` with ``p_worse < alpha_w``; or success
  not significant, ``b >= c``, and slower with ``p < alpha_w``);
- ``not shown``: neither.

The tuned base beats its source when every scenario is ``better``: a claim about all ``k`` at
once, which chance makes for two equal bases less often than ``alpha``. It is worse when any
scenario is ``worse``: a claim about one of ``k``, which chance makes up to ``k`` times as
often, hence the Bonferroni ``alpha / k`` (two equal bases, 100 worlds at 93 % success, 1,000
simulated draws: worse somewhere in four scenarios 20 % of the time at ``alpha``, 6 % at
``alpha / 4``). What a sample cannot see is
said too: with no failure among ``n`` worlds, a failure rate up to about ``3 / n`` is still
likely (the "rule of three", the 95 % upper bound), so ten held-out worlds cannot tell a base
that strikes one world in twenty from one that never does. That is how a 10-world check once
passed a tuned base that at 200 worlds failed 8 % of scattered worlds (docs/tuning.md).
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass
from typing import Iterable, Sequence

from rover_ctl.tuning.episode import Outcome

BETTER, WORSE, NOT_SHOWN = "better", "worse", "not shown"
HEADLINES = {
    BETTER: "The tuned rule base beats its source on every scenario.",
    WORSE: "The tuned rule base is worse than its source: do not use it.",
    NOT_SHOWN: "Not shown better than its source: keep the source.",
}
"""What the report and the terminal say for each overall verdict."""


@dataclass(frozen=True)
class VerdictParams:
    alpha: float = 0.05
    """One-sided significance level of both tests: a difference counts when chance alone would
    give one as large less often than this (``worse`` at ``alpha`` over the number of scenarios)."""


@dataclass(frozen=True)
class ScenarioVerdict:
    scenario: str
    worlds: int
    source_successes: int
    tuned_successes: int
    source_only: int
    """Worlds only the source completed (McNemar's b)."""
    tuned_only: int
    """Worlds only the tuned base completed (McNemar's c)."""
    p_success_better: float
    p_success_worse: float
    both_completed: int
    median_time_change_s: float
    """Median over the worlds both completed of (tuned - source) mission time; NaN if none."""
    p_time_shorter: float
    p_time_longer: float
    verdict: str


def binomial_tail(k: int, n: int) -> float:
    """P(X >= k) for X ~ Binomial(n, 1/2)."""
    if k <= 0:
        return 1.0
    return sum(math.comb(n, i) for i in range(k, n + 1)) / 2.0**n


def signed_rank_p(differences: Sequence[float]) -> tuple[float, float]:
    """One-sided Wilcoxon signed-rank p-values (less, greater) for the paired differences; 1.0 each
    when no difference is non-zero (nothing to rank)."""
    nonzero = [d for d in differences if d != 0.0]
    if not nonzero:
        return 1.0, 1.0
    from scipy.stats import wilcoxon  # only `rover-ctl tune` gets here

    less = float(wilcoxon(nonzero, alternative="less", method="approx").pvalue)
    greater = float(wilcoxon(nonzero, alternative="greater", method="approx").pvalue)
    return less, greater


def compare(scenario: str, source: Sequence[Outcome], tuned: Sequence[Outcome], params: VerdictParams = VerdictParams(),
            scenarios: int = 1) -> ScenarioVerdict:  # fmt: skip
    """One scenario's verdict from its paired outcomes (the same worlds, matched by seed), one of
    ``scenarios`` judged together. ValueError unless both ran the same worlds, each once."""
    tuned_by_seed = {x.seed: x for x in tuned}
    source_seeds = [x.seed for x in source]
    if len(tuned_by_seed) != len(tuned) or len(set(source_seeds)) != len(source) or set(source_seeds) != set(tuned_by_seed):
        raise ValueError(f"{scenario}: the source and tuned outcomes are not the same worlds, each once")
    pairs = [(s, tuned_by_seed[s.seed]) for s in source]
    b = sum(s.success and not t.success for s, t in pairs)
    c = sum(t.success and not s.success for s, t in pairs)
    p_better, p_worse = binomial_tail(c, b + c), binomial_tail(b, b + c)
    both = [(s, t) for s, t in pairs if s.success and t.success]
    changes = [t.duration_s - s.duration_s for s, t in both]
    p_shorter, p_longer = signed_rank_p(changes)
    median = statistics.median(changes) if changes else math.nan
    alpha, alpha_w = params.alpha, params.alpha / max(scenarios, 1)
    success_even = p_better >= alpha and p_worse >= alpha
    if (c > b and p_better < alpha) or (success_even and c >= b and p_shorter < alpha):
        verdict = BETTER
    elif (b > c and p_worse < alpha_w) or (success_even and b >= c and p_longer < alpha_w):
        verdict = WORSE
    else:
        verdict = NOT_SHOWN
    return ScenarioVerdict(
        scenario, len(pairs), sum(s.success for s, _ in pairs), sum(t.success for _, t in pairs), b, c, p_better, p_worse,
        len(both), median, p_shorter, p_longer, verdict,
    )  # fmt: skip


def overall(verdicts: Iterable[ScenarioVerdict]) -> str:
    """``better`` when the tuned base is better on every scenario, ``worse`` when it is worse on
    any (each judged by ``compare`` with ``scenarios`` = how many), else ``not shown``."""
    kinds = [v.verdict for v in verdicts]
    if kinds and all(k == BETTER for k in kinds):
        return BETTER
    return WORSE if WORSE in kinds else NOT_SHOWN


def sentence(v: ScenarioVerdict) -> str:
    """One line for the report and the terminal."""
    time = (f"time {v.median_time_change_s:+.1f} s median over the {v.both_completed} both completed "
            f"(p {min(v.p_time_shorter, v.p_time_longer):.2g})" if v.both_completed else "no world completed by both")  # fmt: skip
    return (f"{v.scenario}: {v.verdict} -- success {v.source_successes} -> {v.tuned_successes} of {v.worlds} "
            f"(source only {v.source_only}, tuned only {v.tuned_only}; p {min(v.p_success_better, v.p_success_worse):.2g}), {time}")
