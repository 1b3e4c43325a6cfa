"""Synthetic rover runs for the estimator tests: a true trajectory and the readings its sensors
would give, with the noise the filter models (so that consistency can be tested) plus GPS bias,
glitches and outages on demand. Everything is seeded."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from rover_ctl.estimation.frame import LocalFrame, enu_to_compass_rad, wrap_pi
from rover_ctl.estimation.readings import Attitude, GpsFix, WheelDistance

CMAC = LocalFrame(-35.363261, 149.165230, 584.0)
TRACK_M = 0.32


@dataclass
class Sensors:
    """Noise of the synthetic sensors (1-sigma; densities per sqrt(s) as in EstimatorParams)."""

    gps_white_m: float = 2.5
    gps_bias_m: float = 0.0
    """Stationary 1-sigma of a first-order Gauss-Markov bias with time constant gps_bias_tau_s."""
    gps_bias_tau_s: float = 120.0
    gps_eph_m: float | None = None
    """eph the receiver reports (default: gps_white_m)."""
    compass_sigma_rad: float = 0.035
    compass_offset_rad: float | None = None
    """Constant compass offset; None: drawn from N(0, compass_offset_sigma_rad)."""
    compass_offset_sigma_rad: float = 0.07
    gps_velocity_sigma_mps: float = 0.1
    gyro_noise_rad_per_sqrt_s: float = 0.003
    gyro_bias_radps: float = 0.01
    wheel_speed_sigma_mps: float = 0.03
    wheel_scale: float = 1.0
    """Encoder metres per metre travelled (tyres not the size the encoders assume)."""
    lateral_slip_per_sqrt_s: float = 0.03
    gps_period_s: float = 0.2
    imu_period_s: float = 0.02
    outages: list[tuple[float, float]] = field(default_factory=list)
    """GPS silent in [start, end)."""
    glitches: list[tuple[float, float, float, float]] = field(default_factory=list)
    """(start, end, east_m, north_m): GPS offset by that much in [start, end)."""
    slides: list[tuple[float, float, float, float]] = field(default_factory=list)
    """(start, end, east_mps, north_mps): the ground carries the rover at that velocity in
    [start, end) and no wheel or gyro sees it (a slide, a ferry, a rover carried)."""


@dataclass
class Run:
    readings: list  # GpsFix | Attitude | WheelDistance, in arrival order
    t_s: np.ndarray
    east_m: np.ndarray
    north_m: np.ndarray
    heading_rad: np.ndarray
    gps_bias_en_m: np.ndarray
    """(len(t), 2) GPS bias at each step (the part no filter can remove)."""

    def truth_at(self, time_s: float) -> tuple[float, float, float]:
        i = int(round(time_s / (self.t_s[1] - self.t_s[0])))
        return float(self.east_m[i]), float(self.north_m[i]), float(self.heading_rad[i])


def simulate(
    duration_s: float,
    speed_mps: Callable[[float], float],
    turn_radps: Callable[[float], float],
    seed: int,
    sensors: Sensors | None = None,
    heading0_rad: float = 0.0,
) -> Run:
    """Integrate the trajectory at the IMU period and emit GPS, ATTITUDE and WHEEL_DISTANCE."""
    s = sensors or Sensors()
    rng = np.random.default_rng(seed)
    dt = s.imu_period_s
    steps = int(round(duration_s / dt)) + 1
    gps_every = int(round(s.gps_period_s / dt))
    t_all = np.arange(steps) * dt
    east = np.zeros(steps)
    north = np.zeros(steps)
    heading = np.zeros(steps)
    bias = np.zeros((steps, 2))
    heading[0] = heading0_rad
    bias[0] = rng.normal(0.0, s.gps_bias_m, 2)
    decay = math.exp(-dt / s.gps_bias_tau_s)
    left = right = 0.0
    offset = s.compass_offset_rad if s.compass_offset_rad is not None else rng.normal(0.0, s.compass_offset_sigma_rad)
    readings: list = []
    for k in range(steps):
        t = t_all[k]
        if k > 0:
            v, w = speed_mps(t - dt), turn_radps(t - dt)
            mid = heading[k - 1] + 0.5 * w * dt
            slip = rng.normal(0.0, s.lateral_slip_per_sqrt_s * math.sqrt(dt), 2)
            east[k] = east[k - 1] + v * dt * math.cos(mid) + slip[0]
            north[k] = north[k - 1] + v * dt * math.sin(mid) + slip[1]
            for a, b, ve, vn in s.slides:
                if a <= t - dt < b:
                    east[k] += ve * dt
                    north[k] += vn * dt
            heading[k] = wrap_pi(heading[k - 1] + w * dt)
            bias[k] = decay * bias[k - 1] + rng.normal(0.0, s.gps_bias_m * math.sqrt(1.0 - decay * decay), 2)
            wheel_v = s.wheel_scale * v + rng.normal(0.0, s.wheel_speed_sigma_mps)
            left += wheel_v * dt - s.wheel_scale * 0.5 * w * TRACK_M * dt
            right += wheel_v * dt + s.wheel_scale * 0.5 * w * TRACK_M * dt
            gyro = w + s.gyro_bias_radps + rng.normal(0.0, s.gyro_noise_rad_per_sqrt_s / math.sqrt(dt))
        else:
            gyro = turn_radps(0.0) + s.gyro_bias_radps
        if k % gps_every == 0 and not any(a <= t < b for a, b in s.outages):
            e = east[k] + bias[k, 0] + rng.normal(0.0, s.gps_white_m)
            n = north[k] + bias[k, 1] + rng.normal(0.0, s.gps_white_m)
            for a, b, ge, gn in s.glitches:
                if a <= t < b:
                    e, n = e + ge, n + gn
            lat, lon = CMAC.to_geodetic(e, n)
            v = speed_mps(t)
            vel = v * np.array([math.cos(heading[k]), math.sin(heading[k])])
            vel += sum((np.array([ve, vn]) for a, b, ve, vn in s.slides if a <= t < b), np.zeros(2))
            vel += rng.normal(0.0, s.gps_velocity_sigma_mps, 2)
            course_deg = math.degrees(enu_to_compass_rad(math.atan2(vel[1], vel[0])))
            readings.append(
                GpsFix(t, lat, lon, 584.0, 3, s.gps_eph_m or s.gps_white_m, float(np.hypot(*vel)), course_deg, 12)
            )
        compass = enu_to_compass_rad(heading[k] + offset + rng.normal(0.0, s.compass_sigma_rad))
        readings.append(Attitude(t, compass, -gyro))
        readings.append(WheelDistance(t, left, right))
    return Run(readings, t_all, east, north, heading, bias)


def feed(estimator, readings, on_step=None) -> list:
    """Give every reading to the estimator; returns the GPS verdicts in order. ``on_step`` is
    called after each wheel reading (the filter's clock tick)."""
    verdicts = []
    for r in readings:
        if isinstance(r, GpsFix):
            verdicts.append((r.time_s, estimator.on_gps(r)))
        elif isinstance(r, Attitude):
            estimator.on_attitude(r)
        else:
            estimator.on_wheels(r)
            if on_step is not None:
                on_step(r.time_s)
    return verdicts
