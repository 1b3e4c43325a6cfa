"""The simulated rover: drive physics in a world of obstacles, sensors and faults. Pure: no I/O,
no clock; the caller (the MAVLink shell) sets the motor PWM, steps sim time and reads sensors at
their rates.

Collisions: every ``collision_check_s`` the rectangular footprint is tested against the obstacles
near it. Driving into an obstacle is refused: the rover is put back where it was at the last check
and stops dead, so motors that keep pushing stall (stall current, encoders creep by at most the
travel of one check interval each time). An obstacle moving
into a stationary rover is reported but not resolved. Each contact gives one ``collision`` event;
it ends when the footprint is ``contact_release_m`` clear of that obstacle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from shapely.geometry import Polygon

from sitl.faults import FaultState
from sitl.geodesy import LocalFrame
from sitl.params import SitlParams
from sitl.physics import DriveTrain
from sitl.sensors import (AttitudeSample, Gps, GpsSample, Imu, RangeSample, Rangefinder, WheelEncoders,
                          WheelSample)
from sitl.world import Home, World


@dataclass(frozen=True)
class Event:
    """Something that happened at ``time_s``: kind "collision" or "fault"."""

    kind: str
    time_s: float
    detail: dict = field(default_factory=dict)


@dataclass(frozen=True)
class TruthState:
    """Ground truth (for the truth log and SIMSTATE, never for navigation)."""

    time_s: float
    lat_deg: float
    lon_deg: float
    alt_m: float
    east_m: float
    north_m: float
    yaw_deg: float
    """Compass heading, 0 north, clockwise, 0..360."""
    speed_mps: float
    """Signed forward ground speed."""
    yaw_rate_dps: float
    """Clockwise positive (as the compass)."""
    wheel_rpm_left: float
    wheel_rpm_right: float
    motor_v_left: float
    motor_v_right: float
    motor_a_left: float
    motor_a_right: float
    battery_v: float


class SimRover:
    """One rover in one world. Deterministic for a given seed and sequence of calls."""

    def __init__(self, params: SitlParams, world: World, home: Home, seed: int) -> None:
        self.params = params
        self.home = home
        self.frame = LocalFrame(home.lat_deg, home.lon_deg)
        self.world = world.local(self.frame)
        self.faults = FaultState(world.faults)
        self.drive = DriveTrain(params.motor, params.robot, params.physics_dt_s, math.radians(90.0 - home.heading_deg))
        mounts = params.rangefinder.sensors
        rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(4 + len(mounts))]
        self._gps = Gps(params.gps, self.frame, home.alt_m, rngs[0])
        self._imu = Imu(params.imu, rngs[1], rngs[2])
        self._encoders = WheelEncoders(params.encoder, params.robot.wheel_radius_m, rngs[3])
        self._rangefinders = [Rangefinder(params.rangefinder, m, rng) for m, rng in zip(mounts, rngs[4:])]
        self.pwm_left_us = self.pwm_right_us = params.motor.pwm_neutral_us
        self._steps = 0
        self._target_s = 0.0
        self._check_every = max(1, round(params.collision_check_s / params.physics_dt_s))
        self._fault_steps = [round(t / params.physics_dt_s) for t in self.faults.transitions()]
        self._pending: list[Event] = []
        self._contacts: set[str] = set()
        self._checkpoint = (self.drive.east_m, self.drive.north_m, self.drive.yaw_rad)
        half_l, half_w = params.robot.footprint_length_m / 2.0, params.robot.footprint_width_m / 2.0
        self._corners = ((half_l, half_w), (-half_l, half_w), (-half_l, -half_w), (half_l, -half_w))
        self._footprint_radius_m = math.hypot(half_l, half_w)
        self._apply_fault_changes()

    @property
    def time_s(self) -> float:
        """Sim time since boot."""
        return self._steps * self.params.physics_dt_s

    # ------------------------------------------------------------------ actuation and time

    def set_motor_pwm(self, left_us: float, right_us: float) -> None:
        """Motor PWM, 1000..2000 us (1500 neutral; beyond is clamped), held until the next call."""
        if not (math.isfinite(left_us) and math.isfinite(right_us)):
            raise ValueError(f"set_motor_pwm: PWM must be finite, got {left_us!r}, {right_us!r}")
        self.pwm_left_us, self.pwm_right_us = left_us, right_us
        self.drive.set_volts(self.drive.pwm_to_volts(left_us), self.drive.pwm_to_volts(right_us))

    def step(self, dt_s: float) -> list[Event]:
        """Advance sim time by ``dt_s`` (whole 1 ms substeps; fractions carry to the next call)."""
        if not (math.isfinite(dt_s) and dt_s >= 0):
            raise ValueError(f"step: dt_s must be a finite number >= 0, got {dt_s}")
        self._target_s += dt_s
        target = round(self._target_s / self.params.physics_dt_s)
        while self._steps < target:
            next_check = (self._steps // self._check_every + 1) * self._check_every
            next_fault = next((s for s in self._fault_steps if s > self._steps), None)
            stop = min(target, next_check, next_fault if next_fault is not None else target)
            self.drive.advance(stop - self._steps)
            self._steps = stop
            if stop == next_fault:
                self._apply_fault_changes()
            if stop == next_check:
                self._check_collisions()
        events, self._pending = self._pending, []
        return events

    def set_fault(self, name: str, value: float) -> None:
        """Set a SIM_* fault parameter (``sitl.faults.FAULT_PARAMS``); FaultError if unknown/invalid."""
        self.faults.set(name, value)
        self.drive.slip = self.faults.wheel_slip
        self._pending.append(Event("fault", self.time_s, {"name": name, "value": self.faults.manual[name],
                                                         "active": self.faults.manual[name] != 0}))

    def _apply_fault_changes(self) -> None:
        # Fault windows are resolved to the nearest substep: evaluate half a substep ahead so a
        # start or end time that falls on this substep counts whatever its rounding.
        for fault, active in self.faults.update(self.time_s + self.params.physics_dt_s / 2.0):
            self._pending.append(Event("fault", self.time_s, {"name": fault.name, "active": active, **fault.params}))
        self.drive.slip = self.faults.wheel_slip

    def _footprint(self, east_m: float, north_m: float, yaw_rad: float) -> Polygon:
        c, s = math.cos(yaw_rad), math.sin(yaw_rad)
        return Polygon([(east_m + c * f - s * l, north_m + s * f + c * l) for f, l in self._corners])

    def _check_collisions(self) -> None:
        d, t = self.drive, self.time_s
        reach = self._footprint_radius_m + self.params.contact_release_m
        near = self.world.near((d.east_m, d.north_m), reach, t)
        if not near and not self._contacts:
            self._checkpoint = (d.east_m, d.north_m, d.yaw_rad)
            return
        footprint = self._footprint(d.east_m, d.north_m, d.yaw_rad)
        shapes = {o.id: o.shape(t) for o in near}
        hits = [ident for ident, shape in shapes.items() if footprint.intersects(shape)]
        if hits:
            before = self._footprint(*self._checkpoint)
            if not any(before.intersects(shapes[ident]) for ident in hits):
                d.east_m, d.north_m, d.yaw_rad = self._checkpoint
                d.stop_wheels()
                footprint = before
        else:
            self._checkpoint = (d.east_m, d.north_m, d.yaw_rad)
        for ident in hits:
            if ident not in self._contacts:
                self._contacts.add(ident)
                lat, lon = self.frame.to_latlon(d.east_m, d.north_m)
                self._pending.append(Event("collision", t, {"obstacle": ident, "lat_deg": float(lat), "lon_deg": float(lon),
                                                           "east_m": d.east_m, "north_m": d.north_m}))
        for ident in list(self._contacts):
            if ident not in shapes or footprint.distance(shapes[ident]) > self.params.contact_release_m:
                self._contacts.discard(ident)

    # ------------------------------------------------------------------ sensors

    def gps(self) -> GpsSample | None:
        """A fix now, or None during an outage or a dropout (call at the GPS rate)."""
        d = self.drive
        v = d.speed_mps
        return self._gps.sample(self.time_s, d.east_m, d.north_m, (v * math.cos(d.yaw_rad), v * math.sin(d.yaw_rad)), self.faults)

    def attitude(self) -> AttitudeSample:
        return self._imu.sample(self.time_s, self.drive.yaw_rad, self.drive.yaw_rate_radps)

    def rangefinders(self) -> list[RangeSample]:
        """One sample per rangefinder; silent ones are left out, stuck ones repeat their value."""
        d, t = self.drive, self.time_s
        samples = (r.sample(t, d.east_m, d.north_m, d.yaw_rad, self.world, self.faults) for r in self._rangefinders)
        return [s for s in samples if s is not None]

    def wheels(self) -> WheelSample:
        return self._encoders.sample(self.time_s, self.drive.angle_l_rad, self.drive.angle_r_rad)

    def truth(self) -> TruthState:
        d = self.drive
        lat, lon = self.frame.to_latlon(d.east_m, d.north_m)
        to_rpm = 60.0 / (2.0 * math.pi)
        return TruthState(
            self.time_s, float(lat), float(lon), self.home.alt_m, d.east_m, d.north_m,
            (90.0 - math.degrees(d.yaw_rad)) % 360.0, d.speed_mps, -math.degrees(d.yaw_rate_radps),
            d.wheel_l_radps * to_rpm, d.wheel_r_radps * to_rpm, d.volts_l, d.volts_r,
            d.current_l_a, d.current_r_a, self.params.motor.battery_v)
