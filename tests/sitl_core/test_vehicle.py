"""SimRover: collisions, faults, determinism, conventions of the samples it hands out."""

from __future__ import annotations

import dataclasses
import math

import pytest

from sitl.faults import FAULT_PARAMS, FaultError
from sitl.geodesy import LocalFrame
from sitl.params import SitlParams
from sitl.vehicle import SimRover
from sitl.world import Home, World, parse_world

HOME = Home(-35.363261, 149.165230, 584.0, 0.0)
FRAME = LocalFrame(HOME.lat_deg, HOME.lon_deg)


def lonlat(east, north):
    lat, lon = FRAME.to_latlon(east, north)
    return [float(lon), float(lat)]


def world_of(*features, faults=()):
    return parse_world({"type": "FeatureCollection", "features": list(features), "faults": list(faults)})


def wall(north, half_width=3.0, ident="wall", **props):
    ring = [lonlat(-half_width, north), lonlat(half_width, north), lonlat(half_width, north + 0.3), lonlat(-half_width, north + 0.3)]
    return {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [ring + [ring[0]]]}, "properties": {"id": ident, **props}}


def drive_for(rover: SimRover, seconds: float, frame_s: float = 0.02) -> list:
    events = []
    for _ in range(round(seconds / frame_s)):
        events += rover.step(frame_s)
    return events


def test_full_throttle_drives_along_the_home_heading_and_truth_uses_compass_conventions():
    rover = SimRover(SitlParams(), World(), Home(HOME.lat_deg, HOME.lon_deg, 584.0, 90.0), seed=1)
    rover.set_motor_pwm(2000, 2000)
    drive_for(rover, 3.0)
    truth = rover.truth()
    assert truth.time_s == pytest.approx(3.0)
    assert truth.east_m > 3.5 and abs(truth.north_m) < 1e-6  # heading 90 = east
    assert truth.yaw_deg == pytest.approx(90.0)
    assert truth.speed_mps == pytest.approx(1.615, abs=0.01)
    assert truth.wheel_rpm_left == pytest.approx(220.4, abs=0.5)
    assert truth.motor_v_left == 12.0 and truth.battery_v == 12.0
    assert (truth.lat_deg, truth.lon_deg) == pytest.approx(FRAME.to_latlon(truth.east_m, truth.north_m))
    rover.set_motor_pwm(1700, 1300)  # left forward, right back: clockwise spin
    drive_for(rover, 1.0)
    assert rover.truth().yaw_rate_dps > 50
    assert rover.attitude().yaw_rate_radps > 0.5


def test_step_keeps_fractional_time_and_refuses_bad_input():
    rover = SimRover(SitlParams(), World(), HOME, seed=1)
    for _ in range(10):
        rover.step(0.0025)
    assert rover.time_s == pytest.approx(0.025, abs=0.0011)
    drive_for(rover, 0.975, 0.0025)
    assert rover.time_s == pytest.approx(1.0)
    for bad in (-0.1, math.nan, math.inf):
        with pytest.raises(ValueError, match="dt_s must be a finite number"):
            rover.step(bad)
    with pytest.raises(ValueError, match="PWM must be finite"):
        rover.set_motor_pwm(math.nan, 1500)
    assert rover.time_s == pytest.approx(1.0) and rover.pwm_left_us == 1500


def test_driving_into_a_wall_is_one_collision_event_and_stops_the_rover():
    rover = SimRover(SitlParams(), world_of(wall(5.0)), HOME, seed=1)
    rover.set_motor_pwm(1800, 1800)
    events = drive_for(rover, 8.0)
    collisions = [e for e in events if e.kind == "collision"]
    assert len(collisions) == 1
    assert collisions[0].detail["obstacle"] == "wall"
    assert collisions[0].time_s == pytest.approx(4.8 / 0.97 + 0.3, abs=1.0)
    truth = rover.truth()
    assert 5.0 - 0.225 - 0.05 < truth.north_m < 5.0 - 0.225
    assert abs(truth.speed_mps) < 0.05
    assert truth.motor_a_left == pytest.approx(truth.motor_v_left / 4.0, rel=0.05)  # stalled: V / R
    # Back off and drive in again: a second contact.
    rover.set_motor_pwm(1200, 1200)
    drive_for(rover, 1.0)
    rover.set_motor_pwm(1800, 1800)
    assert [e.kind for e in drive_for(rover, 3.0)] == ["collision"]


