"""ArduPilot Rover's MANUAL-mode skid-steer mixer: RC steering/throttle PWM -> left/right motor PWM.

It reproduces the chain a real skid-steer ArduPilot rover applies, so that a controller tuned
against this emulator sees the same outputs on a real vehicle, as configured for the daemon
(PILOT_STEER_TYPE 3: the steering keeps its sign at any throttle; ArduPilot's default 0 reverses
it while the throttle output is negative, and its MOT_SLEWRATE throttle slew is not modelled):

1. RC input to control value with the channel's dead zone (``RC_Channel::pwm_to_angle_dz_trim``,
   integer arithmetic): above ``trim + dz`` the value is
   ``high * (pwm - (trim + dz)) // (max - (trim + dz))``, symmetrically below, 0 inside.
   Steering (ch1) has ``high = 4500`` (centidegrees), throttle (ch3) ``high = 100`` (percent).
   The dead zone (RCx_DZ = 30 us on Rover) is why throttle 1800 gives 1785, not 1800:
   ``100 * 270 // 470 = 57 %`` -> ``1500 + 0.57 * 500 = 1785``.
2. ``AP_MotorsUGV::output_skid_steering``: scale to s = steering/4500, t = throttle/100, limit the
   steering range, then if ``t + |s|`` (or the reverse analogue) exceeds 1 scale back, preferring
   steering or throttle by MOT_STR_THR_MIX (0.5 = steering kept, throttle reduced to fit);
   left = t + s, right = t - s, negative outputs multiplied by the thrust asymmetry.
3. Servo output (SERVO1 left, SERVO3 right, angle range 1000): ``trim + out * (max - trim)`` for
   out >= 0, ``trim + out * (trim - min)`` below, the fraction of a microsecond dropped (toward trim).
"""

from __future__ import annotations

from dataclasses import dataclass

STEERING_HIGH_CDEG = 4500
"""Full-scale steering control value of ArduPilot (centidegrees)."""
THROTTLE_HIGH_PCT = 100
"""Full-scale throttle control value of ArduPilot (percent)."""


@dataclass(frozen=True)
class RcChannel:
    """Calibration of one RC input channel (ArduPilot RCx_MIN/TRIM/MAX/DZ; SITL defaults)."""

    min_us: int = 1000
    trim_us: int = 1500
    max_us: int = 2000
    dead_zone_us: int = 30
    """Rover sets a 30 us default dead zone on steering and throttle."""

    def to_control(self, pwm_us: int, high: int) -> int:
        """PWM -> control value in [-high, high], integer maths as ArduPilot's pwm_to_angle_dz_trim."""
        pwm_us = min(max(int(pwm_us), self.min_us), self.max_us)
        upper = self.trim_us + self.dead_zone_us
        lower = self.trim_us - self.dead_zone_us
        if pwm_us > upper and self.max_us != upper:
            return high * (pwm_us - upper) // (self.max_us - upper)
        if pwm_us < lower and self.min_us != lower:
            # C integer division truncates toward zero; Python's // floors, hence the negation.
            return -(high * (lower - pwm_us) // (lower - self.min_us))
        return 0


@dataclass(frozen=True)
class MixerParams:
    """Skid-steer mixer parameters (ArduPilot names in brackets, defaults as ArduPilot Rover)."""

    steering: RcChannel = RcChannel()
    """RC channel 1 calibration (RC1_*)."""
    throttle: RcChannel = RcChannel()
    """RC channel 3 calibration (RC3_*)."""
    steering_throttle_mix: float = 0.5
    """[MOT_STR_THR_MIX] 0..1; >= 0.5 keeps steering and cuts throttle when saturated."""
    thrust_asymmetry: float = 1.0
    """[MOT_THST_ASYM] forward/reverse thrust ratio, >= 1."""
    servo_min_us: int = 1000
    servo_trim_us: int = 1500
    servo_max_us: int = 2000


def _lerp(low_out: float, high_out: float, x: float, low_in: float, high_in: float) -> float:
    """ArduPilot's linear_interpolate: map x in [low_in, high_in] to [low_out, high_out], clamped."""
    if x <= low_in:
        return low_out
    if x >= high_in:
        return high_out
    return low_out + (x - low_in) / (high_in - low_in) * (high_out - low_out)


def mix_scaled(steering: float, throttle: float, params: MixerParams = MixerParams()) -> tuple[float, float]:
    """Scaled steering and throttle (each -1..1) -> (left, right) motor outputs in -1..1."""
    asymmetry = max(params.thrust_asymmetry, 1.0)
    lower_limit = -1.0 / asymmetry
    best_steering_throttle = (1.0 + lower_limit) * 0.5
    if throttle < best_steering_throttle:
        steering_range = max(throttle, 0.0) - lower_limit
    else:
        steering_range = 1.0 - best_steering_throttle
    steering = min(max(steering, -steering_range), steering_range)
    throttle = min(max(throttle, lower_limit), 1.0)

    saturation = max(throttle + abs(steering), (throttle - abs(steering)) / lower_limit)
    if saturation > 1.0:
        mix = min(max(params.steering_throttle_mix, 0.0), 1.0)
        fair_scaler = 1.0 / saturation
        if mix >= 0.5:
            steering *= _lerp(fair_scaler, 1.0, mix, 0.5, 1.0)
            if throttle >= best_steering_throttle:
                throttle = 1.0 - abs(steering)
            else:
                throttle = abs(steering) + lower_limit
        else:
            throttle *= _lerp(fair_scaler, 1.0, 0.5 - mix, 0.0, 0.5)
            sign = 1.0 if steering > 0 else -1.0
            if throttle >= best_steering_throttle:
                steering = (1.0 - throttle) * sign
            else:
                steering = (throttle - lower_limit) * sign

    left = throttle + steering
    right = throttle - steering
    return (left * asymmetry if left < 0 else left, right * asymmetry if right < 0 else right)


def output_to_pwm(output: float, params: MixerParams = MixerParams()) -> int:
    """Motor output -1..1 -> servo PWM (us), truncated toward trim as ArduPilot's
    ``SRV_Channel::pwm_from_angle`` does (``trim +- uint16_t(|out| * span)``): 0.3616 -> 1680, not 1681."""
    output = min(max(output, -1.0), 1.0)
    span = (params.servo_max_us - params.servo_trim_us) if output >= 0 else (params.servo_trim_us - params.servo_min_us)
    offset = int(abs(output) * span)
    return params.servo_trim_us + offset if output >= 0 else params.servo_trim_us - offset


def mix_rc(steering_us: int, throttle_us: int, params: MixerParams = MixerParams()) -> tuple[int, int]:
    """RC ch1 steering and ch3 throttle PWM -> (left, right) motor PWM, as ArduPilot Rover in MANUAL."""
    steering = params.steering.to_control(steering_us, STEERING_HIGH_CDEG) / STEERING_HIGH_CDEG
    throttle = params.throttle.to_control(throttle_us, THROTTLE_HIGH_PCT) / THROTTLE_HIGH_PCT
    left, right = mix_scaled(steering, throttle, params)
    return output_to_pwm(left, params), output_to_pwm(right, params)
