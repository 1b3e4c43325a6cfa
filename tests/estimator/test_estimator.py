"""The pose filter on synthetic runs (tests/estimator/synthetic.py): accuracy, gating, outages,
consistency and the handling of time."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.stats import chi2

from estimator.synthetic import CMAC, TRACK_M, Sensors, feed, simulate
from rover_ctl.config import EstimatorParams
from rover_ctl.estimation.estimator import GpsVerdict, PoseEstimator, motion_model
from rover_ctl.estimation.frame import wrap_pi
from rover_ctl.estimation.readings import Attitude, GpsFix, WheelDistance

CONVERGED_S = 10.0


def new_estimator(**overrides) -> PoseEstimator:
    return PoseEstimator(CMAC, dataclasses.replace(EstimatorParams(), **overrides), TRACK_M)


class Recorder:
    """Pose error against the synthetic truth after every wheel reading."""

    def __init__(self, run, estimator):
        self.run, self.estimator = run, estimator
        self.t, self.err_en, self.err_psi, self.poses = [], [], [], []

    def __call__(self, time_s: float) -> None:
        pose = self.estimator.pose()
        east, north, heading = self.run.truth_at(time_s)
        self.t.append(time_s)
        self.err_en.append((pose.east_m - east, pose.north_m - north))
        self.err_psi.append(wrap_pi(pose.heading_rad - heading))
        self.poses.append(pose)

    def arrays(self, since_s: float = CONVERGED_S):
        t = np.array(self.t)
        keep = t >= since_s
        return t[keep], np.array(self.err_en)[keep], np.array(self.err_psi)[keep]

    def position_rms_m(self, since_s: float = CONVERGED_S) -> float:
        _, en, _ = self.arrays(since_s)
        return float(np.sqrt(np.mean(np.sum(en**2, axis=1))))

    def heading_rms_rad(self, since_s: float = CONVERGED_S) -> float:
        _, _, psi = self.arrays(since_s)
        return float(np.sqrt(np.mean(psi**2)))


def run_filter(run, estimator=None):
    estimator = estimator or new_estimator()
    recorder = Recorder(run, estimator)
    verdicts = feed(estimator, run.readings, recorder)
    return estimator, recorder, verdicts


def gps_rms_m(run) -> float:
    errors = []
    for r in run.readings:
        if isinstance(r, GpsFix):
            east, north = CMAC.to_enu(r.lat_deg, r.lon_deg)
            te, tn, _ = run.truth_at(r.time_s)
            errors.append((east - te) ** 2 + (north - tn) ** 2)
    return math.sqrt(float(np.mean(errors)))


@pytest.mark.parametrize(
    "name, speed, turn",
    [
        ("straight line", lambda t: 1.5, lambda t: 0.0),
        ("circle r=10 m", lambda t: 1.0, lambda t: 0.1),
        ("figure of eight", lambda t: 1.2, lambda t: 0.25 * math.sin(2 * math.pi * t / 50.0)),
    ],
)
def test_trajectory_recovered_from_white_gps(name, speed, turn):
    run = simulate(60.0, speed, turn, seed=11, heading0_rad=0.7)
    estimator, rec, verdicts = run_filter(run)
    assert verdicts[0][1] is GpsVerdict.RESET
    assert all(v is GpsVerdict.ACCEPTED for _, v in verdicts[1:]), name
    raw = gps_rms_m(run)
    assert raw == pytest.approx(2.5 * math.sqrt(2), rel=0.15)
    assert rec.position_rms_m() < 0.25 * raw, name
    assert math.degrees(rec.heading_rms_rad()) < 1.0, name
    pose = estimator.pose()
    assert pose.healthy and pose.gps_ok
    assert pose.speed_mps == pytest.approx(speed(60.0), abs=0.1)
    assert pose.yaw_rate_radps == pytest.approx(turn(60.0), abs=0.02)
    assert pose.position_sigma_m < 1.0


def test_follows_a_slow_gps_bias_it_cannot_see():
    sensors = Sensors(gps_white_m=0.5, gps_bias_m=2.0, gps_bias_tau_s=60.0)
    run = simulate(60.0, lambda t: 1.5, lambda t: 0.05, seed=5, sensors=sensors)
    _, rec, _ = run_filter(run)
    t, err, _ = rec.arrays()
    bias = run.gps_bias_en_m[np.rint(t / 0.02).astype(int)]
    bias_rms = float(np.sqrt(np.mean(np.sum(bias**2, axis=1))))
    assert rec.position_rms_m() == pytest.approx(bias_rms, rel=0.15)
    # the error is mostly the bias, followed with the lag of the filter's averaging
    assert float(np.sqrt(np.mean(np.sum((err - bias) ** 2, axis=1)))) < 0.5 * bias_rms


def test_fifty_metre_gps_jump_is_rejected():
    sensors = Sensors(glitches=[(30.0, 33.0, 50.0, 0.0)])
    run = simulate(50.0, lambda t: 1.5, lambda t: 0.0, seed=3, sensors=sensors)
    _, rec, verdicts = run_filter(run)
    in_glitch = [v for t, v in verdicts if 30.0 <= t < 33.0]
    assert len(in_glitch) == 15 and all(v is GpsVerdict.REJECTED for v in in_glitch)
    assert all(v is GpsVerdict.ACCEPTED for t, v in verdicts if t >= 33.0)
    _, err, _ = rec.arrays(since_s=25.0)
    assert np.max(np.hypot(err[:, 0], err[:, 1])) < 1.0
    assert not rec.poses[int(32.9 / 0.02)].gps_ok


def _truth_error_m(rec, start_s: float, end_s: float) -> np.ndarray:
    t, err, _ = rec.arrays(0.0)
    keep = (t >= start_s) & (t < end_s)
    return np.hypot(err[keep, 0], err[keep, 1])


def test_fifty_metre_jump_held_for_thirty_seconds_is_a_glitch():
    """The GPS jumps 50 m and stays there for 30 s while the rover drives and turns: the GPS keeps
    moving as the wheels say, so it is a glitch, rejected throughout; the pose stays within 2 m
    of the truth and is back to its normal error within 10 s of the glitch's end."""
    glitch = (30.0, 60.0)
    sensors = Sensors(gps_white_m=0.5, glitches=[(*glitch, 30.0, 40.0)])
    run = simulate(90.0, lambda t: 1.5, lambda t: 0.15 * math.sin(t / 5.0), seed=21, sensors=sensors)
    _, rec, verdicts = run_filter(run)
    in_glitch = [v for t, v in verdicts if glitch[0] <= t < glitch[1]]
    assert len(in_glitch) == 150 and all(v is GpsVerdict.REJECTED for v in in_glitch)
    normal_m = float(np.max(_truth_error_m(rec, CONVERGED_S, glitch[0])))
    assert normal_m < 1.0
    assert float(np.max(_truth_error_m(rec, glitch[0], glitch[1]))) < 2.0
    assert float(np.max(_truth_error_m(rec, glitch[1] + 10.0, 90.0))) <= max(normal_m, 0.5)
    assert all(v is GpsVerdict.ACCEPTED for t, v in verdicts if t >= glitch[1] + 0.5)


