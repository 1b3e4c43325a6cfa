"""Skid-steer drive physics: electrical drive -> DC motors -> differential-drive kinematics.

Per side (left, right), with motor voltage V, armature current i, wheel speed w (rad/s), gear ratio
N (motor speed N w)::

    L di/dt = V - R i - Ke N w                          armature circuit
    M dw/dt = N Kt i - N^2 b w                          rotors, wheels and body, at the wheels

The wheels are coupled through the body (rigid, no lateral slip): with v = r (wl + wr) / 2 and
yaw rate r (wr - wl) / track, the kinetic energy of body and drive gives the wheel-space inertia::

    M = (J_wheel + N^2 J_rotor) I + m r^2 / 4 [[1, 1], [1, 1]] + I_z r^2 / track^2 [[1, -1], [-1, 1]]

so the robot's mass loads both motors together and its yaw inertia loads them in opposition.
The linear system x' = A x + B u, x = (i_l, i_r, w_l, w_r), is discretised exactly for a
zero-order-hold voltage over the fixed substep (matrix exponential), so the stiff electrical pole
(L/R = 0.5 ms) is integrated stably at any substep.

Why no combination of parameters in range (``sitl.params.LIMITS``) can give NaN: A is stable for
every R, L, Ke, Kt, N > 0, b >= 0 and M positive definite (M is: its eigenvalues are J_wheel +
N^2 J_rotor plus m r^2 / 2 > 0, or plus 2 I_z r^2 / track^2 > 0). M's eigenvectors (1, 1) and
(1, -1) split the drive into a straight and a turning mode, each ``L i' = -R i - Ke N w + V``,
``m w' = N Kt i - N^2 b w`` with m > 0 that mode's inertia, whose characteristic polynomial
s^2 + (R/L + N^2 b/m) s + N^2 (R b + Ke Kt) / (L m) has positive coefficients: both poles are in
the left half-plane, so exp(A dt) has spectral radius below 1 for every dt > 0. Unlike an explicit
integrator, the step needs no bound for stability. What can fail is floating point: at
L = 1e-300 H, R/L dt overflowed and the exponential came out NaN. The ranges keep every entry of
A dt below 1e12, where scipy's scaling and squaring stays finite; ``drive_inconsistency`` checks
the result at start (finite, spectral radius at most 1 + DECAY_TOLERANCE) and a test sweeps every
corner of the ranges. The pose is integrated on the ground plane
(east/north metres, yaw counter-clockwise from east) with the mid-step heading; wheel slip scales
the ground motion by (1 - slip) while the wheels (and encoders) turn as driven.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import expm

from sitl.params import MotorParams, RobotParams


def wheel_inertia_matrix(motor: MotorParams, robot: RobotParams) -> np.ndarray:
    """The 2x2 inertia seen at the wheels (kg m^2), M in the module docstring."""
    r, track = robot.wheel_radius_m, robot.track_m
    own = robot.wheel_inertia_kgm2 + motor.gear_ratio**2 * motor.rotor_inertia_kgm2
    translation = robot.mass_kg * r * r / 4.0
    rotation = robot.yaw_inertia * r * r / (track * track)
    return np.array([[own + translation + rotation, translation - rotation],
                     [translation - rotation, own + translation + rotation]])


def straight_time_constant_s(motor: MotorParams, robot: RobotParams) -> float:
    """Closed-form mechanical time constant of a straight-line voltage step (L/R neglected)."""
    n2 = motor.gear_ratio**2
    inertia = robot.wheel_inertia_kgm2 + n2 * motor.rotor_inertia_kgm2 + robot.mass_kg * robot.wheel_radius_m**2 / 2.0
    return inertia * motor.resistance_ohm / (
        n2 * (motor.resistance_ohm * motor.viscous_nms_per_rad + motor.kt_nm_per_a * motor.ke_v_per_radps))


DECAY_TOLERANCE = 1e-9
"""How far above 1 the discretised drive's spectral radius may come out in floating point (the
exact value is below 1): a growth of 1e-9 per substep takes 7e8 substeps, 8 days at 1 ms, to double."""


def discretise(motor: MotorParams, robot: RobotParams, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(A_d, B_d): the exact zero-order-hold discretisation of the drive over ``dt_s``."""
    n, L, R = motor.gear_ratio, motor.inductance_h, motor.resistance_ohm
    m_inv = np.linalg.inv(wheel_inertia_matrix(motor, robot))
    a = np.zeros((4, 4))
    a[0:2, 0:2] = -R / L * np.eye(2)
    a[0:2, 2:4] = -motor.ke_v_per_radps * n / L * np.eye(2)
    a[2:4, 0:2] = m_inv * n * motor.kt_nm_per_a
    a[2:4, 2:4] = -m_inv * n * n * motor.viscous_nms_per_rad
    b = np.zeros((4, 2))
    b[0:2, 0:2] = np.eye(2) / L
    augmented = np.zeros((6, 6))
    augmented[:4, :4], augmented[:4, 4:] = a, b
    phi = expm(augmented * dt_s)
    return phi[:4, :4], phi[:4, 4:]


