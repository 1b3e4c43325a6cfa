"""The parameter table: every tunable of the daemon as ArduPilot users know parameters.

Each numeric field of the config sections (``rover_ctl.config``) is declared here once, keyed by
``section.field``, with its MAVLink name (at most 16 characters; ArduPilot's name where ArduPilot
has one: WP_RADIUS, WP_SPEED, RTL_SPEED, FS_GCS_TIMEOUT, FS_ACTION, FENCE_ACTION, SYSID_THISMAV,
WENC_RADIUS, SCHED_LOOP_RATE, WP_PIVOT_ANGLE, WP_PIVOT_RATE; otherwise one prefix per section:
``RBT_`` robot, ``LINK_`` vehicle link, ``PLN_`` planner, ``WP_``/``RTL_``/``MIS_`` executor, ``FS_`` failsafes, ``EKF_`` estimator,
``WHL_`` wheel control, ``DMN_`` control loop, ``GCS_`` ground-station link, ``NAV_`` navigator,
``PRX_`` obstacle memory, ``YLD_`` yielding, ``EVD_`` evasion, ``OMAP_`` persistent obstacles, ``GAP_`` narrow
passages, ``PIV_`` pivot turns, ``CLI_`` the ``rover-ctl mission`` client), its range and units. The default is the
dataclass default and the description is the field's docstring in config.py, so neither is
written twice.

Values on the wire are numbers. A string choice (``failsafe.gcs_action``) is a number as in
ArduPilot (FS_ACTION 0 continue, 1 RTL, 2 hold); a list of rangefinder orientations
(``failsafe.required_rangefinders``) is a bitmask (bit n = MAV_SENSOR_ORIENTATION n). Whole-number
parameters are announced with ArduPilot's integer types (INT8/INT16/INT32, the value carried as a
float, MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT); the rest as REAL32.

Access:
    RW     a ground station may set it (PARAM_SET); it takes effect at once and persists.
    START  set when the daemon starts (system ids, stream rates, link and protocol housekeeping):
           read-only over MAVLink, set in the config file or with ``--set``.
    CONFIG not a daemon parameter (the ``rover-ctl mission`` client's settings): config only.
Strings (URLs, paths) are not parameters at all: config file and command line only.

Pure: no I/O. ``ParamError`` messages are one line and name the parameter and its range.
"""

from __future__ import annotations

import ast
import dataclasses
import enum
import inspect
import math
import textwrap
from dataclasses import dataclass
from functools import cache
from typing import Any, Iterable, Mapping

from rover_ctl.config import Config
from rover_ctl.vocabulary import mav

NAME_MAX = 16
"""PARAM_VALUE.param_id holds 16 characters."""
MASK_BITS = 8
"""Rangefinder masks cover MAV_SENSOR_ORIENTATION 0-7, the yaw steps a rover's sensors use."""
AUTO = -1
"""A mask's automatic value (``Param.auto`` says what it means): the field holds ``[AUTO]``, the wire -1."""
TRUE_WORDS, FALSE_WORDS = ("true", "yes", "on", "1"), ("false", "no", "off", "0")


class ParamError(ValueError):
    """A value a parameter cannot take: one line saying why (with the range); the caller names the parameter."""


class Access(enum.Enum):
    RW = "rw"
    START = "start"
    CONFIG = "config"


class Kind(enum.Enum):
    FLOAT = "float"
    INT = "int"
    CHOICE = "choice"
    """A string field whose values are numbered (``choices``)."""
    MASK = "mask"
    """A list of small integers as a bitmask."""
    BOOL = "bool"
    """True/false, 1/0 on the wire."""