def test_a_jump_held_longer_than_glitch_max_s_is_believed():
    params = EstimatorParams(glitch_max_s=10.0)
    sensors = Sensors(gps_white_m=0.5, glitches=[(20.0, 60.0, 30.0, -20.0)])
    run = simulate(40.0, lambda t: 1.0, lambda t: 0.0, seed=4, sensors=sensors)
    estimator, rec, verdicts = run_filter(run, PoseEstimator(CMAC, params, TRACK_M))
    resets = [t for t, v in verdicts if v is GpsVerdict.RESET]
    assert resets[0] == 0.0 and len(resets) == 2
    assert resets[1] == pytest.approx(20.0 + params.glitch_max_s, abs=0.25)
    assert all(v is GpsVerdict.REJECTED for t, v in verdicts if 20.0 <= t < resets[1])
    assert all(v is GpsVerdict.ACCEPTED for t, v in verdicts if t > resets[1])
    east, north, _ = run.truth_at(40.0)
    pose = estimator.pose()
    assert math.hypot(pose.east_m - east - 30.0, pose.north_m - north + 20.0) < 1.0


def test_motion_the_wheels_do_not_see_is_followed():
    """The rover slides sideways at 1 m/s for 30 s (the ground carries it; wheels and gyro see
    nothing): the GPS drifts away from the odometry without a jump, so it is believed after
    glitch_reset_s of rejection, again and again. Held as a glitch, the pose would be 30 m off."""
    params = EstimatorParams()
    sensors = Sensors(gps_white_m=0.5, slides=[(20.0, 50.0, 0.0, 1.0)])
    run = simulate(60.0, lambda t: 1.0, lambda t: 0.0, seed=7, sensors=sensors)
    _, rec, verdicts = run_filter(run)
    resets = [t for t, v in verdicts if v is GpsVerdict.RESET and t > 0.0]
    assert resets and all(20.0 < t < 50.0 + params.glitch_reset_s + 0.5 for t in resets)
    # behind by about the slide over a reset period plus the gate, never the whole 30 m slide
    assert float(np.max(_truth_error_m(rec, 20.0, 60.0))) < 1.0 * (params.glitch_reset_s + 4.0)
    assert float(np.max(_truth_error_m(rec, 57.0, 60.0))) < 1.0


