"""Pose estimation: wheel odometry, gyro, compass and GPS fused by an extended Kalman filter.

No I/O: the filter takes typed readings (``rover_ctl.estimation.readings``) stamped with vehicle time and
returns a ``Pose`` in the local ENU frame (``rover_ctl.estimation.frame.LocalFrame``). docs/estimator.md has
the derivation, the tuning and the measured figures.

State ``x = [e, n, psi, v, b, c, k]``: east and north (m), ENU heading (rad, 0 east, CCW),
speed along the heading (m/s, negative when reversing), the gyro bias (rad/s, ENU sense), the
compass offset (rad: what the compass reads minus the true heading, a calibration residue of a
few degrees that only the GPS course can reveal) and the wheel scale (what the encoders count
per metre travelled: tyre radius error, wear, longitudinal slip on soft ground).

Motion model over ``dt`` with the latest gyro rate ``g`` (ENU) and ``w = g - b``, integrated at
the mid-point heading ``m = psi + w dt / 2``::

    e'   = e + v dt cos m          psi' = psi + w dt
    n'   = n + v dt sin m          v'   = v,   b' = b,   c' = c,   k' = k

ATTITUDE's yawspeed is the rate at its instant (ArduPilot's and the emulator's), held until the
next one; when that comes, the heading predicted over the gap ``T`` is corrected by
``(g_new - g_old) T / 2``, the trapezoid rule's share (a rover turning in and out of curves
changes its rate by tenths of a rad/s within a 40 ms gap, and the held rate lagged every change).
When no ATTITUDE came for ``attitude_timeout_s`` the turn rate is taken from the wheels instead,
``w = (d_right - d_left) / (k track dt)``: a skid-steer rover slips sideways in turns, so this
over-estimates the rate and is only a fallback. The process noise is
``Q = diag(s_lat^2, s_lat^2, s_gyro^2, s_acc^2, s_bias^2, s_comp^2, s_k^2) * dt`` (random
walks: sideways skid, gyro angle noise, speed change, gyro bias, compass offset and wheel scale
wander). Measurements (all linear but the wheels'):

* wheels: ``z = (d_left + d_right) / 2 / dt`` of two successive cumulative WHEEL_DISTANCE
  readings measures ``k v`` (H = [.., k, .., v]), with ``sigma = floor + slip * |z|``; the GPS
  speed and positions make ``k`` observable, which is what keeps dead reckoning honest when the
  tyres are not the size the encoders assume;
* compass (ATTITUDE yaw, NED -> ENU): measures ``psi + c``; the residual is wrapped to
  [-pi, pi);
* GPS: ``(e, n)`` of the fix measures the position with ``sigma = max(eph, floor)``;
* GPS course and speed over ground, while moving faster than ``gps_course_min_speed_mps``:
  measure ``psi`` (``psi + pi`` when reversing; a skid-steer rover does not crab) with
  ``sigma = atan(sigma_vel / speed)``, and ``|v|`` with ``sigma_vel``. The course is what makes
  the compass offset observable; the speed keeps ``v`` without wheel encoders (many ArduPilot
  rovers have none).

Why an EKF and not a UKF: the only nonlinearity is the heading in the position update, which is
mild over one 20 ms step (the linearisation error is O(v dt psi_err^2)); an EKF with the exact
Jacobian costs one 7x7 covariance product per prediction and a rank-one update per measurement
(each is a scalar, ``rover_ctl.estimation.ekf``), the UKF fifteen sigma points and an angle-aware
mean, for no accuracy a rover can see.

GPS gating and glitches: a fix is fused only if its innovation's Mahalanobis distance
``sqrt(y' S^-1 y)`` is within ``gate_sigma``. Rejected fixes leave the filter dead reckoning and
are judged over the run of rejections, by how the GPS moves against the odometry (EKF3 resets to
the GPS after a timeout; a rover has wheels that say whether it can have moved):

* a jump: the first rejected fix is beyond the gate from the running mean of the accepted
  innovations (time constant ``glitch_innovation_tau_s``) while fixes were being fused. While
  the following fixes keep the same offset (the GPS moves as the odometry does) it is a glitch:
  rejected, for up to ``glitch_max_s``, then believed. A second jump re-anchors the offset;
* a drift: the disagreement grew gradually (slipping wheels, a slide, a rover carried), arrived
  after an outage (dead reckoning drifted), or the offset of a jump started to drift: reset to
  the GPS once it has lasted ``glitch_reset_s``, since then the filter is the likelier wrong.

During a glitch a fix that passes the gate again is fused only if it is nearer the estimate than
the glitch offset (dead reckoning grows the covariance, which would let the glitch in).

Time: each reading carries vehicle time. ATTITUDE and WHEEL_DISTANCE drive the filter's clock:
a reading newer than the filter's time predicts the filter forward to it and is then fused. A
reading up to ``max_lag_s`` older (streams interleave: a fix may arrive after a newer wheel
reading) is fused at the filter's time, shifted by the motion over the lag (GPS by ``v * lag``
along the heading, compass and course by ``w * lag``); older ones are dropped. A reading no newer
than the last one of its own stream is a duplicate or out of order and is dropped; wheel
distances are cumulative, so the next delta covers a dropped one. GPS never moves the clock far:
a fix stamped more than ``gps_max_lead_s`` ahead (a UNIX-epoch stamp) is ignored. A reading more
than ``clock_restart_s`` behind the filter means the vehicle rebooted: the filter starts over.
``pose(at_s)`` gives the estimate at a time up to ``pose_max_lead_s`` after the filter's, its mean
predicted by the motion model without changing the filter (the control step's time is set by
whichever message came last, often not an odometry reading).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from rover_ctl.config import EstimatorParams
from rover_ctl.estimation.ekf import Ekf
from rover_ctl.estimation.frame import LocalFrame, compass_to_enu_rad, wrap_pi
from rover_ctl.estimation.readings import Attitude, GpsFix, WheelDistance

E, N, PSI, V, BIAS, COMPASS, SCALE = range(7)
_DIM = 7


class GpsVerdict(enum.Enum):
    """What ``PoseEstimator.on_gps`` did with a fix."""

    ACCEPTED = "accepted"
    """Fused into the filter."""
    REJECTED = "rejected"
    """Outside the innovation gate: treated as a glitch and not used."""
    RESET = "reset"
    """Set the position outright: the first fix, or after sustained disagreement."""
    IGNORED = "ignored"
    """No fix, a duplicate, or too old to use."""


@dataclass(frozen=True)
class Pose:
    """The estimate at ``time_s`` (vehicle time). Before initialisation every number is NaN and
    ``healthy`` and ``gps_ok`` are false."""

    time_s: float
    east_m: float
    north_m: float
    heading_rad: float
    """ENU: 0 east, counter-clockwise positive, in [-pi, pi)."""
    speed_mps: float
    yaw_rate_radps: float
    """ENU (counter-clockwise positive), gyro minus estimated bias."""
    cov: np.ndarray
    """3x3 covariance of (east_m, north_m, heading_rad)."""
    healthy: bool
    """Initialised and both position and heading 1-sigma within the health limits."""
    gps_ok: bool
    """A fix was fused within the last ``gps_timeout_s``."""
    position_sigma_m: float
    """1-sigma along the worst horizontal axis: sqrt of the largest eigenvalue of cov[:2, :2]."""
    heading_sigma_rad: float


@dataclass
class _Disagreement:
    """A run of rejected fixes: when it started, the GPS offset from the estimate since its last
    jump (mean innovation), and since when that offset has been drifting (None: it holds still,
    a glitch)."""

    start_s: float
    offset: np.ndarray
    drifting_since_s: float | None
    last: np.ndarray
    """The previous rejected fix's innovation (a second jump is measured from it)."""
    count: int = 1

    @property
    def is_jump(self) -> bool:
        return self.drifting_since_s is None


