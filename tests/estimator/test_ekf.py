"""The estimator's own EKF steps (rover_ctl.estimation.ekf) against filterpy's ExtendedKalmanFilter,
which the estimator used before: the same arithmetic, so the same estimates within rounding.
``Ekf.update_scalar`` (the closed form every measurement of the estimator now uses) is compared
with filterpy's general update (Joseph form, ``H`` 1 x n); fusing the two components of a
measurement with diagonal ``R`` one after the other, with filterpy's joint update."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.synthetic import Sensors, feed, simulate
from estimator.test_estimator import new_estimator, run_filter
from rover_ctl.estimation import estimator as estimator_module
from rover_ctl.estimation.estimator import GpsVerdict
from rover_ctl.estimation.ekf import Ekf
from rover_ctl.estimation.frame import wrap_pi

filterpy_kalman = pytest.importorskip("filterpy.kalman", reason="filterpy (the test extra) is the reference")


class FilterpyEkf(filterpy_kalman.ExtendedKalmanFilter):
    """The old path: filterpy's EKF behind the interface of ``Ekf``."""

    def __init__(self, dim_x: int) -> None:
        super().__init__(dim_x=dim_x, dim_z=2)
        self._next = None

    def predict(self, x, jacobian, q):
        self._next, self.Q = (x, jacobian), q
        super().predict()

    def predict_x(self, u=0):
        self.x, self.F = self._next

    def update(self, z, h, hx, r, residual=None):
        super().update(z, lambda _x: h, lambda _x: hx, R=r, residual=residual or np.subtract)

    def update_scalar(self, y, h, r):
        """filterpy's general update with ``H`` the 1 x n row and the innovation given (z = y, h(x) = 0)."""
        row = np.array(h, dtype=float).reshape(1, -1)
        self.update(np.array([[y]]), row, np.zeros((1, 1)), np.array([[r]]))


def random_spd(rng: np.random.Generator, n: int) -> np.ndarray:
    a = rng.normal(size=(n, n))
    return a @ a.T + n * np.eye(n)


