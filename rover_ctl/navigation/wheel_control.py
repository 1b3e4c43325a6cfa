"""Wheel-speed control: left/right wheel rpm setpoints -> RC steering/throttle PWM.

Pure (no I/O, no clock: the caller passes the vehicle-time step). Three pieces:

``WheelSpeedMeter``
    wheel speeds from WHEEL_DISTANCE deltas, ``rpm = 60 * (d_m / dt_s) / (2 pi r)``, smoothed by a
    first-order low-pass with time constant ``speed_filter_tau_s``, and their rate of change
    ``a`` (rpm/s, the filtered speed's change over the latest reading interval). The filtered
    speed is late: a delta gives the mean speed over its interval ``h``, the speed ``h / 2``
    before the reading, and the low-pass ``s += alpha (x - s)``, ``alpha = h / (tau + h)``, lags
    a ramp by ``h (1 - alpha) / alpha = tau``. So ``s + a (tau + h / 2)`` is the speed at the
    reading's time while it changes at a steady rate (``lag_corrected``).
``WheelController``
    per wheel a PI loop with feed-forward on the motor output ``u`` in [-1, 1]:
    ``u = rpm_set / full_output_rpm + kp e + I``, ``I += ki e dt`` only while that does not push a
    saturated output further and while the filtered speed changes slower than
    ``integrate_max_rate_rpm_s`` (conditional-integration anti-windup: in a speed change the error
    is the drive train's lag, and integrating it made a slow-down to a crawl overshoot into
    reverse), ``|I| <= integral_limit``.
    Without a fresh measurement it runs on feed-forward alone. ``brake`` stops the wheels: the
    same loop with a zero setpoint on the lag-corrected speeds, each wheel let go (output 0, its
    integrator cleared) once its speed is below ``brake_release_rpm`` or past zero. On the
    filtered speed alone the brake stayed on after the wheels stopped and drove them backwards:
    0.09 m/s after a stop from 1.2 m/s with readings at 25 Hz, where the filtered speed is 80 ms
    late plus the reading's age at the step.
``motors_to_rc`` / ``rc_to_motors``
    the inverse of ArduPilot's skid-steer mixer (AP_MotorsUGV::output_skid_steering) and the mixer
    itself for checking. The vehicle reads steering s and throttle t in [-1, 1] from PWM with a
    dead zone of ``dz`` around trim, ``x = (|pwm - trim| - dz) / (range - dz)``, truncated to its
    integer units (centidegrees of 4500 for steering, percent for throttle); when
    ``|s| + |t| > 1`` both are scaled by ``1 / (|s| + |t|)`` (MOT_STR_THR_MIX = 0.5); then
    ``left = t + s``, ``right = t - s``. The inverse is ``t = (l + r) / 2``, ``s = (l - r) / 2``;
    with ``|l|, |r| <= 1`` it follows ``|s| + |t| = max(|l|, |r|) <= 1``, so the vehicle never
    saturates what we send.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from rover_ctl.config import WheelControlParams
from rover_ctl.estimation.readings import WheelDistance

STEERING_UNITS = 4500
"""ArduPilot's steering control_in full scale (centidegrees)."""
THROTTLE_UNITS = 100
"""ArduPilot's throttle control_in full scale (percent)."""


def _to_pwm(x: float, params: WheelControlParams) -> int:
    """Normalised input in [-1, 1] -> PWM that the vehicle's dead-zoned RC input reads as ``x``."""
    x = max(-1.0, min(1.0, x))
    if x == 0.0:
        return params.rc_trim_us
    span = params.rc_range_us - params.rc_deadzone_us
    return params.rc_trim_us + int(math.copysign(round(params.rc_deadzone_us + abs(x) * span), x))


