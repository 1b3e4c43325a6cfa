"""The estimator's own EKF steps (rover_ctl.estimation.ekf) against filterpy's ExtendedKalmanFilter,
which the estimator used before: the same arithmetic, so the same estimates within rounding."""

from __future__ import annotations

import math

import numpy as np
import pytest

from estimator.synthetic import Sensors, simulate
from estimator.test_estimator import new_estimator, run_filter
from rover_ctl.estimation import estimator as estimator_module
from rover_ctl.estimation.ekf import Ekf, solve_small
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


def random_spd(rng: np.random.Generator, n: int) -> np.ndarray:
    a = rng.normal(size=(n, n))
    return a @ a.T + n * np.eye(n)


@pytest.mark.parametrize("n", [1, 2, 3])
def test_solve_small_matches_numpy(n):
    rng = np.random.default_rng(n)
    for _ in range(50):
        s, b = random_spd(rng, n), rng.normal(size=(n, 7))
        np.testing.assert_allclose(solve_small(s, b), np.linalg.solve(s, b), rtol=1e-10, atol=1e-12)


def test_steps_match_filterpy():
    rng = np.random.default_rng(7)
    ours, theirs = Ekf(7), FilterpyEkf(7)
    for _ in range(200):
        x, f, q = rng.normal(size=(7, 1)), np.eye(7) + 0.1 * rng.normal(size=(7, 7)), 0.01 * random_spd(rng, 7)
        for kf in (ours, theirs):
            kf.predict(x.copy(), f, q)
        m = int(rng.integers(1, 3))
        h, r, z = rng.normal(size=(m, 7)), random_spd(rng, m), rng.normal(size=(m, 1))
        residual = (lambda a, b: wrap_pi(a - b)) if m == 1 and rng.random() < 0.5 else None
        for kf in (ours, theirs):
            kf.update(z, h, h @ kf.x, r, residual)
        np.testing.assert_allclose(ours.x, theirs.x, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(ours.P, theirs.P, rtol=1e-9, atol=1e-12)


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
