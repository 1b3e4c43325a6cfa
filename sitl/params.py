"""The emulator's parameters: every number the simulated rover is made of, named, with its unit.

Defaults describe the paper's robot (Wondosen & Shiferaw 2017: 6 kg, track 0.32 m, wheel radius
0.07 m, motor constant 0.1 V/(rad/s)) with consumer-grade sensors. The emulator shares nothing with
the daemon's ``rover_ctl.config``: it stands for the physical rover.

Drive-train derivation (defaults). Per wheel, with gear ratio N between motor and wheel
(motor speed w_m = N w), the steady state of ``L di/dt + R i = V - Ke N w`` and
``J dw/dt + N^2 b w = N Kt i`` (inertias reflected to the wheel) is::

    w_ss = Kt V / (N (R b + Kt Ke))
         = 0.1 * 12 / (5 * (4 * 1e-4 + 0.01)) = 23.1 rad/s = 220 rpm  (1.62 m/s)

and, the electrical time constant L/R = 0.5 ms being negligible, the straight-line mechanical time
constant is::

    tau = (J_wheel + N^2 J_rotor + m r^2 / 2) R / (N^2 (R b + Kt Ke))
        = (2.5e-4 + 25 * 1e-4 + 6 * 0.07^2 / 2) * 4 / (25 * 0.0104) = 0.27 s

(each wheel carries half the robot's mass; turning in place each carries I_z r^2 / track^2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field


@dataclass
class MotorParams:
    """One brushed DC motor with its gearbox and the battery driving it through an H-bridge."""

    battery_v: float = 12.0
    """Battery voltage; PWM maps to motor voltage as (pwm - neutral) / range * battery_v."""
    pwm_neutral_us: float = 1500.0
    """PWM width for zero voltage."""
    pwm_range_us: float = 500.0
    """PWM offset from neutral that gives full battery voltage (1000 and 2000 us are full reverse/forward)."""
    resistance_ohm: float = 4.0
    """Armature resistance R (sets the mechanical time constant and the 3 A stall current)."""
    inductance_h: float = 0.002
    """Armature inductance L (electrical time constant L/R = 0.5 ms)."""
    ke_v_per_radps: float = 0.1
    """Back-EMF constant at the motor shaft (the paper's motor constant)."""
    kt_nm_per_a: float = 0.1
    """Torque constant at the motor shaft (equal to Ke in SI units)."""
    gear_ratio: float = 5.0
    """Motor turns per wheel turn N."""
    rotor_inertia_kgm2: float = 1e-4
    """Rotor inertia J at the motor shaft."""
    viscous_nms_per_rad: float = 1e-4
    """Viscous friction b at the motor shaft (bearings, gearbox)."""

    def steady_wheel_radps(self, volts: float) -> float:
        """Closed-form steady wheel speed for a constant voltage: Kt V / (N (R b + Kt Ke))."""
        return self.kt_nm_per_a * volts / (
            self.gear_ratio * (self.resistance_ohm * self.viscous_nms_per_rad + self.kt_nm_per_a * self.ke_v_per_radps)
        )


@dataclass
class RobotParams:
    """The rover's body (defaults: the paper's robot)."""

    mass_kg: float = 6.0
    track_m: float = 0.32
    """Distance between the left and right wheel contact lines."""
    wheel_radius_m: float = 0.07
    wheel_inertia_kgm2: float = 2.5e-4
    """Inertia of one wheel about its axle (0.1 kg disc of radius 0.07 m)."""
    footprint_length_m: float = 0.45
    """Length of the rectangular footprint used for collisions (centred on the axle midpoint)."""
    footprint_width_m: float = 0.40
    yaw_inertia_kgm2: float | None = None
    """Inertia about the vertical axis; None: a uniform box of the footprint, m (l^2 + w^2) / 12."""

    @property
    def yaw_inertia(self) -> float:
        if self.yaw_inertia_kgm2 is not None:
            return self.yaw_inertia_kgm2
        return self.mass_kg * (self.footprint_length_m**2 + self.footprint_width_m**2) / 12.0


@dataclass
class GpsParams:
    """A consumer GNSS receiver (u-blox M8 class, open sky).

    Error per horizontal axis = white noise + first-order Gauss-Markov bias + glitch offset. Such
    receivers are good to ~2.5 m CEP, and most of that error is correlated over minutes (multipath
    and atmosphere), so the bias dominates: per-axis 1-sigma sqrt(0.5^2 + 1.0^2) = 1.1 m."""

    rate_hz: float = 5.0
    white_std_m: float = 0.5
    """Per-axis standard deviation of the sample-to-sample noise."""
    bias_std_m: float = 1.0
    """Per-axis stationary standard deviation of the wandering bias."""
    bias_tau_s: float = 120.0
    """Correlation time of the bias (Gauss-Markov: autocorrelation exp(-|dt| / tau))."""
    dropout_prob: float = 0.002
    """Probability that a fix is lost (sample returns None) independently of faults."""
    speed_std_mps: float = 0.05
    """Per-axis white noise on the reported velocity (speed and course are derived from it)."""
    alt_std_m: float = 1.5
    satellites: int = 10
    fix_type: int = 3
    """GPS_FIX_TYPE reported while the receiver has a fix (3 = 3D)."""

    @property
    def eph_m(self) -> float:
        """The per-axis 1-sigma the receiver reports: consistent with the error model."""
        return math.hypot(self.white_std_m, self.bias_std_m)


@dataclass(frozen=True)
class RangefinderMount:
    """Where one rangefinder sits on the body and where it looks.

    ``orientation`` is MAV_SENSOR_ORIENTATION (0 front, 1 yaw 45 right, 2 right, ..., 7 yaw 315);
    the beam looks ``orientation * 45`` degrees clockwise from the nose."""

    sensor_id: int
    orientation: int
    forward_m: float
    """Mount position ahead of the axle midpoint."""
    left_m: float
    """Mount position left of the axle midpoint."""

    @property
    def bearing_rad(self) -> float:
        """Beam direction in the body frame, counter-clockwise from the nose (ENU convention)."""
        return -self.orientation * math.pi / 4.0


def default_rangefinders() -> list[RangefinderMount]:
    """Front, back, left, right (the paper's four) plus front-left and front-right at 45 degrees,
    on the edges of the 0.45 x 0.40 m footprint."""
    half_l, half_w = 0.225, 0.20
    return [
        RangefinderMount(0, 0, half_l, 0.0),
        RangefinderMount(1, 4, -half_l, 0.0),
        RangefinderMount(2, 6, 0.0, half_w),
        RangefinderMount(3, 2, 0.0, -half_w),
        RangefinderMount(4, 7, half_l, half_w),
        RangefinderMount(5, 1, half_l, -half_w),
    ]


def paper_rangefinders() -> list[RangefinderMount]:
    """The paper's four sensors only: front, back, left, right."""
    return default_rangefinders()[:4]


@dataclass
class RangefinderParams:
    """Ultrasonic rangefinders (HC-SR04 class)."""

    rate_hz: float = 20.0
    min_m: float = 0.2
    """Closer echoes are reported as min_m."""
    max_m: float = 4.0
    """Nothing within max_m: no echo (range None)."""
    fov_deg: float = 15.0
    """Full beam width; the nearest hit over the beam is reported."""
    rays_per_beam: int = 5
    """Rays cast across the beam (evenly from -fov/2 to +fov/2)."""
    noise_std_m: float = 0.02
    """White noise on every echo."""
    sensors: list[RangefinderMount] = field(default_factory=default_rangefinders)


@dataclass
class ImuParams:
    """Compass and yaw-rate gyro (MEMS IMU class)."""

    rate_hz: float = 50.0
    compass_noise_std_deg: float = 1.0
    """White noise per compass sample."""
    compass_bias_std_deg: float = 2.0
    """Standard deviation of the constant compass offset drawn per run (calibration residue)."""
    gyro_noise_std_dps: float = 0.3
    """White noise per gyro sample."""
    gyro_bias_std_dps: float = 0.1
    """Stationary standard deviation of the Gauss-Markov gyro bias."""
    gyro_bias_tau_s: float = 300.0


@dataclass
class EncoderParams:
    """Quadrature wheel encoders reporting cumulative distance."""

    rate_hz: float = 50.0
    ticks_per_rev: int = 1440
    """Counts per wheel turn: distance quantum 2 pi r / ticks (0.3 mm)."""
    slip_noise_m2_per_m: float = 1e-4
    """Variance of the random walk between wheel and ground per metre rolled (1 cm after 1 m)."""


@dataclass
class SitlParams:
    """All sections of the emulator."""

    motor: MotorParams = field(default_factory=MotorParams)
    robot: RobotParams = field(default_factory=RobotParams)
    gps: GpsParams = field(default_factory=GpsParams)
    rangefinder: RangefinderParams = field(default_factory=RangefinderParams)
    imu: ImuParams = field(default_factory=ImuParams)
    encoder: EncoderParams = field(default_factory=EncoderParams)
    physics_dt_s: float = 0.001
    """Fixed integration substep."""
    collision_check_s: float = 0.01
    """Interval of footprint-versus-obstacle checks (2 cm of travel at top speed)."""
    contact_release_m: float = 0.05
    """A contact ends once the footprint is this far from the obstacle (one event per contact)."""


RANGEFINDER_SETS = {"default": default_rangefinders, "paper": paper_rangefinders}
"""Named rangefinder layouts: ``default`` (six: the paper's four plus front-left/right at 45 deg)
and ``paper`` (front, back, left, right)."""


@dataclass(frozen=True)
class Limits:
    """The values a numeric parameter may take: finite, above ``low`` (from it with ``low_included``)
    and up to ``high``, in ``unit``."""

    low: float = 0.0
    high: float = math.inf
    low_included: bool = False
    unit: str = ""

    def admits(self, value: float) -> bool:
        above = self.low <= value if self.low_included else self.low < value
        return above and value <= self.high and math.isfinite(value)

    def __str__(self) -> str:
        low = f"{'>=' if self.low_included else '>'} {self.low:g}"
        text = low if math.isinf(self.high) else f"{low} and <= {self.high:g}"
        return f"{text} {self.unit}" if self.unit else text


def between(low: float, high: float, unit: str = "") -> Limits:
    """``low`` to ``high`` inclusive, in ``unit``."""
    return Limits(low, high, low_included=True, unit=unit)


POSITIVE = Limits()
"""The rule for a sensor parameter LIMITS does not name: a magnitude (a rate, time constant, count)
that cannot be zero."""
NON_NEGATIVE = Limits(low_included=True)
NOISE = Limits(0.0, 100.0, low_included=True)
"""A noise or bias spread in its field's unit (m, m/s, deg, deg/s): more is a broken sensor, and
pushes the telemetry out of its MAVLink fields."""
LIMITS: dict[str, Limits] = {
    # The drive and the body: every field has a realistic range, from a 0.1 kg toy on N20 micro
    # gearmotors (6 V, 20-60 ohm, 1000:1) to a 1 t research platform on 1 kW wheelchair or hub
    # motors (24-48 V, 0.05-0.2 ohm, direct drive). Within them the exact discretisation of
    # sitl.physics stays finite and decaying (its docstring; a test sweeps every corner), and
    # inconsistency() refuses combinations that drive faster or turn more per substep than the
    # emulator models.
    "motor.battery_v": between(3.0, 65.534, "V"),  # one lithium cell; SYS_STATUS carries millivolts in a uint16
    "motor.pwm_neutral_us": between(500.0, 2500.0, "us"),  # the span of any RC servo pulse
    "motor.pwm_range_us": between(50.0, 1000.0, "us"),
    "motor.resistance_ohm": between(0.01, 100.0, "ohm"),
    "motor.inductance_h": between(1e-5, 0.1, "H"),  # 1e-300 overflowed the discretisation to NaN
    "motor.ke_v_per_radps": between(0.001, 10.0, "V/(rad/s)"),  # a 30 000 rpm micro motor to a slow hub motor
    "motor.kt_nm_per_a": between(0.001, 10.0, "N m/A"),
    "motor.gear_ratio": between(1.0, 1000.0),  # direct drive to a micro gearmotor's 1000:1
    "motor.rotor_inertia_kgm2": between(0.0, 0.01, "kg m^2"),  # a 1 kW motor's rotor is a few 1e-3
    "motor.viscous_nms_per_rad": between(0.0, 0.01, "N m s/rad"),  # 0.01: a 1 kW motor's whole torque at 300 rad/s
    "robot.mass_kg": between(0.1, 1000.0, "kg"),
    "robot.track_m": between(0.05, 5.0, "m"),  # as the daemon's RBT_TRACK (rover_ctl/parameters.py)
    "robot.wheel_radius_m": between(0.01, 1.0, "m"),  # as the daemon's WENC_RADIUS
    "robot.wheel_inertia_kgm2": between(0.0, 20.0, "kg m^2"),  # a 20 kg wheel of radius 1 m
    "robot.footprint_length_m": between(0.05, 10.0, "m"),  # as the daemon's RBT_LENGTH and RBT_WIDTH
    "robot.footprint_width_m": between(0.05, 10.0, "m"),
    "physics_dt_s": between(1e-6, 0.01, "s"),  # 1e-300 hung in one frame, deaf to SIGTERM; above 10 ms the pose steps coarsely
    "collision_check_s": between(1e-6, 0.1, "s"),
    "contact_release_m": between(0.0, 10.0, "m"),
    # Sensors: wire bounds and broken-sensor bounds; the rest is POSITIVE.
    "gps.white_std_m": NOISE,
    "gps.bias_std_m": NOISE,
    "gps.dropout_prob": Limits(0.0, 1.0, low_included=True),
    "gps.speed_std_mps": NOISE,
    "gps.alt_std_m": NOISE,
    "gps.satellites": Limits(0, 255, low_included=True),  # uint8 in GPS_RAW_INT
    "gps.fix_type": Limits(0, 255, low_included=True),
    # DISTANCE_SENSOR: centimetres in a uint16, and "no echo" is max + 1 cm
    "rangefinder.min_m": Limits(0.0, 655.34, low_included=True),
    "rangefinder.max_m": Limits(0.0, 655.34),
    "rangefinder.fov_deg": Limits(0.0, 360.0, low_included=True),
    "rangefinder.rays_per_beam": Limits(0, 1000),  # each ray is cast every sample: a billion exhausted memory
    "rangefinder.noise_std_m": NOISE,
    "imu.compass_noise_std_deg": NOISE,
    "imu.compass_bias_std_deg": NOISE,
    "imu.gyro_noise_std_dps": NOISE,
    "imu.gyro_bias_std_dps": NOISE,
    "encoder.slip_noise_m2_per_m": NON_NEGATIVE,
}
"""What ``--set`` admits, by ``SECTION.FIELD`` as it names them; a field not here is POSITIVE. Every
field of the drive and the body (``motor``, ``robot``, the physics step) is here with its range."""
MAX_TOP_SPEED_MPS = 30.0
"""The drive's no-load top speed at full battery at most (r times the steady wheel speed): six
times a Warthog-sized platform's 5 m/s, room for a fast hobby build, and far below GPS_RAW_INT's
655 m/s (a uint16 of cm/s), which 65 V on a motor of ke 0.001 V/(rad/s) driving 1 m wheels
overflowed mid-run though each value was in range."""
MAX_SUBSTEP_TURN_RAD = 0.1
"""The most the heading may turn in one physics substep at the top turn rate (wheels at full
opposite speeds, 2 v_top / track). The pose is integrated explicitly with the mid-step heading:
it cannot diverge, but it cuts arcs into chords, and at 0.1 rad (6 deg) a chord is within 0.05%
of the arc."""


def inconsistency(params: SitlParams) -> str | None:
    """Why fields that each passed their LIMITS cannot go together, or None.

    The drive's linear system is discretised exactly (sitl.physics): it is stable at any substep,
    and :func:`sitl.physics.drive_inconsistency` confirms that its discretisation is finite and
    decays. What remains explicit is the pose, integrated with the mid-step heading: it has no
    feedback to go unstable, but it is only as good as the turn per substep, bounded here
    (MAX_SUBSTEP_TURN_RAD), and the top speed bounds how far it goes (MAX_TOP_SPEED_MPS)."""
    from sitl.physics import drive_inconsistency  # sitl.physics imports this module

    r = params.rangefinder
    if not r.min_m < r.max_m:
        return f"rangefinder.min_m {r.min_m:g} must be below rangefinder.max_m {r.max_m:g}"
    motor, robot = params.motor, params.robot
    top_mps = robot.wheel_radius_m * motor.steady_wheel_radps(motor.battery_v)
    if top_mps > MAX_TOP_SPEED_MPS:
        return (f"the motor.* and robot.* fields give a top speed of {top_mps:.3g} m/s (robot.wheel_radius_m times the steady "
                f"wheel speed at motor.battery_v), over {MAX_TOP_SPEED_MPS:g} m/s")
    turn_rad = 2.0 * top_mps / robot.track_m * params.physics_dt_s
    if turn_rad > MAX_SUBSTEP_TURN_RAD:
        return (f"physics_dt_s {params.physics_dt_s:g} s turns the rover {turn_rad:.3g} rad per substep at its top turn rate "
                f"(2 * {top_mps:.3g} m/s / robot.track_m {robot.track_m:g} m), over {MAX_SUBSTEP_TURN_RAD:g} rad: lower physics_dt_s")
    return drive_inconsistency(motor, robot, params.physics_dt_s)


def apply_override(params: SitlParams, assignment: str) -> None:
    """Apply one ``section.field=value`` (e.g. ``gps.white_std_m=2.5``) to ``params`` in place.

    Raises ValueError with a one-line message naming the key for an unknown section or field, a
    value that is not a number or is outside the field's LIMITS, or a non-scalar field.
    """
    import dataclasses

    key, sep, text = assignment.partition("=")
    path = key.strip().split(".")
    if not sep or len(path) not in (1, 2):
        raise ValueError(f"expected SECTION.FIELD=VALUE (or FIELD=VALUE), got {assignment!r}")
    target = params
    for name in path[:-1]:
        if not dataclasses.is_dataclass(getattr(target, name, None)):
            sections = [f.name for f in dataclasses.fields(params) if dataclasses.is_dataclass(getattr(params, f.name))]
            raise ValueError(f"{key}: unknown section {name!r} (known: {', '.join(sections)})")
        target = getattr(target, name)
    leaf = path[-1]
    fields = {f.name: f for f in dataclasses.fields(target)}
    current = getattr(target, leaf, None)
    if leaf not in fields or not isinstance(current, (int, float)) or isinstance(current, bool):
        scalars = [n for n in fields if isinstance(getattr(target, n), (int, float)) and not isinstance(getattr(target, n), bool)]
        raise ValueError(f"{key}: unknown numeric field {leaf!r} (known: {', '.join(scalars)})")
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{key}: expected a number, got {text.strip()!r}") from None
    limits = LIMITS.get(".".join(path), POSITIVE)
    if not limits.admits(value):
        raise ValueError(f"{key}: expected a finite number {limits}, got {text.strip()!r}")
    if isinstance(current, int):
        if value != int(value):
            raise ValueError(f"{key}: expected a whole number, got {text.strip()!r}")
        value = int(value)
    setattr(target, leaf, value)
