"""Wheel-speed PI loop, speed meter and the inverse of ArduPilot's skid-steer mixer."""

from __future__ import annotations

import math

import pytest

from rover_ctl.config import WheelControlParams
from rover_ctl.estimation.readings import WheelDistance
from rover_ctl.navigation.wheel_control import WheelController, WheelSpeedMeter, motors_to_rc, rc_to_motors

P = WheelControlParams()
RADIUS_M = 0.07


@pytest.mark.parametrize(
    "steering_us, throttle_us, left_us, right_us",
    [(1500, 1800, 1785, 1785), (1800, 1700, 1967, 1393), (2000, 1500, 2000, 1000), (1500, 1500, 1500, 1500)],
)
def test_forward_mixer_matches_ardupilot_sitl(steering_us, throttle_us, left_us, right_us):
    left, right = rc_to_motors(steering_us, throttle_us, P)
    assert 1500 + left * 500 == pytest.approx(left_us, abs=0.6)
    assert 1500 + right * 500 == pytest.approx(right_us, abs=0.6)


@pytest.mark.parametrize("left", [-1.0, -0.63, -0.2, 0.0, 0.05, 0.4, 0.77, 1.0])
@pytest.mark.parametrize("right", [-1.0, -0.5, 0.0, 0.12, 0.6, 1.0])
def test_inverse_mixer_round_trips_through_the_vehicle_mixer(left, right):
    steering_us, throttle_us = motors_to_rc(left, right, P)
    assert 1000 <= steering_us <= 2000 and 1000 <= throttle_us <= 2000
    got_left, got_right = rc_to_motors(steering_us, throttle_us, P)
    # Quantisation: 1 % of throttle, 1/4500 of steering, rounding to whole microseconds.
    assert got_left == pytest.approx(left, abs=0.015)
    assert got_right == pytest.approx(right, abs=0.015)


def test_inverse_mixer_agrees_with_the_emulators_mixer():
    mixer = pytest.importorskip("sitl.mixer")
    for left, right in [(0.9, 0.3), (-0.4, 0.8), (1.0, -1.0), (0.33, 0.33)]:
        steering_us, throttle_us = motors_to_rc(left, right, P)
        left_us, right_us = mixer.mix_rc(steering_us, throttle_us)
        assert (left_us - 1500) / 500 == pytest.approx(left, abs=0.015)
        assert (right_us - 1500) / 500 == pytest.approx(right, abs=0.015)


def test_out_of_range_outputs_are_clamped():
    assert motors_to_rc(3.0, 3.0, P) == motors_to_rc(1.0, 1.0, P)
    assert motors_to_rc(1.0, 1.0, P)[1] == 2000


def test_speed_meter_measures_rpm_and_ignores_repeats():
    meter = WheelSpeedMeter(RADIUS_M, P)
    rpm = 120.0
    speed_mps = rpm / 60 * 2 * math.pi * RADIUS_M
    for k in range(100):
        t = k * 0.02
        meter.update(WheelDistance(t, speed_mps * t, -speed_mps * t))
        meter.update(WheelDistance(t, speed_mps * t, -speed_mps * t))  # duplicate: no effect
    assert meter.left_rpm == pytest.approx(rpm, rel=1e-3)
    assert meter.right_rpm == pytest.approx(-rpm, rel=1e-3)
    assert meter.time_s == pytest.approx(99 * 0.02)


def simulate(controller: WheelController, setpoints, gain_rpm: float = 190.0, tau_s: float = 0.15, dt_s: float = 0.02):
    """Drive a first-order motor model (its true gain differs from the feed-forward's) and
    return the wheel speed history (left)."""
    rpm = [0.0, 0.0]
    dist = [0.0, 0.0]
    history = []
    for k, (left_set, right_set) in enumerate(setpoints):
        t = k * dt_s
        controller.on_wheels(WheelDistance(t, dist[0], dist[1]))
        cmd = controller.step(t, dt_s, left_set, right_set)
        outs = rc_to_motors(cmd.steering_us, cmd.throttle_us, P)
        for i in range(2):
            rpm[i] += (outs[i] * gain_rpm - rpm[i]) * dt_s / tau_s
            dist[i] += rpm[i] / 60 * 2 * math.pi * RADIUS_M * dt_s
        history.append(tuple(rpm))
    return history


def test_pi_loop_removes_the_feed_forward_error():
    controller = WheelController(RADIUS_M, P)
    history = simulate(controller, [(120.0, 60.0)] * 250)
    left, right = history[-1]
    assert left == pytest.approx(120.0, rel=0.03)
    assert right == pytest.approx(60.0, rel=0.03)
    # Open loop (feed-forward only) would settle at 120 * 190 / 250 = 91 rpm.
    assert abs(history[-1][0] - 91.2) > 20


def test_anti_windup_limits_overshoot_after_saturation():
    controller = WheelController(RADIUS_M, P)
    # Ask for more than the motor can give for 3 s, then for something reachable.
    history = simulate(controller, [(400.0, 400.0)] * 150 + [(100.0, 100.0)] * 150)
    after = [left for left, _ in history[150:]]
    assert max(after[25:]) < 100.0 * 1.1
    assert after[-1] == pytest.approx(100.0, rel=0.03)


def test_stale_measurements_fall_back_to_feed_forward():
    controller = WheelController(RADIUS_M, P)
    controller.on_wheels(WheelDistance(0.0, 0.0, 0.0))
    controller.on_wheels(WheelDistance(0.02, 0.0, 0.0))
    cmd = controller.step(5.0, 0.04, 125.0, 125.0)  # wheel data 5 s old
    assert cmd.left_out == pytest.approx(125.0 / P.full_output_rpm)
    assert controller.neutral().throttle_us == P.rc_trim_us


