"""ArduPilot skid-steer mixing, checked against outputs measured on ArduPilot's own SITL."""

from __future__ import annotations

import pytest

from sitl.mixer import MixerParams, RcChannel, mix_rc, mix_scaled


@pytest.mark.parametrize(
    ("steering_us", "throttle_us", "expected"),
    [
        (1500, 1800, (1785, 1785)),  # dead zone: 100*270//470 = 57 %
        (1800, 1700, (1967, 1393)),
        (2000, 1500, (2000, 1000)),  # pivot at neutral throttle
        (1700, 1500, (1680, 1320)),  # 180.8 us truncated toward trim (python -m bench motion)
        (1000, 1500, (1000, 2000)),
        (1500, 1500, (1500, 1500)),
    ],
)
def test_matches_ardupilot_sitl(steering_us: int, throttle_us: int, expected: tuple[int, int]) -> None:
    assert mix_rc(steering_us, throttle_us) == expected


def test_dead_zone_gives_neutral() -> None:
    assert mix_rc(1525, 1470) == (1500, 1500)


def test_saturation_keeps_steering_and_cuts_throttle() -> None:
    # full throttle + full right: steering halved by the fair scaler, throttle = 1 - |steering|
    assert mix_scaled(1.0, 1.0) == pytest.approx((1.0, 0.0))
    assert mix_rc(2000, 2000) == (2000, 1500)


def test_throttle_priority_mix_keeps_throttle() -> None:
    left, right = mix_scaled(1.0, 1.0, MixerParams(steering_throttle_mix=0.0))
    assert (left, right) == pytest.approx((1.0, 1.0))


def test_reverse_is_symmetric_and_clamped() -> None:
    assert mix_rc(1500, 1000) == (1000, 1000)
    assert mix_rc(1500, 900) == (1000, 1000)  # below RC min clamps
    left, right = mix_rc(1800, 1200)  # reverse + right: right saturates, throttle is cut to fit
    assert right == 1000 and left > right


def test_thrust_asymmetry_amplifies_reverse() -> None:
    left, right = mix_scaled(0.0, -0.25, MixerParams(thrust_asymmetry=2.0))
    assert left == pytest.approx(-0.5) and right == pytest.approx(-0.5)


def test_rc_channel_integer_maths_truncates_toward_zero() -> None:
    channel = RcChannel()
    assert channel.to_control(1800, 4500) == 2585
    assert channel.to_control(1200, 4500) == -2585
