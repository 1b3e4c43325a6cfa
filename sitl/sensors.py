"""Sensor error models: GPS, compass and gyro, rangefinders, wheel encoders.

Each sensor owns one numpy Generator (seeded from the run seed), so a run is deterministic per seed
and one sensor's call rate does not perturb another's noise. Correlated errors are first-order
Gauss-Markov processes advanced by the sim time elapsed since the previous sample (exact
discretisation: b <- phi b + sigma sqrt(1 - phi^2) n, phi = exp(-dt / tau)), so their statistics do
not depend on how often a sensor is read. White noise is drawn per sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sitl.faults import FaultState
from sitl.geodesy import LocalFrame
from sitl.params import EncoderParams, GpsParams, ImuParams, RangefinderMount, RangefinderParams
from sitl.world import LocalWorld


@dataclass(frozen=True)
class GpsSample:
    """One fix as the receiver reports it, with the error components that went into it."""

    time_s: float
    lat_deg: float
    lon_deg: float
    alt_m: float
    fix_type: int
    eph_m: float
    """Per-axis 1-sigma of the horizontal error the receiver claims (consistent with its model)."""
    speed_mps: float
    course_deg: float
    """Compass course over ground, 0..360."""
    satellites: int
    err_white_en_m: tuple[float, float]
    err_bias_en_m: tuple[float, float]
    err_glitch_en_m: tuple[float, float]


@dataclass(frozen=True)
class AttitudeSample:
    time_s: float
    yaw_rad: float
    """Compass heading, NED (0 north, clockwise positive), in (-pi, pi], with noise and bias."""
    yaw_rate_radps: float
    """Gyro yaw rate, NED (clockwise positive), with noise and bias."""


@dataclass(frozen=True)
class RangeSample:
    time_s: float
    sensor_id: int
    orientation: int
    """MAV_SENSOR_ORIENTATION of the beam."""
    min_m: float
    max_m: float
    range_m: float | None
    """None: no echo within max_m."""


@dataclass(frozen=True)
class WheelSample:
    time_s: float
    left_m: float
    """Cumulative distance rolled by the left wheel as its encoder counts it."""
    right_m: float


class GaussMarkov:
    """A vector of independent first-order Gauss-Markov processes, stationary from the start."""

    def __init__(self, rng: np.random.Generator, std: float, tau_s: float, size: int) -> None:
        self.rng, self.std, self.tau_s = rng, std, tau_s
        self.value = rng.normal(0.0, std, size) if std > 0 else np.zeros(size)
        self.time_s = 0.0

    def at(self, time_s: float) -> np.ndarray:
        """The process at ``time_s`` (advanced by the time since the last call)."""
        dt = max(0.0, time_s - self.time_s)
        self.time_s = max(self.time_s, time_s)
        phi = math.exp(-dt / self.tau_s)
        noise = self.rng.normal(0.0, 1.0, self.value.size)
        self.value = phi * self.value + self.std * math.sqrt(1.0 - phi * phi) * noise
        return self.value


class Gps:
    """Position = truth + white + Gauss-Markov bias + glitch; dropouts and outages give no fix."""

    def __init__(self, params: GpsParams, frame: LocalFrame, alt_m: float, rng: np.random.Generator) -> None:
        self.params, self.frame, self.alt_m, self.rng = params, frame, alt_m, rng
        self.bias = GaussMarkov(rng, params.bias_std_m, params.bias_tau_s, 2)

    def sample(self, time_s: float, east_m: float, north_m: float, vel_en_mps: tuple[float, float],
               faults: FaultState) -> GpsSample | None:
        p = self.params
        bias = self.bias.at(time_s)
        white = self.rng.normal(0.0, p.white_std_m, 2)
        vel = self.rng.normal(0.0, p.speed_std_mps, 2) + vel_en_mps
        alt = self.alt_m + self.rng.normal(0.0, p.alt_std_m)
        dropped = self.rng.uniform() < p.dropout_prob
        if faults.gps_disabled or dropped:
            return None
        glitch = faults.gps_glitch_en_m
        lat, lon = self.frame.to_latlon(east_m + white[0] + bias[0] + glitch[0], north_m + white[1] + bias[1] + glitch[1])
        return GpsSample(
            time_s, float(lat), float(lon), float(alt), p.fix_type, p.eph_m,
            float(math.hypot(vel[0], vel[1])), math.degrees(math.atan2(vel[0], vel[1])) % 360.0, p.satellites,
            (float(white[0]), float(white[1])), (float(bias[0]), float(bias[1])), glitch)


class Imu:
    """Compass (constant per-run offset + white noise) and gyro (Gauss-Markov bias + white noise)."""

    def __init__(self, params: ImuParams, compass_rng: np.random.Generator, gyro_rng: np.random.Generator) -> None:
        self.params = params
        self.compass_rng, self.gyro_rng = compass_rng, gyro_rng
        self.compass_bias_rad = math.radians(compass_rng.normal(0.0, params.compass_bias_std_deg))
        self.gyro_bias = GaussMarkov(gyro_rng, math.radians(params.gyro_bias_std_dps), params.gyro_bias_tau_s, 1)

    def sample(self, time_s: float, yaw_enu_rad: float, yaw_rate_enu_radps: float) -> AttitudeSample:
        p = self.params
        compass = math.pi / 2.0 - yaw_enu_rad + self.compass_bias_rad + math.radians(self.compass_rng.normal(0.0, p.compass_noise_std_deg))
        bias = float(self.gyro_bias.at(time_s)[0])
        gyro = -yaw_rate_enu_radps + bias + math.radians(self.gyro_rng.normal(0.0, p.gyro_noise_std_dps))
        return AttitudeSample(time_s, math.remainder(compass, 2.0 * math.pi), gyro)


class Rangefinder:
    """One beam: the nearest obstacle over ``rays_per_beam`` rays spanning the field of view."""

    def __init__(self, params: RangefinderParams, mount: RangefinderMount, rng: np.random.Generator) -> None:
        self.params, self.mount, self.rng = params, mount, rng
        n = max(1, params.rays_per_beam)
        half = math.radians(params.fov_deg) / 2.0
        self.ray_offsets_rad = [0.0] if n == 1 else [-half + 2.0 * half * k / (n - 1) for k in range(n)]
        self.last_range_m: float | None = None

    def sample(self, time_s: float, east_m: float, north_m: float, yaw_enu_rad: float, world: LocalWorld,
               faults: FaultState) -> RangeSample | None:
        p, mount = self.params, self.mount
        if faults.rangefinder_silent(mount.sensor_id):
            return None
        if not faults.rangefinder_stuck(mount.sensor_id):
            c, s = math.cos(yaw_enu_rad), math.sin(yaw_enu_rad)
            origin = (east_m + c * mount.forward_m - s * mount.left_m, north_m + s * mount.forward_m + c * mount.left_m)
            beam = yaw_enu_rad + mount.bearing_rad
            hit = world.fan_cast(origin, [beam + offset for offset in self.ray_offsets_rad], p.max_m, time_s)
            noise = self.rng.normal(0.0, p.noise_std_m)
            if hit is None or hit[0] + noise > p.max_m:
                self.last_range_m = None
            else:
                self.last_range_m = max(p.min_m, hit[0] + noise)
        return RangeSample(time_s, mount.sensor_id, mount.orientation, p.min_m, p.max_m, self.last_range_m)


class WheelEncoders:
    """Cumulative wheel distance: rolled distance + slip random walk, quantised to encoder ticks."""

    def __init__(self, params: EncoderParams, wheel_radius_m: float, rng: np.random.Generator) -> None:
        self.params, self.rng = params, rng
        self.wheel_radius_m = wheel_radius_m
        self.tick_m = 2.0 * math.pi * wheel_radius_m / params.ticks_per_rev
        self.rolled_m = np.zeros(2)
        self.slip_m = np.zeros(2)

    def sample(self, time_s: float, angle_l_rad: float, angle_r_rad: float) -> WheelSample:
        rolled = np.array([angle_l_rad, angle_r_rad]) * self.wheel_radius_m
        step = np.abs(rolled - self.rolled_m)
        self.rolled_m = rolled
        # Random-walk slip with variance proportional to the distance rolled: rate-independent.
        self.slip_m += self.rng.normal(0.0, 1.0, 2) * np.sqrt(self.params.slip_noise_m2_per_m * step)
        counted = np.floor((rolled + self.slip_m) / self.tick_m) * self.tick_m
        return WheelSample(time_s, float(counted[0]), float(counted[1]))
