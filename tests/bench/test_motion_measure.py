"""bench/bench_motion.py's steady-state measurement on synthetic ground truth (no vehicle runs here:
the firmware and emulator runs are the benchmark's, ``python -m bench motion``)."""

from __future__ import annotations

import math

import pytest

from bench.bench_motion import AP_EARTH_RADIUS_M, ardupilot_frame, ardupilot_model, is_steady, relative_difference, steady_state
from sitl.geodesy import LocalFrame

HOME = (-35.363261, 149.165230)
RATE_HZ = 20


def truth(speed_mps: float, turn_dps: float, seconds: float = 3.0, yaw0_deg: float = 30.0, quantise: bool = True):
    """SIMSTATE-like samples of uniform motion: (t, lat, lon, yaw NED rad), lat/lon rounded to 1e-7 deg."""
    frame = LocalFrame(*HOME)
    samples, east, north = [], 0.0, 0.0
    omega = math.radians(turn_dps)
    for k in range(int(seconds * RATE_HZ) + 1):
        t = k / RATE_HZ
        yaw = math.radians(yaw0_deg) + omega * t
        if omega:
            # Exact circular arc along the heading (clockwise positive, NED yaw).
            east = speed_mps / omega * (math.cos(math.radians(yaw0_deg)) - math.cos(yaw))
            north = speed_mps / omega * (math.sin(yaw) - math.sin(math.radians(yaw0_deg)))
        else:
            east, north = speed_mps * t * math.sin(yaw), speed_mps * t * math.cos(yaw)
        lat, lon = frame.to_latlon(east, north)
        if quantise:
            lat, lon = round(lat * 1e7) / 1e7, round(lon * 1e7) / 1e7
        samples.append((t, lat, lon, math.remainder(yaw, 2 * math.pi)))
    return samples


@pytest.mark.parametrize(("speed_mps", "turn_dps"), [(0.4, 0.0), (4.0, 0.0), (1.2, 60.0), (0.8, -150.0), (2.0, 300.0), (-0.5, 20.0)])
def test_uniform_motion_is_measured_within_a_percent(speed_mps, turn_dps):
    motion = steady_state(truth(speed_mps, turn_dps))
    assert motion.speed_mps == pytest.approx(speed_mps, rel=0.01)
    assert motion.turn_rate_dps == pytest.approx(turn_dps, abs=0.1)


def test_a_pivot_has_no_speed_and_quantisation_is_not_motion():
    pivot = steady_state(truth(0.0, 580.0))  # yaw wraps several times in the window
    assert abs(pivot.speed_mps) < 0.01 and pivot.turn_rate_dps == pytest.approx(580.0, abs=0.1)
    still = steady_state(truth(0.0, 0.0, yaw0_deg=0.0))
    assert abs(still.speed_mps) < 0.01 and still.turn_rate_dps == 0.0


def test_only_the_last_window_counts_and_a_ramp_is_not_steady():
    accelerating = [(t + 3.0, lat, lon, yaw) for t, lat, lon, yaw in truth(1.0, 0.0)]
    ramp = truth(0.0, 0.0)[:-1] + accelerating
    assert steady_state(ramp, 2.0).speed_mps == pytest.approx(1.0, rel=0.01)
    assert is_steady(truth(1.0, 45.0))
    assert not is_steady(ramp, 6.0)


def test_ardupilot_skid_model_and_differences():
    assert ardupilot_model(1625, 1625).speed_mps == pytest.approx(1.0)
    assert ardupilot_model(1680, 1320).turn_rate_dps == pytest.approx(100.8)
    assert ardupilot_model(2000, 1000).turn_rate_dps == 280.0
    assert ardupilot_model(2000, 1000).speed_mps == 0.0
    assert relative_difference(0.404, 1.0, 0.05) == pytest.approx(-0.596)
    assert relative_difference(0.01, 0.0, 0.05) == 0.0
    assert relative_difference(0.3, 0.0, 0.05) is None


def test_ardupilot_positions_are_measured_in_ardupilot_metres():
    """ArduPilot's SITL moves on a sphere (RADIUS_OF_EARTH): 1 m/s due north on it is 0.33 % less
    in WGS84 metres at CMAC; its own frame measures it exactly."""
    metres_per_deg = math.radians(1.0) * AP_EARTH_RADIUS_M
    samples = [(k / RATE_HZ, HOME[0] + k / RATE_HZ / metres_per_deg, HOME[1], 0.0) for k in range(61)]
    assert steady_state(samples, frame=ardupilot_frame).speed_mps == pytest.approx(1.0, rel=1e-6)
    assert steady_state(samples).speed_mps == pytest.approx(1.0, abs=0.01)
    assert steady_state(samples).speed_mps != pytest.approx(1.0, rel=1e-3)
