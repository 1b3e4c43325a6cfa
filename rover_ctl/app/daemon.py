"""The controller daemon: one single-threaded loop around the pure autopilot, with the links and the logs.

Each turn of the loop

1. reads the vehicle link: wheel distances, attitude and GPS go to the estimator (wheel distances
   also to the autopilot's wheel-speed meter), the latest range per orientation is kept, the
   vehicle's armed flag goes to the autopilot; SIMSTATE truth only goes to the tlog;
2. runs ``Autopilot.step`` when the vehicle (sensor) clock has reached the next tick of
   ``daemon.control_rate_hz``, sends its command (RC override, release, or neutral) and applies
   its events (STATUSTEXT, MISSION_CURRENT, MISSION_ITEM_REACHED on the GCS link, arm requests to
   the vehicle, the event log); in lockstep (the vehicle sends TIMESYNC frame markers) the step runs
   at the frame's marker and the marker is answered only after the step's override went out;
3. polls the GCS link (``rover_ctl.mavlink.gcs.GcsLink``), for which the daemon is the
   ``AutopilotHandlers``: each request is the autopilot's decision, its events applied at once (a
   refusal's STATUSTEXT goes out before the COMMAND_ACK);
4. sends telemetry to the GCS and blocks on both sockets for at most ``daemon.idle_wait_s``
   (unless the vehicle link holds messages it has read but not handed over yet).

Every decision is the autopilot's (``rover_ctl.autopilot``); the vehicle itself is kept in MANUAL
mode and steered with RC overrides.

Time: the autopilot decides on vehicle time (message timestamps), so a run is the same at any
speed-up; the GCS heartbeat's age too is measured in vehicle time (the vehicle time at which the
daemon received it). The wall clock serves link housekeeping and one failsafe: a silent vehicle
link cannot advance vehicle time, so its silence is measured on the wall clock.
"""

from __future__ import annotations

import functools
import json
import logging
import math
import select
import time
from pathlib import Path
from typing import Any

from rover_ctl.app.logs import CsvLog, LogBudget, LogClock, TlogWriter
from rover_ctl.autopilot.autopilot import LOG_COLUMNS, RELEASE, Autopilot, Readings, StepOutput
from rover_ctl.autopilot.events import ArmRequest, Event, ItemReached, MissionCurrent, StatusText
from rover_ctl.autopilot.loop_rate import ControlTicks
from rover_ctl.config import Config
from rover_ctl.estimation.estimator import PoseEstimator
from rover_ctl.estimation.frame import LocalFrame, enu_to_compass_rad
from rover_ctl.estimation.readings import Attitude, GpsFix, RangeReading, WheelDistance
from rover_ctl.fuzzy import load_rulebase
from rover_ctl.mavlink import budget
from rover_ctl.mavlink.budget import StreamPlan
from rover_ctl.mavlink.commands import ACK_LATER
from rover_ctl.mavlink.gcs import ConfigParams, GcsLink, VehicleState
from rover_ctl.mavlink.vehicle import NO_ANSWER, PYMAVLINK_DEFAULT_BAUD, Battery, CommandResult, FrameMarker, LinkError, StatusText as VehicleText, VehicleLink, VehicleParam, VehicleStatus
from rover_ctl.mavlink.signing import KeyStore
from rover_ctl.mission.model import Home, Mission
from rover_ctl.mission.store import MissionStore
from rover_ctl.vocabulary import ARM_FORCE_MAGIC, RoverMode, Severity, mav

log = logging.getLogger("rover_ctl.app.daemon")

# Exit codes (sysexits.h), so that a service manager can tell a bad setup from a crash.
EXIT_OK = 0
EXIT_SOFTWARE = 70
EXIT_UNAVAILABLE = 69
"""The vehicle never answered."""
EXIT_CONFIG = 78

CSV_COLUMNS = LOG_COLUMNS
SENSORS_PRESENT = (mav.MAV_SYS_STATUS_SENSOR_GPS | mav.MAV_SYS_STATUS_SENSOR_3D_GYRO | mav.MAV_SYS_STATUS_SENSOR_3D_MAG
                   | mav.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS | mav.MAV_SYS_STATUS_PREARM_CHECK)  # fmt: skip