@dataclass(frozen=True)
class Param:
    name: str
    key: str
    """``section.field`` in the config."""
    minimum: float
    maximum: float
    units: str
    access: Access
    kind: Kind
    choices: Mapping[int, str] | None = None
    auto: str = ""
    """For a mask that may also be ``[AUTO]`` (-1): what that means ("learn from the vehicle")."""
    description: str = ""
    default: float = 0.0
    """The MAVLink value of the dataclass default."""

    @property
    def section(self) -> str:
        return self.key.split(".")[0]

    @property
    def field(self) -> str:
        return self.key.split(".")[1]

    @property
    def mav_type(self) -> int:
        """ArduPilot's type for the parameter: the smallest integer type holding the range, or REAL32."""
        if self.kind is Kind.FLOAT:
            return mav.MAV_PARAM_TYPE_REAL32
        for bits, kind in ((8, mav.MAV_PARAM_TYPE_INT8), (16, mav.MAV_PARAM_TYPE_INT16)):
            if -(2 ** (bits - 1)) <= self.minimum and self.maximum < 2 ** (bits - 1):
                return kind
        return mav.MAV_PARAM_TYPE_INT32

    def range_text(self) -> str:
        if self.kind is Kind.CHOICE:
            return ", ".join(f"{number} {label}" for number, label in self.choices.items())
        if self.kind is Kind.MASK:
            return f"bitmask, bits 0-{MASK_BITS - 1}" + (f"; {AUTO} {self.auto}" if self.auto else "")
        if self.kind is Kind.BOOL:
            return "0 false, 1 true"
        units = f" {self.units}" if self.units else ""
        return f"{_number_text(self.minimum)} .. {_number_text(self.maximum)}{units}"

    # ---- conversions: field value (as in the config) <-> MAVLink value (a number)

    def get(self, config: Config) -> Any:
        return getattr(getattr(config, self.section), self.field)

    def set(self, config: Config, value: Any) -> None:
        """Store an already checked field value (from ``decode`` or ``parse``)."""
        setattr(getattr(config, self.section), self.field, value)

    def encode(self, value: Any) -> float:
        """A field value as the number a ground station sees."""
        if self.kind is Kind.CHOICE:
            return float(next(number for number, label in self.choices.items() if label == value))
        if self.kind is Kind.MASK:
            if self.auto and list(value) == [AUTO]:
                return float(AUTO)
            return float(sum(1 << int(bit) for bit in set(value)))
        return float(value)

    def decode(self, number: float) -> Any:
        """A number (PARAM_SET, a .parm line, ``--set NAME=``) as the field value; ParamError if refused."""
        if isinstance(number, bool) or not isinstance(number, (int, float)):
            raise ParamError(f"expected a number, got {number!r}")
        try:
            finite = math.isfinite(number)
        except OverflowError:  # an integer beyond any float (a TOML config may hold one)
            raise ParamError(f"a {len(str(abs(number)))}-digit number is out of range ({self.range_text()})") from None
        if not finite:
            raise ParamError(f"{number} is not a finite number")
        if self.kind is not Kind.FLOAT and number != int(number):
            raise ParamError(f"{_number_text(number)} is not a whole number ({self.range_text()})")
        if self.auto and number == AUTO:
            return [AUTO]
        if self.kind is Kind.CHOICE:
            if int(number) not in self.choices:
                raise ParamError(f"{_number_text(number)} is not one of {self.range_text()}")
            return self.choices[int(number)]
        if not self.minimum <= number <= self.maximum:
            raise ParamError(f"{_number_text(number)} is out of range {self.range_text()}")
        if self.kind is Kind.MASK:
            return [bit for bit in range(MASK_BITS) if int(number) >> bit & 1]
        if self.kind is Kind.BOOL:
            return bool(number)
        return int(number) if self.kind is Kind.INT else float(number)

    def parse(self, value: Any) -> Any:
        """A config-file or ``--set section.key=`` value (TOML type or text) as the field value.

        Choices take their label or number; masks take a list of bits (``[0, 2]``, ``0,2`` or
        ``[]``) or the bitmask number; numbers take numbers or numeric text."""
        if self.kind is Kind.CHOICE and isinstance(value, str) and value.strip() in self.choices.values():
            return value.strip()
        if self.kind is Kind.BOOL and isinstance(value, (bool, str)):
            word = str(value).strip().lower()
            if word in TRUE_WORDS or word in FALSE_WORDS:
                return word in TRUE_WORDS
            raise ParamError(f"expected true or false, got {value!r}")
        if self.auto and (value == [AUTO] or value == AUTO or (isinstance(value, str) and value.strip().lower() in ("auto", "learn", str(AUTO)))):
            return [AUTO]
        if self.kind is Kind.MASK and (isinstance(value, (list, tuple)) or (isinstance(value, str) and ("," in value or "[" in value))):
            return self._bits(value)
        if isinstance(value, str):
            try:
                value = float(value.strip())
            except ValueError:
                expected = f"one of {self.range_text()}" if self.kind is Kind.CHOICE else "a number"
                raise ParamError(f"expected {expected}, got {value!r}") from None
        return self.decode(value)

    def _bits(self, value: Any) -> list[int]:
        if isinstance(value, str):
            text = value.strip().removeprefix("[").removesuffix("]")
            value = [part for part in (p.strip() for p in text.split(",")) if part]
        bits = []
        for item in value:
            try:
                bit = float(item) if not isinstance(item, bool) else math.nan
            except (TypeError, ValueError):
                bit = math.nan
            if not (math.isfinite(bit) and bit == int(bit) and 0 <= bit < MASK_BITS):
                raise ParamError(f"list item {item!r} is not an orientation 0-{MASK_BITS - 1}")
            bits.append(int(bit))
        return sorted(set(bits))


def _number_text(value: float) -> str:
    return f"{value:g}"


# ---- the table ----------------------------------------------------------------------------------

_UNITS = (
    ("_radps_per_sqrt_s", "(rad/s)/sqrt(s)"), ("_rad_per_sqrt_s", "rad/sqrt(s)"), ("_per_sqrt_s", "1/sqrt(s)"),
    ("_radps", "rad/s"), ("_mps", "m/s"), ("_rpm", "rpm"), ("_hz", "Hz"), ("_us", "PWM us"), ("_deg", "deg"),
    ("_rad", "rad"), ("_m", "m"), ("_s", "s"),
)  # fmt: skip
"""Unit from the field name's suffix (longest first); a declaration may say otherwise."""


def _units_of(field_name: str) -> str:
    return next((units for suffix, units in _UNITS if field_name.endswith(suffix)), "")


RW, START, CONFIG = Access.RW, Access.START, Access.CONFIG
FS_ACTIONS = {0: "continue", 1: "rtl", 2: "hold"}
"""failsafe.gcs_action as ArduPilot Rover's FS_ACTION numbers (0 nothing, 1 RTL, 2 hold)."""
FENCE_ACTIONS = {1: "rtl", 2: "hold"}
"""failsafe.fence_action as ArduPilot Rover's FENCE_ACTION numbers (1 RTL, 2 hold)."""

