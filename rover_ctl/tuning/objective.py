"""The score a candidate rule base gets on its episodes: lower is better.

Per episode (``Outcome``), with the weights of ``Weights``::

    cost = collision_cost * collisions            a collision is far worse than anything else
         + incomplete_cost * (not complete)       then not finishing (a timeout)
         + time_cost_per_s * duration_s           then time...
         + path_cost_per_m * path_length_m        ...and path length

A timed-out episode costs at most ``incomplete_cost`` + the budget's seconds and its path
(about 300 + 240 + 0.5 * 240 * 1.5 = 720 with the defaults), less than one collision (2000), so
the order collisions > timeouts > time and path holds whatever the episode. A candidate's score
is the mean cost over its episodes (every scenario and training world, the same for every
candidate of a run: common random numbers, so two candidates differ by their rule bases only).
"""

from __future__ import annotations

import statistics
from dataclasses import dataclass

from rover_ctl.tuning.episode import Outcome


@dataclass(frozen=True)
class Weights:
    collision_cost: float = 2000.0
    """Per collision."""
    incomplete_cost: float = 300.0
    """Mission not complete (timed out, or stopped early by a collision)."""
    time_cost_per_s: float = 1.0
    """Per sim second from the start of AUTO."""
    path_cost_per_m: float = 0.5
    """Per metre driven (truth)."""


def episode_cost(outcome: Outcome, weights: Weights = Weights()) -> float:
    return (weights.collision_cost * outcome.collisions + weights.incomplete_cost * (not outcome.complete)
            + weights.time_cost_per_s * outcome.duration_s + weights.path_cost_per_m * outcome.path_length_m)  # fmt: skip


def score(outcomes: list[Outcome], weights: Weights = Weights()) -> float:
    """A candidate's score: the mean episode cost."""
    return statistics.fmean(episode_cost(o, weights) for o in outcomes)
