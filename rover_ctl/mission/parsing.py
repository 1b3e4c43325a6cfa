"""What every mission file parser returns, and the error raised for a refused file."""

from __future__ import annotations

from dataclasses import dataclass, field

from rover_ctl.mission.model import Mission, MissionType

HOME_INDEX = -1
"""Label key of the home position: ``Parsed.labels[(MissionType.MISSION, HOME_INDEX)]``."""


class MissionFileError(ValueError):
    """A mission file that cannot be loaded or saved.

    ``str()`` is the first problem ("file:line: what is wrong"); ``errors`` lists them all.
    """

    def __init__(self, errors: list[str]) -> None:
        super().__init__(errors[0])
        self.errors = list(errors)


@dataclass
class Parsed:
    """A parsed file: the mission, where each item came from, and the syntax problems found.

    ``labels[(mission_type, index)]`` is the prefix validation messages use for that item
    ("file:line" for WPL, "file: mission.items[3]" for .plan).
    """

    mission: Mission = field(default_factory=Mission)
    labels: dict[tuple[MissionType, int], str] = field(default_factory=dict)
    errors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