# (key, name, minimum, maximum, access, options); options: units=..., choices=..., mask=True, int=True
_DECLARED: tuple[tuple, ...] = (
    ("robot.track_m", "RBT_TRACK", 0.05, 5.0, RW, {}),
    ("robot.wheel_radius_m", "WENC_RADIUS", 0.01, 1.0, RW, {}),
    ("robot.max_wheel_rpm", "RBT_MAX_RPM", 1.0, 2000.0, RW, {}),
    ("robot.footprint_length_m", "RBT_LENGTH", 0.05, 10.0, RW, {}),
    ("robot.footprint_width_m", "RBT_WIDTH", 0.05, 10.0, RW, {}),
    ("link.source_system", "LINK_SYSID", 1, 255, START, {}),
    ("link.source_component", "LINK_COMPID", 1, 255, START, {}),
    ("link.heartbeat_period_s", "LINK_HB_PERIOD", 0.1, 10.0, START, {}),
    ("link.override_timeout_s", "LINK_OVR_TIMEOUT", 0.1, 10.0, START, {}),
    ("planner.clearance_margin_m", "PLN_CLEARANCE", 0.0, 10.0, RW, {}),
    ("planner.circle_segments", "PLN_CIRCLE_SEGS", 4, 64, RW, {}),
    ("planner.lookahead_m", "PLN_LOOKAHEAD", 0.2, 50.0, RW, {}),
    ("planner.max_corner_cut_m", "PLN_CORNER_CUT", 0.01, 10.0, RW, {}),
    ("planner.projection_window_m", "PLN_PROJ_WINDOW", 0.5, 100.0, RW, {}),
    ("planner.replan_off_path_m", "PLN_REPLAN_DIST", 0.2, 100.0, RW, {}),
    ("planner.replan_min_interval_s", "PLN_REPLAN_INTVL", 0.0, 60.0, RW, {}),
    ("planner.blocked_radius_m", "PLN_BLOCK_RADIUS", 0.05, 20.0, RW, {}),
    ("planner.blocked_ttl_s", "PLN_BLOCK_TTL", 0.0, 3600.0, RW, {}),
    ("executor.acceptance_radius_m", "WP_RADIUS", 0.1, 100.0, RW, {}),
    ("executor.cruise_speed_mps", "WP_SPEED", 0.0, 20.0, RW, {}),
    ("executor.rtl_speed_mps", "RTL_SPEED", 0.0, 20.0, RW, {}),
    ("executor.rtl_radius_m", "RTL_RADIUS", 0.1, 100.0, RW, {}),
    ("executor.max_items_per_update", "MIS_ITEMS_STEP", 1, 10000, RW, {}),
    ("failsafe.recovery_s", "FS_RECOVERY", 0.0, 60.0, RW, {}),
    ("failsafe.vehicle_timeout_s", "FS_VEH_TIMEOUT", 0.1, 60.0, RW, {}),
    ("failsafe.gcs_timeout_s", "FS_GCS_TIMEOUT", 0.5, 300.0, RW, {}),
    ("failsafe.gcs_action", "FS_ACTION", 0, 2, RW, {"choices": FS_ACTIONS}),
    ("failsafe.rangefinder_timeout_s", "FS_RNG_TIMEOUT", 0.05, 60.0, RW, {}),
    ("failsafe.required_rangefinders", "FS_RNG_MASK", AUTO, 2**MASK_BITS - 1, RW, {"mask": True, "auto": "every one the rule base reads"}),
    ("failsafe.degraded_speed_mps", "FS_RNG_SPEED", 0.0, 20.0, RW, {}),
    ("failsafe.range_travel_m", "FS_RNG_TRAVEL", 0.01, 10.0, RW, {}),
    ("failsafe.min_sensor_rate_hz", "FS_SENSOR_RATE", 0.0, 100.0, RW, {}),
    ("failsafe.gps_timeout_s", "FS_GPS_TIMEOUT", 0.1, 60.0, RW, {}),
    ("failsafe.dead_reckoning_max_s", "FS_DR_MAX", 0.0, 3600.0, RW, {}),
    ("failsafe.estimator_unhealthy_s", "FS_EKF_TIMEOUT", 0.0, 60.0, RW, {}),
    ("failsafe.fence_action", "FENCE_ACTION", 1, 2, RW, {"choices": FENCE_ACTIONS}),
    ("failsafe.stuck_window_s", "FS_STUCK_TIME", 0.5, 120.0, RW, {}),
    ("failsafe.stuck_progress_m", "FS_STUCK_DIST", 0.01, 20.0, RW, {}),
    ("failsafe.stuck_min_command_mps", "FS_STUCK_SPEED", 0.0, 10.0, RW, {}),
    ("failsafe.parked_window_s", "FS_PARKED_TIME", 0.0, 600.0, RW, {}),
    ("failsafe.back_off_s", "FS_BACKOFF_TIME", 0.0, 60.0, RW, {}),
    ("failsafe.back_off_speed_mps", "FS_BACKOFF_SPEED", 0.0, 5.0, RW, {}),
    ("failsafe.back_off_clear_m", "FS_BACKOFF_CLEAR", 0.0, 5.0, RW, {}),
    ("failsafe.stuck_max_tries", "FS_STUCK_TRIES", 0, 100, RW, {}),
    ("failsafe.stuck_clear_m", "FS_STUCK_CLEAR", 0.0, 100.0, RW, {}),
    ("estimator.gyro_noise_rad_per_sqrt_s", "EKF_GYRO_NSE", 1e-6, 1.0, RW, {}),
    ("estimator.gyro_bias_walk_radps_per_sqrt_s", "EKF_GBIAS_NSE", 1e-7, 0.1, RW, {}),
    ("estimator.gyro_bias_sigma0_radps", "EKF_GBIAS_INIT", 1e-5, 1.0, RW, {}),
    ("estimator.compass_sigma_rad", "EKF_YAW_NSE", 1e-4, 1.0, RW, {}),
    ("estimator.compass_offset_sigma0_rad", "EKF_YAWOFS_INIT", 1e-4, 3.2, RW, {}),
    ("estimator.compass_offset_walk_rad_per_sqrt_s", "EKF_YAWOFS_NSE", 0.0, 0.1, RW, {}),
    ("estimator.speed_accel_per_sqrt_s", "EKF_ACC_NSE", 1e-3, 20.0, RW, {"units": "(m/s)/sqrt(s)"}),
    ("estimator.wheel_speed_sigma_mps", "EKF_WHL_NSE", 1e-4, 5.0, RW, {}),
    ("estimator.wheel_slip_fraction", "EKF_WHL_SLIP", 0.0, 1.0, RW, {}),
    ("estimator.lateral_slip_per_sqrt_s", "EKF_SKID_NSE", 1e-5, 5.0, RW, {"units": "m/sqrt(s)"}),
    ("estimator.wheel_scale_sigma0", "EKF_WSCL_INIT", 0.0, 1.0, RW, {}),
    ("estimator.wheel_scale_walk_per_sqrt_s", "EKF_WSCL_NSE", 0.0, 0.1, RW, {}),
    ("estimator.wheel_max_speed_mps", "EKF_WHL_MAXSPD", 0.1, 100.0, RW, {}),
    ("estimator.gps_min_sigma_m", "EKF_POS_MIN_NSE", 0.01, 100.0, RW, {}),
    ("estimator.gps_default_sigma_m", "EKF_POS_DFL_NSE", 0.01, 1000.0, RW, {}),
    ("estimator.gps_velocity_sigma_mps", "EKF_VEL_NSE", 1e-3, 10.0, RW, {}),
    ("estimator.gps_course_min_speed_mps", "EKF_CRS_MINSPD", 0.0, 20.0, RW, {}),
    ("estimator.gate_sigma", "EKF_POS_GATE", 1.0, 100.0, RW, {"units": "sigma"}),
    ("estimator.glitch_reset_s", "EKF_GLITCH_TIME", 0.0, 600.0, RW, {}),
    ("estimator.attitude_timeout_s", "EKF_ATT_TIMEOUT", 0.01, 60.0, RW, {}),
    ("estimator.max_lag_s", "EKF_MAX_LAG", 0.0, 10.0, RW, {}),
    ("estimator.pose_max_lead_s", "EKF_POSE_LEAD", 0.0, 10.0, RW, {}),
    ("estimator.clock_restart_s", "EKF_CLK_RESET", 0.1, 600.0, RW, {}),
    ("estimator.gps_max_lead_s", "EKF_GPS_LEAD", 0.0, 60.0, RW, {}),
    ("estimator.gps_timeout_s", "EKF_GPS_TIMEOUT", 0.1, 60.0, RW, {}),
    ("estimator.health_max_position_sigma_m", "EKF_HLTH_POS", 0.0, 1000.0, RW, {}),
    ("estimator.health_max_heading_sigma_rad", "EKF_HLTH_YAW", 0.0, 3.2, RW, {}),
    ("wheel_control.full_output_rpm", "WHL_FULL_RPM", 1.0, 5000.0, RW, {}),
    ("wheel_control.kp", "WHL_P", 0.0, 1.0, RW, {"units": "1/rpm"}),
    ("wheel_control.ki", "WHL_I", 0.0, 1.0, RW, {"units": "1/(rpm s)"}),
    ("wheel_control.integral_limit", "WHL_IMAX", 0.0, 1.0, RW, {}),
    ("wheel_control.integrate_max_rate_rpm_s", "WHL_I_MAXRATE", 0.0, 100000.0, RW, {"units": "rpm/s"}),
    ("wheel_control.speed_filter_tau_s", "WHL_FILT_TAU", 0.0, 5.0, RW, {}),
    ("wheel_control.measurement_timeout_s", "WHL_MEAS_TIMEOUT", 0.01, 10.0, RW, {}),
    ("wheel_control.brake_release_rpm", "WHL_BRAKE_REL", 0.0, 100.0, RW, {"units": "rpm"}),
    ("wheel_control.rc_trim_us", "WHL_RC_TRIM", 800, 2200, RW, {}),
    ("wheel_control.rc_range_us", "WHL_RC_RANGE", 100, 1000, RW, {}),
    ("wheel_control.rc_deadzone_us", "WHL_RC_DZ", 0, 200, RW, {}),
    ("daemon.control_rate_hz", "SCHED_LOOP_RATE", 1.0, 400.0, RW, {}),
    ("daemon.loop_rate_window_s", "SCHED_RATE_WIN", 0.2, 60.0, RW, {}),
    ("daemon.slow_loop_fraction", "SCHED_SLOW_FRAC", 0.0, 1.0, RW, {}),
    ("daemon.max_step_travel_m", "SCHED_STEP_TRVL", 0.01, 10.0, RW, {}),
    ("daemon.lockstep_silence_s", "DMN_LOCK_SILENT", 0.1, 3600.0, START, {}),
    ("daemon.vehicle_wait_s", "DMN_VEH_WAIT", 0.1, 3600.0, START, {}),
    ("daemon.command_timeout_s", "DMN_CMD_TIMEOUT", 0.05, 60.0, START, {}),
    ("daemon.command_retries", "DMN_CMD_RETRIES", 0, 100, START, {}),
    ("daemon.sensor_rate_hz", "DMN_SENSOR_RATE", 0.0, 400.0, START, {}),
    ("daemon.gps_rate_hz", "DMN_GPS_RATE", 0.0, 50.0, START, {}),
    ("daemon.rangefinder_rate_hz", "DMN_RNG_RATE", 0.0, 200.0, START, {}),
    ("daemon.min_gps_rate_hz", "DMN_GPS_MIN", 0.1, 50.0, START, {}),
    ("daemon.min_rangefinder_rate_hz", "DMN_RNG_MIN", 0.1, 200.0, START, {}),
    ("daemon.core_rate_hz", "DMN_CORE_RATE", 1.0, 400.0, START, {}),
    ("daemon.status_rate_hz", "DMN_STAT_RATE", 0.0, 50.0, START, {}),
    ("daemon.truth_rate_hz", "DMN_TRUTH_RATE", 0.0, 200.0, START, {}),
    ("daemon.stream_rerequest_s", "DMN_STREAM_RERQ", 0.1, 600.0, START, {}),
    ("daemon.idle_wait_s", "DMN_IDLE_WAIT", 0.001, 1.0, START, {}),
    ("daemon.hold_speed_mps", "DMN_HOLD_SPEED", 0.0, 5.0, RW, {}),
    ("gcs.system_id", "SYSID_THISMAV", 1, 255, START, {}),
    ("gcs.ground_station_system_id", "MAV_GCS_SYSID", 0, 255, START, {}),
    ("gcs.component_id", "GCS_COMPID", 1, 255, START, {}),
    ("gcs.heartbeat_period_s", "GCS_HB_PERIOD", 0.1, 10.0, START, {}),
    ("gcs.mission_item_retry_s", "GCS_MIS_RETRY", 0.05, 10.0, START, {}),
    ("gcs.mission_upload_timeout_s", "GCS_MIS_TIMEOUT", 0.5, 600.0, START, {}),
    ("gcs.mission_max_items", "GCS_MIS_MAX", 2, 65535, START, {}),
    ("gcs.param_send_rate_hz", "GCS_PARAM_RATE", 1.0, 1000.0, START, {}),
    ("gcs.position_rate_hz", "GCS_POS_RATE", 0.0, 50.0, START, {}),
    ("gcs.gps_rate_hz", "GCS_GPS_RATE", 0.0, 50.0, START, {}),
    ("gcs.attitude_rate_hz", "GCS_ATT_RATE", 0.0, 50.0, START, {}),
    ("gcs.sys_status_rate_hz", "GCS_SYS_RATE", 0.0, 50.0, START, {}),
    ("gcs.mission_current_rate_hz", "GCS_MCUR_RATE", 0.0, 50.0, START, {}),
    ("gcs.vehicle_text_severity", "GCS_VEH_TEXT_SEV", -1, 7, START, {}),
    ("gcs.client_retry_s", "CLI_RETRY", 0.05, 60.0, CONFIG, {}),
    ("gcs.client_retries", "CLI_RETRIES", 0, 1000, CONFIG, {}),
    ("gcs.client_connect_timeout_s", "CLI_CONN_TIMEOUT", 0.1, 600.0, CONFIG, {}),
    ("link.wheel_left_index", "WHL_L_INDEX", 0, 15, START, {}),
    ("link.wheel_right_index", "WHL_R_INDEX", 0, 15, START, {}),
    ("link.wheel_left_sign", "WHL_L_SIGN", -1.0, 1.0, START, {}),
    ("link.wheel_right_sign", "WHL_R_SIGN", -1.0, 1.0, START, {}),
    ("link.rangefinders", "RNG_PRESENT", AUTO, 2**MASK_BITS - 1, START, {"mask": True, "auto": "learn from the vehicle"}),
    ("link.rangefinder_discovery_s", "RNG_LEARN_TIME", 0.1, 60.0, START, {}),
    ("link.line_bytes_per_s", "LINK_LINE_BPS", 0.0, 1e7, START, {"units": "B/s"}),
    ("link.network_bytes_per_s", "LINK_NET_BPS", 100.0, 1e8, START, {"units": "B/s"}),
    ("link.line_use_max", "LINK_USE_MAX", 0.05, 1.0, START, {}),
    ("link.rate_window_s", "LINK_RATE_WIN", 0.2, 60.0, RW, {}),
    ("link.health_period_s", "LINK_HLTH_PER", 0.5, 3600.0, RW, {}),
    ("link.radio_txbuf_low_pct", "LINK_TXBUF_LOW", 0.0, 100.0, RW, {"units": "%"}),
    ("link.override_min_hz", "LINK_RC_MIN", 0.5, 50.0, RW, {}),
    ("link.radio_status_timeout_s", "LINK_RADIO_TMO", 0.5, 60.0, RW, {}),
    ("autopilot.loiter_radius_m", "LOIT_RADIUS", 0.1, 100.0, RW, {}),
    ("autopilot.mission_restart", "MIS_RESTART", 0, 1, RW, {}),
    ("autopilot.arming_max_distance_m", "ARMING_MAX_DIST", 1.0, 1.0e6, RW, {}),
    ("estimator.glitch_max_s", "EKF_GLITCH_MAX", 0.0, 3600.0, RW, {}),
    ("estimator.glitch_innovation_tau_s", "EKF_GLITCH_TAU", 0.01, 60.0, RW, {}),
    ("daemon.log_max_total_mb", "LOG_MAX_MB", 0.0, 1.0e6, START, {"units": "MB"}),
    ("daemon.link_chatter_s", "DMN_CHATTER_S", 0.0, 3600.0, START, {}),
    ("gcs.max_messages_per_poll", "GCS_MAX_MSGS", 1, 10000, START, {}),
    ("gcs.max_peers", "GCS_MAX_PEERS", 1, 64, START, {}),
    ("gcs.require_signing", "GCS_SIGN_REQ", 0, 1, START, {}),
    ("gcs.signing_setup_from_loopback", "GCS_SIGN_LOCAL", 0, 1, START, {}),
    ("gcs.signing_timestamp_save_s", "GCS_SIGN_SAVE_S", 1.0, 3600.0, START, {}),
    ("gcs.mission_upload_margin_s", "GCS_MIS_MARGIN", 0.0, 3600.0, START, {}),
    ("gcs.mission_upload_holdoff_s", "GCS_MIS_HOLDOFF", 0.0, 600.0, START, {}),
    ("gcs.param_save_s", "GCS_PARAM_SAVE_S", 0.1, 60.0, START, {}),
    ("gcs.client_item_retry_s", "CLI_ITEM_RETRY", 0.01, 60.0, CONFIG, {}),
    ("navigator.paper_range_units_per_m", "NAV_RNG_SCALE", 0.01, 1000.0, RW, {"units": "1/m"}),
    ("navigator.missing_range_m", "NAV_MISSING_RNG", 0.0, 100.0, RW, {}),
    ("proximity.memory_s", "PRX_MEMORY", 0.0, 60.0, RW, {}),
    ("proximity.sector_half_deg", "PRX_SECTOR", 1.0, 180.0, RW, {}),
    ("proximity.horizon_s", "PRX_HORIZON", 0.0, 10.0, RW, {}),
    ("proximity.prediction_step_s", "PRX_PRED_STEP", 0.02, 2.0, RW, {}),
    ("proximity.track_gate_m", "PRX_TRK_GATE", 0.05, 10.0, RW, {}),
    ("proximity.track_confirm_hits", "PRX_TRK_CONFIRM", 1, 100, RW, {}),
    ("proximity.track_coast_s", "PRX_TRK_COAST", 0.05, 60.0, RW, {}),
    ("proximity.track_echo_sigma_m", "PRX_TRK_ECHO_SD", 0.001, 10.0, RW, {}),
    ("proximity.track_beam_half_deg", "PRX_TRK_BEAM", 0.0, 89.0, RW, {"units": "deg"}),
    ("proximity.track_accel_sigma_mps2", "PRX_TRK_ACCEL", 0.01, 100.0, RW, {"units": "m/s/s"}),
    ("proximity.track_init_speed_sigma_mps", "PRX_TRK_VEL_SD", 0.01, 100.0, RW, {}),
    ("proximity.track_min_speed_mps", "PRX_TRK_MIN_SPD", 0.0, 100.0, RW, {}),
    ("proximity.track_max_speed_mps", "PRX_TRK_MAX_SPD", 0.0, 100.0, RW, {}),
    ("proximity.track_pace_sigma", "PRX_TRK_PACE", 0.0, 100.0, RW, {"units": "sigma"}),
    ("proximity.track_max_count", "PRX_TRK_MAX", 1, 1000, RW, {}),
    ("yielding.enabled", "YLD_ENABLE", 0, 1, RW, {}),
    ("yielding.horizon_s", "YLD_HORIZON", 0.1, 30.0, RW, {}),
    ("yielding.margin_m", "YLD_MARGIN", 0.0, 10.0, RW, {}),
    ("yielding.release_margin_m", "YLD_RELEASE", 0.0, 10.0, RW, {}),
    ("yielding.min_cross_mps", "YLD_MIN_CROSS", 0.0, 10.0, RW, {}),
    ("yielding.min_cross_deg", "YLD_MIN_ANGLE", 0.0, 90.0, RW, {"units": "deg"}),
    ("yielding.min_hits", "YLD_MIN_HITS", 1, 1000, RW, {}),
    ("yielding.max_speed_sd_mps", "YLD_MAX_VEL_SD", 0.01, 10.0, RW, {}),
    ("yielding.min_travel_m", "YLD_MIN_TRAVEL", 0.0, 100.0, RW, {}),
    ("yielding.max_heading_off_deg", "YLD_MAX_HDG_OFF", 0.0, 180.0, RW, {"units": "deg"}),
    ("yielding.after_evasion_s", "YLD_AFTER_EVD", 0.0, 60.0, RW, {}),
    ("yielding.after_evasion_heading_off_deg", "YLD_EVD_HDG_OFF", 0.0, 180.0, RW, {"units": "deg"}),
    ("yielding.max_wait_s", "YLD_MAX_WAIT", 0.0, 120.0, RW, {}),
    ("yielding.speed_steps", "YLD_SPD_STEPS", 1, 20, RW, {}),
    ("evasion.enabled", "EVD_ENABLE", 0, 1, RW, {}),
    ("evasion.horizon_s", "EVD_HORIZON", 0.5, 6.0, RW, {}),
    ("evasion.margin_m", "EVD_MARGIN", 0.0, 10.0, RW, {}),
    ("evasion.release_margin_m", "EVD_RELEASE", 0.0, 10.0, RW, {}),
    ("evasion.min_hits", "EVD_MIN_HITS", 1, 1000, RW, {}),
    ("evasion.max_speed_sd_mps", "EVD_MAX_VEL_SD", 0.01, 10.0, RW, {}),
    ("evasion.min_travel_m", "EVD_MIN_TRAVEL", 0.0, 100.0, RW, {}),
    ("evasion.min_closing_mps", "EVD_MIN_CLOSING", 0.0, 10.0, RW, {}),
    ("evasion.max_cross_deg", "EVD_MAX_ANGLE", 0.0, 90.0, RW, {"units": "deg"}),
    ("evasion.max_heading_off_deg", "EVD_MAX_HDG_OFF", 0.0, 180.0, RW, {"units": "deg"}),
    ("evasion.min_start_speed_mps", "EVD_MIN_SPEED", 0.0, 10.0, RW, {}),
    ("evasion.min_start_range_m", "EVD_MIN_RANGE", 0.0, 10.0, RW, {}),
    ("evasion.max_velocity_jump_mps", "EVD_MAX_VEL_JMP", 0.0, 10.0, RW, {}),
    ("evasion.not_oncoming_s", "EVD_NOT_ONCOMING", 0.0, 10.0, RW, {}),
    ("evasion.side_free_m", "EVD_SIDE_FREE", 0.0, 10.0, RW, {}),
    ("evasion.front_free_m", "EVD_FRONT_FREE", 0.0, 10.0, RW, {}),
    ("evasion.max_s", "EVD_MAX_TIME", 0.1, 120.0, RW, {}),
    ("evasion.rejoin_s", "EVD_REJOIN_TIME", 0.0, 120.0, RW, {}),
    ("evasion.rejoin_lookahead_m", "EVD_REJOIN_DIST", 0.5, 50.0, RW, {}),
    ("evasion.max_delta_deg", "EVD_MAX_DELTA", 5.0, 120.0, RW, {"units": "deg"}),
    ("evasion.delta_step_deg", "EVD_DELTA_STEP", 5.0, 90.0, RW, {"units": "deg"}),
    ("evasion.slow_fraction", "EVD_SLOW", 0.0, 1.0, RW, {}),
    ("evasion.heading_gain", "EVD_HDG_GAIN", 0.1, 100.0, RW, {}),
    ("evasion.max_yaw_rate_radps", "EVD_MAX_YAW_RATE", 0.1, 20.0, RW, {}),
    ("evasion.accel_mps2", "EVD_ACCEL", 0.01, 100.0, RW, {"units": "m/s/s"}),
    ("evasion.rollout_step_s", "EVD_ROLLOUT_DT", 0.05, 0.5, RW, {}),
    ("side_guard.enabled", "SIDE_ENABLE", 0, 1, RW, {}),
    ("side_guard.range_m", "SIDE_RANGE", 0.0, 5.0, RW, {}),
    ("side_guard.max_yaw_rate_radps", "SIDE_YAW_RATE", 0.0, 20.0, RW, {}),
    ("side_guard.pass_speed_mps", "SIDE_PASS_SPD", 0.0, 10.0, RW, {}),
    ("side_guard.front_clear_m", "SIDE_FRONT_CLR", 0.0, 10.0, RW, {}),
    ("side_guard.rear_range_m", "SIDE_REAR_RNG", 0.0, 10.0, RW, {}),
    ("side_guard.rear_min_travel_m", "SIDE_REAR_TRAV", 0.0, 10.0, RW, {}),
    ("side_guard.rear_min_bearing_deg", "SIDE_REAR_BRG", 90.0, 180.0, RW, {"units": "deg"}),
    ("obstacle_map.enabled", "OMAP_ENABLE", 0, 1, RW, {}),
    ("obstacle_map.cell_m", "OMAP_CELL", 0.05, 5.0, RW, {}),
    ("obstacle_map.miss_score", "OMAP_MISS", 0.0, 100.0, RW, {}),
    ("obstacle_map.max_score", "OMAP_MAX_SCORE", 1.0, 1000.0, RW, {}),
    ("obstacle_map.persist_score", "OMAP_PERSIST", 1.0, 1000.0, RW, {}),
    ("obstacle_map.min_span_s", "OMAP_MIN_SPAN", 0.0, 600.0, RW, {}),
    ("obstacle_map.free_memory_s", "OMAP_FREE_MEM", 0.0, 60.0, RW, {}),
    ("obstacle_map.ttl_s", "OMAP_TTL", 0.1, 86400.0, RW, {}),
    ("obstacle_map.max_cells", "OMAP_MAX_CELLS", 1, 100000, RW, {}),
    ("obstacle_map.update_period_s", "OMAP_UPD_PERIOD", 0.02, 60.0, RW, {}),
    ("obstacle_map.min_change_cells", "OMAP_MIN_CHANGE", 1, 1000, RW, {}),
    ("obstacle_map.rebuild_min_interval_s", "OMAP_REBUILD_INT", 0.0, 600.0, RW, {}),
    ("obstacle_map.max_obstacles", "OMAP_MAX_OBST", 1, 1000, RW, {}),
    ("obstacle_map.track_on_wall_m", "OMAP_TRK_WALL", 0.0, 10.0, RW, {}),
    ("obstacle_map.simplify_m", "OMAP_SIMPLIFY", 0.0, 5.0, RW, {}),
    ("obstacle_map.margin_m", "OMAP_MARGIN", 0.0, 10.0, RW, {}),
    ("passage.enabled", "GAP_ENABLE", 0, 1, RW, {}),
    ("passage.side_clearance_m", "GAP_SIDE_CLEAR", 0.0, 1.0, RW, {}),
    ("passage.max_width_m", "GAP_MAX_WIDTH", 0.0, 10.0, RW, {}),
    ("passage.wall_range_m", "GAP_WALL_RANGE", 0.2, 10.0, RW, {}),
    ("passage.depth_m", "GAP_DEPTH", 0.05, 5.0, RW, {}),
    ("passage.beam_half_deg", "GAP_BEAM_HALF", 0.0, 45.0, RW, {}),
    ("passage.history_s", "GAP_HISTORY", 0.5, 60.0, RW, {}),
    ("passage.min_free", "GAP_MIN_FREE", 1, 100, RW, {}),
    ("passage.match_m", "GAP_MATCH", 0.01, 5.0, RW, {}),
    ("passage.standoff_m", "GAP_STANDOFF", 0.3, 5.0, RW, {}),
    ("passage.heading_tol_deg", "GAP_HDG_TOL", 0.5, 30.0, RW, {}),
    ("passage.position_tol_m", "GAP_POS_TOL", 0.005, 0.5, RW, {}),
    ("passage.look_s", "GAP_LOOK", 0.0, 10.0, RW, {}),
    ("passage.speed_mps", "GAP_SPEED", 0.05, 2.0, RW, {}),
    ("passage.turn_rate_dps", "GAP_TURN_RATE", 5.0, 180.0, RW, {"units": "deg/s"}),
    ("passage.lookahead_m", "GAP_LOOKAHEAD", 0.1, 5.0, RW, {}),
    ("passage.stop_m", "GAP_STOP", 0.0, 2.0, RW, {}),
    ("passage.scan_max_deg", "GAP_SCAN_MAX", 0.0, 60.0, RW, {"units": "deg"}),
    ("passage.scan_rate_dps", "GAP_SCAN_RATE", 1.0, 90.0, RW, {"units": "deg/s"}),
    ("passage.scan_tol_m", "GAP_SCAN_TOL", 0.005, 0.5, RW, {}),
    ("passage.scan_tries", "GAP_SCAN_TRIES", 1, 20, RW, {}),
    ("passage.guard_near_m", "GAP_GUARD_NEAR", 0.0, 2.0, RW, {}),
    ("passage.guard_skew_m", "GAP_GUARD_SKEW", 0.0, 2.0, RW, {}),
    ("passage.stall_s", "GAP_STALL", 0.1, 10.0, RW, {}),
    ("passage.stall_m", "GAP_STALL_DIST", 0.0, 1.0, RW, {}),
    ("passage.exit_m", "GAP_EXIT", 0.0, 5.0, RW, {}),
    ("passage.search_m", "GAP_SEARCH", 0.0, 20.0, RW, {}),
    ("passage.search_speed_mps", "GAP_SEARCH_SPD", 0.05, 2.0, RW, {}),
    ("passage.timeout_s", "GAP_TIMEOUT", 1.0, 600.0, RW, {}),
    ("passage.reject_s", "GAP_REJECT", 0.0, 3600.0, RW, {}),
    ("passage.wall_mapped_m", "GAP_WALL_MAP", 0.0, 5.0, RW, {}),
    ("pivot.angle_deg", "WP_PIVOT_ANGLE", 0.0, 360.0, RW, {"units": "deg"}),
    ("pivot.rate_dps", "WP_PIVOT_RATE", 1.0, 720.0, RW, {"units": "deg/s"}),
    ("pivot.heading_gain", "PIV_GAIN", 0.1, 20.0, RW, {"units": "1/s"}),
    ("pivot.accuracy_deg", "PIV_ACCURACY", 0.5, 90.0, RW, {"units": "deg"}),
    ("pivot.clear_m", "PIV_CLEAR", 0.0, 10.0, RW, {"units": "m"}),
    ("pivot.open_m", "PIV_OPEN", 0.0, 10.0, RW, {"units": "m"}),
    ("pivot.open_half_deg", "PIV_OPEN_HALF", 0.0, 180.0, RW, {"units": "deg"}),
    ("pivot.timeout_s", "PIV_TIMEOUT", 0.1, 60.0, RW, {"units": "s"}),
    ("pivot.mover_m", "PIV_MOVER", 0.0, 100.0, RW, {"units": "m"}),
    ("pivot.rest_s", "PIV_REST", 0.0, 60.0, RW, {"units": "s"}),
    ("pivot.retry_after_m", "PIV_RETRY_DIST", 0.0, 100.0, RW, {"units": "m"}),
    ("pivot.max_cross_track_m", "PIV_XTRACK", 0.0, 100.0, RW, {"units": "m"}),
    ("obstacle_map.odometry_frame", "OMAP_ODOM", 0, 1, RW, {}),
    ("proximity.edge_sectors", "PRX_EDGE", 0, 1, RW, {}),
)
CONFIG_ONLY = frozenset({"link.vehicle_url", "link.gcs_url", "gcs.mission_store_path", "daemon.log_dir", "gcs.signing_key_path"})
"""Text fields: config file and command line only, never parameters."""