def test_dead_reckoning_drift_through_an_outage_is_reset_when_fixes_return():
    """During a 20 s outage the rover slides 16 m unseen: the fixes that come back are far outside
    the gate but did not jump while tracking, so the filter believes them after glitch_reset_s."""
    params = EstimatorParams()
    sensors = Sensors(gps_white_m=0.5, outages=[(20.0, 40.0)], slides=[(22.0, 38.0, 1.0, 0.0)])
    run = simulate(55.0, lambda t: 1.0, lambda t: 0.0, seed=12, sensors=sensors)
    _, rec, verdicts = run_filter(run)
    after = [(t, v) for t, v in verdicts if t >= 40.0]
    assert after[0][1] is GpsVerdict.REJECTED
    resets = [t for t, v in after if v is GpsVerdict.RESET]
    assert resets == [pytest.approx(40.0 + params.glitch_reset_s, abs=0.25)]
    assert float(np.max(_truth_error_m(rec, 46.0, 55.0))) < 1.0


def test_ten_second_outage_is_bridged_with_growing_covariance():
    sensors = Sensors(outages=[(30.0, 40.0)])
    run = simulate(50.0, lambda t: 1.5, lambda t: 0.15 * math.sin(t / 4.0), seed=8, sensors=sensors)
    _, rec, _ = run_filter(run)
    t, err, _ = rec.arrays(0.0)
    at = {round(x, 2): i for i, x in enumerate(t)}
    start, end = at[30.0], at[39.98]
    drift_m = float(np.hypot(*(err[end] - err[start])))
    assert drift_m < 0.02 * 15.0
    sigmas = [p.position_sigma_m for p in rec.poses[start:end]]
    assert np.all(np.diff(sigmas) > 0.0)
    # at least the sideways-skid random walk the model assumes (the rest depends on heading)
    slip = EstimatorParams().lateral_slip_per_sqrt_s
    assert sigmas[-1] ** 2 - sigmas[0] ** 2 > 0.9 * slip**2 * 10.0
    assert all(p.healthy for p in rec.poses[start:end])
    assert not rec.poses[end].gps_ok and rec.poses[at[41.0]].gps_ok
    assert np.hypot(*err[end]) < 3.0 * rec.poses[end].position_sigma_m