"""SYS_STATUS sensors the daemon reports on the GCS link (through the vehicle)."""
SENSOR_FAILSAFES = {"GPS lost": mav.MAV_SYS_STATUS_SENSOR_GPS, "fence breach": mav.MAV_SYS_STATUS_GEOFENCE,
                    "vehicle link": mav.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS}  # fmt: skip
"""Active failsafe -> the SYS_STATUS health bit it clears."""


class EventLog:
    """events.jsonl: what happened when (vehicle time), for the report."""

    def __init__(self, path: Path | None):
        self.path = path
        self._file = open(path, "w", encoding="utf-8") if path else None

    def write(self, t_s: float, kind: str, **fields: Any) -> None:
        if self._file:
            try:
                self._file.write(json.dumps({"t_s": round(t_s, 3), "type": kind, **fields}) + "\n")
                self._file.flush()
            except OSError as exc:  # a full disk: the daemon goes on without its event log
                log.warning("logs: %s: %s; not written from here on", self.path, exc)
                self._file = None

    def close(self) -> None:
        if self._file:
            try:
                self._file.close()
            except OSError as exc:
                log.warning("logs: %s: %s on closing; its last lines are lost", self.path, exc)


class Daemon:
    """The controller. ``run()`` returns an exit code; ``stop()`` (signal-safe) ends the loop."""

    def __init__(self, config: Config, rulebase: str = "default", log_dir: str | Path | None = None):
        self.config = config
        self.rulebase = load_rulebase(rulebase)
        self.log_dir = Path(log_dir) if log_dir else None
        """This run's log folder (``rover-ctl run`` makes a new numbered one each start); None: no logs."""
        self.settings = config.daemon
        self._stop = False
        self.autopilot = Autopilot(config, self.rulebase)
        self.link: VehicleLink | None = None
        self.gcs: GcsLink | None = None
        self.vehicle: VehicleStatus | None = None
        self.home: Home | None = None
        self.frame: LocalFrame | None = None
        self.estimator: PoseEstimator | None = None
        self.last_fix_s: float | None = None
        self.ranges: dict[int, RangeReading] = {}
        self.battery: Battery | None = None
        self.lockstep = False
        self.ticks = ControlTicks(lambda: self.period_s)
        self._released = False
        self._gcs_readable = True
        """Whether the last wait found the GCS socket readable (or did not wait): its next poll reads it."""
        self._rx_perf: float | None = None
        self._marker_wall_s = 0.0
        self._silent_neutral_wall_s = 0.0
        self._gcs_heartbeat_wall_s: float | None = None
        self._gcs_heartbeat_vehicle_s: float | None = None
        """Vehicle time at which the last ground-station heartbeat was received."""
        self.steps = 0
        self.table = ConfigParams.persistent(config)
        self.events = EventLog(None)
        self.csv: CsvLog | None = None
        self.tlogs: list[TlogWriter] = []
        self.log_budget: LogBudget | None = None
        self._saved_seq: int | None = None
        self.log_clock = LogClock(lambda: self.link.vehicle_time_s if self.lockstep else None)
        self.stream_plan: StreamPlan | None = None
        self._planned_rangefinders: int | None = None
        self._rates_from_s = math.inf
        """Vehicle time from which the measured odometry rates reflect the plan (one window after asking)."""
        self._next_health_wall_s = 0.0
        self._odometry_rates: dict[str, float] = {}
        self._streams_checked_s = math.inf
        self._next_override_wall_s = 0.0
        self._arm_results = {arm: functools.partial(self._on_arm_result, arm=arm) for arm in (True, False)}
        self._arm_accepted: bool | None = None
        """An arming or disarming the vehicle just ACCEPTED, for its COMMAND_ACK's item."""
        """One callback per arming direction, so that a repeated request joins the waiting one (VehicleLink.command_async)."""

    @property
    def period_s(self) -> float:
        return 1.0 / self.settings.control_rate_hz

    # ---- lifecycle -----------------------------------------------------------------------------

    def stop(self) -> None:
        self._stop = True

    def open(self) -> bool:
        """Connect both links and open the logs. False if stopped while waiting for the vehicle;
        raises LinkError when the vehicle is absent."""
        cfg = self.config
        if self.log_dir:
            self.log_dir.mkdir(parents=True, exist_ok=True)
            self.events = EventLog(self.log_dir / "events.jsonl")
            self.csv = CsvLog(self.log_dir / "control.csv", CSV_COLUMNS)
            self.log_budget = LogBudget(self.log_dir, self.settings.log_max_total_mb, on_full=self._log_budget_full)
        url = cfg.link.vehicle_url
        if budget.is_serial(url) and budget.serial_baud(url) is None:
            log.warning("vehicle link %s: no baud rate given, opened at pymavlink's %d; a radio at another rate "
                        "gives only garbage: write DEVICE,BAUD (e.g. /dev/ttyUSB0,57600)", url, PYMAVLINK_DEFAULT_BAUD)  # fmt: skip
        self.link = VehicleLink(
            cfg.link.vehicle_url,
            cfg.link,
            command_timeout_s=self.settings.command_timeout_s,
            command_retries=self.settings.command_retries,
        )
        if self.log_dir:
            self.tlogs.append(TlogWriter(self.log_dir / "vehicle.tlog", clock=self.log_clock, budget=self.log_budget))
            self.tlogs[-1].attach(self.link.conn)
        log.info("vehicle link %s: waiting for a heartbeat", cfg.link.vehicle_url)
        self.vehicle = self.link.wait_vehicle(self.settings.vehicle_wait_s, cancelled=lambda: self._stop)
        if self.vehicle is None:
            return False
        self.autopilot.on_vehicle(self.vehicle.armed)
        log.info("vehicle sysid %d found (mode %d, armed %s)", self.link.target_system, self.vehicle.custom_mode, self.vehicle.armed)
        self._request_streams()
        result = self.link.command(mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, RoverMode.MANUAL)
        if not result.accepted:
            log.warning("vehicle refused MANUAL mode (result %d): overrides may be ignored", result.result)
        store_path = cfg.gcs.mission_store_path
        store = MissionStore(Path(store_path).expanduser()) if store_path else None
        signing = KeyStore(cfg.gcs.signing_key_path) if cfg.gcs.signing_key_path else None
        self.gcs = GcsLink(cfg.link.gcs_url, cfg.gcs, handlers=self, store=store, signing=signing)
        if store is not None and (seq := store.load_progress(self.autopilot.mission)) is not None:
            self._saved_seq = seq
            self.autopilot.resume_from(seq)
        self._apply(self.autopilot.drain())
        if self.log_dir:
            self.tlogs.append(TlogWriter(self.log_dir / "gcs.tlog", clock=self.log_clock, budget=self.log_budget))
            self.tlogs[-1].attach(self.gcs.conn)
        log.info("GCS link %s ready", cfg.link.gcs_url)
        return True

    def _log_budget_full(self, size_bytes: int) -> None:
        """This run's folder outgrew ``daemon.log_max_total_mb``: the tlogs stopped (``LogBudget`` warned)."""
        self.events.write(self._now(), "log_budget", size_mb=round(size_bytes / 1e6, 1), max_mb=self.settings.log_max_total_mb)

    def _rangefinder_count(self) -> int:
        """DISTANCE_SENSOR per period the vehicle will send: the reporting ones once the autopilot
        has its rangefinder plan, else the configured list, else what the rule base reads."""
        if self.autopilot.rangefinder_plan is not None:
            return len(self.ranges)
        configured = self.config.link.rangefinders
        return len(configured) if configured != [-1] else len(self.autopilot.navigator.orientations)

    def _request_streams(self) -> None:
        """Ask the vehicle for the link budget's rates (``rover_ctl.mavlink.budget``); say what
        they are, and loudly when even the minimum rates do not fit the line."""
        link = self.link
        count = self._rangefinder_count()
        sizes = {n: size for n in ("WHEEL_DISTANCE", "ATTITUDE", "GPS_RAW_INT", "DISTANCE_SENSOR", "SYS_STATUS", "HEARTBEAT")
                 if (size := link.health.mean_size(n)) is not None}  # fmt: skip
        plan = budget.plan(self.settings, self.config.link, self.config.failsafe, link.url, count, measured_bytes=sizes)
        link.request_streams(plan)
        self._streams_requested_wall_s = time.monotonic()
        self._rates_from_s = link.vehicle_time_s + self.config.link.rate_window_s
        self._streams_checked_s = self._rates_from_s + self.config.link.rate_window_s
        self._planned_rangefinders = count
        if plan != self.stream_plan:
            log.info("vehicle link budget: %s", plan.describe())
            self.events.write(link.vehicle_time_s, "link_plan", rates_hz=plan.rates_hz, bytes_per_s=round(plan.bytes_per_s),
                              line_bytes_per_s=plan.line_bytes_per_s, source=plan.source)  # fmt: skip
            if plan.shortfall:
                text = f"Link too slow: {plan.shortfall}"
                log.error("%s", text)
                self.events.write(link.vehicle_time_s, "statustext", text=text, severity=int(Severity.CRITICAL))
                if self.gcs is not None:
                    self.gcs.send_statustext(text, mav.MAV_SEVERITY_CRITICAL)
        self.stream_plan = plan

    def _sensor_rates(self) -> dict[str, float]:
        """Measured odometry rates for the failsafes and the loop-rate target, once the plan's
        rates can have arrived; meanwhile (a re-plan) the last ones measured before it."""
        link = self.link
        now = link.vehicle_time_s
        if now >= self._rates_from_s:
            self._odometry_rates = {n: hz for n in ("ATTITUDE", "WHEEL_DISTANCE") if (hz := link.health.rate_hz(n, now)) is not None}
        return self._odometry_rates

    def _check_streams(self) -> None:
        """Two windows after asking, once: a planned message arriving at less than half its rate
        (a request lost on a noisy line, a vehicle that forgot) is asked for again."""
        link, plan = self.link, self.stream_plan
        if plan is None or link.vehicle_time_s < self._streams_checked_s:
            return
        self._streams_checked_s = math.inf
        wanted = {"ATTITUDE": plan.rates_hz.get(budget.EXTRA1, 0.0), "GPS_RAW_INT": plan.rates_hz.get("GPS_RAW_INT", 0.0)}
        short = [n for n, hz in wanted.items() if hz > 0 and (link.health.rate_hz(n, link.vehicle_time_s) or 0.0) < hz / 2]
        if short:
            log.warning("vehicle link: %s below half the rate asked: asking again", ", ".join(short))
            self._request_streams()

    def _report_link(self, final: bool = False) -> None:
        """Every ``link.health_period_s`` of wall time, and once more at shutdown (a lockstep run may
        end before the first period does): what the vehicle link carried, in the log and the event
        log. The counters (lost, bad CRC, garbage) are the whole run's."""
        now = time.monotonic()
        if now < self._next_health_wall_s and not final:
            return
        self._next_health_wall_s = now + self.config.link.health_period_s
        link = self.link
        stats = link.health.stats(link.vehicle_time_s)
        radio = link.radio
        line = stats.describe(("WHEEL_DISTANCE", "ATTITUDE", "GPS_RAW_INT", "DISTANCE_SENSOR"))
        if radio is not None:
            line += f"; radio rssi {radio.rssi}/{radio.remote_rssi}, txbuf {radio.txbuf_pct}%, rx errors {radio.rx_errors}"
        log.info("vehicle link: %s", line)
        record = {"rates_hz": {k: round(v, 2) for k, v in stats.rates_hz.items()}, "rx_bytes_per_s": round(stats.rx_bytes_per_s),
                  "lost": stats.lost, "crc_errors": stats.crc_errors, "garbage": stats.garbage, "loss_pct": round(stats.loss_pct, 3)}  # fmt: skip
        if radio is not None:
            record |= {"rssi": radio.rssi, "remote_rssi": radio.remote_rssi, "txbuf_pct": radio.txbuf_pct}
        self.events.write(link.vehicle_time_s, "link", **record)

    def run(self) -> int:
        """Open, loop until stopped, close. Returns a process exit code."""
        try:
            if not self.open():
                self.close()
                return EXIT_OK
        except LinkError as exc:
            log.error("%s", exc)
            self.close()
            return EXIT_UNAVAILABLE
        try:
            while not self._stop:
                self.turn()
        except Exception:
            log.exception("control loop failed")
            self.shutdown()
            return EXIT_SOFTWARE
        self.shutdown()
        return EXIT_OK

    def shutdown(self) -> None:
        """Motors neutral first, then disarm, then close links and logs."""
        if self.link:
            self.link.send_override(self.config.wheel_control.rc_trim_us, self.config.wheel_control.rc_trim_us)
            self.link.arm_async(False)
            log.info("stopped: motors neutral, disarm sent")
            self._report_link(final=True)
        self.close()

    def close(self) -> None:
        """Close everything, each whatever the others do (a full disk must not leave a link open)."""
        for closeable in (self.gcs, self.table, self.link, self.csv, self.events, *self.tlogs):
            if closeable is not None:
                try:
                    closeable.close()
                except Exception as exc:  # noqa: BLE001: shutting down, the rest must still close
                    log.warning("closing %s: %s", type(closeable).__name__, exc)

    # ---- one loop turn -------------------------------------------------------------------------

    def turn(self) -> None:
        link = self.link
        link.tick()
        items = link.poll()
        marker: FrameMarker | None = None
        for item in items:
            if isinstance(item, FrameMarker):
                marker = item
            else:
                self._on_item(item)
        if marker is not None:
            self.lockstep = True
            self._marker_wall_s = time.monotonic()
            self._maybe_step(marker.time_s)
        elif not self.lockstep and items:
            self._maybe_step(link.vehicle_time_s)
        self._check_silence()
        if self.autopilot.rangefinder_plan is not None and self._rangefinder_count() != self._planned_rangefinders:
            self._request_streams()  # the rover's rangefinders are known now: budget them
        self._check_streams()
        if marker is not None:  # after everything this frame sends the vehicle: it applies them at this frame
            link.answer_marker(marker)
        self._report_link()
        self.gcs.poll(time.monotonic(), readable=self._gcs_readable)
        self.table.flush()  # parameters set from a ground station: written at most every gcs.param_save_s
        self._note_gcs_heartbeat()
        self._send_telemetry()
        # Sleep until the next message even after a busy turn (a turn that only finds the sockets
        # empty costs as much as a short one), unless messages already read are waiting.
        gcs_fd = getattr(self.gcs.conn, "fd", None)
        self._gcs_readable = True
        if not link.backlog:
            fds = [fd for fd in (link.fileno(), gcs_fd) if fd is not None]
            ready, _, _ = select.select(fds, [], [], self.settings.idle_wait_s)
            self._gcs_readable = gcs_fd is None or gcs_fd in ready

    def _on_item(self, item: Any) -> None:
        if isinstance(item, WheelDistance):
            self._rx_perf = time.perf_counter()
            self.autopilot.on_wheels(item)
            if self.estimator:
                self.estimator.on_wheels(item)
        elif isinstance(item, Attitude):
            self._rx_perf = time.perf_counter()
            self.autopilot.on_attitude(item)
            if self.estimator:
                self.estimator.on_attitude(item)
        elif isinstance(item, RangeReading):
            self._rx_perf = time.perf_counter()
            self.ranges[item.orientation] = item
        elif isinstance(item, GpsFix):
            self._rx_perf = time.perf_counter()
            if item.has_fix:
                self.last_fix_s = item.time_s
            if self.home is None and item.has_fix:
                self._set_home(item)
            if self.estimator:
                self.estimator.on_gps(item)
        elif isinstance(item, VehicleStatus):
            self.vehicle = item
            self.autopilot.on_vehicle(item.armed)
        elif isinstance(item, CommandResult) and item.command == mav.MAV_CMD_COMPONENT_ARM_DISARM and self._arm_accepted is not None:
            self.autopilot.on_vehicle(self._arm_accepted)
            self._arm_accepted = None
        elif isinstance(item, Battery):
            self.battery = item
        elif isinstance(item, VehicleParam):
            log.info("vehicle parameter %s = %g", item.name, item.value)
            self.autopilot.on_vehicle_param(item.name, item.value)
        elif isinstance(item, VehicleText):
            log.info("vehicle: %s", item.text)
            self.events.write(item.time_s, "statustext", text=item.text, severity=item.severity, source="vehicle")
            if item.severity <= self.config.gcs.vehicle_text_severity:
                self.gcs.send_statustext(item.text, item.severity)

    def _set_home(self, fix: GpsFix) -> None:
        self.home = Home(fix.lat_deg, fix.lon_deg, fix.alt_m)
        self.frame = LocalFrame(fix.lat_deg, fix.lon_deg, fix.alt_m)
        self.estimator = PoseEstimator(self.frame, self.config.estimator, lambda: self.config.robot.track_m)
        self.events.write(fix.time_s, "frame", lat_deg=fix.lat_deg, lon_deg=fix.lon_deg, alt_m=fix.alt_m)
        log.info("home set at %.7f %.7f", fix.lat_deg, fix.lon_deg)
        self.autopilot.set_home(self.home, self.frame)
        self._apply(self.autopilot.drain())

    def _now(self) -> float:
        return self.link.vehicle_time_s if self.link else 0.0

    def _note_gcs_heartbeat(self) -> None:
        """Stamp a newly received ground-station heartbeat with the vehicle time."""
        seen = self.gcs.last_gcs_heartbeat_s
        if seen is not None and seen != self._gcs_heartbeat_wall_s:
            self._gcs_heartbeat_wall_s = seen
            self._gcs_heartbeat_vehicle_s = self._now()

    # ---- AutopilotHandlers (the GCS link calls these): the autopilot decides, its events go out now

    def state(self) -> VehicleState:
        s = self.autopilot.state()
        return VehicleState(s.armed, int(s.mode), s.system_status, s.home, int(s.mission_state))

    def arm(self, arm: bool, force: bool) -> int:
        """The autopilot's checks decide whether the request goes to the vehicle; if it does, the
        vehicle's answer is the ground station's (``_on_arm_result``): its own checks may refuse."""
        reply = self.autopilot.arm(arm, force)
        events = self.autopilot.drain()
        self._apply(events)
        if reply.accepted and any(isinstance(e, ArmRequest) for e in events):
            return ACK_LATER
        return reply.result

    def set_mode(self, custom_mode: int) -> int:
        return self._request(self.autopilot.set_mode(custom_mode))

    def mission_start(self) -> int:
        return self._request(self.autopilot.mission_start())

    def return_to_launch(self) -> int:
        return self._request(self.autopilot.return_to_launch())

    def set_current(self, seq: int) -> bool:
        ok = self.autopilot.set_current(seq)
        self._apply(self.autopilot.drain())
        return ok

    def mission_changed(self, mission: Mission, mission_type: int) -> None:
        self.autopilot.mission_changed(mission, mission_type)
        if self.gcs is not None:  # during GcsLink's construction the events wait for open()
            self._apply(self.autopilot.drain())

    def guided_target(self, lat_deg: float, lon_deg: float, change_mode: bool) -> int:
        return self._request(self.autopilot.guided_target(lat_deg, lon_deg, change_mode))

    def params(self) -> dict[str, float]:
        return self.table.params()

    def set_param(self, name: str, value: float) -> tuple[bool, str]:
        return self.table.set_param(name, value)

    def _request(self, reply) -> int:
        self._apply(self.autopilot.drain())
        return reply.result

    # ---- the autopilot's outputs ---------------------------------------------------------------

    def _apply(self, events: list[Event] | tuple[Event, ...]) -> None:
        """Events -> GCS messages, vehicle commands and the event log, in order."""
        now = self._now()
        for event in events:
            kind, fields = event.log_record()
            self.events.write(now, kind, **fields)
            if isinstance(event, StatusText):
                log.log(logging.WARNING if event.severity <= Severity.WARNING else logging.INFO, "%s", event.text)
                self.gcs.send_statustext(event.text, int(event.severity))
            elif isinstance(event, MissionCurrent):
                self._save_progress(event.seq)  # stored before the GCS hears of it
                self.gcs.send_mission_current(event.seq, int(event.state))
            elif isinstance(event, ItemReached):
                self.gcs.send_mission_item_reached(event.seq)
            elif isinstance(event, ArmRequest):
                params = (1.0 if event.arm else 0.0, float(ARM_FORCE_MAGIC) if event.force else 0.0)
                self.link.command_async(mav.MAV_CMD_COMPONENT_ARM_DISARM, *params, on_result=self._arm_results[event.arm])
            elif kind in ("mode", "complete"):
                log.info("%s %s at t=%.2f s", kind, fields, now)

    def _save_progress(self, seq: int) -> None:
        """Keep the current item beside the stored mission (MIS_RESTART 0 resumes there after a restart)."""
        store = getattr(self.gcs, "store", None)
        if store is None or seq == self._saved_seq or not self.autopilot.mission.items:
            return
        self._saved_seq = seq
        try:
            store.save_progress(self.autopilot.mission, seq)
        except OSError as exc:
            log.warning("%s: cannot save the mission's progress: %s", store.progress_path, exc)

    def _on_arm_result(self, result, arm: bool) -> None:
        """The vehicle's answer to an arming or disarming: told, and acknowledged to the ground
        stations that asked (FAILED when it gave none). ACCEPTED means the vehicle has armed or
        disarmed (ArduPilot answers after the change, not before), so the autopilot takes it at
        once rather than at the vehicle's next heartbeat, up to a second later; the heartbeats
        stay the truth from then on. Taken in the stream's order, with the COMMAND_ACK's item
        (``_on_item``): this runs while the link decodes, before the items read with the ACK are
        handled, and a heartbeat the vehicle sent before it armed would otherwise undo it."""
        if result.accepted:
            self._arm_accepted = arm
        unanswered = result.result == NO_ANSWER
        if not result.accepted:
            text = ("Vehicle did not answer arming/disarming" if unanswered else
                    f"Vehicle refused arming/disarming (result {result.result})")  # fmt: skip
            log.warning("%s", text)
            self.events.write(self._now(), "statustext", text=text, severity=int(Severity.WARNING))
            self.gcs.send_statustext(text, mav.MAV_SEVERITY_WARNING)
        self.gcs.command_result(result.command, mav.MAV_RESULT_FAILED if unanswered else result.result)

    def _send_command(self, out: StepOutput) -> None:
        if out.command is RELEASE:
            if not self._released:
                self.link.release_override()
                self._released = True
            return
        self._released = False
        if self._radio_full():
            now = time.monotonic()
            if now < self._next_override_wall_s:
                return  # the radio's buffer is filling: refresh at override_min_hz only
            self._next_override_wall_s = now + 1.0 / self.config.link.override_min_hz
        self.link.send_override(out.command.steering_us, out.command.throttle_us)

    def _radio_full(self) -> bool:
        """The local telemetry radio reports its transmit buffer nearly full (RADIO_STATUS.txbuf),
        the signal ArduPilot's own stream code backs off on."""
        radio, p = self.link.radio, self.config.link
        return (radio is not None and radio.txbuf_pct < p.radio_txbuf_low_pct
                and time.monotonic() - radio.wall_s <= p.radio_status_timeout_s)  # fmt: skip

    # ---- the control step ------------------------------------------------------------------------

    def _maybe_step(self, t_s: float) -> None:
        """Run the control step if vehicle time ``t_s`` reached the next tick."""
        if not self.ticks.due(t_s):
            return
        last = self.link.last_rx_vehicle_s
        self.control_step(t_s, vehicle_age_s=0.0 if last is None else max(0.0, t_s - last))

    def control_step(self, t_s: float, vehicle_age_s: float) -> None:
        out = self.autopilot.step(t_s, self._pose(t_s), self._readings(t_s, vehicle_age_s))
        self._send_command(out)
        self._apply(out.events)
        row = out.log_row
        if self._rx_perf is not None:
            row["latency_ms"] = (time.perf_counter() - self._rx_perf) * 1e3
        self.steps += 1
        if self.csv:
            self.csv.write(row)
            if self.steps % 50 == 0:
                self.csv.flush()

    def _pose(self, t_s: float):
        """The estimate at ``t_s`` (vehicle time; ``PoseEstimator.pose`` predicts up to its lead)."""
        return self.estimator.pose(t_s) if self.estimator and self.estimator.initialised else None

    def _readings(self, t_s: float, vehicle_age_s: float) -> Readings:
        gcs_s = self._gcs_heartbeat_vehicle_s
        return Readings(
            ranges=dict(self.ranges),
            vehicle_age_s=vehicle_age_s,
            gcs_age_s=math.inf if gcs_s is None else self._gcs_age_s(t_s, gcs_s),
            gps_age_s=math.inf if self.last_fix_s is None else max(0.0, t_s - self.last_fix_s),
            sensor_rates_hz=self._sensor_rates(),
            odometry_planned_hz=self.stream_plan.rates_hz.get(budget.EXTRA1) if self.stream_plan else None,
        )

    def _gcs_age_s(self, t_s: float, heartbeat_vehicle_s: float) -> float:
        """The last GCS heartbeat's age: the smaller of its age in vehicle time and in wall time.
        A ground station paces its heartbeat by the wall clock, and the vehicle's clock may run
        faster (lockstep) or slower (a starved simulator): a heartbeat is late only when it is late
        by both. On a real vehicle the two clocks agree."""
        wall_age_s = time.monotonic() - self._gcs_heartbeat_wall_s
        return max(0.0, min(t_s - heartbeat_vehicle_s, wall_age_s))

    def _check_silence(self) -> None:
        """Nothing at all from the vehicle (not even lockstep markers, which would drive the
        control step and its failsafe in vehicle time): step the autopilot on the wall clock, at
        most once a control period, so that its vehicle-link failsafe sends neutral. In lockstep
        only after ``daemon.lockstep_silence_s``: a starved emulator is paused, not gone. The
        silence is measured up to the link's latest poll, not to now: a turn the daemon itself was
        kept from (a blocking write, the machine's load) is not the vehicle's silence."""
        link = self.link
        if link.last_rx_wall_s is None or link.last_poll_wall_s is None:
            return
        age_s = link.last_poll_wall_s - max(link.last_rx_wall_s, self._marker_wall_s)
        timeout_s = self.config.daemon.lockstep_silence_s if self.lockstep else self.config.failsafe.vehicle_timeout_s
        if age_s <= timeout_s or time.monotonic() < self._silent_neutral_wall_s:
            return
        self._silent_neutral_wall_s = time.monotonic() + self.period_s
        t_s = link.vehicle_time_s + age_s
        out = self.autopilot.step(t_s, self._pose(t_s), self._readings(t_s, age_s))
        self._apply(out.events)
        if out.command is not RELEASE:
            self._send_command(out)
        if age_s > self.settings.stream_rerequest_s and time.monotonic() - self._streams_requested_wall_s > self.settings.stream_rerequest_s:
            self._request_streams()  # the vehicle may have rebooted and forgotten our rates

    # ---- telemetry to the GCS ------------------------------------------------------------------

    def _send_telemetry(self) -> None:
        now = time.monotonic()
        if self.link.last_gps_msg is not None:
            self.gcs.send_gps_raw_int(now, self.link.last_gps_msg)
        if self.battery is not None and self.gcs.sys_status_due(now):
            present = SENSORS_PRESENT | (mav.MAV_SYS_STATUS_GEOFENCE if self.autopilot.mission.fence else 0)
            reasons = self.autopilot.state().failsafes
            failed = sum(bit for reason, bit in SENSOR_FAILSAFES.items() if reason in reasons)
            failed |= 0 if self.autopilot.ready_to_arm() else mav.MAV_SYS_STATUS_PREARM_CHECK
            health = self.link.health
            self.gcs.send_sys_status(now, self.battery.voltage_v, self.battery.remaining_pct, present=present, failed=failed,
                                     drop_rate_cpct=round(100 * health.loss_pct), errors_comm=health.crc_errors)  # fmt: skip
        if self.estimator is None or not self.estimator.initialised or not self.gcs.pose_due(now):
            return
        pose = self.estimator.pose(self.link.vehicle_time_s)
        lat, lon = self.frame.to_geodetic(pose.east_m, pose.north_m)
        time_boot_ms = int(pose.time_s * 1000)
        compass_rad = enu_to_compass_rad(pose.heading_rad)
        self.gcs.send_global_position_int(
            now, lat, lon, self.home.alt_m, 0.0, pose.speed_mps * math.cos(pose.heading_rad),
            pose.speed_mps * math.sin(pose.heading_rad), math.degrees(compass_rad), time_boot_ms,
        )  # fmt: skip
        self.gcs.send_attitude(now, compass_rad, -pose.yaw_rate_radps, time_boot_ms)