def test_a_moving_obstacle_hitting_a_parked_rover_is_reported():
    walker = {"type": "Feature", "geometry": {"type": "Point", "coordinates": lonlat(-3.0, 0.0)},
              "properties": {"id": "walker", "radius_m": 0.3, "motion": {"type": "velocity", "velocity_mps": [1.0, 0.0]}}}
    rover = SimRover(SitlParams(), world_of(walker), HOME, seed=1)
    events = drive_for(rover, 6.0)
    assert [(e.kind, e.detail["obstacle"]) for e in events] == [("collision", "walker")]
    assert events[0].time_s == pytest.approx(3.0 - 0.3 - 0.2, abs=0.02)


def test_the_front_rangefinder_sees_the_wall_get_closer():
    rover = SimRover(SitlParams(), world_of(wall(4.5)), HOME, seed=2)
    front = [s for s in rover.rangefinders() if s.orientation == 0][0]
    assert front.range_m is None  # 4.275 m away: beyond the 4 m maximum
    rover.set_motor_pwm(1700, 1700)
    drive_for(rover, 1.0)
    truth = rover.truth()
    front = [s for s in rover.rangefinders() if s.orientation == 0][0]
    assert front.range_m == pytest.approx(4.5 - 0.225 - truth.north_m, abs=0.08)
    assert {s.orientation for s in rover.rangefinders()} == {0, 1, 2, 4, 6, 7}


def test_same_seed_same_run_different_seed_different_noise():
    def run(seed):
        rover = SimRover(SitlParams(), world_of(wall(6.0)), HOME, seed)
        out = []
        for k in range(200):
            rover.set_motor_pwm(1700 + k % 7, 1750)
            rover.step(0.02)
            out.append((rover.truth(), rover.attitude(), rover.wheels(), tuple(rover.rangefinders()),
                        rover.gps() if k % 10 == 0 else None))
        return out

    assert run(11) == run(11)
    assert run(11) != run(12)


def test_scheduled_faults_start_and_end_on_time_with_their_effects():
    faults = [
        {"name": "gps_outage", "start_s": 1.0, "duration_s": 1.0},
        {"name": "gps_glitch", "start_s": 3.0, "duration_s": 1.0, "north_m": 20.0, "east_m": 0.0},
        {"name": "rangefinder_silent", "start_s": 0.5, "duration_s": 1.0, "sensor_id": 2},
        {"name": "wheel_slip", "start_s": 0.0, "duration_s": 10.0, "fraction": 0.5},
        {"name": "link_loss", "start_s": 2.0, "duration_s": 1.0, "pct": 30.0},
        {"name": "link_quiet", "start_s": 2.5, "duration_s": 0.25},
    ]
    params = SitlParams()
    params.gps = dataclasses.replace(params.gps, dropout_prob=0.0)
    rover = SimRover(params, world_of(faults=faults), HOME, seed=3)
    rover.set_motor_pwm(1800, 1800)
    timeline = []
    observed = {}
    for k in range(250):
        timeline += [(round(e.time_s, 3), e.detail["name"], e.detail["active"]) for e in rover.step(0.02)]
        t = round(rover.time_s, 2)
        observed[t] = (rover.gps(), {s.sensor_id for s in rover.rangefinders()}, rover.faults.link_loss_pct, rover.faults.link_quiet)
    assert timeline == [
        (0.0, "wheel_slip", True), (0.5, "rangefinder_silent", True), (1.0, "gps_outage", True),
        (1.5, "rangefinder_silent", False), (2.0, "gps_outage", False), (2.0, "link_loss", True),
        (2.5, "link_quiet", True), (2.75, "link_quiet", False), (3.0, "link_loss", False),
        (3.0, "gps_glitch", True), (4.0, "gps_glitch", False)]
    assert observed[0.9][0] is not None and observed[1.0][0] is None and observed[1.98][0] is None and observed[2.0][0] is not None
    assert 2 not in observed[1.0][1] and 2 in observed[1.6][1]
    assert observed[2.5][2:] == (30.0, True) and observed[2.8][2:] == (30.0, False) and observed[3.2][2:] == (0.0, False)
    assert observed[3.5][0].err_glitch_en_m == (0.0, 20.0) and observed[4.5][0].err_glitch_en_m == (0.0, 0.0)
    truth = rover.truth()
    assert truth.north_m == pytest.approx(0.5 * rover.wheels().left_m, rel=0.01)  # half the rolling lost