def test_nees_within_95_percent_bounds():
    """Average NEES over runs at each sampled time against its chi-square 95 % interval."""
    runs, dims = 20, 3
    sample_s = np.arange(5.0, 30.0, 1.0)
    nees = np.zeros((runs, len(sample_s)))
    columns = {round(s / 0.02): j for j, s in enumerate(sample_s)}
    for k in range(runs):
        run = simulate(30.0, lambda t: 1.2, lambda t: 0.2 * math.sin(t / 3.0), seed=100 + k)
        estimator = new_estimator()

        def sample(time_s, k=k, estimator=estimator, run=run):
            j = columns.get(round(time_s / 0.02))
            if j is not None:
                pose = estimator.pose()
                east, north, heading = run.truth_at(time_s)
                d = np.array([pose.east_m - east, pose.north_m - north, wrap_pi(pose.heading_rad - heading)])
                nees[k, j] = d @ np.linalg.solve(pose.cov, d)

        feed(estimator, run.readings, sample)
    mean_nees = nees.mean(axis=0)
    low, high = chi2.ppf([0.025, 0.975], runs * dims) / runs
    inside = np.mean((mean_nees >= low) & (mean_nees <= high))
    assert inside >= 0.8, (mean_nees, low, high)
    assert low <= mean_nees.mean() <= high


def test_duplicates_and_out_of_order_readings_are_tolerated():
    run = simulate(30.0, lambda t: 1.5, lambda t: 0.1, seed=21)
    reference, _, _ = run_filter(run)
    shuffled = list(run.readings)
    rng = np.random.default_rng(0)
    # swap neighbours (cross-stream interleaving, and an occasional older same-stream reading)
    for i in rng.choice(len(shuffled) - 1, 400, replace=False):
        shuffled[i], shuffled[i + 1] = shuffled[i + 1], shuffled[i]
    doubled = [r for r in shuffled for _ in (0, 1)]
    estimator = new_estimator()
    verdicts = feed(estimator, doubled)
    assert sum(v is GpsVerdict.IGNORED for _, v in verdicts) >= len(verdicts) // 2
    a, b = estimator.pose(), reference.pose()
    assert math.hypot(a.east_m - b.east_m, a.north_m - b.north_m) < 0.3
    assert abs(wrap_pi(a.heading_rad - b.heading_rad)) < math.radians(1.0)
    assert a.time_s == b.time_s == 30.0


def test_stale_gps_is_ignored_and_lagged_gps_is_compensated():
    estimator = new_estimator(gps_min_sigma_m=0.1)
    lat, lon = CMAC.to_geodetic(0.0, 0.0)
    estimator.on_attitude(Attitude(0.0, math.pi / 2, 0.0))  # facing east
    assert estimator.on_gps(GpsFix(0.0, lat, lon, 584.0, 3, 0.1, 0.0, math.nan, 10)) is GpsVerdict.RESET
    for k in range(1, 101):
        t = k * 0.02
        estimator.on_wheels(WheelDistance(t, 2.0 * t, 2.0 * t))
        estimator.on_attitude(Attitude(t, math.pi / 2, 0.0))
    pose = estimator.pose()
    assert pose.speed_mps == pytest.approx(2.0, abs=0.01)
    # a fix taken 0.3 s ago where the rover then was: consistent once shifted by v * lag
    lat, lon = CMAC.to_geodetic(pose.east_m - 0.6, pose.north_m)
    assert estimator.on_gps(GpsFix(1.7, lat, lon, 584.0, 3, 0.1, 2.0, 90.0, 10)) is GpsVerdict.ACCEPTED
    assert estimator.pose().east_m == pytest.approx(pose.east_m, abs=0.05)
    assert estimator.on_gps(GpsFix(1.7, lat, lon, 584.0, 3, 0.1, 2.0, 90.0, 10)) is GpsVerdict.IGNORED
    assert estimator.on_gps(GpsFix(1.0, lat, lon, 584.0, 3, 0.1, 2.0, 90.0, 10)) is GpsVerdict.IGNORED
    no_fix = GpsFix(2.1, math.nan, math.nan, math.nan, 1, math.nan, math.nan, math.nan, 0)
    assert estimator.on_gps(no_fix) is GpsVerdict.IGNORED