@cache
def field_docs(cls: type) -> dict[str, str]:
    """The docstring under each field of a config dataclass, joined into one line."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    body = tree.body[0].body
    docs: dict[str, str] = {}
    for node, following in zip(body, body[1:]):
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            if isinstance(following, ast.Expr) and isinstance(following.value, ast.Constant) and isinstance(following.value.value, str):
                docs[node.target.id] = " ".join(following.value.value.split())
    return docs


def _build() -> tuple[Param, ...]:
    defaults = Config()
    out = []
    for key, name, low, high, access, options in _DECLARED:
        section, field_name = key.split(".")
        cls = type(getattr(defaults, section))
        if options.get("choices"):
            kind = Kind.CHOICE
        elif isinstance(getattr(defaults, section).__dict__[field_name], bool):
            kind = Kind.BOOL
        elif options.get("mask"):
            kind = Kind.MASK
        elif isinstance(getattr(defaults, section).__dict__[field_name], int):
            kind = Kind.INT
        else:
            kind = Kind.FLOAT
        param = Param(name, key, float(low), float(high), options.get("units", _units_of(field_name)), access, kind,
                      options.get("choices"), options.get("auto", ""), field_docs(cls).get(field_name, ""))  # fmt: skip
        out.append(dataclasses.replace(param, default=param.encode(param.get(defaults))))
    return tuple(out)


TABLE: tuple[Param, ...] = _build()
"""Every parameter, in the order ground stations list them."""
BY_NAME: dict[str, Param] = {p.name: p for p in TABLE}
BY_KEY: dict[str, Param] = {p.key: p for p in TABLE}
MAVLINK: tuple[Param, ...] = tuple(p for p in TABLE if p.access is not Access.CONFIG)
"""What a ground station sees (PARAM_REQUEST_LIST order, param_index = position here)."""


def lookup(name_or_key: str) -> Param | None:
    """A parameter by MAVLink name (any case) or ``section.field``."""
    return BY_KEY.get(name_or_key) or BY_NAME.get(name_or_key.upper())


def values(config: Config, params: Iterable[Param] = MAVLINK) -> dict[str, float]:
    """MAVLink name -> value in force, in table order."""
    return {p.name: p.encode(p.get(config)) for p in params}


def check(config: Config) -> None:
    """Raise ParamError if any field of ``config`` is outside its parameter's range."""
    for param in TABLE:
        param.decode(param.encode(param.get(config)))


