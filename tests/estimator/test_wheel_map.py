"""The wheel map check: wheel-derived turn rate against the gyro's."""

from __future__ import annotations

import pytest

from rover_ctl.estimation.readings import Attitude, WheelDistance
from rover_ctl.estimation.wheel_map import WheelMapCheck

TRACK_M = 0.32


def turn(check: WheelMapCheck, swap: bool, seconds: float = 3.0, rate_ccw_radps: float = 1.0) -> None:
    """A pivot to the left (counter-clockwise): right wheel forwards, left backwards."""
    left = right = 0.0
    for k in range(int(seconds * 50)):
        t = k * 0.02
        check.on_attitude(Attitude(t, 0.0, -rate_ccw_radps))  # ATTITUDE yawspeed is clockwise
        d = rate_ccw_radps * TRACK_M / 2 * 0.02
        left, right = left - d, right + d
        check.on_wheels(WheelDistance(t, right, left) if swap else WheelDistance(t, left, right))


@pytest.mark.parametrize("swap, verdict", [(False, "ok"), (True, "reversed")])
def test_turning_decides_the_map(swap, verdict):
    check = WheelMapCheck(TRACK_M)
    turn(check, swap)
    assert check.verdict == verdict


def test_straight_driving_decides_nothing():
    check = WheelMapCheck(TRACK_M)
    for k in range(500):
        check.on_attitude(Attitude(k * 0.02, 0.0, 0.01))
        check.on_wheels(WheelDistance(k * 0.02, k * 0.01, k * 0.01))
    assert check.verdict is None