def test_unknown_until_gps_and_heading():
    estimator = new_estimator()
    estimator.on_wheels(WheelDistance(0.0, 0.0, 0.0))
    estimator.on_wheels(WheelDistance(0.02, 0.01, 0.01))
    pose = estimator.pose()
    assert not estimator.initialised and not pose.healthy and not pose.gps_ok and math.isnan(pose.east_m)
    lat, lon = CMAC.to_geodetic(12.0, -3.0)
    assert estimator.on_gps(GpsFix(0.04, lat, lon, 584.0, 3, 1.5, 0.0, math.nan, 9)) is GpsVerdict.RESET
    assert not estimator.initialised
    estimator.on_attitude(Attitude(0.05, 0.0, 0.0))  # compass: north
    pose = estimator.pose()
    assert estimator.initialised and pose.healthy and pose.gps_ok
    assert (pose.east_m, pose.north_m) == pytest.approx((12.0, -3.0), abs=1e-6)
    assert pose.heading_rad == pytest.approx(math.pi / 2)
    assert pose.position_sigma_m == pytest.approx(1.5)


def test_wheel_counter_reset_is_rebaselined_not_fused():
    run = simulate(12.0, lambda t: 1.0, lambda t: 0.0, seed=2)
    estimator = new_estimator()
    readings = [
        WheelDistance(r.time_s, r.left_m - 11.0, r.right_m - 11.0)
        if isinstance(r, WheelDistance) and r.time_s > 10.0
        else r
        for r in run.readings
    ]
    feed(estimator, readings)
    assert estimator.pose().speed_mps == pytest.approx(1.0, abs=0.1)


def test_lost_wheels_and_gps_make_the_pose_unhealthy():
    sensors = Sensors(outages=[(20.0, 61.0)])
    run = simulate(60.0, lambda t: 1.0, lambda t: 0.0, seed=6, sensors=sensors)
    estimator = new_estimator()
    readings = [r for r in run.readings if not (isinstance(r, WheelDistance) and r.time_s > 20.0)]
    for r in readings:
        if isinstance(r, GpsFix):
            estimator.on_gps(r)
        elif isinstance(r, Attitude):
            estimator.on_attitude(r)
            if r.time_s == 25.0:
                assert estimator.pose().healthy
        else:
            estimator.on_wheels(r)
    pose = estimator.pose()
    assert not pose.healthy and not pose.gps_ok
    assert pose.position_sigma_m > EstimatorParams().health_max_position_sigma_m


def test_wheels_steer_when_the_gyro_is_silent():
    run = simulate(30.0, lambda t: 1.0, lambda t: 0.2, seed=9, sensors=Sensors(outages=[(10.0, 30.0)]))
    estimator = new_estimator()
    readings = [r for r in run.readings if not (isinstance(r, Attitude) and r.time_s > 10.0)]
    rec = Recorder(run, estimator)
    feed(estimator, readings, rec)
    # 20 s of wheels only, a 90-degree-per-8-s circle: heading from the wheel difference
    assert abs(rec.err_psi[-1]) < math.radians(5.0)
    assert estimator.pose().yaw_rate_radps == pytest.approx(0.2, abs=0.02)


def test_bad_track_is_refused():
    with pytest.raises(ValueError, match="track_m"):
        PoseEstimator(CMAC, EstimatorParams(), 0.0)