# ---- .parm files (MAVProxy / Mission Planner): "NAME VALUE" per line, '#' comments ----------------


def format_parm(values_by_name: Mapping[str, float], header: str = "") -> str:
    lines = [f"# {line}" for line in header.splitlines()]
    lines += [f"{name:<16} {_parm_number(value)}" for name, value in values_by_name.items()]
    return "\n".join(lines) + "\n"


def _parm_number(value: float) -> str:
    return str(int(value)) if value == int(value) and abs(value) < 2**53 else repr(float(value))


def parse_parm(text: str, where: str) -> dict[str, tuple[Param, Any]]:
    """Every line of a .parm text checked: name -> (parameter, field value). Raises ParamError
    naming the first bad line (``where:LINE: ...``); nothing is returned unless all are good.
    Separators: spaces, a tab or a comma (Mission Planner writes ``NAME,VALUE``)."""
    out: dict[str, tuple[Param, Any]] = {}
    for number, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.replace(",", " ").replace("\t", " ").split()
        if len(parts) != 2:
            raise ParamError(f"{where}:{number}: expected NAME VALUE, got {raw.strip()!r}")
        name, text_value = parts
        param = BY_NAME.get(name.upper())
        if param is None:
            raise ParamError(f"{where}:{number}: unknown parameter {name!r}")
        try:
            value = float(text_value)
        except ValueError:
            raise ParamError(f"{where}:{number}: {name}: {text_value!r} is not a number") from None
        try:
            out[param.name] = (param, param.decode(value))
        except ParamError as exc:
            raise ParamError(f"{where}:{number}: {param.name}: {exc}") from None
    return out


# ---- the documentation table (docs/gcs.md) ------------------------------------------------------

ACCESS_TEXT = {Access.RW: "", Access.START: "read-only (start)", Access.CONFIG: "config only"}


def markdown() -> str:
    """The parameter list of docs/gcs.md, generated from the table (``rover-ctl params --markdown``)."""
    rows = ["| name | config | default | range | access | description |", "|---|---|---|---|---|---|"]
    for p in TABLE:
        description = p.description.replace("|", "\\|")
        rows.append(f"| {p.name} | `{p.key}` | {_parm_number(p.default)} | {p.range_text()} | {ACCESS_TEXT[p.access]} | {description} |")
    return "\n".join(rows) + "\n"

