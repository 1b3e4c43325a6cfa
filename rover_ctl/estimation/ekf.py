"""The extended Kalman filter's steps, for the pose estimator (``rover_ctl.estimation.estimator``).

``predict`` takes the propagated state and the motion model's Jacobian ``F``::

    P = F P F' + Q                      (then symmetrised: P = (P + P') / 2)

``update_scalar`` fuses one measurement ``z`` with Jacobian row ``h`` (1 x n), prediction ``h(x)``
and noise variance ``r``: the EKF update ``S = H P H' + R``, ``K = P H' S^-1``, ``x += K y``,
``P = (I - K H) P`` for m = 1, in closed form. Every measurement the estimator makes is one (its
two-dimensional ones, the GPS position and the GPS course and speed, have a diagonal ``R`` and are
fused one component after the other, which gives the same posterior as the joint update)::

    y = z - h(x)        (or an angle-aware residual, wrapped by the caller)
    u = P h'            (n,)  the column P H'; P's column i when h is the unit row e_i
    s = h u + r               innovation variance (a scalar: no inverse)
    K = u / s
    x = x + K y
    P = P - u u' / s    (= P - K H P)

It costs a matrix-vector product and an outer product instead of the Joseph form
``P = (I - K H) P (I - K H)' + K R K'`` (filterpy's) and its three n x n matrix products. What the
Joseph form guards against does not arise here:

* symmetry: ``u u' / s`` is computed as the outer product ``v v'`` of ``v = u / sqrt(s)``, whose
  entries ``v_i v_j`` and ``v_j v_i`` are the same floating-point product, so a symmetric ``P``
  stays exactly symmetric; ``predict`` symmetrises what ``F P F'`` rounds off, so ``P`` is
  exactly symmetric before every scalar update (the Joseph form is symmetric only to rounding).
* positive definiteness: the Joseph form also tolerates a gain that is not the optimal one,
  which cannot happen here (``K`` comes from the same ``u`` and ``s``). With the optimal gain
  ``P - u u' / s`` is positive definite in exact arithmetic, its variance along ``h`` becoming
  ``(h P h') r / (h P h' + r)``; rounding could only break that where a measurement shrinks a
  variance by a factor near machine epsilon (``r / (h P h' + r)`` ~ 1e-16). The estimator's
  noises have floors, and the smallest ratio it meets is about 4e-5 (a wheel reading,
  ``r = (0.03 m/s)^2``, against the initial speed variance ``(5 m/s)^2``); an hour without wheel
  readings would take it to some 1e-6. tests/estimator/test_ekf.py checks that ``P`` stays
  exactly symmetric with positive eigenvalues after every reading of a run with a glitch, an
  outage, a slide and a reset.

The arithmetic is filterpy's ``ExtendedKalmanFilter``'s (tests/estimator/test_ekf.py runs both on
the same sequences, ``update_scalar`` against filterpy's update with the 1 x n ``H``), written out
for two reasons measured on the daemon:

* importing any of filterpy imports all of it (its package ``__init__`` loads every submodule),
  and with it scipy.stats, scipy.optimize, scipy.sparse and scipy.ndimage, none of which the
  estimator uses (docs/daemon.md, "On a companion computer", has the seconds and megabytes);
* filterpy inverts ``S`` with scipy's general ``linalg.inv`` and forms the Joseph form with
  n x n products, whose call overheads cost more than the arithmetic on matrices this small
  (``update_scalar``: 6 us against 14 us for the general Joseph-form update with a 1 x 7 ``H``
  on the bench machine).
"""

from __future__ import annotations

import math
import numpy as np

class Ekf:
    """State ``x`` (n x 1) and covariance ``P`` (n x n), set directly by the estimator."""

    def __init__(self, dim_x: int) -> None:
        self.x = np.zeros((dim_x, 1))
        self.P = np.eye(dim_x)

    def predict(self, x: np.ndarray, jacobian: np.ndarray, q: np.ndarray) -> None:
        """The state propagated by the motion model, its Jacobian ``F`` and the process noise ``Q``:
        ``x = x'``, ``P = F P F' + Q``, symmetrised. ``F`` and ``Q`` are read during the call only
        (the caller may reuse their buffers)."""
        p = jacobian.dot(self.P).dot(jacobian.T)  # ndarray.dot: a third of the @ operator's call cost at 7 x 7
        p += q
        p += p.T.copy()
        p *= 0.5
        self.x = x
        self.P = p

    def update_scalar(self, y: float, h: np.ndarray, r: float) -> None:
        """Fuse one measurement given its innovation ``y = z - h(x)`` (wrapped by the caller if an
        angle), its Jacobian row ``h`` (shape (n,)) and its variance ``r``: ``u = P h'``,
        ``s = h u + r``, ``x += u y / s``, ``P -= v v'`` with ``v = u / sqrt(s)`` (the module
        docstring says why this form and not Joseph's)."""
        u = self.P.dot(h)
        s = float(u.dot(h)) + r
        self.x[:, 0] += u * (y / s)
        v = u * (1.0 / math.sqrt(s))
        self.P -= v[:, None].dot(v[None, :])  # v v': each entry one product, so exactly symmetric