def test_run_time_faults_combine_with_the_schedule():
    rover = SimRover(SitlParams(), world_of(faults=[{"name": "rangefinder_silent", "start_s": 1.0, "duration_s": 1.0, "sensor_id": 0}]),
                     HOME, seed=1)
    rover.set_fault("SIM_RF_FAIL", 0b10)
    events = rover.step(1.5)
    assert [(e.kind, e.detail["name"], e.detail["active"]) for e in events] == [
        ("fault", "SIM_RF_FAIL", True), ("fault", "rangefinder_silent", True)]
    assert {s.sensor_id for s in rover.rangefinders()} == {2, 3, 4, 5}
    rover.step(1.0)
    assert {s.sensor_id for s in rover.rangefinders()} == {0, 2, 3, 4, 5}
    rover.set_fault("SIM_LINK_LOSS", 12.5)
    rover.set_fault("SIM_LINK_QUIET", 1)
    assert rover.faults.link_loss_pct == 12.5 and rover.faults.link_quiet
    rover.set_fault("SIM_GPS_DISABLE", 1)
    assert rover.gps() is None


@pytest.mark.parametrize("name, value, message", [
    ("SIM_WARP", 1, "unknown fault parameter 'SIM_WARP'"),
    ("SIM_WHEEL_SLIP", 1.5, "SIM_WHEEL_SLIP: 1.5 is outside 0..1"),
    ("SIM_RF_FAIL", 2.5, "SIM_RF_FAIL: expected a non-negative integer bitmask"),
    ("SIM_GPS_GLITCH_X", "far", "SIM_GPS_GLITCH_X: expected a number"),
    ("SIM_GPS_GLITCH_Y", 1e300, r"SIM_GPS_GLITCH_Y: 1e\+300 is outside -10000\.\.10000"),  # wrapped the fix round the Earth
])
def test_bad_run_time_faults_are_refused_and_change_nothing(name, value, message):
    rover = SimRover(SitlParams(), World(), HOME, seed=1)
    with pytest.raises(FaultError, match=message):
        rover.set_fault(name, value)
    assert rover.faults.values == {n: d for n, (d, _doc) in FAULT_PARAMS.items()}
    assert rover.step(0.1) == []


def test_paper_four_sensor_setup_works():
    from sitl.params import paper_rangefinders

    params = SitlParams()
    params.rangefinder.sensors = paper_rangefinders()
    rover = SimRover(params, World(), HOME, seed=1)
    assert sorted(s.orientation for s in rover.rangefinders()) == [0, 2, 4, 6]
    assert math.isfinite(rover.attitude().yaw_rad)


def test_frame_size_does_not_change_the_physics():
    world = world_of(wall(3.0))
    coarse, fine = SimRover(SitlParams(), world, HOME, 1), SimRover(SitlParams(), world, HOME, 1)
    for rover in (coarse, fine):
        rover.set_motor_pwm(1800, 1790)
    events_coarse = coarse.step(4.0)
    events_fine = drive_for(fine, 4.0, 0.004)
    assert coarse.truth() == fine.truth()
    assert events_coarse == events_fine and events_coarse


def test_playground_world_fires_every_scheduled_fault():
    from pathlib import Path

    from sitl.world import load_world

    world = load_world(Path(__file__).resolve().parents[2] / "missions" / "worlds" / "playground.geojson")
    rover = SimRover(SitlParams(), world, world.home, seed=1)
    events = rover.step(90.0)
    faults = [(e.detail["name"], e.detail["active"]) for e in events if e.kind == "fault"]
    assert sorted(faults) == sorted((f.name, active) for f in world.faults for active in (True, False))


def test_fault_windows_off_the_substep_grid_still_fire():
    world = world_of(faults=[{"name": "gps_outage", "start_s": 0.0005, "duration_s": 0.0021},
                             {"name": "link_quiet", "start_s": 0.1 + 0.2, "duration_s": 0.7 - 0.4}])
    rover = SimRover(SitlParams(), world, HOME, seed=1)
    events = [(e.detail["name"], e.detail["active"], round(e.time_s, 4)) for e in rover.step(1.0)]
    assert events == [("gps_outage", True, 0.0), ("gps_outage", False, 0.003),
                      ("link_quiet", True, 0.3), ("link_quiet", False, 0.6)]


