"""Sensor error models: statistics over long synthetic runs and known geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sitl.faults import FaultState
from sitl.geodesy import LocalFrame
from sitl.params import EncoderParams, GpsParams, ImuParams, RangefinderMount, RangefinderParams
from sitl.sensors import GaussMarkov, Gps, Imu, Rangefinder, WheelEncoders
from sitl.world import LocalObstacle, LocalWorld

FRAME = LocalFrame(-35.363261, 149.165230)


def gps_errors(params: GpsParams, rate_hz: float, duration_s: float, seed: int = 3):
    gps = Gps(params, FRAME, 584.0, np.random.default_rng(seed))
    faults = FaultState()
    samples = [gps.sample(k / rate_hz, 10.0, 20.0, (0.0, 0.0), faults) for k in range(int(duration_s * rate_hz))]
    return gps, [s for s in samples if s is not None]


def autocorrelation(x: np.ndarray, lag: int) -> float:
    x = x - x.mean()
    return float(np.dot(x[:-lag], x[lag:]) / np.dot(x, x))


def test_gps_white_and_bias_statistics_and_correlation_time():
    params = GpsParams(white_std_m=0.5, bias_std_m=1.0, bias_tau_s=10.0, dropout_prob=0.0)
    _, samples = gps_errors(params, 5.0, 3000.0)
    white = np.array([s.err_white_en_m for s in samples])
    bias = np.array([s.err_bias_en_m for s in samples])
    assert white.std(axis=0) == pytest.approx([0.5, 0.5], rel=0.05)
    assert bias.std(axis=0) == pytest.approx([1.0, 1.0], rel=0.15)
    for axis in range(2):
        assert autocorrelation(bias[:, axis], 50) == pytest.approx(math.exp(-1), abs=0.08)  # lag = tau
        assert abs(autocorrelation(white[:, axis], 1)) < 0.05
    assert abs(np.corrcoef(bias[:, 0], bias[:, 1])[0, 1]) < 0.15


def test_gps_reported_position_is_truth_plus_its_error_components():
    params = GpsParams(dropout_prob=0.0)
    gps = Gps(params, FRAME, 584.0, np.random.default_rng(1))
    faults = FaultState()
    faults.set("SIM_GPS_GLITCH_X", 7.0)
    faults.set("SIM_GPS_GLITCH_Y", -3.0)
    s = gps.sample(1.0, 10.0, 20.0, (1.0, 0.0), faults)
    east, north = FRAME.to_en(s.lat_deg, s.lon_deg)
    assert s.err_glitch_en_m == (-3.0, 7.0)
    assert east == pytest.approx(10.0 + s.err_white_en_m[0] + s.err_bias_en_m[0] - 3.0, abs=1e-6)
    assert north == pytest.approx(20.0 + s.err_white_en_m[1] + s.err_bias_en_m[1] + 7.0, abs=1e-6)
    assert s.eph_m == pytest.approx(params.eph_m)
    assert s.fix_type == 3 and s.satellites == params.satellites
    assert s.speed_mps == pytest.approx(1.0, abs=0.3)
    assert s.course_deg == pytest.approx(90.0, abs=20.0)  # moving east


def test_gps_bias_statistics_do_not_depend_on_the_call_rate():
    params = GpsParams(bias_std_m=1.0, bias_tau_s=10.0, dropout_prob=0.0)
    _, fast = gps_errors(params, 5.0, 2000.0, seed=5)
    _, slow = gps_errors(params, 1.0, 2000.0, seed=5)
    fast_bias = np.array([s.err_bias_en_m[0] for s in fast])
    slow_bias = np.array([s.err_bias_en_m[0] for s in slow])
    assert slow_bias.std() == pytest.approx(fast_bias.std(), rel=0.2)
    assert autocorrelation(slow_bias, 10) == pytest.approx(autocorrelation(fast_bias, 50), abs=0.1)


def test_gps_dropouts_happen_at_their_probability_and_outage_gives_no_fix():
    params = GpsParams(dropout_prob=0.1)
    _, samples = gps_errors(params, 5.0, 400.0)
    assert len(samples) / 2000 == pytest.approx(0.9, abs=0.03)
    gps = Gps(GpsParams(dropout_prob=0.0), FRAME, 584.0, np.random.default_rng(0))
    faults = FaultState()
    faults.set("SIM_GPS_DISABLE", 1)
    assert gps.sample(0.2, 0.0, 0.0, (0.0, 0.0), faults) is None


def test_gauss_markov_is_stationary_from_the_start():
    starts = [GaussMarkov(np.random.default_rng(seed), 2.0, 5.0, 1).value[0] for seed in range(2000)]
    assert np.std(starts) == pytest.approx(2.0, rel=0.06)


def test_compass_and_gyro_noise_bias_and_conventions():
    params = ImuParams(compass_noise_std_deg=1.0, compass_bias_std_deg=2.0, gyro_noise_std_dps=0.3,
                       gyro_bias_std_dps=0.1, gyro_bias_tau_s=300.0)
    imu = Imu(params, np.random.default_rng(1), np.random.default_rng(2))
    yaw_enu = math.radians(30.0)  # compass 60 degrees
    rate_enu = 0.2  # counter-clockwise: the gyro (NED) reads -0.2
    samples = [imu.sample(k * 0.02, yaw_enu, rate_enu) for k in range(5000)]
    compass = np.degrees([s.yaw_rad for s in samples])
    gyro = np.array([s.yaw_rate_radps for s in samples])
    assert compass.mean() == pytest.approx(60.0 + math.degrees(imu.compass_bias_rad), abs=0.1)
    assert compass.std() == pytest.approx(1.0, rel=0.05)
    assert gyro.mean() == pytest.approx(-0.2, abs=math.radians(0.5))
    assert np.degrees(gyro).std() == pytest.approx(0.3, rel=0.1)
    south = imu.sample(200.0, math.radians(-90.0), 0.0).yaw_rad
    assert abs(abs(south) - math.pi) < math.radians(10.0)  # wrapped into (-pi, pi]


def rangefinder(mount: RangefinderMount, **kwargs) -> Rangefinder:
    params = RangefinderParams(noise_std_m=0.0, **kwargs)
    return Rangefinder(params, mount, np.random.default_rng(0))


def circle(ident, east, north, radius, velocity=(0.0, 0.0)):
    return LocalObstacle(ident, "circle", (east, north), radius, [], None, velocity, 0.0, True)


FRONT = RangefinderMount(0, 0, 0.225, 0.0)
RIGHT = RangefinderMount(3, 2, 0.0, -0.2)


def test_rangefinder_sees_the_nearest_obstacle_along_its_mounted_beam():
    world = LocalWorld([circle("ahead", 0.0, 3.225, 1.0), circle("east", 2.7, 0.0, 0.5)])
    heading_north = math.pi / 2
    sample = rangefinder(FRONT).sample(0.0, 0.0, 0.0, heading_north, world, FaultState())
    assert sample.range_m == pytest.approx(2.0, abs=1e-9)
    assert (sample.sensor_id, sample.orientation, sample.min_m, sample.max_m) == (0, 0, 0.2, 4.0)
    right = rangefinder(RIGHT).sample(0.0, 0.0, 0.0, heading_north, world, FaultState())
    assert right.range_m == pytest.approx(2.0, abs=0.01)  # 2.7 - 0.5 - 0.2 mount offset
    assert rangefinder(FRONT, max_m=1.5).sample(0.0, 0.0, 0.0, heading_north, world, FaultState()).range_m is None


def test_rangefinder_field_of_view_and_minimum_range():
    off_axis = LocalWorld([circle("c", 2.225 * math.tan(math.radians(6.0)) + 0.3, 2.225, 0.3)])
    # The object sits 6 degrees off the beam axis (plus its radius): inside a 15-degree beam, outside a 5-degree one.
    assert rangefinder(FRONT, fov_deg=15.0).sample(0.0, 0.0, 0.0, math.pi / 2, off_axis, FaultState()).range_m is not None
    assert rangefinder(FRONT, fov_deg=5.0).sample(0.0, 0.0, 0.0, math.pi / 2, off_axis, FaultState()).range_m is None
    touching = LocalWorld([circle("c", 0.0, 0.3, 0.05)])
    assert rangefinder(FRONT).sample(0.0, 0.0, 0.0, math.pi / 2, touching, FaultState()).range_m == 0.2


def test_rangefinder_noise_std_and_silent_and_stuck_faults():
    world = LocalWorld([circle("c", 0.0, 3.225, 1.0, velocity=(0.0, -0.1))])
    sensor = Rangefinder(RangefinderParams(noise_std_m=0.02), FRONT, np.random.default_rng(4))
    faults = FaultState()
    ranges = np.array([sensor.sample(0.0, 0.0, 0.0, math.pi / 2, world, faults).range_m for _ in range(2000)])
    assert ranges.mean() == pytest.approx(2.0, abs=0.003)
    assert ranges.std() == pytest.approx(0.02, rel=0.08)
    faults.set("SIM_RF_STUCK", 1)
    stuck = sensor.last_range_m
    assert sensor.sample(5.0, 0.0, 0.0, math.pi / 2, world, faults).range_m == stuck  # the obstacle moved 0.5 m
    faults.set("SIM_RF_STUCK", 0)
    assert sensor.sample(5.0, 0.0, 0.0, math.pi / 2, world, faults).range_m == pytest.approx(1.5, abs=0.1)
    faults.set("SIM_RF_FAIL", 1)
    assert sensor.sample(5.0, 0.0, 0.0, math.pi / 2, world, faults) is None


def test_encoders_quantise_to_ticks_and_slip_noise_grows_with_distance():
    params = EncoderParams(ticks_per_rev=100, slip_noise_m2_per_m=1e-4)
    tick = 2 * math.pi * 0.07 / 100
    finals = []
    for seed in range(200):
        enc = WheelEncoders(params, 0.07, np.random.default_rng(seed))
        for k in range(1, 101):
            sample = enc.sample(k * 0.02, k * 10.0 / 0.07 / 100, k * 10.0 / 0.07 / 100)  # 10 m in 100 samples
        assert sample.left_m / tick == pytest.approx(round(sample.left_m / tick), abs=1e-6)
        finals.append(sample.left_m - 10.0)
    assert np.std(finals) == pytest.approx(math.sqrt(1e-4 * 10.0), rel=0.15)  # 3.2 cm after 10 m
    exact = WheelEncoders(EncoderParams(ticks_per_rev=100, slip_noise_m2_per_m=0.0), 0.07, np.random.default_rng(0))
    sample = exact.sample(0.0, 1.0, 2.0)
    assert (sample.left_m, sample.right_m) == pytest.approx((math.floor(0.07 / tick) * tick, math.floor(0.14 / tick) * tick))
