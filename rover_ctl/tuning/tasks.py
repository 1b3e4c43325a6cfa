"""What a Dask worker runs: one episode of one candidate rule base.

The arguments are plain data (the candidate's TOML document as a dict, the scenario name, the
seed, the daemon config overrides) and so is the result (``Outcome.to_dict()``): nothing but
these moves between the tuner and the workers, and a worker needs no shared files, only
rover_ctl installed. A worker keeps the rule bases it parsed (the candidates of a generation
each run on several worlds).
"""

from __future__ import annotations

import json
import random
from functools import lru_cache
from typing import Any

from rover_ctl.fuzzy import RuleBase, parse_rulebase
from rover_ctl.tuning.episode import Episode, episode_config


START_SPREAD_S = 15.0
"""Each world's mission starts at a sim time drawn from 0..this (seeded): the moving obstacles
move on sim time, and a SITL run's start depends on its arming retries (4-20 s measured on the
bench's moving and crossing worlds), so a rule base is tuned for any meeting point, not one."""
START_SALT = 0x5354
"""Mixed into the world seed for the start-time draw (the emulator's draws use the seed itself)."""


def start_time_s(seed: int) -> float:
    return round(START_SPREAD_S * random.Random(seed ^ START_SALT).random(), 2)


@lru_cache(maxsize=64)
def _rulebase(text: str, where: str) -> RuleBase:
    return parse_rulebase(json.loads(text), where)


def run_episode_task(document: dict[str, Any], where: str, scenario: str, seed: int,
                     overrides: tuple[str, ...] = (), estimator: str = "ekf") -> dict[str, Any]:  # fmt: skip
    """One episode, started at ``start_time_s(seed)``; it stops at the first collision (the
    search needs no more of a failed run)."""
    rulebase = _rulebase(json.dumps(document, sort_keys=True), where)
    episode = Episode(rulebase, scenario, seed, episode_config(tuple(overrides)), estimator=estimator, stop_on_collision=True,
                      start_s=start_time_s(seed))  # fmt: skip
    return episode.run().to_dict()