def test_scalar_update_matches_filterpy():
    rng = np.random.default_rng(11)
    ours, theirs = Ekf(7), FilterpyEkf(7)
    for _ in range(200):
        x, f, q = rng.normal(size=(7, 1)), np.eye(7) + 0.1 * rng.normal(size=(7, 7)), 0.01 * random_spd(rng, 7)
        for kf in (ours, theirs):
            kf.predict(x.copy(), f, q)
        h = np.zeros(7)
        h[rng.choice(7, size=int(rng.integers(1, 3)), replace=False)] = rng.normal(size=1) if rng.random() < 0.5 else 1.0
        r, y = float(rng.uniform(0.01, 2.0)), float(rng.normal())
        for kf in (ours, theirs):
            kf.update_scalar(y, h, r)
        np.testing.assert_allclose(ours.x, theirs.x, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(ours.P, theirs.P, rtol=1e-9, atol=1e-12)
        assert np.array_equal(ours.P, ours.P.T)


def test_one_component_after_the_other_is_the_joint_update():
    """What the estimator does with the GPS position and the GPS course and speed (R diagonal)."""
    rng = np.random.default_rng(5)
    for _ in range(100):
        p = random_spd(rng, 7)
        x, z = rng.normal(size=(7, 1)), rng.normal(size=(2, 1))
        i, j = rng.choice(7, size=2, replace=False)
        h = np.zeros((2, 7))
        h[0, i] = h[1, j] = 1.0
        r = np.diag(rng.uniform(0.01, 2.0, size=2))
        joint = FilterpyEkf(7)
        joint.x, joint.P = x.copy(), p.copy()
        joint.update(z, h, h @ x, r)
        ours = Ekf(7)
        ours.x, ours.P = x.copy(), p.copy()
        ours.update_scalar(float(z[0, 0] - ours.x[i, 0]), h[0], r[0, 0])
        ours.update_scalar(float(z[1, 0] - ours.x[j, 0]), h[1], r[1, 1])
        np.testing.assert_allclose(ours.x, joint.x, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(ours.P, joint.P, rtol=1e-9, atol=1e-12)


def test_covariance_stays_symmetric_positive_definite():
    """Over a run with a glitch, an outage, resets and mis-sized tyres, after every reading."""
    sensors = Sensors(gps_white_m=0.5, gps_bias_m=1.0, wheel_scale=1.05, outages=[(40.0, 60.0)],
                      glitches=[(25.0, 29.0, 39.0, 0.0)], slides=[(45.0, 55.0, 1.0, 0.0)])  # fmt: skip
    run = simulate(90.0, lambda t: 1.5, lambda t: 0.15 * math.sin(t / 5.0), seed=3, sensors=sensors)
    estimator = new_estimator()
    verdicts, smallest = [], math.inf
    for reading in run.readings:
        verdicts += feed(estimator, [reading])
        if estimator.initialised:
            p = estimator._kf.P
            assert np.array_equal(p, p.T)
            smallest = min(smallest, float(np.linalg.eigvalsh(p)[0]))
    assert smallest > 0.0
    assert any(v is GpsVerdict.RESET for _, v in verdicts[1:])  # the slide after the outage was reset to


def test_estimator_matches_the_filterpy_path(monkeypatch):
    """A run with a GPS glitch, an outage and mis-sized tyres: every pose within rounding of the old path's."""
    sensors = Sensors(gps_white_m=0.5, gps_bias_m=1.0, wheel_scale=1.05, outages=[(40.0, 45.0)], glitches=[(25.0, 29.0, 39.0, 0.0)])
    run = simulate(60.0, lambda t: 1.5, lambda t: 0.15 * math.sin(t / 5.0), seed=21, sensors=sensors)
    _, ours, our_verdicts = run_filter(run, new_estimator())
    monkeypatch.setattr(estimator_module, "Ekf", FilterpyEkf)
    _, theirs, their_verdicts = run_filter(run, new_estimator())
    assert our_verdicts == their_verdicts
    assert len(ours.poses) == len(theirs.poses) > 1000
    for a, b in zip(ours.poses, theirs.poses):
        assert (a.time_s, a.healthy, a.gps_ok) == (b.time_s, b.healthy, b.gps_ok)
        np.testing.assert_allclose([a.east_m, a.north_m, a.heading_rad, a.speed_mps, a.position_sigma_m],
                                   [b.east_m, b.north_m, b.heading_rad, b.speed_mps, b.position_sigma_m], rtol=0, atol=1e-7)  # fmt: skip
        np.testing.assert_allclose(a.cov, b.cov, rtol=1e-7, atol=1e-12)


def test_a_changed_noise_parameter_applies_at_the_next_prediction():
    """The estimator keeps Q/dt between predictions; a parameter a ground station changed must
    still apply at the next one (params are read at every reading)."""
    run = simulate(5.0, lambda t: 1.0, lambda t: 0.1, seed=4)
    estimator = new_estimator()
    feed(estimator, run.readings)
    for name, value in (("speed_accel_per_sqrt_s", 2.0), ("lateral_slip_per_sqrt_s", 0.3), ("wheel_scale_walk_per_sqrt_s", 0.01)):
        setattr(estimator.params, name, value)
        p = estimator.params
        kf = estimator._kf
        x, before, dt_s = kf.x.copy(), kf.P.copy(), 0.02
        _, f = estimator_module.motion_model(x, dt_s, estimator._rate_input_radps(estimator._time_s + dt_s))
        q = np.diag([p.lateral_slip_per_sqrt_s**2, p.lateral_slip_per_sqrt_s**2, p.gyro_noise_rad_per_sqrt_s**2,
                     p.speed_accel_per_sqrt_s**2, p.gyro_bias_walk_radps_per_sqrt_s**2,
                     p.compass_offset_walk_rad_per_sqrt_s**2, p.wheel_scale_walk_per_sqrt_s**2]) * dt_s  # fmt: skip
        assert estimator._advance(estimator._time_s + dt_s)
        np.testing.assert_allclose(kf.P, f @ before @ f.T + q, rtol=1e-12, atol=1e-15)