def stop_from_cruise(reading_hz: float, phase_s: float, setpoints_rpm: tuple[float, float] = (160.0, 160.0),
                     by_setpoint: bool = False, then_rpm: tuple[float, float] | None = None) -> list[tuple[float, float]]:  # fmt: skip
    """The emulator's drive train (its DC motors, mixer and body) driven at ``setpoints_rpm`` for
    4 s (160 rpm: 1.2 m/s), then the brake at 25 Hz with wheel readings at ``reading_hz``, the first
    control step ``phase_s`` after a reading; neutral once the brake lets go. ``by_setpoint``: the
    stop asked as zero setpoints to ``step`` (a navigator told to stand) instead; ``then_rpm``: no
    stop, these setpoints instead. Returns the left and right wheel rim speeds (m/s) every 10 ms
    from the moment the brake (or the new setpoints) starts."""
    physics = pytest.importorskip("sitl.physics")
    params = pytest.importorskip("sitl.params")
    mixer = pytest.importorskip("sitl.mixer")
    sitl = params.SitlParams()
    drive = physics.DriveTrain(sitl.motor, sitl.robot, sitl.physics_dt_s)
    radius_m = sitl.robot.wheel_radius_m
    controller = WheelController(radius_m, P)

    def apply(command) -> None:
        left_us, right_us = mixer.mix_rc(command.steering_us, command.throttle_us)
        drive.set_volts(drive.pwm_to_volts(left_us), drive.pwm_to_volts(right_us))

    step_ms, reading_ms = 40, round(1000 / reading_hz)
    speeds, braking = [], False
    for t_ms in range(0, 6000):
        t_s = t_ms / 1000
        if t_ms % reading_ms == 0:
            controller.on_wheels(WheelDistance(t_s, drive.angle_l_rad * radius_m, drive.angle_r_rad * radius_m))
        if t_ms % step_ms == round(phase_s * 1000) % step_ms:
            braking = braking or t_ms >= 4000
            if not braking:
                apply(controller.step(t_s, step_ms / 1000, *setpoints_rpm))
            elif then_rpm is not None:
                apply(controller.step(t_s, step_ms / 1000, *then_rpm))
            elif by_setpoint:
                apply(controller.step(t_s, step_ms / 1000, 0.0, 0.0))
            else:
                apply(controller.brake(t_s, step_ms / 1000) or controller.neutral())
        if braking and t_ms % 10 == 0:
            speeds.append((drive.wheel_l_radps * radius_m, drive.wheel_r_radps * radius_m))
        drive.advance(1)
    return speeds


@pytest.mark.parametrize("reading_hz", [25.0, 50.0])
@pytest.mark.parametrize("phase_s", [0.0, 0.01, 0.02, 0.03])
@pytest.mark.parametrize("setpoints_rpm", [(160.0, 160.0), (120.0, -120.0)], ids=["straight", "pivot"])
@pytest.mark.parametrize("by_setpoint", [False, True], ids=["brake", "zero-setpoints"])
def test_the_brake_stops_the_wheels_without_driving_them_backwards(reading_hz, phase_s, setpoints_rpm, by_setpoint):
    speeds = stop_from_cruise(reading_hz, phase_s, setpoints_rpm, by_setpoint)
    for wheel, setpoint in enumerate(setpoints_rpm):
        direction = math.copysign(1.0, setpoint)
        along = [direction * v[wheel] for v in speeds]  # positive: the way the wheel was turning
        assert along[0] > 0.8
        assert min(along) > -0.02  # never pushed through the stop into reverse
        assert max(abs(v) for v in along[50:]) < 0.03  # standing half a second after the brake


@pytest.mark.parametrize("reading_hz", [25.0, 50.0])
@pytest.mark.parametrize("phase_s", [0.0, 0.02])
@pytest.mark.parametrize("crawl_rpm, least_mps, settle_share", [(40.0, 0.22, 0.1), (10.0, -0.01, 0.3)])
def test_slowing_to_a_crawl_does_not_wind_the_integrator_into_reverse(reading_hz, phase_s, crawl_rpm, least_mps, settle_share):
    """From 1.2 m/s to a crawl (a yield): the error while the drive train slows is its own lag.
    Integrated, it drove the wheels backwards at up to 0.135 m/s when slowing to 10 rpm (0.073 m/s),
    and down to 0.12 m/s for over a second when slowing to 40 rpm (0.293 m/s)."""
    speeds = stop_from_cruise(reading_hz, phase_s, then_rpm=(crawl_rpm, crawl_rpm))
    crawl_mps = crawl_rpm * 2.0 * math.pi * RADIUS_M / 60.0
    left = [v[0] for v in speeds]
    assert left[0] > 0.8
    assert min(left) > least_mps
    assert abs(left[-1] - crawl_mps) < settle_share * crawl_mps  # two seconds later


def test_without_fresh_wheel_readings_the_brake_leaves_the_stop_to_neutral():
    controller = WheelController(RADIUS_M, P)
    assert controller.brake(0.0, 0.04) is None  # no reading yet
    controller.on_wheels(WheelDistance(0.0, 0.0, 0.0))
    controller.on_wheels(WheelDistance(0.02, 0.02, 0.02))  # 1 m/s
    assert controller.brake(0.04, 0.04) is not None
    assert controller.brake(0.02 + P.measurement_timeout_s + 0.01, 0.04) is None  # readings gone stale