def test_fault_parameter_names_fit_a_mavlink_param_id():
    from sitl.faults import FAULT_PARAMS

    assert all(len(name) <= 16 for name in FAULT_PARAMS), "MAVLink param_id carries at most 16 characters"


def test_model_parameters_are_overridden_by_name():
    import pytest

    from sitl.params import SitlParams, apply_override

    params = SitlParams()
    apply_override(params, "gps.white_std_m=2.5")
    apply_override(params, "encoder.ticks_per_rev=360")
    assert params.gps.white_std_m == 2.5 and params.encoder.ticks_per_rev == 360
    for bad, message in [
        ("gps.nope=1", "unknown numeric field 'nope'"),
        ("gpz.white_std_m=1", "unknown section 'gpz'"),
        ("gps.white_std_m=wide", "expected a number"),
        ("encoder.ticks_per_rev=1.5", "expected a whole number"),
        ("gps.white_std_m", "expected SECTION.FIELD=VALUE"),
        ("gps.white_std_m=-1", r"expected a finite number >= 0 and <= 100, got '-1'"),  # numpy: "scale < 0"
        ("gps.white_std_m=nan", "expected a finite number"),
        ("gps.rate_hz=0", "expected a finite number > 0"),  # divided by
        ("motor.inductance_h=inf", "expected a finite number >= 1e-05 and <= 0.1 H"),
        ("gps.satellites=1e300", "<= 255"),  # a uint8 on the wire
        ("rangefinder.max_m=1000", "<= 655.34"),
        ("encoder.ticks_per_rev=0", "> 0"),
        ("physics_dt_s=1e-300", ">= 1e-06"),  # hung
        ("rangefinder.rays_per_beam=1e9", "<= 1000"),  # exhausted memory
    ]:
        with pytest.raises(ValueError, match=message):
            apply_override(params, bad)


def test_model_parameter_limits_name_fields_and_admit_the_defaults():
    import dataclasses

    from sitl.params import LIMITS, POSITIVE, SitlParams

    params = SitlParams()
    numeric = {}
    for section in dataclasses.fields(params):
        value = getattr(params, section.name)
        fields = ({f"{section.name}.{f.name}": getattr(value, f.name) for f in dataclasses.fields(value)}
                  if dataclasses.is_dataclass(value) else {section.name: value})
        numeric |= {key: v for key, v in fields.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}
    assert set(LIMITS) <= set(numeric), "LIMITS names a field that --set cannot reach"
    for key, default in numeric.items():
        assert LIMITS.get(key, POSITIVE).admits(default), key


@pytest.mark.parametrize("assignment", [
    # each of these printed "ready" and then crashed (NaN in SIMSTATE, ZeroDivisionError, OverflowError)
    "motor.inductance_h=1e-300", "motor.resistance_ohm=1e300", "motor.ke_v_per_radps=1e300", "motor.kt_nm_per_a=1e300",
    "robot.wheel_radius_m=1e300", "robot.track_m=1e-300", "motor.gear_ratio=1e300", "robot.footprint_length_m=1e300",
    "robot.footprint_width_m=1e300", "motor.viscous_nms_per_rad=1e300",
    "motor.battery_v=1", "motor.pwm_range_us=1e-300", "motor.pwm_neutral_us=1e300", "motor.rotor_inertia_kgm2=1e300",
    "robot.mass_kg=1e-300", "robot.wheel_inertia_kgm2=1e300", "physics_dt_s=1", "collision_check_s=1e300",
    "contact_release_m=1e300",
])
def test_drive_and_body_fields_outside_their_range_are_refused_naming_field_value_and_range(assignment):
    from sitl.params import LIMITS, SitlParams, apply_override

    key, _, value = assignment.partition("=")
    with pytest.raises(ValueError) as err:
        apply_override(SitlParams(), assignment)
    limits = LIMITS[key]
    assert str(err.value) == f"{key}: expected a finite number {limits}, got {value!r}"
    assert f">= {limits.low:g} and <= {limits.high:g}" in str(limits)