def _from_pwm(pwm: int, units: int, params: WheelControlParams) -> float:
    """The vehicle's reading of a PWM value: dead zone around trim, integer control units."""
    offset = pwm - params.rc_trim_us
    if abs(offset) <= params.rc_deadzone_us:
        return 0.0
    span = params.rc_range_us - params.rc_deadzone_us
    magnitude = min(abs(offset), params.rc_range_us) - params.rc_deadzone_us
    return math.copysign(int(units * magnitude / span) / units, offset)


def motors_to_rc(left: float, right: float, params: WheelControlParams) -> tuple[int, int]:
    """Motor outputs ``left, right`` in [-1, 1] -> (steering_us, throttle_us) for RC ch1 and ch3."""
    left = max(-1.0, min(1.0, left))
    right = max(-1.0, min(1.0, right))
    return _to_pwm((left - right) / 2.0, params), _to_pwm((left + right) / 2.0, params)


def rc_to_motors(steering_us: int, throttle_us: int, params: WheelControlParams) -> tuple[float, float]:
    """ArduPilot's skid-steer mixer (MANUAL mode, MOT_STR_THR_MIX 0.5): PWM in -> motor outputs."""
    steering = _from_pwm(steering_us, STEERING_UNITS, params)
    throttle = _from_pwm(throttle_us, THROTTLE_UNITS, params)
    saturation = abs(steering) + abs(throttle)
    if saturation > 1.0:
        steering /= saturation
        throttle = math.copysign(min(abs(throttle), 1.0 - abs(steering)), throttle)
    return throttle + steering, throttle - steering


class WheelSpeedMeter:
    """Low-passed wheel speeds (rpm) from cumulative WHEEL_DISTANCE readings."""

    def __init__(self, wheel_radius_m: float | Callable[[], float], params: WheelControlParams):
        self._radius_m = wheel_radius_m if callable(wheel_radius_m) else (lambda: wheel_radius_m)
        self.params = params
        self._last: WheelDistance | None = None
        self.left_rpm = 0.0
        self.right_rpm = 0.0
        self.left_rate_rpm_s = 0.0
        self.right_rate_rpm_s = 0.0
        """Change of the filtered speeds per second over the latest reading interval."""
        self.interval_s = 0.0
        """The latest reading interval (vehicle time)."""
        self.time_s: float | None = None
        """Vehicle time of the latest reading used, None before two readings."""

    def update(self, reading: WheelDistance) -> None:
        last, self._last = self._last, reading
        if last is None:
            return
        dt_s = reading.time_s - last.time_s
        if dt_s <= 0.0:
            self._last = last  # a repeated or out-of-order reading carries no speed
            return
        to_rpm = 60.0 / (2.0 * math.pi * self._radius_m() * dt_s)
        alpha = dt_s / (self.params.speed_filter_tau_s + dt_s)
        d_left = alpha * ((reading.left_m - last.left_m) * to_rpm - self.left_rpm)
        d_right = alpha * ((reading.right_m - last.right_m) * to_rpm - self.right_rpm)
        self.left_rpm += d_left
        self.right_rpm += d_right
        self.left_rate_rpm_s, self.right_rate_rpm_s = d_left / dt_s, d_right / dt_s
        self.interval_s = dt_s
        self.time_s = reading.time_s

    def lag_corrected(self) -> tuple[float, float]:
        """(left, right) rpm at the latest reading's time, the filter's and the delta's lag taken
        out (module docstring). Extrapolated further, to the control step's time, it let the
        brake go early: the deceleration falls with the speed."""
        lag_s = self.params.speed_filter_tau_s + self.interval_s / 2.0
        return self.left_rpm + self.left_rate_rpm_s * lag_s, self.right_rpm + self.right_rate_rpm_s * lag_s


@dataclass(frozen=True)
class WheelCommand:
    steering_us: int
    throttle_us: int
    left_out: float
    right_out: float
    """Motor outputs in [-1, 1] before mixing."""


