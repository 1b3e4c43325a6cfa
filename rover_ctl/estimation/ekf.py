"""The extended Kalman filter's two steps, for the pose estimator (``rover_ctl.estimation.estimator``).

``predict`` takes the propagated state and the motion model's Jacobian ``F``:
``P = F P F' + Q``. ``update`` takes a measurement ``z``, its Jacobian ``H`` and prediction
``h(x)``: ``S = H P H' + R``, ``K = P H' S^-1``, ``x += K y`` with ``y = z - h(x)`` (or an angle-aware
residual), and the covariance in Joseph form ``P = (I - K H) P (I - K H)' + K R K'``, which stays
symmetric and positive with rounding.

This is filterpy's ``ExtendedKalmanFilter`` arithmetic, in the same order (tests/estimator/test_ekf.py
runs both on the same sequences), written out for two reasons measured on the daemon:

* importing any of filterpy imports all of it (its package ``__init__`` loads every submodule),
  and with it scipy.stats, scipy.optimize, scipy.sparse and scipy.ndimage, none of which the
  estimator uses (docs/daemon.md, "On a companion computer", has the seconds and megabytes);
* filterpy inverts ``S`` with scipy's general ``linalg.inv``, whose argument checks cost more than
  the arithmetic on the 1x1 and 2x2 matrices every measurement here has; they get the closed
  formula (larger ones numpy's solve).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

Residual = Callable[[np.ndarray, np.ndarray], np.ndarray]


def solve_small(s: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``S^-1 b`` for a symmetric positive definite ``S``: closed formulas for 1x1 and 2x2."""
    n = s.shape[0]
    if n == 1:
        return b / s[0, 0]
    if n == 2:
        a, c, d = s[0, 0], s[0, 1], s[1, 1]
        inverse = np.array([[d, -c], [-c, a]])
        return (inverse @ b) / (a * d - c * c)
    return np.linalg.solve(s, b)


class Ekf:
    """State ``x`` (n x 1) and covariance ``P`` (n x n), set directly by the estimator."""

    def __init__(self, dim_x: int) -> None:
        self.x = np.zeros((dim_x, 1))
        self.P = np.eye(dim_x)
        self._eye = np.eye(dim_x)

    def predict(self, x: np.ndarray, jacobian: np.ndarray, q: np.ndarray) -> None:
        """The state propagated by the motion model, its Jacobian ``F`` and the process noise ``Q``."""
        self.x = x
        self.P = jacobian @ self.P @ jacobian.T + q

    def update(self, z: np.ndarray, h: np.ndarray, hx: np.ndarray, r: np.ndarray, residual: Residual | None = None) -> None:
        """Fuse measurement ``z`` (m x 1) with Jacobian ``H`` (m x n), prediction ``hx`` = h(x) and noise ``R``."""
        pht = self.P @ h.T
        s = h @ pht + r
        gain = solve_small(s, pht.T).T  # P H' S^-1, S symmetric
        y = z - hx if residual is None else residual(z, hx)
        self.x = self.x + gain @ y
        i_kh = self._eye - gain @ h
        self.P = i_kh @ self.P @ i_kh.T + gain @ r @ gain.T
