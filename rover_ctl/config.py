"""The daemon's one configuration object.

Every tunable number of the daemon lives here as a named, documented field of a section
dataclass, with its unit in the name. ``Config`` groups the sections; ``load_config`` reads a TOML
file whose tables are the section names (``[robot]``, ``[link]``, ...) and applies dotted
``section.field=value`` (or ``NAME=value``, a parameter's MAVLink name) overrides from the command
line. Every numeric field is a parameter of ``rover_ctl.parameters`` (MAVLink name, range, units),
and every value from the file, the command line or a ground station goes through that table:
unknown sections or keys, values of the wrong type, out of range or not finite are refused with a
one-line error naming the file and key.

The SITL emulator has its own parameters (``sitl.params``): it stands for the physical rover and
shares nothing with the daemon but the wire.
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rover_ctl import inputfile


class ConfigError(ValueError):
    """A configuration file or override that cannot be used; the message names what and where."""


@dataclass
class RobotParams:
    """The rover as the controller knows it (defaults: the paper's robot)."""

    track_m: float = 0.32
    """Distance between the left and right wheel contact lines."""
    wheel_radius_m: float = 0.07
    """Wheel radius: wheel rpm <-> ground speed (ArduPilot WENC_RADIUS)."""
    max_wheel_rpm: float = 200.0
    """Wheel speed the navigator may command at most (the paper's forward_fast peak)."""
    footprint_length_m: float = 0.45
    """Length of the rectangular footprint (front/back rangefinders sit on its edges)."""
    footprint_width_m: float = 0.40
    """Width of the footprint: the planner keeps half of it plus the clearance margin free."""

    @property
    def max_speed_mps(self) -> float:
        """Top ground speed: wheel rpm -> rad/s -> m/s."""
        import math

        return self.max_wheel_rpm * 2.0 * math.pi / 60.0 * self.wheel_radius_m


@dataclass
class LinkParams:
    """The vehicle link: how the daemon talks to the rover (or the SITL)."""

    vehicle_url: str = "tcp:127.0.0.1:5760"
    """pymavlink connection string of the vehicle (udp/tcp/serial)."""
    gcs_url: str = "udpout:127.0.0.1:14550"
    """pymavlink connection string of the ground-station link."""
    source_system: int = 255
    """Our system id on the vehicle link; ArduPilot accepts RC overrides only from MAV_GCS_SYSID (255; SYSID_MYGCS before Rover 4.7)."""
    source_component: int = 190
    """Our component id on the vehicle link (MAV_COMP_ID_MISSIONPLANNER, as a ground station)."""
    heartbeat_period_s: float = 1.0
    """Our HEARTBEAT period on the vehicle link."""
    override_timeout_s: float = 1.0
    """The vehicle's RC override timeout: overrides must be refreshed faster than this."""
    wheel_left_index: int = 0
    """WHEEL_DISTANCE.distance[] entry of the left wheel. ArduPilot orders them by encoder
    instance (WENC, WENC2); its simulated instance 0 is the RIGHT wheel, so a stock ArduPilot SITL
    rover needs 1 here and 0 in ``wheel_right_index`` (docs/ardupilot.md)."""
    wheel_right_index: int = 1
    """WHEEL_DISTANCE.distance[] entry of the right wheel."""
    wheel_left_sign: float = 1.0
    """+1, or -1 for an encoder that counts backwards when its wheel rolls forwards."""
    wheel_right_sign: float = 1.0
    """+1, or -1 for an encoder that counts backwards when its wheel rolls forwards."""
    rangefinders: list[int] = field(default_factory=lambda: [-1])
    """DISTANCE_SENSOR orientations the rover has. ``[-1]`` (default): learnt from what the vehicle
    reports during ``rangefinder_discovery_s``; ``[]``: none (GPS-only navigation, avoidance off);
    otherwise the list, e.g. ``[0, 2, 4, 6]`` (docs/ardupilot.md, "Rangefinders")."""
    rangefinder_discovery_s: float = 3.0
    """Vehicle seconds after the first sensor message during which reporting rangefinders are counted."""
    line_bytes_per_s: float = 0.0
    """The vehicle link's capacity one way, bytes per second. 0 (default): a serial device's baud
    rate / 10 (``/dev/ttyUSB0,57600``: 5760), ``network_bytes_per_s`` for UDP and TCP
    (``rover_ctl.mavlink.budget``)."""
    network_bytes_per_s: float = 100_000.0
    """The capacity assumed for a UDP or TCP vehicle link (generous: a radio bridged to the network
    must set ``line_bytes_per_s`` instead)."""
    line_use_max: float = 0.7
    """Share of the line the requested message rates may fill; the rest is for what the vehicle
    sends unasked (heartbeats, acknowledgements, STATUSTEXT) and for bursts."""
    rate_window_s: float = 2.0
    """Vehicle time over which the link measures each message's rate (link health, sensor-rate failsafe)."""
    health_period_s: float = 10.0
    """Wall seconds between two link-health lines in the daemon's log and event log."""
    radio_txbuf_low_pct: float = 50.0
    """RADIO_STATUS.txbuf (free space of the local radio's transmit buffer, percent) below which
    the daemon sends RC overrides less often, as ArduPilot slows its streams."""
    radio_status_timeout_s: float = 3.0
    """A RADIO_STATUS older than this (wall seconds) no longer thins the overrides: the radio was
    reset or stopped reporting (a SiK radio sends one a second)."""
    override_min_hz: float = 4.0
    """The slowest the daemon refreshes RC overrides when its radio's buffer is full (well inside
    ArduPilot's RC_OVERRIDE_TIME, 3 s by default)."""


@dataclass
class PlannerParams:
    """Global planner (``rover_ctl.navigation.planner``): visibility graph around fences and known obstacles."""

    clearance_margin_m: float = 0.5
    """Kept free beyond the robot's half-width: obstacles and exclusion zones are inflated, and
    inclusion fences shrunk, by ``robot.footprint_width_m / 2 + clearance_margin_m``."""
    circle_segments: int = 16
    """Vertices of the polygon that stands for an inflated circle (circumscribed, so it never
    cuts into the clearance); more vertices: shorter paths, a bigger graph (over its node budget
    the planner refuses to plan: docs/missions.md)."""
    lookahead_m: float = 3.0
    """Carrot distance: the path target is this far along the path beyond the rover's projection."""
    max_corner_cut_m: float = 0.25
    """Where the path bends, the carrot is pulled back towards the rover until the straight line
    from the rover to it passes within this of every bend between (pure pursuit cuts corners, and
    the rover drives roughly that line): a bend around an obstacle then keeps at least
    ``clearance_margin_m`` minus this free, where a 3 m carrot cut a tight detour by up to a metre."""
    projection_window_m: float = 10.0
    """The rover is projected on the path only up to this far beyond its last projection, so a
    path that comes back near itself does not make the carrot jump ahead."""
    replan_off_path_m: float = 3.0
    """Re-plan from the current position when the cross-track error exceeds this."""
    replan_min_interval_s: float = 1.0
    """At most one re-plan per this interval (a new goal or a new blocked segment always re-plans)."""
    blocked_radius_m: float = 0.6
    """Radius of the temporary circular obstacle placed where the daemon reports a blocked leg."""
    blocked_ttl_s: float = 30.0
    """A temporary obstacle is forgotten after this long (moving obstacles go away)."""


@dataclass
class ExecutorParams:
    """Mission executor (``rover_ctl.autopilot.executor``), ArduPilot Rover's WP_* / RTL_* counterparts."""

    acceptance_radius_m: float = 2.0
    """Waypoint reached within this distance when the item's param2 is 0 (ArduPilot WP_RADIUS)."""
    cruise_speed_mps: float = 1.2
    """Speed limit in AUTO until a DO_CHANGE_SPEED (ArduPilot WP_SPEED); clamped to the robot's max."""
    rtl_speed_mps: float = 0.0
    """Speed limit in RTL; 0 uses the current mission speed (ArduPilot RTL_SPEED)."""
    rtl_radius_m: float = 2.0
    """Home reached within this distance, in RTL mode or at a NAV_RETURN_TO_LAUNCH item."""
    max_items_per_update: int = 64
    """Non-navigation items (DO_*, skipped ones) executed in one update at most: a mission that
    jumps in a loop without a navigation command stops with a warning instead of hanging."""


@dataclass
class FailsafeParams:
    """Failsafes (``rover_ctl.autopilot.failsafe``); docs/failsafes.md gives trigger, action and recovery."""

    recovery_s: float = 2.0
    """A failsafe clears only after its cause has been gone this long (hysteresis)."""
    vehicle_timeout_s: float = 0.4
    """Vehicle link silent (no message at all) for longer than this: motors neutral, hold."""
    gcs_timeout_s: float = 5.0
    """GCS heartbeat older than this, once one was seen: GCS lost (ArduPilot FS_GCS_TIMEOUT)."""
    gcs_action: str = "continue"
    """On GCS loss: "continue" the mission, "hold" or "rtl" (ArduPilot FS_GCS_ENABLE/FS_ACTION)."""
    rangefinder_timeout_s: float = 0.5
    """A rangefinder silent for longer than this is reported so the navigator treats that side as blocked."""
    required_rangefinders: list[int] = field(default_factory=lambda: [-1])
    """DISTANCE_SENSOR orientations that must keep reporting: one silent holds the rover, with a
    STATUSTEXT naming it. ``[-1]`` (default): every rangefinder the rule base reads on this rover
    (the rangefinder plan). A rangefinder the rule base reads that is not listed: while it is
    silent its side counts as blocked and the rover goes on at ``degraded_speed_mps``."""
    degraded_speed_mps: float = 0.5
    """Speed limit while a rangefinder the rule base reads, but not a required one, is silent."""
    range_travel_m: float = 0.15
    """The rover moves at most this far between two readings of a rangefinder the navigator reads:
    the speed is limited to this times the slowest such rangefinder's measured rate (3 m/s at
    20 Hz, 1.2 m/s at 8 Hz), so that a slow line does not let it outrun its avoidance."""
    min_sensor_rate_hz: float = 4.0
    """ATTITUDE or WHEEL_DISTANCE arriving slower than this (measured on the vehicle link over
    ``link.rate_window_s``) holds the rover: the estimator cannot follow it. The link budget
    never plans below it."""
    gps_timeout_s: float = 1.0
    """No GPS fix for longer than this: dead reckoning."""
    dead_reckoning_max_s: float = 20.0
    """Dead reckoning this long without a fix: hold."""
    estimator_unhealthy_s: float = 0.5
    """Estimator unhealthy for longer than this: hold."""
    fence_action: str = "hold"
    """On a fence breach: "hold" or "rtl" (ArduPilot FENCE_ACTION)."""
    stuck_window_s: float = 4.0
    """Stuck: motion commanded for this long while the rover moved less than stuck_progress_m."""
    stuck_progress_m: float = 0.3
    """Moving less than this within stuck_window_s while commanded to move counts as stuck."""
    stuck_min_command_mps: float = 0.2
    """A forward speed setpoint above this counts as commanded motion."""
    parked_window_s: float = 10.0
    """Stuck too: the rule base, given a speed to make, no yield holding it back and something
    ahead (a front rangefinder within side_guard.front_clear_m), commanded less than
    stuck_min_command_mps and moved less than stuck_progress_m for this long (s; 0: off): it had
    settled facing obstacles on both sides of its way (docs/failsafes.md)."""
    back_off_s: float = 2.0
    """How long to back off when stuck, before a re-plan."""
    back_off_speed_mps: float = 0.3
    """Reverse speed while backing off (the daemon drives it)."""
    back_off_clear_m: float = 0.3
    """Backing off stops short, the wheels held for the rest of ``back_off_s``, while the back
    rangefinder reads within this (m); 0: back off blind. Blind, a rover stuck turning in a
    cul-de-sac's corner backed into the wall behind it (in-process runner, cul_de_sac seed 97 with
    the persistent-obstacle map on: the back beam read 0.68 m as the back-off began, 0.2 m at the
    contact)."""
    stuck_max_tries: int = 3
    """Back-offs before giving up and holding."""
    stuck_clear_m: float = 3.0
    """Travelling this far after a back-off counts as free again: the tries start over."""


@dataclass
class EstimatorParams:
    """The pose filter (rover_ctl.estimation.estimator): sensor noise, gating, recovery and health.

    Noise densities are 1-sigma; a ``..._per_sqrt_s`` figure adds ``value**2 * dt`` of variance
    per ``dt`` seconds of prediction (a random walk)."""

    gyro_noise_rad_per_sqrt_s: float = 0.003
    """Heading random walk from gyro noise (angle random walk), rad/sqrt(s)."""
    gyro_bias_walk_radps_per_sqrt_s: float = 0.0005
    """How fast the gyro bias may wander, (rad/s)/sqrt(s)."""
    gyro_bias_sigma0_radps: float = 0.02
    """Gyro bias uncertainty at start (a consumer MEMS gyro is within about 1 deg/s)."""
    compass_sigma_rad: float = 0.035
    """Compass heading white noise, 1-sigma (about 2 deg)."""
    compass_offset_sigma0_rad: float = 0.07
    """Compass offset (calibration residue, declination error) uncertainty at start, about 4 deg;
    the GPS course estimates it once the rover moves."""
    compass_offset_walk_rad_per_sqrt_s: float = 0.0005
    """How fast the compass offset may wander (motor currents, nearby iron), rad/sqrt(s)."""
    speed_accel_per_sqrt_s: float = 0.5
    """Random walk of the speed state between wheel readings, (m/s)/sqrt(s)."""
    wheel_speed_sigma_mps: float = 0.03
    """Wheel speed noise floor (encoder quantisation, timing), 1-sigma."""
    wheel_slip_fraction: float = 0.03
    """Longitudinal slip as a fraction of wheel speed, 1-sigma, added to the floor."""
    lateral_slip_per_sqrt_s: float = 0.03
    """Skid of the body sideways and along track not seen by wheels or gyro, m/sqrt(s)."""
    wheel_scale_sigma0: float = 0.03
    """Uncertainty of the wheel scale (encoder metres per metre travelled) at start: tyre size
    and wear, 1-sigma as a fraction."""
    wheel_scale_walk_per_sqrt_s: float = 0.0005
    """How fast the wheel scale may change (ground, load), 1/sqrt(s)."""
    wheel_max_speed_mps: float = 5.0
    """A wheel delta faster than this is a counter reset or a glitch: re-baseline, do not fuse."""
    gps_min_sigma_m: float = 0.5
    """Floor on a fix's 1-sigma: eph below this is not believed."""
    gps_default_sigma_m: float = 5.0
    """1-sigma used when a fix reports no eph (UINT16_MAX)."""
    gps_velocity_sigma_mps: float = 0.1
    """Per-axis 1-sigma of the GPS velocity (u-blox M8 class: 0.05-0.1 m/s); sets the course's
    sigma as atan(sigma / speed)."""
    gps_course_min_speed_mps: float = 0.5
    """Slower than this the GPS course says little and is not fused."""
    gate_sigma: float = 5.0
    """Innovation gate: a fix whose Mahalanobis distance exceeds this is rejected (EKF3's
    EK3_POS_I_GATE is 5 sigma too)."""
    glitch_reset_s: float = 5.0
    """Fixes rejected continuously for this long while the GPS moves unlike the odometry (the
    wheels slip, the rover slides or is carried, or dead reckoning drifted through an outage)
    mean the GPS really moved: reset the position to the GPS."""
    glitch_max_s: float = 60.0
    """A GPS jump (a step beyond the gate while fixes were being fused) after which the GPS keeps
    moving as the odometry does is a glitch: rejected for up to this long, then believed (reset),
    as EKF3 resets when its dead reckoning no longer knows better."""
    glitch_innovation_tau_s: float = 1.0
    """Time constant of the mean of the accepted fixes' innovations: the reference a jump is
    measured from (a slow drift moves it along, a jump leaves it behind)."""
    attitude_timeout_s: float = 0.5
    """Without ATTITUDE for this long the turn rate comes from the wheel speed difference."""
    max_lag_s: float = 0.5
    """Readings older than the filter's time by up to this are fused with lag compensation;
    older ones are dropped."""
    pose_max_lead_s: float = 0.25
    """The control step's pose is predicted from the last odometry reading to the step's time (a
    rangefinder or GPS message may set it between two readings) over at most this; a longer gap
    (odometry lost) is not bridged, the failsafes judge it."""
    clock_restart_s: float = 3.0
    """A reading this much older than the filter's time means the vehicle rebooted: start over."""
    gps_max_lead_s: float = 1.0
    """A fix stamped this far ahead of the wheels and compass is on another clock (ArduPilot
    stamps GPS_RAW_INT with UNIX time once it has GPS time): ignored."""
    gps_timeout_s: float = 1.0
    """gps_ok is false when no fix was fused for longer than this."""
    health_max_position_sigma_m: float = 5.0
    """healthy is false when the position 1-sigma (worst axis) exceeds this."""
    health_max_heading_sigma_rad: float = 0.26
    """healthy is false when the heading 1-sigma exceeds this (about 15 deg)."""


@dataclass
class GcsParams:
    """The GCS link: the daemon as the rover's autopilot, its mission service and the CLI client."""

    system_id: int = 1
    """Our MAVLink system id towards ground stations (SYSID_THISMAV)."""
    component_id: int = 1
    """MAV_COMP_ID_AUTOPILOT1."""
    ground_station_system_id: int = 255
    """The system id whose HEARTBEAT keeps the GCS-loss failsafe off (ArduPilot's MAV_GCS_SYSID,
    SYSID_MYGCS before Rover 4.7): a heartbeat from anyone else, a stranger on an unsigned link
    included, does not hide a lost ground station. 255 is QGroundControl's and MAVProxy's; MAVSDK
    uses 245. 0: any ground station's heartbeat counts."""
    heartbeat_period_s: float = 1.0
    """Our HEARTBEAT period on the GCS link."""
    mission_item_retry_s: float = 0.25
    """Upload: re-request the expected item after this long without it (the mission protocol's
    item timeout, mavlink.io services/mission "Timeouts and Retries")."""
    mission_upload_timeout_s: float = 1.5
    """Upload: cancel after this long without progress: 5 re-requests after the first (the
    protocol's default timeout, 1500 ms)."""
    mission_max_items: int = 700
    """Largest list (wire items, home included) accepted per mission type."""
    mission_upload_margin_s: float = 10.0
    """Upload deadline: one transaction (a sender's upload of one mission type, restarts included)
    must end within ``count * mission_upload_timeout_s`` plus this after its first MISSION_COUNT
    (``count`` the largest in it), or it is cancelled: an upload that keeps making progress takes
    at most the first term, and this covers a client's resent COUNTs (5, 1.5 s apart). A repeated
    COUNT does not extend it beyond that."""
    mission_upload_holdoff_s: float = 5.0
    """A sender whose upload was cancelled at its deadline (``mission_upload_margin_s``) may not
    start another of the same mission type for this long, so that another ground station (which
    resends its COUNT every 1.5 s) gets its turn."""
    max_messages_per_poll: int = 100
    """GCS link: messages read per loop turn at most, so a flood cannot starve the control loop."""
    max_peers: int = 8
    """A GCS link listening on UDP (udpin) sends to this many ground stations at most: an address
    becomes one when a frame from it passes signing (with a key) and the gate; a newcomer beyond
    this replaces the one silent longest."""
    mission_store_path: str = "~/.local/state/rover-ctl/mission.json"
    """Where the current mission, fence and rally are persisted; empty = not persisted."""
    position_rate_hz: float = 4.0
    """Default GLOBAL_POSITION_INT rate until a GCS asks for another (SET_MESSAGE_INTERVAL)."""
    gps_rate_hz: float = 2.0
    """Default GPS_RAW_INT rate to the GCS."""
    attitude_rate_hz: float = 10.0
    """Default ATTITUDE rate to the GCS."""
    sys_status_rate_hz: float = 1.0
    """Default SYS_STATUS rate to the GCS."""
    mission_current_rate_hz: float = 1.0
    """Default MISSION_CURRENT rate to the GCS."""
    vehicle_text_severity: int = 4
    """The vehicle's STATUSTEXTs this urgent or more (MAV_SEVERITY: 0 emergency .. 7 debug; 4 =
    WARNING) are passed on to the ground stations as the vehicle said them: behind the daemon the
    autopilot's own reasons ("PreArm: ...", ArduPilot's CRITICAL) reach nobody else. -1: none."""
    param_save_s: float = 1.0
    """Parameters set from a ground station are written to ``params.parm`` at most this often: the
    first change at once, later ones when this long has passed since the last write, and all on
    shutdown; a crash loses at most this long of changes (the answer reflects them at once)."""
    param_send_rate_hz: float = 50.0
    """PARAM_VALUE messages per second while answering PARAM_REQUEST_LIST (about 2.5 kB/s, under
    half of a 57600 baud telemetry radio)."""
    client_retry_s: float = 1.5
    """`rover-ctl mission` client: resend MISSION_COUNT, REQUEST_LIST or CLEAR_ALL after this long
    without an answer (the mission protocol's default timeout)."""
    client_item_retry_s: float = 0.25
    """Client: resend an item (upload) or an item request (download) after this long without an
    answer (the protocol's item timeout)."""
    client_retries: int = 5
    """Client: resends of one message before giving up with a timeout error (the protocol's 5)."""
    client_connect_timeout_s: float = 5.0
    """Client: wait this long for the autopilot's HEARTBEAT."""
    signing_key_path: str = "~/.local/state/rover-ctl/signing.key"
    """MAVLink 2 signing key (64 hex digits, mode 0600; its timestamp in ``<this>.timestamp``);
    with a key every GCS frame must be signed (docs/gcs.md, "Signing"); empty = no signing."""
    require_signing: bool = False
    """Refuse to run without a signing key, and refuse a SETUP_SIGNING that would disable signing."""
    signing_setup_from_loopback: bool = False
    """While no key is set, accept SETUP_SIGNING if the GCS link is loopback-only (bound to
    127.0.0.1 or ::1; off: only ``rover-ctl signing setup`` or a key holder can set a key)."""
    signing_timestamp_save_s: float = 30.0
    """The signing timestamp is saved this often and on shutdown; a start adds this much to the
    saved value, so a timestamp is never reused even after a crash (the MAVLink spec asks for at
    least once a minute)."""


@dataclass
class WheelControlParams:
    """Wheel-speed loop and RC mixing (``rover_ctl.navigation.wheel_control``)."""

    full_output_rpm: float = 220.0
    """Wheel speed at full motor output on flat ground: the feed-forward ``u = rpm / this``."""
    kp: float = 0.002
    """Proportional gain, motor output per rpm of error."""
    ki: float = 0.006
    """Integral gain, motor output per rpm*s of error."""
    integral_limit: float = 0.4
    """Bound on the integral term's share of the motor output."""
    integrate_max_rate_rpm_s: float = 100.0
    """The integrator runs only while the wheel's filtered speed changes slower than this (rpm/s;
    0.73 m/s^2 at the 0.07 m wheel). In a speed change the error is the drive train's own lag, which
    the feed-forward already allows for; integrated, it wound up. Against the emulator's drive
    train, odometry at 25 Hz, the control step on a wheel reading or 20 ms after one: slowing from
    160 to 10 rpm (1.17 to 0.07 m/s) drove the wheels backwards at up to 0.135 m/s, and slowing to
    40 rpm (0.29 m/s) dipped to 0.12-0.135 m/s for over a second; with this gate they dip to
    0.003-0.034 and 0.23-0.26 m/s. Speeding up from 40 to 160 rpm peaked at 1.33 m/s for 1.17,
    now 1.21."""
    speed_filter_tau_s: float = 0.06
    """Low-pass time constant on wheel speeds measured from WHEEL_DISTANCE deltas."""
    measurement_timeout_s: float = 0.3
    """Wheel speeds older than this are not trusted: feed-forward only."""
    brake_release_rpm: float = 3.5
    """Braking to a stop lets a wheel go (output 0) once its lag-corrected speed is below this
    (0.026 m/s at the 0.07 m wheel). With odometry at 25 Hz, stopping from 1.2 m/s against the
    emulator: at 0 the brake held on into reverse in 3 of 5 stops (up to 0.033 m/s backwards); at
    the 6.8 rpm of ``daemon.hold_speed_mps`` the rover still rolled at up to 0.022 m/s half a
    second after HOLD; at this value 0.004-0.024 m/s, at most 0.024 m/s backwards (6 stops)."""
    rc_trim_us: int = 1500
    """RC neutral (ArduPilot RC1/RC3_TRIM)."""
    rc_range_us: int = 500
    """RC full deflection from trim (RCx_MAX - RCx_TRIM)."""
    rc_deadzone_us: int = 30
    """The vehicle's RC dead zone (Rover's RC1_DZ/RC3_DZ default), inverted when mixing."""


@dataclass
class DaemonParams:
    """The control loop (``rover_ctl.app.daemon``) and its vehicle-link housekeeping."""

    control_rate_hz: float = 25.0
    """Control steps per second of vehicle (sensor) time."""
    loop_rate_window_s: float = 2.0
    """Vehicle time over which the control loop's achieved rate is measured
    (``rover_ctl.autopilot.loop_rate``)."""
    slow_loop_fraction: float = 0.8
    """The loop counts as slow (STATUSTEXT warning, speed limit) below this share of
    ``control_rate_hz``; it recovers above the midpoint between this and the full rate."""
    max_step_travel_m: float = 0.25
    """While the loop is slow, the speed is limited so that the rover moves at most this far
    between two control steps (6.25 m/s at 25 Hz: a loop that keeps up is never limited; 1.4 m/s at
    5.6 Hz, above the cruise speed: a tighter limit made the firmware at 50x track worse, 210 m
    driven for a 170 m mission against 182 m without it, as the slow stretch lasted longer)."""
    lockstep_silence_s: float = 2.0
    """In lockstep, wall-clock seconds without a message from the emulator before the vehicle-link
    failsafe acts on the wall clock (its 0.4 s ``failsafe.vehicle_timeout_s`` is vehicle time).
    A lockstep emulator's time stands still while its process waits for the CPU, so a loaded
    machine pauses it for a while without anything being wrong; a real vehicle sends no lockstep
    markers and gets the vehicle timeout on the wall clock."""
    vehicle_wait_s: float = 30.0
    """Start-up: give up when no vehicle heartbeat arrives within this (wall clock)."""
    command_timeout_s: float = 0.5
    """Vehicle COMMAND_LONG answered by no COMMAND_ACK within this is sent again."""
    command_retries: int = 3
    """Re-sends of an unanswered vehicle command before it counts as failed."""
    sensor_rate_hz: float = 25.0
    """Rate asked for ATTITUDE and (through EXTRA1) WHEEL_DISTANCE: the control rate. At 50 Hz the
    daemon reads and filters twice the odometry frames for the same pose (1.75 against 1.22 ms of
    CPU per step in `bench loop`'s timed runs; docs/daemon.md, "On a companion computer"); the
    estimator integrates between readings and predicts the pose to each step, and the brake
    corrects the wheel speeds for their lag."""
    gps_rate_hz: float = 5.0
    """Rate asked of the vehicle for GPS_RAW_INT."""
    rangefinder_rate_hz: float = 20.0
    """Rate asked of the vehicle for DISTANCE_SENSOR (each rangefinder)."""
    min_gps_rate_hz: float = 1.0
    """The link budget never plans GPS_RAW_INT below this."""
    min_rangefinder_rate_hz: float = 4.0
    """The link budget never plans DISTANCE_SENSOR below this (each rangefinder)."""
    core_rate_hz: float = 10.0
    """On a line too slow for everything, odometry and then the rangefinders are raised to this
    first, before odometry gets the full control rate (``rover_ctl.mavlink.budget``)."""
    status_rate_hz: float = 1.0
    """Rate asked for SYS_STATUS (the battery, forwarded to the ground station)."""
    truth_rate_hz: float = 10.0
    """SIMSTATE (emulator ground truth, logged for evaluation; a real vehicle ignores the request)."""
    stream_rerequest_s: float = 3.0
    """After this long without vehicle messages the stream rates are asked for again."""
    idle_wait_s: float = 0.05
    """Longest blocking wait for link input in one loop turn (wall clock; bounds reaction to GCS)."""
    hold_speed_mps: float = 0.05
    """Below this estimated speed a hold counts as stopped."""
    log_dir: str = ""
    """Where each start writes a new numbered run folder (vehicle.tlog, gcs.tlog, control.csv,
    events.jsonl) and the ``latest`` link to it; empty: no logs."""
    log_max_total_mb: float = 1000.0
    """Budget of all run folders together: at each start the oldest are removed (never the new
    one) until the rest fit; during a run the tlogs stop (one warning, a log_budget event) once
    the run's own folder exceeds it; 0 = no limit. A lockstep run of cmac_loop (155 s of sim time)
    writes about 4 MB."""
    link_chatter_s: float = 60.0
    """pymavlink's reconnect messages: each distinct line is logged at most once per this (wall
    clock), with a count of the repeats."""


@dataclass
class NavigatorParams:
    """The fuzzy navigator (``rover_ctl.navigation.navigator``): geometry and ranges to rule-base inputs."""

    paper_range_units_per_m: float = 5.0
    """Scale from metres to the obstacle units of a rule base whose obstacle inputs are not in
    metres (the paper's 0..20 units): 5 maps the emulator's 4 m rangefinders onto 0..20."""
    missing_range_m: float = 0.0
    """Range assumed for a rangefinder the rule base reads but the caller did not pass (or NaN):
    0 = that side is blocked, the safe reading the rangefinder failsafe relies on."""


@dataclass
class ProximityParams:
    """The short-term obstacle memory (``rover_ctl.navigation.proximity``) between rangefinders and navigator."""

    memory_s: float = 1.5
    """How long an echo is remembered: long enough to cover the turn that takes an obstacle out of
    a narrow beam, short enough that a moving obstacle leaves little trail."""
    sector_half_deg: float = 22.5
    """Each sensor answers for this much either side of its axis: with eight 45 degree directions
    the sectors tile the circle, as AP_Proximity's do."""
    edge_sectors: bool = True
    """The front and back sensors answer for their whole edge: a remembered echo counts for them
    anywhere ahead of (behind) the footprint's edge within ``sector_half_deg`` of its ends, at its
    distance from that edge, not only inside the cone from the sensor at the edge's middle. Near
    the bumper that cone is narrower than the rover (at 0.2 m, +-0.08 m of a 0.4 m wide one): an
    echo remembered there left every sector as the rover turned a little, and it drove on into the
    obstacle (``rover_ctl.navigation.proximity``). False: the cones alone."""
    horizon_s: float = 0.0
    """Prediction horizon: each sensor's range is also shortened to the closest approach of every
    moving obstacle track within this many seconds of its predicted path (its own motion only;
    ``rover_ctl.navigation.proximity``). 0: no prediction, the ranges are the echoes'."""
    prediction_step_s: float = 0.2
    """The predicted path is sampled this often (s): at 1 m/s, 0.2 m between samples."""
    track_gate_m: float = 0.8
    """An echo joins the nearest track predicted within this distance (m); else it starts one.
    About an obstacle's radius plus what it moves between two echoes."""
    track_confirm_hits: int = 4
    """Echoes before a track counts (a few rangefinder readings: one stray echo is no obstacle)."""
    track_coast_s: float = 0.8
    """A track without an echo for this long is dropped."""
    track_echo_sigma_m: float = 0.1
    """1-sigma of an echo's position along its beam: rangefinder noise plus the pose estimate's
    step-to-step jitter."""
    track_beam_half_deg: float = 7.5
    """Half-width of a rangefinder's cone (deg): an echo is placed on the beam's axis, but the
    obstacle may be anywhere across the cone, so across the beam its position is that uncertain
    too (``rover_ctl.navigation.tracks``). 0: an echo is as sure across the beam as along it."""
    track_accel_sigma_mps2: float = 1.0
    """White-noise acceleration of the constant-velocity model (m/s^2): a walking person changes
    speed and direction at about this rate."""
    track_init_speed_sigma_mps: float = 1.0
    """1-sigma of a new track's velocity (zero): obstacles move at walking pace or less."""
    track_min_speed_mps: float = 0.2
    """A track slower than this is static (what the noise of echoes and pose alone can fake)."""
    track_max_speed_mps: float = 2.0
    """A track faster than this is not an obstacle but a beam's echo sliding along a surface as the
    rover turns: treated as static."""
    track_pace_sigma: float = 2.0
    """A track whose velocity is within this many of its own standard deviations of the rover's
    keeps pace with it and is not moving (``rover_ctl.navigation.tracks``): a wall's echo slides
    across a side beam at the rover's speed, which the beam's cone leaves uncertain. 0: only
    ``track_min_speed_mps`` tells them apart."""
    track_max_count: int = 32
    """Tracks kept at once (bounds the control step's cost); a new one replaces the oldest silent one."""


@dataclass
class YieldParams:
    """Yielding to crossing traffic (``rover_ctl.navigation.yielding``): the speed along the path
    at which no moving obstacle track comes within the robot's radius plus ``margin_m``."""

    enabled: bool = True
    """Yield to crossing obstacles (needs their tracks: the obstacle memory builds them while this is on)."""
    horizon_s: float = 4.0
    """How far ahead the closest approach is looked for (s): at 1.2 m/s, 4.8 m of path, about the
    rangefinders' reach."""
    margin_m: float = 0.9
    """Clearance kept between the robot's outline (its circumscribed radius) and a crossing
    obstacle's near surface (m)."""
    release_margin_m: float = 0.3
    """A track yielded to is released only when full speed clears it by this much more (m), so
    that track noise does not make the rover lurch."""
    min_cross_mps: float = 0.15
    """A track counts as crossing when its velocity across the rover's heading is at least this
    (m/s); slower across, it walks along the rover's line and is steered around instead."""
    min_hits: int = 8
    """A track is yielded to only after this many echoes (about half a second of one rangefinder)."""
    max_speed_sd_mps: float = 0.3
    """...and only while the standard deviation of its velocity across the rover's course, the
    crossing it is yielded for, is at most this (m/s)."""
    min_travel_m: float = 0.6
    """...and only once it has gone this far from its first echo (m): an echo sliding over a static
    drum's face moves up to about its radius; 1.6 s of a pedestrian at 0.5 m/s."""
    max_heading_off_deg: float = 45.0
    """No new yield starts while the rover's heading is more than this off its course to the
    target (deg): it is turning around something, and its tracks' velocities are unreliable. At
    30 a crosser the rule base had already turned from (the way it walks) was never yielded to,
    and struck the rover's flank (the runner's ``moving`` seeds 61-160: 74 successes, at 45: 93);
    the price is more false yields at static drums passed mid-turn (docs/perception.md)."""
    after_evasion_s: float = 3.0
    """For this long after stepping aside from a walker (s), a new yield starts only within
    ``after_evasion_heading_off_deg`` of the course: the rover is turning back to its line, its
    tracks' velocities are swept, and a second walker coming head-on read as crossing would stop
    the rover in its way instead of being stepped aside from (SITL ``head_on`` seed 13). The walker
    stepped aside from is held to ``max_heading_off_deg`` (it crosses after all: SITL ``crossing`` 80)."""
    after_evasion_heading_off_deg: float = 30.0
    """...the heading limit then (deg); the evader's own is ``evasion.max_heading_off_deg``."""
    max_wait_s: float = 10.0
    """Longest an obstacle yielded to is still waited for after its track was lost (s): meanwhile
    it is taken to move on at its last velocity."""
    min_cross_deg: float = 45.0
    """...and its course at least this far off the rover's line (deg): a walker coming head-on or
    walking ahead, whose estimated velocity wobbles a little across the line, is steered around."""
    speed_steps: int = 4
    """Speeds tried below full: fractions (steps-1)/steps ... 0 of it (4: 75, 50, 25 and 0%)."""


@dataclass
class EvadeParams:
    """Stepping aside for oncoming traffic (``rover_ctl.navigation.evasion``): the heading and speed,
    found by rolling the rover out, that keep a walker coming head-on beyond the rover's half-width
    plus ``margin_m``."""

    enabled: bool = True
    """Step aside from oncoming obstacles (needs their tracks: the obstacle memory builds them while this is on)."""
    horizon_s: float = 3.0
    """How far ahead the rollouts look (s): two walkers closing at 2.2 m/s meet within the
    rangefinders' 4 m in under 2 s."""
    margin_m: float = 0.9
    """Clearance kept between the rover's side and the track's point, the obstacle's near surface
    (m): the largest walker's radius (0.5 m) and 0.4 m, as far as an echo placed on a 15-degree beam's axis 3 m out may be from where it came."""
    release_margin_m: float = 0.2
    """The manoeuvre ends once going straight along the course clears the track by this much more (m)."""
    min_hits: int = 6
    """A track is stepped aside from only after this many echoes (0.3 s of one rangefinder at 20 Hz)."""
    max_speed_sd_mps: float = 0.35
    """...and only while the standard deviation of its velocity along the rover's course, the
    closing it is stepped aside for, is at most this (m/s)."""
    min_travel_m: float = 0.45
    """...and only once it has gone this far from its first echo (m): a drum crossing the front
    beam gives echoes that come at the rover by up to its radius as its face passes (0.45: 0.5 s of a walker
    at 0.9 m/s; in the in-process runner, 0.35 instead struck one more crossing world in 100)."""
    min_closing_mps: float = 0.2
    """...and only when it comes towards the rover along its course at least this fast (m/s)."""
    max_cross_deg: float = 45.0
    """...and only when its course is within this of the rover's line (deg): a crosser is yielded to."""
    max_heading_off_deg: float = 30.0
    """No manoeuvre starts while the rover points more than this off its course (deg): turning, its
    tracks' velocities are unreliable."""
    min_start_speed_mps: float = 0.6
    """...nor while it goes slower than this (m/s): slowed or stopped, it is yielding or at close
    quarters, where the rule base drives."""
    min_start_range_m: float = 1.5
    """...nor for a track nearer ahead than this (m): no room is left to step aside."""
    max_velocity_jump_mps: float = 0.4
    """During the manoeuvre a live estimate replaces the latched one only while its velocity is
    within this of it (m/s): the turning rover's beams slide over the walker."""
    not_oncoming_s: float = 0.5
    """A manoeuvre ends once the live track has not closed on the rover along its course
    (``min_closing_mps``) for this long (s; 0: never), and none starts again for that track: the
    latch had kept a wrong first estimate (a crosser taken for a walker coming at the rover, SITL
    ``crossing`` world 80, stepped aside into for 1.8 s to a contact). Runner, seeds 1-300 of
    head_on, crossing and moving: 10 failed episodes with 0, 9 with 0.5 (docs/perception.md)."""
    side_free_m: float = 1.0
    """A side whose 45-degree rangefinder reads nearer than this is not stepped to (m)."""
    front_free_m: float = 0.8
    """No manoeuvre starts, and one under way ends, while the front rangefinder reads nearer than
    this (m): something other than the walker is in the rover's way, which the rollouts do not
    see, and the rule base is better at close quarters (0: off)."""
    max_s: float = 6.0
    """Longest manoeuvre (s)."""
    rejoin_s: float = 6.0
    """For this long after a manoeuvre (s; 0: off) the rover goes back to its path at a shallow
    angle, its carrot ``rejoin_lookahead_m`` ahead: the front rangefinder then looks down the path,
    where more oncoming traffic comes from. Turning straight back (the 3 m carrot, about 30 degrees
    off the path 1.5 m away) can keep a second walker on the path in the blind wedge between the
    front beam and a front diagonal: in the runner's ``head_on`` seeds 45 and 351 it was first read
    1.15 and 1.5 m out, too late. Runner, ``head_on`` seeds 1-500: 13 failed without this, 5 with
    it (8 m for 10 s: also 5; 6 m and 10 m for 6 s: 7 and 6)."""
    rejoin_lookahead_m: float = 8.0
    """The carrot's distance along the path while rejoining it after a manoeuvre (m), instead of
    ``planner.lookahead_m``: about 11 degrees off a path 1.5 m away."""
    max_delta_deg: float = 90.0
    """Largest heading offset from the course tried (deg)..."""
    delta_step_deg: float = 15.0
    """...in steps of this (deg): 15, 30, ... 90."""
    slow_fraction: float = 0.5
    """Each heading is tried at the speed given, then at this fraction of it."""
    heading_gain: float = 3.0
    """Yaw rate commanded per radian of heading error (1/s), up to ``max_yaw_rate_radps``."""
    max_yaw_rate_radps: float = 1.5
    """Largest yaw rate commanded (rad/s): the wheels' 200 rpm leave about 1.6 rad/s at 1.2 m/s."""
    accel_mps2: float = 1.0
    """Speed change per second the rollouts assume (m/s^2)."""
    rollout_step_s: float = 0.1
    """Time step of the rollouts (s). The ranges allowed for this, ``horizon_s`` and the headings
    bound a manoeuvre's start (both sides rolled out) to about 11,500 rollout steps, some 10 ms;
    the defaults take 720."""

    @property
    def deltas_deg(self) -> list[float]:
        """The heading offsets tried, smallest first."""
        step = max(self.delta_step_deg, 1.0)
        count = max(1, int(self.max_delta_deg / step + 1e-9))  # at least one, whatever the two are set to
        return [min(step * k, self.max_delta_deg) for k in range(1, count + 1)]


@dataclass
class SideGuardParams:
    """Keeping the flanks clear (``rover_ctl.navigation.side_guard``): a turn away from an obstacle
    the left or right rangefinder sees closer than ``range_m``, added to the rule base's wheels."""

    enabled: bool = True
    """Turn away from close side readings while the rule base drives."""
    range_m: float = 0.35
    """A side reading below this turns the rover away (m); the rangefinders read down to 0.2 m."""
    max_yaw_rate_radps: float = 2.75
    """Yaw rate at a reading of 0 m (rad/s), in proportion below ``range_m``: 1.18 rad/s at 0.2 m.
    0.35 and 0.45 m, 2.75 and 4.58 rad/s did about equally well in the in-process runner
    (docs/perception.md "Flank contacts")."""
    pass_speed_mps: float = 1.2
    """While the guard turns and the way ahead is clear, the rover keeps at least this forward speed
    (m/s; never above the speed it was given; 0: off): slowed beside an obstacle that moves, it kept
    the obstacle alongside until it closed on the flank. 0.8, 1.0 and 1.2 m/s did about as well
    (docs/perception.md "Flank contacts")."""
    front_clear_m: float = 1.5
    """The way ahead is clear when every front rangefinder the rover has (front and the two front
    diagonals) reads beyond this (m); 1.0 and 2.5 m changed nothing in the in-process runner."""
    rear_range_m: float = 2.0
    """A moving obstacle track behind the side beams (``rear_min_bearing_deg``) within this (m,
    centre to the track's point) keeps the rover going: no slower than ``pass_speed_mps`` (never
    above the speed given), no turn towards it, while the way ahead is clear and no yield holds the
    rover (needs the tracks, which yielding or evasion builds; 0: off). No rangefinder looks there,
    and a rover that stopped to pivot towards a target behind it was walked into: in the in-process
    runner's ``head_on`` seeds 1-500, 22 failed episodes without it, 13 with it (docs/perception.md
    "Walked into from behind")."""
    rear_min_travel_m: float = 0.45
    """A track counts for ``rear_range_m`` only once it has gone this far from its first echo (m):
    a static drum the side beam slides over as the rover passes gives a track that seems to follow it."""
    rear_min_bearing_deg: float = 100.0
    """A track counts for ``rear_range_m`` only this far round from the heading (deg, either side,
    seen from the rover's centre; 90: abeam counts too): behind the side rangefinders, whose 15 deg
    cones reach 97.5 deg, where no beam sees it. Abeam a side beam does, and the guard answers; and
    among walls 62-72 % of the steps the check acted on, without this limit, were on tracks within
    100 deg: a wall's echo sliding along a passing or turning rover's beam (36 % in ``head_on``)."""


@dataclass
class PivotParams:
    """Pivot turns (``rover_ctl.navigation.pivot``): a target far off the heading is first faced by
    turning in place, as ArduPilot Rover's WP_PIVOT_ANGLE / WP_PIVOT_RATE do."""

    angle_deg: float = 60.0
    """Pivot when the target is more than this off the heading (deg; ArduPilot's default); at most
    ``accuracy_deg``: off, the rule base turns as it will."""
    rate_dps: float = 60.0
    """Largest yaw rate of a pivot (deg/s; ArduPilot's default)."""
    heading_gain: float = 2.0
    """Yaw rate per radian of the target's direction (1/s), below ``rate_dps``: slows the turn's end."""
    accuracy_deg: float = 5.0
    """A pivot ends with the target this close to the heading (deg; ArduPilot's 5)."""
    clear_m: float = 0.3
    """No pivot while any range is at most this (m): a turn in place sweeps the footprint's corners."""
    open_m: float = 1.5
    """No pivot towards a target whose beams (within ``open_half_deg``) read at most this (m)."""
    open_half_deg: float = 50.0
    """Beams this close to the target's direction count for ``open_m`` (deg)."""
    timeout_s: float = 6.0
    """A pivot ends after this long whatever the heading (s)."""
    rest_s: float = 2.0
    """After a pivot ends, the next waits this long (s)."""
    retry_after_m: float = 1.0
    """After a pivot that timed out, the next waits until the rover has moved this far (m): one
    that cannot turn is left to the rule base and the stuck failsafe."""
    max_cross_track_m: float = 1.0
    """No pivot farther than this from the planned path (m): off the path the rule base is going
    round something, and what it is going round may be beside the rover where no beam looks."""
    mover_m: float = 5.0
    """No pivot while a moving obstacle track is within this (m): a rover turning in place is a
    rover standing in a walker's way."""


@dataclass
class PassageParams:
    """Narrow passages (``rover_ctl.navigation.gaps``): an opening barely wider than the rover,
    seen through by a side rangefinder as the rover follows a wall, lined up on and driven through."""

    enabled: bool = True
    """Look for narrow passages and drive through them (docs/perception.md, "Narrow passages"). On by
    default since 2026-11-28, with the persistent-obstacle map: together they drive the benchmark's
    narrow_gap through its opening in 99 of 100 worlds (0 with both off; lockstep SITL, 2026-11-29,
    docs/BENCHMARKS.md). With the map off, the search's return along a wall costs walls about 21 s
    (in-process runner)."""
    side_clearance_m: float = 0.02
    """An opening is passable when it was seen free over at least the footprint's width plus this
    much on each side (m). What a 15 degree cone sees free of a 0.6 m opening in a 0.3 m wall is
    about 0.47 m (docs/perception.md), so a 1.5x gap passes with up to 0.03."""
    max_width_m: float = 1.2
    """Openings that may be wider than this (m) are left to the rule base: its sides read near
    only inside 0.7 m, so it drives through them unaided."""
    wall_range_m: float = 1.6
    """Side echoes farther than this (m) do not bound a gap: a side cone wider than the opening
    (2 r tan(beam_half): 0.42 m at 1.6 m) never sees through it."""
    depth_m: float = 0.5
    """A side reading is free when it has no echo or one at least this far (m) beyond the wall;
    from the line-up point the front beam must see this far beyond the wall's line."""
    beam_half_deg: float = 7.5
    """Half the rangefinders' beam width (deg): an echo at range r may come from anywhere within
    r tan(beam_half) of the beam's axis, and a free reading shows that whole cone free."""
    history_s: float = 8.0
    """Side readings kept to find a gap in (s), and how long a gap found stays usable."""
    min_free: int = 2
    """Free side readings needed between the wall's two echoes (one could be a dropped echo)."""
    match_m: float = 0.4
    """A gap found within this (m) of one given up or passed is that gap again."""
    standoff_m: float = 1.0
    """The rover lines up on the gap's centre line this far (m, its centre) before the wall's line."""
    heading_tol_deg: float = 3.0
    """Lining up: turned in place until its heading is within this (deg) of the gap's axis."""
    position_tol_m: float = 0.03
    """Lining up: the line-up point is reached within this (m)."""
    look_s: float = 0.3
    """Lined up, the front beam must see through the gap for this long (s) before the rover goes."""
    speed_mps: float = 0.3
    """Speed while lining up and passing (m/s)."""
    turn_rate_dps: float = 45.0
    """Largest yaw rate while lining up and passing (deg/s)."""
    lookahead_m: float = 0.6
    """Passing: pure pursuit on the gap's centre line, aiming this far (m) beyond the rover's
    projection on it."""
    stop_m: float = 0.25
    """Passing: a front echo nearer than this (m) stops the rover and gives the gap up."""
    scan_max_deg: float = 30.0
    """Looking: the rover turns in place slowly, at most this far (deg) either side of the gap's
    axis, the front beam scanning the opening: free only while its cone lies wholly inside it, so
    the middle of the free headings points at the opening's centre, measured from where the rover
    stands (dead reckoning and the sweep err by 0.1 m and more). 0: no scan (look straight ahead)."""
    scan_rate_dps: float = 10.0
    """Looking: the scan's yaw rate (deg/s): 0.5 degrees between two front readings at 20 Hz."""
    scan_tol_m: float = 0.04
    """Looking: the scan puts the rover this close (m) to the opening's centre line or it lines up
    again on the measured line (the margin of a 1.5x gap is 0.1 m a side)."""
    scan_tries: int = 3
    """Looking: scans at most (each after a line-up on the last one's line) before the gap is
    given up; a scan that sees the opening narrower than needed, or its centre more than
    ``match_m`` from the sweep's, gives it up at once."""
    guard_near_m: float = 0.21
    """Passing: a front diagonal's mean over its last three readings, each counted as at least
    this (m; the emulator's rangefinders report anything nearer as 0.2, their minimum), at this
    value ..."""
    guard_skew_m: float = 0.05
    """... while the other's is at least this much (m) farther, the nose within 0.12 m of the wall's
    line: the body is off the centre line by about the 0.1 m margin or more (the near corner is
    about to meet the post's face; the other diagonal sees into the opening): stop, back out
    straight to ``standoff_m`` and give the gap up."""
    stall_s: float = 1.0
    """Passing: driven forwards for this long (s) ..."""
    stall_m: float = 0.05
    """... with the wheels moving the rover less than this (m) along the axis: it is pushing against
    something: stop, back out and give the gap up."""
    exit_m: float = 0.3
    """The passage is over when the rover's back is this far (m) beyond the wall's line."""
    search_m: float = 3.0
    """A wall across the way to the goal (the straight line to the goal meets its line at most this
    far ahead) that a side beam has followed this far (m) without a narrow opening found is
    searched back the other way, at ``search_speed_mps``, to this far beyond
    where its echoes began: the rule base turns one way at a wall (east, in the benchmark), so an
    opening behind it, or passed while it turned, is never swept. 0: never. Costs about
    ``2 search_m / search_speed_mps`` plus two half turns where there is nothing to find."""
    search_speed_mps: float = 0.6
    """Speed of the search back along the wall (m/s). The search has only to notice where the side
    beam stops echoing: an opening that may be wide enough is swept again backwards at
    ``speed_mps`` (the inspection's second sweep). In-process runner, narrow_gap seeds 1-100 with
    the map on: through the opening 97, 98 and 96 times at 0.3, 0.6 and 0.8 m/s, mean time 66.9,
    60.2 and 59.2 s (docs/perception.md)."""
    timeout_s: float = 40.0
    """A passage not through after this long (s) is given up ..."""
    reject_s: float = 60.0
    """... and a gap given up or passed is not taken again for this long (s)."""
    wall_mapped_m: float = 0.5
    """An opening is inspected only when the persistent-obstacle map (``obstacle_map``) holds an
    obstacle within this (m) of the last echo of the wall before it. A walker passed at the side
    gives the side beam the same run of echoes as a wall that ends (its echo slides with the rover
    as a wall's does), and the slow inspection then let it catch up from behind-left, where no
    beam looks (lockstep SITL, crossing world 18; docs/perception.md). 0: no such test;
    with the map off or not in the odometry frame, inspections start without it."""


@dataclass
class AutopilotParams:
    """Modes and arming (``rover_ctl.autopilot``), ArduPilot Rover's LOIT_* / ARMING_* counterparts."""

    loiter_radius_m: float = 2.0
    """LOITER (and a GUIDED rover that has arrived) drives back once pushed farther than this from
    its point, until within half of it (ArduPilot LOIT_RADIUS)."""
    mission_restart: int = 0
    """Entering AUTO (ArduPilot MIS_RESTART): 0 resumes at the item the mission was on, also after
    the daemon restarted (the item is stored beside the mission); 1 starts the mission over."""
    arming_max_distance_m: float = 1000.0
    """Pre-arm: a mission whose first waypoint, or a fence whose nearest point, is farther than this
    from home was made for another place: arming is refused."""


@dataclass
class ObstacleMapParams:
    """Persistent obstacles (``rover_ctl.navigation.obstacle_map``): places the rangefinders echo
    from repeatedly, folded into the planner's map so that it plans around them."""

    enabled: bool = True
    """Fold persistent obstacles into the planner's map (off: the planner knows only fences,
    known obstacles and the circles of a stuck rover). On by default since 2026-11-28, with narrow
    passages: against both off (2026-11-29's rows) the cul-de-sac takes 20 s less and walls 11 s
    less, every other scenario as many worlds complete or more (docs/BENCHMARKS.md). `make
    demo`'s mission, lockstep, seeds 1-11: no contact, 169.4-175.3 m (169.0-174.4 m with the map
    in the odometry frame, 169.4-174.2 m with ``proximity.edge_sectors`` too, 2026-11-29).
    (Before the free-space rule, ``free_memory_s``, and the passages' hand-back, the map alone met
    the demo's looping walker in a way that ended in a collision in 3 of 18 runs, 1 of 15 with it
    off; docs/perception.md.)"""
    cell_m: float = 0.5
    """Side of a grid cell (m): the resolution of the persistent obstacles."""
    miss_score: float = 0.5
    """Evidence a cell loses each time a beam passes through it (an echo in it adds 1)."""
    max_score: float = 20.0
    """Most evidence a cell holds (one second of a rangefinder staring at it at 20 Hz), so that
    free space seen later clears it in a bounded time."""
    persist_score: float = 6.0
    """A cell is persistent with at least this much evidence..."""
    min_span_s: float = 1.5
    """...and echoes spanning at least this long (s): a crossing pedestrian passes a cell in less."""
    free_memory_s: float = 3.0
    """An echo in a cell that a beam saw free less than this long before (s) adds no evidence:
    something moved in (0: no such test). A drum crossing the front beam of a rover stopped for
    it made its own persistent cell, and the re-plan round it met the next walker. In-process
    runner, map and passages on, seeds 1-300 of crossing, head_on and moving: 12 failed episodes
    without it, 11 with 1 s, 10 with 3 s (the same 10 episodes as with both off); seeds 1-100
    of cul_de_sac 54.0 / 58.7 / 60.2 s (one failure at 1 s; 68.2 s with the map off), walls 83.7 /
    84.5 / 86.2 s (77.6 s): walls are taken into the map a little later."""
    ttl_s: float = 60.0
    """A cell with no echo for this long is forgotten (s), as AP_OADatabase's OA_DB_EXPIRE."""
    max_cells: int = 5000
    """Cells kept at most (the least recently hit go first): bounds memory and the update's cost."""
    update_period_s: float = 0.5
    """The queued readings are folded into the grid this often (s), not at every control step."""
    min_change_cells: int = 2
    """The planner gets new persistent obstacles only when at least this many cells became or
    stopped being persistent..."""
    rebuild_min_interval_s: float = 2.0
    """...and at most once per this interval (s): each hand-over rebuilds the visibility graph."""
    max_obstacles: int = 16
    """Clusters handed to the planner at most, the nearest to the rover first."""
    track_on_wall_m: float = 0.5
    """A moving obstacle track within this of a persistent cell (m) is taken for that obstacle's
    face swept by a beam, not for a mover: the yielder, the evader, the side guard's rear check and
    the narrow passages' hand-back leave it out (in SITL ``cul_de_sac`` a turning rover's beams on
    the U's walls made tracks that started false manoeuvres and yields). 0: every moving track
    counts."""
    simplify_m: float = 0.25
    """Tolerance (m) of the simplification of a cluster's outline (a diagonal staircase of cells
    becomes a straight side)."""
    margin_m: float = 0.2
    """The planner keeps the robot's half-width plus this (m) from a persistent obstacle; less
    than ``planner.clearance_margin_m`` because a cell already reaches beyond its echoes."""
    odometry_frame: bool = True
    """Keep the map in the dead-reckoning frame of the wheels and the gyro
    (``rover_ctl.navigation.odometry``), laid onto the fused pose afresh at each control step,
    rather than in the fused pose's own frame, which moves against the ground as GPS fixes come
    in (0.1-0.4 m over 5 s): a wall seen along its length then stays one line of cells. In-process
    runner, seeds 1-100: cul_de_sac path / shortest 1.52 -> 1.44 and 56.4 -> 50.7 s, walls 1.33 ->
    1.31, the other scenarios as many failed episodes (docs/perception.md). Off, or no odometry
    heard: the fused pose's frame. A change clears the map."""


@dataclass
class Config:
    """All sections. Add a section by adding a dataclass field here (and its numeric fields to the
    parameter table, ``rover_ctl.parameters``)."""

    robot: RobotParams = field(default_factory=RobotParams)
    link: LinkParams = field(default_factory=LinkParams)
    planner: PlannerParams = field(default_factory=PlannerParams)
    executor: ExecutorParams = field(default_factory=ExecutorParams)
    failsafe: FailsafeParams = field(default_factory=FailsafeParams)
    estimator: EstimatorParams = field(default_factory=EstimatorParams)
    wheel_control: WheelControlParams = field(default_factory=WheelControlParams)
    daemon: DaemonParams = field(default_factory=DaemonParams)
    gcs: GcsParams = field(default_factory=GcsParams)
    navigator: NavigatorParams = field(default_factory=NavigatorParams)
    proximity: ProximityParams = field(default_factory=ProximityParams)
    yielding: YieldParams = field(default_factory=YieldParams)
    evasion: EvadeParams = field(default_factory=EvadeParams)
    passage: PassageParams = field(default_factory=PassageParams)
    side_guard: SideGuardParams = field(default_factory=SideGuardParams)
    pivot: PivotParams = field(default_factory=PivotParams)
    autopilot: AutopilotParams = field(default_factory=AutopilotParams)
    obstacle_map: ObstacleMapParams = field(default_factory=ObstacleMapParams)
    command_line: frozenset[str] = field(default=frozenset(), repr=False, compare=False)
    """``section.field`` keys given with ``--set``: they win over values persisted from a ground station."""


def sections(config: Config) -> dict[str, Any]:
    """Section name -> section object."""
    return {f.name: getattr(config, f.name) for f in dataclasses.fields(config) if dataclasses.is_dataclass(getattr(config, f.name))}


def _apply(config: Config, data: dict[str, Any], where: str) -> set[str]:
    """Set ``{section: {field: value}}`` through the parameter table; returns the keys set."""
    from rover_ctl.parameters import BY_KEY, ParamError  # the table is built from this module's dataclasses

    known = sections(config)
    done = set()
    for name, values in data.items():
        if name not in known:
            raise ConfigError(f"{where}: unknown key {name!r} (known: {', '.join(sorted(known))})")
        if not isinstance(values, dict):
            raise ConfigError(f"{where}: {name} must be a table of keys")
        section = known[name]
        fields = {f.name for f in dataclasses.fields(section)}
        for key, value in values.items():
            if key not in fields:
                raise ConfigError(f"{where}: unknown key {key!r} in [{name}] (known: {', '.join(sorted(fields))})")
            dotted = f"{name}.{key}"
            param = BY_KEY.get(dotted)
            if param is None:  # a text field (URL, path)
                if not isinstance(value, str):
                    raise ConfigError(f"{where}: {dotted}: expected a string, got {value!r}")
                setattr(section, key, value)
            else:
                try:
                    param.set(config, param.parse(value))
                except ParamError as exc:
                    raise ConfigError(f"{where}: {dotted}: {exc} ({param.name})") from None
            done.add(dotted)
    return done


def apply_overrides(config: Config, overrides: list[str]) -> set[str]:
    """``section.field=value`` or ``NAME=value`` (a parameter's MAVLink name) items, as given to
    ``--set``; returns the ``section.field`` keys set. Lists: ``0,2,4,6`` or ``[0,2,4,6]``."""
    from rover_ctl.parameters import BY_NAME

    done: set[str] = set()
    for item in overrides:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ConfigError(f"--set {item!r}: expected section.key=value or NAME=value")
        if "." not in key:
            param = BY_NAME.get(key.upper())
            if param is None:
                raise ConfigError(f"--set {item!r}: {key!r} is no parameter name; expected section.key=value or NAME=value")
            key = param.key
        section, _, leaf = key.partition(".")
        done |= _apply(config, {section: {leaf: value.strip()}}, "--set")
    return done


def load_config(path: str | Path | None = None, overrides: list[str] | None = None) -> Config:
    """Defaults, then the TOML file at ``path``, then ``--set`` overrides; every numeric value
    checked against its parameter's range (``rover_ctl.parameters``)."""
    config = Config()
    if path is not None:
        path = Path(path)
        try:
            data = tomllib.loads(inputfile.read_text(path))
        except FileNotFoundError:
            raise ConfigError(f"{path}: no such config file") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise ConfigError(f"{path}: cannot read: {exc}") from None
        except (ValueError, RecursionError) as exc:  # TOMLDecodeError, a 5000-digit number, nesting
            raise ConfigError(f"{path}: invalid TOML: {str(exc).splitlines()[0] or type(exc).__name__}") from None
        _apply(config, data, str(path))
    config.command_line = frozenset(apply_overrides(config, overrides or []))
    return config