def drive_inconsistency(motor: MotorParams, robot: RobotParams, dt_s: float) -> str | None:
    """Why the drive cannot be stepped with these parameters (its discretisation is not finite or
    does not decay), or None. Within ``sitl.params.LIMITS`` it never says so (module docstring)."""
    with np.errstate(all="ignore"):
        try:
            ad, bd = discretise(motor, robot, dt_s)
        except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
            return f"the motor.* and robot.* fields cannot be discretised with physics_dt_s {dt_s:g} s: {exc}"
        finite = bool(np.all(np.isfinite(ad)) and np.all(np.isfinite(bd)))
        radius = float(np.max(np.abs(np.linalg.eigvals(ad)))) if finite else math.nan
    if not finite or not radius <= 1.0 + DECAY_TOLERANCE:
        return (f"the motor.* and robot.* fields with physics_dt_s {dt_s:g} s give a drive that does not decay "
                f"in floating point (substep spectral radius {radius:g})")
    return None


class DriveTrain:
    """The two motors, the wheels and the body pose, advanced in fixed substeps of ``dt_s``."""

    def __init__(self, motor: MotorParams, robot: RobotParams, dt_s: float, yaw_rad: float = 0.0) -> None:
        self.motor = motor
        self.robot = robot
        self.dt_s = dt_s
        ad, self._bd = discretise(motor, robot, dt_s)
        # Plain tuples: the substep loop runs on Python floats (numpy scalars are slower here).
        self._ad = tuple(tuple(float(v) for v in row) for row in ad)
        self._forced = (0.0, 0.0, 0.0, 0.0)
        self.current_l_a = self.current_r_a = 0.0
        self.wheel_l_radps = self.wheel_r_radps = 0.0
        self.volts_l = self.volts_r = 0.0
        self.east_m = self.north_m = 0.0
        self.yaw_rad = yaw_rad
        """Heading counter-clockwise from east (ENU)."""
        self.angle_l_rad = self.angle_r_rad = 0.0
        """Cumulative wheel rotation."""
        self.slip = 0.0
        """Fraction of the wheels' rolling lost to slip (0 = none)."""

    def pwm_to_volts(self, pwm_us: float) -> float:
        """Motor voltage for a PWM width, clamped to the battery: (pwm - 1500) / 500 * V_batt."""
        m = self.motor
        duty = max(-1.0, min(1.0, (pwm_us - m.pwm_neutral_us) / m.pwm_range_us))
        return duty * m.battery_v

    def set_volts(self, left_v: float, right_v: float) -> None:
        self.volts_l, self.volts_r = left_v, right_v
        self._forced = tuple(float(v) for v in self._bd @ np.array([left_v, right_v]))

    def stop_wheels(self) -> None:
        """An impact: the body (and so the wheels) stops dead."""
        self.wheel_l_radps = self.wheel_r_radps = 0.0

    @property
    def speed_mps(self) -> float:
        """Signed forward ground speed."""
        return (1.0 - self.slip) * self.robot.wheel_radius_m * (self.wheel_l_radps + self.wheel_r_radps) / 2.0

    @property
    def yaw_rate_radps(self) -> float:
        """Ground yaw rate, counter-clockwise positive (ENU)."""
        return (1.0 - self.slip) * self.robot.wheel_radius_m * (self.wheel_r_radps - self.wheel_l_radps) / self.robot.track_m

    def advance(self, steps: int) -> None:
        """Advance ``steps`` substeps with the voltages held."""
        (a00, a01, a02, a03), (a10, a11, a12, a13), (a20, a21, a22, a23), (a30, a31, a32, a33) = self._ad
        f0, f1, f2, f3 = self._forced
        il, ir, wl, wr = self.current_l_a, self.current_r_a, self.wheel_l_radps, self.wheel_r_radps
        x, y, yaw, al, ar = self.east_m, self.north_m, self.yaw_rad, self.angle_l_rad, self.angle_r_rad
        dt = self.dt_s
        ground = (1.0 - self.slip) * self.robot.wheel_radius_m
        track = self.robot.track_m
        for _ in range(steps):
            nil = a00 * il + a01 * ir + a02 * wl + a03 * wr + f0
            nir = a10 * il + a11 * ir + a12 * wl + a13 * wr + f1
            nwl = a20 * il + a21 * ir + a22 * wl + a23 * wr + f2
            nwr = a30 * il + a31 * ir + a32 * wl + a33 * wr + f3
            # Trapezoidal wheel speeds over the substep, mid-step heading for the pose.
            ml, mr = (wl + nwl) * 0.5, (wr + nwr) * 0.5
            al += ml * dt
            ar += mr * dt
            v = ground * (ml + mr) * 0.5
            dyaw = ground * (mr - ml) / track * dt
            heading = yaw + dyaw * 0.5
            x += v * dt * math.cos(heading)
            y += v * dt * math.sin(heading)
            yaw += dyaw
            il, ir, wl, wr = nil, nir, nwl, nwr
        self.current_l_a, self.current_r_a, self.wheel_l_radps, self.wheel_r_radps = il, ir, wl, wr
        self.east_m, self.north_m, self.angle_l_rad, self.angle_r_rad = x, y, al, ar
        self.yaw_rad = math.remainder(yaw, 2.0 * math.pi)