class _PiWheel:
    def __init__(self, params: WheelControlParams):
        self.params = params
        self.integral = 0.0

    def step(self, setpoint_rpm: float, measured_rpm: float | None, dt_s: float, rate_rpm_s: float = 0.0) -> float:
        """Motor output for ``setpoint_rpm``; ``measured_rpm`` the filtered speed (None: feed-forward
        alone), ``rate_rpm_s`` its rate of change."""
        p = self.params
        feed_forward = setpoint_rpm / p.full_output_rpm
        if measured_rpm is None:
            return max(-1.0, min(1.0, feed_forward))
        error = setpoint_rpm - measured_rpm
        unclamped = feed_forward + p.kp * error + self.integral
        saturated_same_way = abs(unclamped) >= 1.0 and math.copysign(1.0, unclamped) == math.copysign(1.0, error)
        if not saturated_same_way and abs(rate_rpm_s) <= p.integrate_max_rate_rpm_s:
            self.integral = max(-p.integral_limit, min(p.integral_limit, self.integral + p.ki * error * dt_s))
        return max(-1.0, min(1.0, feed_forward + p.kp * error + self.integral))


class WheelController:
    """Closes the left and right wheel speeds; output mixed into RC PWM. ``params`` is read at every
    step and ``wheel_radius_m`` may be a function giving the radius in force."""

    def __init__(self, wheel_radius_m: float | Callable[[], float], params: WheelControlParams):
        self.params = params
        self.meter = WheelSpeedMeter(wheel_radius_m, params)
        self._left = _PiWheel(params)
        self._right = _PiWheel(params)

    def on_wheels(self, reading: WheelDistance) -> None:
        self.meter.update(reading)

    def reset(self) -> None:
        """Forget the integrators (on hold, mode change or failsafe)."""
        self._left.integral = self._right.integral = 0.0

    def neutral(self) -> WheelCommand:
        self.reset()
        return WheelCommand(self.params.rc_trim_us, self.params.rc_trim_us, 0.0, 0.0)

    def _fresh(self, time_s: float) -> bool:
        return self.meter.time_s is not None and time_s - self.meter.time_s <= self.params.measurement_timeout_s

    def step(self, time_s: float, dt_s: float, left_rpm: float, right_rpm: float) -> WheelCommand:
        """One control step at vehicle time ``time_s`` lasting ``dt_s``. A stop (both setpoints
        zero) is a ``brake``, then neutral: the PI loop on the late filtered speed winds its
        integrators backwards while the wheels slow down, and after a stop from 1.2 m/s it drove
        them in reverse at 0.17 m/s for over half a second (a rover yielding to a walker ahead
        backed into one passing behind it: the runner's ``crossing`` seed 155)."""
        if left_rpm == 0.0 and right_rpm == 0.0:
            return self.brake(time_s, dt_s) or self.neutral()
        fresh = self._fresh(time_s)
        meter = self.meter
        left = self._left.step(left_rpm, meter.left_rpm if fresh else None, dt_s, meter.left_rate_rpm_s)
        right = self._right.step(right_rpm, meter.right_rpm if fresh else None, dt_s, meter.right_rate_rpm_s)
        steering_us, throttle_us = motors_to_rc(left, right, self.params)
        return WheelCommand(steering_us, throttle_us, left, right)

    def brake(self, time_s: float, dt_s: float) -> WheelCommand | None:
        """One braking step (module docstring); None once both wheels are let go, or without a
        fresh measurement: the caller sends neutral."""
        if not self._fresh(time_s):
            return None
        outputs = []
        for wheel, filtered, corrected in zip(
            (self._left, self._right), (self.meter.left_rpm, self.meter.right_rpm), self.meter.lag_corrected()
        ):
            if abs(corrected) <= self.params.brake_release_rpm or corrected * filtered <= 0.0:
                wheel.integral = 0.0
                outputs.append(0.0)
            else:
                outputs.append(wheel.step(0.0, corrected, dt_s))
        if outputs == [0.0, 0.0]:
            return None
        steering_us, throttle_us = motors_to_rc(outputs[0], outputs[1], self.params)
        return WheelCommand(steering_us, throttle_us, outputs[0], outputs[1])