def test_compass_offset_is_learnt_from_the_gps_course():
    offset = math.radians(5.0)
    run = simulate(60.0, lambda t: 1.5, lambda t: 0.05, seed=13, sensors=Sensors(compass_offset_rad=offset))
    estimator, rec, _ = run_filter(run)
    assert math.degrees(rec.heading_rms_rad(since_s=20.0)) < 1.0
    assert estimator.pose().heading_sigma_rad < math.radians(1.0)
    # without the course the offset stays in the heading (the position fixes alone see it slowly)
    run.readings = [dataclasses.replace(r, course_deg=math.nan) if isinstance(r, GpsFix) else r for r in run.readings]
    _, blind, _ = run_filter(run)
    assert math.degrees(blind.heading_rms_rad(since_s=5.0)) > 2.0


def test_gps_on_another_clock_is_ignored_and_a_reboot_starts_over():
    run = simulate(20.0, lambda t: 1.0, lambda t: 0.0, seed=31)
    estimator = new_estimator()
    feed(estimator, run.readings)
    pose = estimator.pose()
    lat, lon = CMAC.to_geodetic(pose.east_m, pose.north_m)
    epoch_s = 1.7e9  # ArduPilot stamps GPS_RAW_INT with UNIX time once the receiver has it
    assert estimator.on_gps(GpsFix(epoch_s, lat, lon, 584.0, 3, 1.0, 1.0, 90.0, 10)) is GpsVerdict.IGNORED
    assert estimator.pose().time_s == 20.0
    # the vehicle reboots: its clock starts again at zero
    estimator.on_attitude(Attitude(0.1, 0.0, 0.0))
    assert not estimator.initialised
    lat, lon = CMAC.to_geodetic(5.0, 5.0)
    assert estimator.on_gps(GpsFix(0.2, lat, lon, 584.0, 3, 1.0, 0.0, math.nan, 10)) is GpsVerdict.RESET
    pose = estimator.pose()
    assert estimator.initialised and (pose.east_m, pose.north_m) == pytest.approx((5.0, 5.0), abs=1e-6)


def test_motion_model_jacobian_matches_finite_differences():
    x = np.array([[3.0], [-2.0], [2.9], [1.4], [0.02], [0.05], [1.03]])
    dt_s, gyro = 0.3, 0.4
    _, jac = motion_model(x, dt_s, gyro)
    step = 1e-6
    numeric = np.zeros((7, 7))
    for j in range(7):
        dx = np.zeros((7, 1))
        dx[j] = step
        plus, _ = motion_model(x + dx, dt_s, gyro)
        minus, _ = motion_model(x - dx, dt_s, gyro)
        diff = plus - minus
        diff[2] = wrap_pi(diff[2])
        numeric[:, j] = diff[:, 0] / (2 * step)
    assert np.allclose(jac, numeric, atol=1e-6)
    moved, _ = motion_model(x, dt_s, gyro)
    assert moved[2, 0] == pytest.approx(wrap_pi(2.9 + (0.4 - 0.02) * 0.3))


def test_without_wheel_encoders_gps_velocity_keeps_the_speed():
    """Many ArduPilot rovers send no WHEEL_DISTANCE: the gyro drives the clock, GPS the speed."""
    run = simulate(60.0, lambda t: 1.0 + 0.5 * math.sin(t / 6.0), lambda t: 0.1, seed=17)
    estimator = new_estimator()
    rec = Recorder(run, estimator)
    for r in run.readings:
        if isinstance(r, GpsFix):
            estimator.on_gps(r)
        elif isinstance(r, Attitude):
            estimator.on_attitude(r)
            rec(r.time_s)
    converged = rec.poses[int(CONVERGED_S / 0.02):]
    speed_errors = [p.speed_mps - (1.0 + 0.5 * math.sin(p.time_s / 6.0)) for p in converged]
    assert float(np.sqrt(np.mean(np.square(speed_errors)))) < 0.15
    assert rec.position_rms_m() < 0.5 * gps_rms_m(run)
    assert all(p.healthy for p in converged)