def test_every_drive_and_body_field_has_a_finite_range_with_its_unit():
    from sitl.params import LIMITS, SitlParams

    params = SitlParams()
    for section in ("motor", "robot"):
        for f in dataclasses.fields(getattr(params, section)):
            value = getattr(getattr(params, section), f.name)
            if isinstance(value, (int, float)):  # robot.yaw_inertia_kgm2 is None: derived from the footprint, not settable
                limits = LIMITS[f"{section}.{f.name}"]
                assert math.isfinite(limits.high) and limits.low_included, f.name
                assert limits.unit or f.name == "gear_ratio", f.name


TOY = ["motor.battery_v=6", "motor.resistance_ohm=15", "motor.inductance_h=0.001", "motor.ke_v_per_radps=0.0019",
       "motor.kt_nm_per_a=0.0019", "motor.gear_ratio=100", "motor.rotor_inertia_kgm2=1e-8", "motor.viscous_nms_per_rad=1e-7",
       "robot.mass_kg=0.2", "robot.track_m=0.1", "robot.wheel_radius_m=0.02", "robot.wheel_inertia_kgm2=1e-6",
       "robot.footprint_length_m=0.12", "robot.footprint_width_m=0.1"]
"""An N20-gearmotor toy: 6 V, 100:1, 300 rpm at the wheel."""
HUSKY = ["motor.battery_v=24", "motor.resistance_ohm=0.3", "motor.inductance_h=0.0005", "motor.ke_v_per_radps=0.13",
         "motor.kt_nm_per_a=0.13", "motor.gear_ratio=30", "robot.mass_kg=50", "robot.track_m=0.55", "robot.wheel_radius_m=0.165",
         "robot.wheel_inertia_kgm2=0.05", "robot.footprint_length_m=0.99", "robot.footprint_width_m=0.67"]
"""A Clearpath Husky-sized research rover (50 kg, about 1 m/s)."""
WARTHOG = ["motor.battery_v=48", "motor.resistance_ohm=0.05", "motor.inductance_h=0.0001", "motor.ke_v_per_radps=0.144",
           "motor.kt_nm_per_a=0.144", "motor.gear_ratio=20", "motor.rotor_inertia_kgm2=0.002", "robot.mass_kg=280",
           "robot.track_m=1.1", "robot.wheel_radius_m=0.3", "robot.wheel_inertia_kgm2=1.0", "robot.footprint_length_m=1.52",
           "robot.footprint_width_m=1.38"]
"""A Clearpath Warthog-sized one (280 kg, about 5 m/s)."""


@pytest.mark.parametrize("rover", [TOY, HUSKY, WARTHOG], ids=["toy", "husky", "warthog"])
def test_small_and_large_rovers_are_in_range_and_drive(rover):
    from sitl.params import SitlParams, apply_override, inconsistency

    params = SitlParams()
    for assignment in rover:
        apply_override(params, assignment)
    assert inconsistency(params) is None
    sim = SimRover(params, World(), HOME, seed=1)
    sim.set_motor_pwm(2000, 1800)
    drive_for(sim, 3.0)
    truth = sim.truth()
    assert all(math.isfinite(v) for v in dataclasses.astuple(truth))
    assert 0.2 < truth.speed_mps < 8.0


@pytest.mark.parametrize("assignments, message", [
    # each field in range, together 65 m/s: GPS_RAW_INT's speed (a uint16 of cm/s) overflowed mid-run
    (["motor.battery_v=65", "motor.ke_v_per_radps=0.001", "motor.kt_nm_per_a=10", "motor.resistance_ohm=0.01",
      "motor.gear_ratio=1", "robot.wheel_radius_m=1", "motor.viscous_nms_per_rad=0"], "top speed of 6.5e+04 m/s"),
    (["motor.ke_v_per_radps=0.001"], "top speed of 33.6 m/s"),
    (["robot.track_m=0.05", "physics_dt_s=0.01"], "physics_dt_s 0.01 s turns the rover 0.646 rad per substep"),
])
def test_fields_in_range_that_cannot_go_together_are_refused(assignments, message):
    from sitl.params import SitlParams, apply_override, inconsistency

    params = SitlParams()
    for assignment in assignments:
        apply_override(params, assignment)
    why = inconsistency(params)
    assert why is not None and message in why and "\n" not in why