def _largest_eigenvalue_2x2(a: float, b: float, d: float) -> float:
    """Of the symmetric matrix [[a, b], [b, d]]."""
    return float(0.5 * (a + d) + math.hypot(0.5 * (a - d), b))


def _mahalanobis2(y: np.ndarray, cov: np.ndarray) -> float:
    """``y' S^-1 y`` for a 2-vector ``y`` (2 x 1) and a symmetric positive definite 2 x 2 ``S``,
    in closed form: ``(d y0^2 - 2 b y0 y1 + a y1^2) / (a d - b^2)`` for ``S = [[a, b], [b, d]]``."""
    return _mahalanobis2_floats(y.item(0), y.item(1), cov.item(0, 0), cov.item(0, 1), cov.item(1, 1))


def _mahalanobis2_floats(y0: float, y1: float, a: float, b: float, d: float) -> float:
    """``_mahalanobis2`` on plain numbers: ``y = (y0, y1)``, ``S = [[a, b], [b, d]]``."""
    return (d * y0 * y0 - 2.0 * b * y0 * y1 + a * y1 * y1) / (a * d - b * b)


def motion_model(
    x: np.ndarray, dt_s: float, gyro_radps: float, jacobian: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """State ``x`` (7x1) propagated ``dt_s`` with the gyro rate ``gyro_radps`` (ENU), and the
    Jacobian ``F = d x' / d x``: the identity but for

        dE/dpsi = -v dt sin m      dE/dv = dt cos m      dE/db =  v dt^2 sin(m) / 2
        dN/dpsi =  v dt cos m      dN/dv = dt sin m      dN/db = -v dt^2 cos(m) / 2
        dpsi/db = -dt

    (``m`` the mid-point heading; ``d m / d b = -dt / 2``). ``jacobian``: a 7x7 buffer to write
    ``F`` into instead of a new array (the estimator's, reused at every prediction); only these
    seven entries are written, so it must hold the identity everywhere else, as it does when it
    starts as ``np.eye(7)`` and is only ever passed here."""
    psi, v, bias = x.item(PSI), x.item(V), x.item(BIAS)
    w = gyro_radps - bias
    mid = psi + 0.5 * w * dt_s
    c, s = math.cos(mid), math.sin(mid)
    out = x.copy()
    out[E, 0] += v * dt_s * c
    out[N, 0] += v * dt_s * s
    out[PSI, 0] = wrap_pi(psi + w * dt_s)
    jac = np.eye(_DIM) if jacobian is None else jacobian
    jac[E, PSI] = -v * dt_s * s
    jac[E, V] = dt_s * c
    jac[E, BIAS] = 0.5 * v * dt_s * dt_s * s  # d mid / d b = -dt/2
    jac[N, PSI] = v * dt_s * c
    jac[N, V] = dt_s * s
    jac[N, BIAS] = -0.5 * v * dt_s * dt_s * c
    jac[PSI, BIAS] = -dt_s
    return out, jac


def _unit_row(*components: int) -> np.ndarray:
    """A linear scalar measurement's Jacobian row (h(x) = h x): ones at ``components``. Read-only:
    shared by every estimator."""
    h = np.zeros(_DIM)
    h[list(components)] = 1.0
    h.flags.writeable = False
    return h


_H_E = _unit_row(E)
_H_N = _unit_row(N)
_H_PSI = _unit_row(PSI)
_H_V = _unit_row(V)
_H_COMPASS = _unit_row(PSI, COMPASS)
_EYE2 = np.eye(2)


class PoseEstimator:
    """The rover's pose from wheels, gyro, compass and GPS (see the module docstring)."""

    def __init__(self, frame: LocalFrame, params: EstimatorParams, track_m: float | Callable[[], float]) -> None:
        """``params`` is read at every reading; ``track_m`` may be a function giving the track in
        force, so that a changed parameter applies at the next reading."""
        self._track_m = track_m if callable(track_m) else (lambda: track_m)
        if not self.track_m > 0.0:
            raise ValueError(f"PoseEstimator: track_m must be positive, got {self.track_m!r}")
        self.frame = frame
        self.params = params
        self._clear()

    @property
    def track_m(self) -> float:
        return self._track_m()

    def _clear(self) -> None:
        """Forget everything: the state before the first reading."""
        self._kf = Ekf(_DIM)
        self._jacobian = np.eye(_DIM)
        """The motion model's Jacobian, rewritten in place at every prediction."""
        self._h_wheels = np.zeros(_DIM)
        """The wheel speed's Jacobian row, rewritten in place at every wheel reading."""
        self._q_densities: tuple[float, ...] | None = None
        self._q_per_s = np.zeros((_DIM, _DIM))
        self._time_s = -math.inf
        self._initialised = False
        self._gyro_radps = 0.0
        self._wheel_turn_radps = 0.0
        self._last_wheel: WheelDistance | None = None
        self._last_attitude_s = -math.inf
        self._last_gps_s = -math.inf
        self._gps_fused_s = -math.inf
        self._disagreement: _Disagreement | None = None
        self._innovation_mean = np.zeros((2, 1))
        """Running mean of the accepted fixes' innovations: what a jump is measured from."""
        self._pending_fix: tuple[float, float, float] | None = None  # east, north, sigma
        self._pending_heading: float | None = None

    # ----------------------------------------------------------------------------- state access
    @property
    def initialised(self) -> bool:
        """True once a GPS fix and a compass heading have both arrived."""
        return self._initialised

    def pose(self, at_s: float | None = None) -> Pose:
        """The current estimate (NaNs and unhealthy before initialisation).

        ``at_s``: the time it is wanted for (vehicle time). When that is after the filter's own
        time by at most ``pose_max_lead_s``, the mean is predicted there by the motion model (the
        speed and turn rate held, the covariance the filter's own); otherwise it is the filter's
        time. Odometry slower than the control step (a 25 Hz stream, 10 Hz on a 57600 baud
        radio) leaves the filter behind whenever a rangefinder or GPS message sets the step's
        time: at 1 rad/s, 40 ms behind is 2.3 degrees of heading."""
        if not self._initialised:
            nan = math.nan
            return Pose(self._time_s, nan, nan, nan, nan, nan, np.full((3, 3), nan), False, False, nan, nan)
        east_m, north_m, heading_rad, speed_mps, bias = self._kf.x[:5, 0].tolist()
        time_s = float(self._time_s)
        rate_input_radps = self._rate_input_radps(time_s)
        yaw_rate_radps = rate_input_radps - bias
        params = self.params
        if at_s is not None and 0.0 < at_s - time_s <= params.pose_max_lead_s:
            # The mean only; the Jacobian buffer is scratch, rewritten at every prediction.
            ahead, _ = motion_model(self._kf.x, at_s - time_s, rate_input_radps, self._jacobian)
            east_m, north_m, heading_rad = ahead.item(E), ahead.item(N), ahead.item(PSI)
            time_s = float(at_s)
        cov = self._kf.P[:3, :3].copy()
        var_e, cov_en, var_psi, var_n = cov.item(0, 0), cov.item(0, 1), cov.item(2, 2), cov.item(1, 1)
        position_sigma_m = math.sqrt(max(_largest_eigenvalue_2x2(var_e, cov_en, var_n), 0.0))
        heading_sigma_rad = math.sqrt(max(var_psi, 0.0))
        healthy = (
            position_sigma_m <= params.health_max_position_sigma_m and heading_sigma_rad <= params.health_max_heading_sigma_rad
        )
        return Pose(
            time_s=time_s,
            east_m=east_m,
            north_m=north_m,
            heading_rad=heading_rad,
            speed_mps=speed_mps,
            yaw_rate_radps=yaw_rate_radps,
            cov=cov,
            healthy=bool(healthy),
            gps_ok=bool(time_s - self._gps_fused_s <= params.gps_timeout_s),
            position_sigma_m=position_sigma_m,
            heading_sigma_rad=heading_sigma_rad,
        )

    # ------------------------------------------------------------------------------- readings
    def on_wheels(self, r: WheelDistance) -> None:
        """Cumulative wheel distances: the speed measurement is their mean rate since the last."""
        self._check_clock(r.time_s)
        last = self._last_wheel
        if last is not None and r.time_s <= last.time_s:
            return
        if not (math.isfinite(r.left_m) and math.isfinite(r.right_m)):
            return
        self._last_wheel = r
        if last is None:
            return
        dt_s = r.time_s - last.time_s
        speed_mps = ((r.left_m - last.left_m) + (r.right_m - last.right_m)) / 2.0 / dt_s
        turn_radps = ((r.right_m - last.right_m) - (r.left_m - last.left_m)) / self.track_m / dt_s
        wheel_rate = max(abs(r.left_m - last.left_m), abs(r.right_m - last.right_m)) / dt_s
        if wheel_rate > self.params.wheel_max_speed_mps:
            return  # counter reset or glitch: r is the new baseline
        self._wheel_turn_radps = turn_radps
        if not self._advance(r.time_s):
            return
        sigma = self.params.wheel_speed_sigma_mps + self.params.wheel_slip_fraction * abs(speed_mps)
        kf = self._kf
        v, k = kf.x.item(V), kf.x.item(SCALE)
        h = self._h_wheels  # d(k v)/dx: k at v, v at k, zero elsewhere
        h[V], h[SCALE] = k, v
        kf.update_scalar(speed_mps - k * v, h, sigma * sigma)

    def on_attitude(self, r: Attitude) -> None:
        """Gyro rate for the prediction from now on, and the compass heading as a measurement."""
        if not (math.isfinite(r.yaw_rad) and math.isfinite(r.yaw_rate_radps)):
            return
        self._check_clock(r.time_s)
        if r.time_s <= self._last_attitude_s:
            return
        previous_s, self._last_attitude_s = self._last_attitude_s, r.time_s
        heading_rad = compass_to_enu_rad(r.yaw_rad)
        if not self._initialised:
            self._gyro_radps = -r.yaw_rate_radps
            self._pending_heading = heading_rad
            self._time_s = max(self._time_s, r.time_s)
            self._try_initialise()
            return
        held_radps = self._gyro_radps
        if not self._advance(r.time_s):
            return
        self._gyro_radps = -r.yaw_rate_radps  # NED clockwise -> ENU counter-clockwise
        kf = self._kf
        gap_s = r.time_s - previous_s
        if r.time_s >= self._time_s and 0.0 < gap_s <= self.params.attitude_timeout_s:
            # The gap was predicted with the rate held from its start; the rate at its end says
            # how it changed meanwhile: the trapezoid's half of the difference.
            kf.x[PSI, 0] += 0.5 * (self._gyro_radps - held_radps) * gap_s
        lag_s = self._time_s - r.time_s
        z = wrap_pi(heading_rad + (self._gyro_radps - kf.x.item(BIAS)) * lag_s)
        sigma = self.params.compass_sigma_rad
        kf.update_scalar(wrap_pi(z - (kf.x.item(PSI) + kf.x.item(COMPASS))), _H_COMPASS, sigma * sigma)
        kf.x[PSI, 0] = wrap_pi(kf.x.item(PSI))

    def on_gps(self, r: GpsFix) -> GpsVerdict:
        """Fuse, reject (gate) or reset to a fix; see the module docstring."""
        if not r.has_fix:
            return GpsVerdict.IGNORED
        self._check_clock(r.time_s)
        if r.time_s <= self._last_gps_s:
            return GpsVerdict.IGNORED
        if math.isfinite(self._time_s) and r.time_s - self._time_s > self.params.gps_max_lead_s:
            return GpsVerdict.IGNORED
        self._last_gps_s = r.time_s
        east_m, north_m = self.frame.to_enu(r.lat_deg, r.lon_deg)
        eph_m = r.eph_m if math.isfinite(r.eph_m) else self.params.gps_default_sigma_m
        sigma_m = max(eph_m, self.params.gps_min_sigma_m)
        if not self._initialised:
            self._pending_fix = (east_m, north_m, sigma_m)
            self._gps_fused_s = r.time_s
            self._try_initialise()
            return GpsVerdict.RESET
        if not self._advance(r.time_s):
            return GpsVerdict.IGNORED
        kf = self._kf
        x_e, x_n, psi, v = kf.x[:4, 0].tolist()
        lag_s = self._time_s - r.time_s
        z_e, z_n = east_m + v * lag_s * math.cos(psi), north_m + v * lag_s * math.sin(psi)
        var = sigma_m * sigma_m
        innovation = np.array([[z_e - x_e], [z_n - x_n]])
        s_cov = kf.P[:2, :2] + var * _EYE2
        distance2 = _mahalanobis2(innovation, s_cov)
        glitch = self._disagreement
        if distance2 <= self.params.gate_sigma**2 and not (
            glitch is not None and glitch.is_jump and _mahalanobis2(innovation - glitch.offset, s_cov) < distance2
        ):
            tracking = self._time_s - self._gps_fused_s <= self.params.gps_timeout_s
            # (e, n) with R = var I, one after the other: the same as fusing them together
            kf.update_scalar(z_e - x_e, _H_E, var)
            kf.update_scalar(z_n - kf.x.item(N), _H_N, var)
            self._disagreement = None
            alpha = 1.0 - math.exp(-(self._time_s - self._gps_fused_s) / self.params.glitch_innovation_tau_s)
            self._innovation_mean = self._innovation_mean + alpha * (innovation - self._innovation_mean) if tracking else innovation
            self._gps_fused_s = self._time_s
            verdict = GpsVerdict.ACCEPTED
        elif self._judge_rejection(r.time_s, innovation, s_cov):
            self._reset_position(np.array([[z_e], [z_n]]), var * _EYE2)
            verdict = GpsVerdict.RESET
        else:
            verdict = GpsVerdict.REJECTED
        self._fuse_velocity(r, lag_s)
        return verdict

    def _judge_rejection(self, time_s: float, innovation: np.ndarray, s_cov: np.ndarray) -> bool:
        """Follow a run of rejected fixes (see the module docstring); True: reset to this fix."""
        p = self.params
        gate2 = p.gate_sigma**2
        glitch = self._disagreement
        if glitch is None:
            tracking = self._time_s - self._gps_fused_s <= p.gps_timeout_s
            jump = tracking and _mahalanobis2(innovation - self._innovation_mean, s_cov) > gate2
            self._disagreement = _Disagreement(time_s, innovation, None if jump else time_s, innovation)
            return False
        if _mahalanobis2(innovation - glitch.last, s_cov) > gate2:  # a new jump: re-anchor
            glitch.offset, glitch.count, glitch.drifting_since_s = innovation, 1, None
        elif glitch.drifting_since_s is None and _mahalanobis2(innovation - glitch.offset, s_cov) > gate2:
            glitch.drifting_since_s = time_s  # the GPS moves unlike the odometry
        elif glitch.drifting_since_s is None:
            glitch.count += 1
            glitch.offset = glitch.offset + (innovation - glitch.offset) / glitch.count
        glitch.last = innovation
        if glitch.drifting_since_s is not None:
            return time_s - glitch.drifting_since_s >= p.glitch_reset_s
        return time_s - glitch.start_s >= p.glitch_max_s

    # -------------------------------------------------------------------------------- internals
    def _check_clock(self, time_s: float) -> None:
        """A reading far older than the filter means the vehicle's clock restarted (a reboot):
        start over rather than drop every reading from now on."""
        if self._time_s - time_s > self.params.clock_restart_s:
            self._clear()

    def _fuse_velocity(self, r: GpsFix, lag_s: float) -> None:
        """GPS course and speed over ground as heading and speed measurements, when moving fast
        enough for the course to mean something (slower, noise dominates both). Gated on their
        own, as EKF3 gates velocity apart from position: a position glitch leaves the velocity
        good, and it keeps the heading and speed honest while the position dead reckons."""
        p = self.params
        if not (math.isfinite(r.course_deg) and math.isfinite(r.speed_mps)) or r.speed_mps < p.gps_course_min_speed_mps:
            return
        kf = self._kf
        psi, v, bias = kf.x.item(PSI), kf.x.item(V), kf.x.item(BIAS)
        track_rad = compass_to_enu_rad(math.radians(r.course_deg))
        speed_mps = r.speed_mps
        if v < 0.0:  # reversing: the rover points against its track
            track_rad += math.pi
            speed_mps = -speed_mps
        z_psi = wrap_pi(track_rad + (self._rate_input_radps(self._time_s) - bias) * lag_s)
        course_var = math.atan2(p.gps_velocity_sigma_mps, r.speed_mps) ** 2
        speed_var = p.gps_velocity_sigma_mps**2
        y_psi, y_v = wrap_pi(z_psi - psi), speed_mps - v
        cov = kf.P
        distance2 = _mahalanobis2_floats(y_psi, y_v, cov.item(PSI, PSI) + course_var, cov.item(PSI, V), cov.item(V, V) + speed_var)
        if distance2 > p.gate_sigma**2:
            return  # a velocity glitch, or crabbing (a slide) the model has no state for
        # course and speed (R diagonal), one after the other: the same as fusing them together
        kf.update_scalar(y_psi, _H_PSI, course_var)
        kf.update_scalar(speed_mps - kf.x.item(V), _H_V, speed_var)
        kf.x[PSI, 0] = wrap_pi(kf.x.item(PSI))

    def _advance(self, time_s: float) -> bool:
        """Predict forward to ``time_s`` if it is newer; False if it is too old to use."""
        if not self._initialised:
            return False
        dt_s = time_s - self._time_s
        if dt_s <= 0.0:
            return -dt_s <= self.params.max_lag_s
        x, jacobian = motion_model(self._kf.x, dt_s, self._rate_input_radps(time_s), self._jacobian)
        self._kf.predict(x, jacobian, self._process_noise_density() * dt_s)
        self._time_s = time_s
        return True

    def _process_noise_density(self) -> np.ndarray:
        """``Q / dt = diag(s_lat^2, s_lat^2, s_gyro^2, s_acc^2, s_bias^2, s_comp^2, s_k^2)`` from the
        parameters in force, rebuilt only when one of them changed."""
        p = self.params
        densities = (
            p.lateral_slip_per_sqrt_s,
            p.gyro_noise_rad_per_sqrt_s,
            p.speed_accel_per_sqrt_s,
            p.gyro_bias_walk_radps_per_sqrt_s,
            p.compass_offset_walk_rad_per_sqrt_s,
            p.wheel_scale_walk_per_sqrt_s,
        )
        if densities != self._q_densities:
            lat, gyro, acc, bias, comp, scale = densities
            self._q_per_s = np.diag([lat**2, lat**2, gyro**2, acc**2, bias**2, comp**2, scale**2])
            self._q_densities = densities
        return self._q_per_s

    def _rate_input_radps(self, time_s: float) -> float:
        """The gyro rate, or without a recent gyro the wheels' turn rate plus the bias estimate
        (the model subtracts the bias, which only the gyro has)."""
        if time_s - self._last_attitude_s <= self.params.attitude_timeout_s:
            return self._gyro_radps
        return self._wheel_turn_radps / self._kf.x.item(SCALE) + self._kf.x.item(BIAS)

    def _try_initialise(self) -> None:
        if self._pending_fix is None or self._pending_heading is None:
            return
        east_m, north_m, sigma_m = self._pending_fix
        p = self.params
        self._kf.x = np.array([[east_m], [north_m], [self._pending_heading], [0.0], [0.0], [0.0], [1.0]])
        # Speed unknown until the next wheel reading: any plausible speed. The heading is the
        # compass reading, so its error is the unknown offset (plus noise) and the offset's
        # error is minus that offset: correlated -1.
        offset_var = p.compass_offset_sigma0_rad**2
        self._kf.P = np.diag(
            [
                sigma_m**2,
                sigma_m**2,
                p.compass_sigma_rad**2 + offset_var,
                p.wheel_max_speed_mps**2,
                p.gyro_bias_sigma0_radps**2,
                offset_var,
                p.wheel_scale_sigma0**2,
            ]
        )
        self._kf.P[PSI, COMPASS] = self._kf.P[COMPASS, PSI] = -offset_var
        self._initialised = True

    def _reset_position(self, z: np.ndarray, r_cov: np.ndarray) -> None:
        """Position := the fix, uncorrelated with the rest of the state."""
        self._kf.x[E:N + 1] = z
        self._kf.P[:2, :] = 0.0
        self._kf.P[:, :2] = 0.0
        self._kf.P[:2, :2] = r_cov
        self._disagreement = None
        self._innovation_mean = np.zeros((2, 1))
        self._gps_fused_s = self._time_s