def test_wheel_scale_error_is_learnt_before_an_outage():
    """Tyres 6 % larger than the encoders assume: dead reckoning would drift 6 % of the distance;
    the scale learnt from GPS before the outage keeps it under 2 %."""
    sensors = Sensors(wheel_scale=1.06, outages=[(60.0, 70.0)])
    run = simulate(70.0, lambda t: 1.5, lambda t: 0.05, seed=23, sensors=sensors)
    estimator, rec, _ = run_filter(run)
    t, err, _ = rec.arrays(0.0)
    start, end = int(round(60.0 / 0.02)), len(t) - 1
    assert float(np.hypot(*(err[end] - err[start]))) < 0.02 * 1.5 * 10.0
    assert estimator.pose().speed_mps == pytest.approx(1.5, abs=0.05)


def test_pose_is_predicted_to_the_asked_time_between_odometry_readings():
    """Odometry at 25 Hz, the pose wanted halfway between two readings (a control step whose time
    a rangefinder set): the pose moves on from the filter's last state as the rover did over those
    20 ms, the filter itself is left as it was, and beyond ``pose_max_lead_s`` nothing is
    predicted."""
    turn, speed = 0.8, 1.0
    run = simulate(40.0, lambda t: speed, lambda t: turn, seed=5)
    odometry_s = {round(t, 3) for t in run.t_s[::2]}  # every other 50 Hz sample: 25 Hz
    readings = [r for r in run.readings if isinstance(r, GpsFix) or round(r.time_s, 3) in odometry_s]
    estimator = new_estimator()
    turned, moved = [], []

    def halfway(time_s: float) -> None:
        at_s = round(time_s + 0.02, 3)
        if time_s < CONVERGED_S or at_s > 39.9:
            return
        before = estimator.pose()
        ahead = estimator.pose(at_s)
        assert ahead.time_s == at_s and before.time_s == pytest.approx(time_s)
        again = estimator.pose()
        assert (again.time_s, again.east_m, again.heading_rad) == (before.time_s, before.east_m, before.heading_rad)
        turned.append(wrap_pi(ahead.heading_rad - before.heading_rad))
        moved.append(math.hypot(ahead.east_m - before.east_m, ahead.north_m - before.north_m))

    feed(estimator, readings, halfway)
    assert len(turned) > 700
    assert np.mean(turned) == pytest.approx(turn * 0.02, rel=0.05)  # 0.9 degrees
    assert np.mean(moved) == pytest.approx(speed * 0.02, rel=0.05)
    last = estimator.pose()
    late = estimator.pose(last.time_s + estimator.params.pose_max_lead_s + 0.01)
    assert late.time_s == last.time_s and late.heading_rad == last.heading_rad


@pytest.mark.parametrize("rate_hz", [25.0, 50.0])
def test_a_changing_turn_rate_is_integrated_by_the_trapezoid(rate_hz):
    """ATTITUDE's yawspeed is the rate at its instant (ArduPilot's and the emulator's). Held
    from one reading to the next, a rate rising at 1 rad/s^2 leaves the prediction behind by half
    a period's worth of the change every period, which the compass only slowly pulls back (0.17
    degrees behind after 2 s at 25 Hz, 0.05 at 50 Hz); with the trapezoid the heading keeps up."""
    estimator = new_estimator()
    lat, lon = CMAC.to_geodetic(0.0, 0.0)
    estimator.on_gps(GpsFix(0.0, lat, lon, 584.0, 3, 1.0, 0.0, math.nan, 9))
    accel = 1.0
    period = 1.0 / rate_hz
    for k in range(int(round(2.0 / period)) + 1):
        t = k * period
        heading = 0.5 * accel * t * t  # ENU
        estimator.on_attitude(Attitude(t, wrap_pi(math.pi / 2 - heading), -accel * t))  # NED yaw and yawspeed
    assert math.degrees(abs(wrap_pi(estimator.pose().heading_rad - 2.0))) < 0.01
