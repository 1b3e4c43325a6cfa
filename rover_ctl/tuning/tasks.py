"""What a Dask worker runs: one episode of one candidate rule base.

The arguments are plain data (the candidate's TOML document as a dict, the scenario name, the
seed, the daemon config overrides) and so is the result (``Outcome.to_dict()``): nothing but
these moves between the tuner and the workers, and a worker needs no shared files, only
rover_ctl installed. A worker keeps the rule bases it parsed (the candidates of a generation
each run on several worlds).
"""

from __future__ import annotations

import json
from functools import lru_cache
from typing import Any

from rover_ctl.fuzzy import RuleBase, parse_rulebase
from rover_ctl.tuning.episode import Episode, episode_config


@lru_cache(maxsize=64)
def _rulebase(text: str, where: str) -> RuleBase:
    return parse_rulebase(json.loads(text), where)


def run_episode_task(document: dict[str, Any], where: str, scenario: str, seed: int,
                     overrides: tuple[str, ...] = (), estimator: str = "ekf") -> dict[str, Any]:  # fmt: skip
    """One episode; it stops at the first collision (the search needs no more of a failed run).
    Every scenario's moving obstacles start at arming and meet the rover where the seed says
    (``rover_ctl.tuning.scenarios``), so the mission starts as soon as the rover can arm."""
    rulebase = _rulebase(json.dumps(document, sort_keys=True), where)
    episode = Episode(rulebase, scenario, seed, episode_config(tuple(overrides)), estimator=estimator, stop_on_collision=True)
    return episode.run().to_dict()
