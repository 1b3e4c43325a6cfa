"""Back to the path after stepping aside (``evasion.rejoin_s``, ``evasion.rejoin_lookahead_m``),
closed loop in the in-process runner (the emulator's physics and sensors, the daemon's autopilot
and pose filter; no sockets).

``head_on`` seed 45: two walkers come down the leg one behind the other, the second hidden behind
the first from the front rangefinder. The rover steps aside for the first. Turning straight back
to its path (the 3 m carrot, about 30 degrees off it) put the second walker in the blind wedge
between the front beam and the front-left diagonal: it was first read at about 1.1 m, too late,
and walked into the rover. Rejoining at a shallow angle keeps the front beam down the path. (The
tracker of ``SURE_ECHOES``, the case's.)"""

from __future__ import annotations

import math

from shapely.geometry import Point
from support import SURE_ECHOES

from rover_ctl.fuzzy import load_rulebase
from rover_ctl.tuning.episode import Episode, episode_config

SEED = 45
RANGE_COLUMNS = ("range_front_m", "range_front_left_m", "range_front_right_m", "range_left_m", "range_right_m")
ECHO_TOLERANCE_M = 0.35
"""A reading within this of a walker's true distance from the rover's centre is taken as its echo."""


def first_echoes(overrides: tuple[str, ...]) -> tuple[bool, dict[int, tuple[float, str]]]:
    """The episode's success, and for each walker the true distance and the rangefinder of the
    first reading that matches it."""
    episode = Episode(load_rulebase("default"), "head_on", SEED, episode_config((*SURE_ECHOES, *overrides)), stop_on_collision=True, start_s=30.0)
    walkers = [o for o in episode.rover.world.obstacles if getattr(o, "moving", False)]
    seen: dict[int, tuple[float, str]] = {}
    step = episode.autopilot.step

    def observed(t_s, pose, readings):
        out = step(t_s, pose, readings)
        drive = episode.rover.drive
        centre = Point(drive.east_m, drive.north_m)
        for k, walker in enumerate(walkers):
            distance_m = walker.shape(episode.rover.time_s).distance(centre)
            for column in RANGE_COLUMNS:
                range_m = out.log_row.get(column)
                if k not in seen and isinstance(range_m, float) and math.isfinite(range_m) and abs(range_m - distance_m) < ECHO_TOLERANCE_M:
                    seen[k] = (distance_m, column)
        return out

    episode.autopilot.step = observed
    return episode.run().success, seen


def test_after_stepping_aside_the_front_beam_finds_the_second_walker_down_the_path():
    success, seen = first_echoes(())
    assert success
    assert len(seen) == 2 and all(column == "range_front_m" and distance_m > 3.0 for distance_m, column in seen.values()), seen


def test_turning_straight_back_meets_the_second_walker_late_and_is_walked_into():
    success, seen = first_echoes(("evasion.rejoin_s=0",))
    assert not success
    assert min(distance_m for distance_m, _ in seen.values()) < 2.0, seen
