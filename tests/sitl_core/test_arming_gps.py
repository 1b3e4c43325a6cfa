"""The emulator's GPS arming check reads the receiver's state as ArduPilot's AP_GPS keeps it: the
last fix stands for GPS_TIMEOUT_S, so one dropped epoch (a 0.2% chance per 5 Hz sample by default)
does not refuse an arming, and a receiver silent for longer does."""

from __future__ import annotations

from dataclasses import replace

from sitl.endpoints import mavlink
from sitl.mavlink_vehicle import GPS_TIMEOUT_S, LinkParams, MavlinkVehicle
from sitl.params import SitlParams
from sitl.vehicle import SimRover
from sitl.world import Home, World


def _arm(vehicle: MavlinkVehicle, t_s: float) -> int:
    ack = vehicle.handle(mavlink.MAVLink_command_long_message(1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0), t_s)[0]
    return ack.result


def _vehicle(samples: list[tuple[float, str]]) -> MavlinkVehicle:
    """A vehicle whose receiver reports, at each sample time, a "3d" fix, a "2d" one or nothing
    (a dropout, an outage)."""
    rover = SimRover(SitlParams(), World(), Home(-35.363262, 149.165237, 584.0, 0.0), seed=1)
    vehicle = MavlinkVehicle(rover, LinkParams())
    real_gps = rover.gps
    reports = {"3d": real_gps, "2d": lambda: replace(real_gps(), fix_type=mavlink.GPS_FIX_TYPE_2D_FIX), "none": lambda: None}
    for t_s, kind in samples:
        rover.gps = reports[kind]
        vehicle.sensor_next_s["gps"] = t_s  # due now
        vehicle.sample_sensors(t_s)
    return vehicle


def test_one_dropped_epoch_does_not_refuse_an_arming():
    vehicle = _vehicle([(0.0, "3d"), (0.2, "3d"), (0.4, "none")])
    assert vehicle.gps is None and _arm(vehicle, 0.4) == mavlink.MAV_RESULT_ACCEPTED and vehicle.armed


def test_a_receiver_silent_longer_than_the_timeout_refuses():
    vehicle = _vehicle([(0.0, "3d")] + [(0.2 * k, "none") for k in range(1, 25)])
    assert _arm(vehicle, 0.2 + GPS_TIMEOUT_S) == mavlink.MAV_RESULT_FAILED and not vehicle.armed
    assert (mavlink.MAV_SEVERITY_CRITICAL, "PreArm: GPS 1: Bad fix") in vehicle.pending_text


def test_no_fix_ever_or_a_2d_fix_refuses_at_once():
    assert _arm(_vehicle([(0.0, "none"), (0.2, "none")]), 0.2) == mavlink.MAV_RESULT_FAILED
    assert _arm(_vehicle([(0.0, "3d"), (0.2, "2d")]), 0.2) == mavlink.MAV_RESULT_FAILED
