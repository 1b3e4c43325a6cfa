"""Drive physics against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sitl.params import MotorParams, RobotParams, SitlParams
from sitl.physics import DriveTrain, straight_time_constant_s


def drive(dt_s: float = 0.001) -> DriveTrain:
    return DriveTrain(MotorParams(), RobotParams(), dt_s)


def test_defaults_give_the_papers_top_wheel_speed_and_a_few_hundred_ms_time_constant():
    motor, robot = MotorParams(), RobotParams()
    top_rpm = motor.steady_wheel_radps(motor.battery_v) * 60 / (2 * math.pi)
    assert 200 <= top_rpm <= 270
    assert 0.1 <= straight_time_constant_s(motor, robot) <= 0.6


def test_pwm_maps_linearly_to_battery_voltage_and_saturates():
    d = drive()
    assert d.pwm_to_volts(1500) == 0.0
    assert d.pwm_to_volts(2000) == pytest.approx(12.0)
    assert d.pwm_to_volts(1250) == pytest.approx(-6.0)
    assert d.pwm_to_volts(2300) == pytest.approx(12.0)
    assert d.pwm_to_volts(700) == pytest.approx(-12.0)


@pytest.mark.parametrize("volts", [12.0, 6.0, -9.0])
def test_steady_state_wheel_speed_matches_closed_form(volts):
    d = drive()
    d.set_volts(volts, volts)
    d.advance(4000)  # 15 time constants
    expected = MotorParams().steady_wheel_radps(volts)
    assert d.wheel_l_radps == pytest.approx(expected, rel=1e-6)
    assert d.wheel_r_radps == pytest.approx(expected, rel=1e-6)
    assert d.speed_mps == pytest.approx(expected * 0.07, rel=1e-6)
    assert d.yaw_rate_radps == pytest.approx(0.0, abs=1e-9)


def test_step_response_time_constant_matches_closed_form():
    d = drive()
    d.set_volts(12.0, 12.0)
    final = MotorParams().steady_wheel_radps(12.0)
    speeds = []
    for _ in range(2000):
        d.advance(1)
        speeds.append(d.wheel_l_radps)
    speeds = np.array(speeds)
    t63 = (np.argmax(speeds >= (1 - math.exp(-1)) * final) + 1) * 0.001
    assert t63 == pytest.approx(straight_time_constant_s(MotorParams(), RobotParams()), rel=0.02)
    assert np.all(np.diff(speeds) >= -1e-12), "a first-order step response does not overshoot"


def test_turning_in_place_is_slower_to_spin_up_when_the_body_has_more_yaw_inertia():
    light, heavy = RobotParams(yaw_inertia_kgm2=0.05), RobotParams(yaw_inertia_kgm2=0.5)
    rates = []
    for robot in (light, heavy):
        d = DriveTrain(MotorParams(), robot, 0.001)
        d.set_volts(-12.0, 12.0)
        d.advance(100)
        rates.append(d.yaw_rate_radps)
    assert rates[0] > rates[1] > 0


def test_constant_differential_traces_the_kinematic_circle():
    d = drive()
    vl, vr = d.pwm_to_volts(1800), d.pwm_to_volts(1850)
    d.set_volts(vl, vr)
    d.advance(3000)  # settle
    points = []
    for _ in range(400):
        d.advance(25)
        points.append((d.east_m, d.north_m))
    x, y = np.array(points).T
    # Algebraic least-squares circle: x^2 + y^2 + D x + E y + F = 0.
    D, E, F = np.linalg.lstsq(np.column_stack([x, y, np.ones_like(x)]), -(x**2 + y**2), rcond=None)[0]
    radius = math.sqrt(D * D / 4 + E * E / 4 - F)
    expected = 0.32 / 2 * (vr + vl) / (vr - vl)  # wheel speeds are proportional to voltage at steady state
    assert radius == pytest.approx(expected, rel=2e-3)
    residual = np.hypot(x + D / 2, y + E / 2) - radius
    assert np.max(np.abs(residual)) < 1e-3


def test_the_integration_is_stable_with_a_stiff_armature_and_large_substeps():
    motor = MotorParams(inductance_h=1e-5)  # L/R = 2.5 us, far below the substep
    for dt in (0.001, 0.01):
        d = DriveTrain(motor, RobotParams(), dt)
        d.set_volts(12.0, 12.0)
        d.advance(round(3.0 / dt))
        assert d.wheel_l_radps == pytest.approx(motor.steady_wheel_radps(12.0), rel=1e-4)
        assert d.current_l_a == pytest.approx((12.0 - 0.1 * 5 * d.wheel_l_radps) / 4.0, rel=1e-4)


def test_wheel_slip_reduces_ground_motion_but_not_wheel_rotation():
    d = drive()
    d.slip = 0.25
    d.set_volts(12.0, 12.0)
    d.advance(3000)
    rolled = d.angle_l_rad * 0.07
    assert d.north_m == pytest.approx(0.0, abs=1e-9)  # yaw 0 = east
    assert d.east_m == pytest.approx(0.75 * rolled, rel=1e-9)


def test_sitl_params_defaults_are_consistent():
    params = SitlParams()
    assert [m.sensor_id for m in params.rangefinder.sensors] == list(range(6))
    assert {m.orientation for m in params.rangefinder.sensors} == {0, 1, 2, 4, 6, 7}
    assert params.gps.eph_m == pytest.approx(math.hypot(params.gps.white_std_m, params.gps.bias_std_m))


def test_every_corner_of_the_ranges_discretises_finite_and_decaying():
    """The drive is stable for any positive parameters and discretised exactly (module docstring);
    the ranges keep the exponential in floating point: 2^14 corners of the fields that enter it."""
    import itertools

    from sitl.params import LIMITS
    from sitl.physics import drive_inconsistency

    outside_a = {"motor.battery_v", "motor.pwm_neutral_us", "motor.pwm_range_us"}  # they set the input, not the system
    keys = [k for k in LIMITS if k.startswith(("motor.", "robot.")) and k not in outside_a] + ["physics_dt_s"]
    assert len(keys) == 14
    failures = []
    for corner in itertools.product(*[(LIMITS[k].low, LIMITS[k].high) for k in keys]):
        values = dict(zip(keys, corner))
        motor = MotorParams(**{k[len("motor."):]: v for k, v in values.items() if k.startswith("motor.")})
        robot = RobotParams(**{k[len("robot."):]: v for k, v in values.items() if k.startswith("robot.")})
        if (why := drive_inconsistency(motor, robot, values["physics_dt_s"])) is not None:
            failures.append((values, why))
    assert not failures, failures[:3]


def test_a_discretisation_that_overflows_is_reported_not_stepped():
    from sitl.physics import drive_inconsistency

    assert drive_inconsistency(MotorParams(), RobotParams(), 0.001) is None
    why = drive_inconsistency(MotorParams(inductance_h=1e-300), RobotParams(), 0.001)  # the NaN that crashed SIMSTATE
    assert why is not None and "does not decay" in why and "physics_dt_s 0.001 s" in why
    assert "cannot be discretised" in drive_inconsistency(MotorParams(), RobotParams(track_m=1e-300), 0.001)
