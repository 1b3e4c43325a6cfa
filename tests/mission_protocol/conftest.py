"""Fixtures of the mission-protocol tests."""

from __future__ import annotations

import pytest
from mission_protocol.helpers import sample_mission

from rover_ctl.mission.model import Mission


@pytest.fixture
def mission() -> Mission:
    return sample_mission()
