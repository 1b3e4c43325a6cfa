"""The MAVLink parameter microservice on the GCS link, as ArduPilot answers it.

* PARAM_REQUEST_LIST: every parameter as PARAM_VALUE, paced at ``gcs.param_send_rate_hz`` so a
  full list does not flood a telemetry radio (ArduPilot too spreads it over its update loop). A
  request while a list is going out does not start it over (a stream of requests would keep any
  list from finishing): the list goes on, and a ground station asks for what it missed by index,
  as the parameter protocol has it; a request after the list ended starts a new one.
* PARAM_REQUEST_READ by name (``param_index`` -1) or by index: that PARAM_VALUE.
* PARAM_SET: the value is checked against the parameter table (``rover_ctl.parameters``) and
  answered with PARAM_VALUE carrying the value in force; a refused value (out of range, not
  finite, not a whole number, not a choice) or a read-only parameter keeps the old value and a
  STATUSTEXT says why. An unknown name is ignored, as ArduPilot does.

PARAM_VALUE: ``param_count`` the table's size, ``param_index`` the parameter's position in
``params()`` (also for the reply to a read by name or a set, where ArduPilot sends -1), and
``param_type`` ArduPilot's type for the parameter (INT8/INT16/INT32 for whole numbers, choices and
bitmasks, REAL32 otherwise) with the value itself as a float (AUTOPILOT_VERSION announces
MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT, not byte-wise encoding), which MAVProxy and QGroundControl
read as they read ArduPilot's.

``ConfigParams`` is the table behind the autopilot handlers' ``params()`` / ``set_param()``: the
daemon's ``Config`` seen through ``rover_ctl.parameters``, persisted by ``ParamStore``. A change
takes effect (and is answered) at once; writing it is coalesced: the first change is written at
once, later ones when ``gcs.param_save_s`` has passed since the last write (``flush()``, every loop
turn), the rest by ``close()`` on shutdown. So a stream of PARAM_SETs costs one atomic write (two
fsyncs) per ``param_save_s``, and a crash loses at most that long of changes.

Log lines about what a ground station sends are rate-limited (``rover_ctl.mavlink.ratelog``).
"""

from __future__ import annotations

import logging
import time
from typing import Any, Callable

from rover_ctl.config import Config
from rover_ctl.mavlink.ratelog import LogLimit
from rover_ctl.param_store import ParamStore, ParamStoreError, store_path
from rover_ctl.parameters import BY_NAME, MAVLINK, Access, ParamError, values
from rover_ctl.vocabulary import mav

log = logging.getLogger(__name__)

HANDLED = ("PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_SET")
LIST_BURST = 10
"""PARAM_VALUEs sent at most in one poll while a list is going out."""
SET_LOG_BURST = 10
"""Info lines about PARAM_SETs per second at most (a ground station's import, not a stranger's flood)."""


class ConfigParams:
    """The parameters of a ``Config`` (every one the table exposes over MAVLink, in table order).

    ``set_param`` applies a value to the config section that owns it, which every consumer reads
    at its next use, and saves it in ``store`` (if any): at once if the last write is
    ``gcs.param_save_s`` old, else at the first ``flush()`` after that, or at ``close()``.
    ``persistent(config)`` is the daemon's: it loads the values a ground station set before the
    restart (precedence: defaults < config file < stored < ``--set``; docs/gcs.md). ``clock``:
    monotonic seconds, for the save interval."""

    def __init__(self, config: Config, store: ParamStore | None = None, clock: Callable[[], float] = time.monotonic) -> None:
        self.config = config
        self.store = store
        self.clock = clock
        self.stored: dict[str, float] = {}
        """What the store holds, or will hold at the next write (values set from a ground station
        or imported)."""
        self.unsaved = False
        """``stored`` has changes not written yet."""
        self.writes = 0
        """Writes of the store attempted by this table."""
        self._written_s: float | None = None
        self.store_error: str | None = None
        """Why the stored parameters could not be loaded (the file was moved aside), if they could not."""

    @classmethod
    def persistent(cls, config: Config, read_only: bool = False, clock: Callable[[], float] = time.monotonic) -> "ConfigParams":
        """``read_only``: a command that only looks (``rover-ctl params``) leaves a corrupt store
        where it is and only says why."""
        path = store_path(config)
        table = cls(config, ParamStore(path) if path else None, clock)
        table.load(read_only)
        return table

    def load(self, read_only: bool = False) -> None:
        """Apply the stored values, except to parameters given with ``--set``. A corrupt store is
        moved aside with one error line; the daemon then runs on its config."""
        if self.store is None:
            return
        try:
            self.stored = self.store.load()
        except ParamStoreError as exc:
            if read_only:
                self.store_error = f"{exc}; fix or remove it (the daemon moves it aside when it starts)"
                return
            aside = self.store.quarantine()
            kept = f"moved to {aside}" if aside else "left as it is"
            self.store_error = f"{exc}; {kept}, starting without stored parameters"
            log.error("%s", self.store_error)
            return
        applied = []
        for name, number in self.stored.items():
            param = BY_NAME[name]
            if param.access is Access.CONFIG or param.key in self.config.command_line:
                continue
            param.set(self.config, param.decode(number))
            applied.append(name)
        if applied:
            log.info("parameters from %s: %s", self.store.path, ", ".join(applied))

    def params(self) -> dict[str, float]:
        return values(self.config, MAVLINK)

    def set_param(self, name: str, value: float) -> tuple[bool, str]:
        """(True, "") when applied; (False, why) when refused (the value stays). A store that
        cannot be written when the change is (not when a later ``flush`` writes it: that is logged
        and tried again every ``param_save_s``) keeps the value for this run and says so: (True, why)."""
        param = BY_NAME.get(name)
        if param is None or param.access is Access.CONFIG:
            return False, f"{name}: no such parameter"
        if param.access is not Access.RW:
            return False, f"{name} is read-only: set at start"
        try:
            field_value = param.decode(value)
        except ParamError as exc:
            return False, f"{name}: {exc}"
        param.set(self.config, field_value)
        number = param.encode(field_value)
        if self.store is None or self.stored.get(name) == number:
            return True, ""
        self.stored[name] = number
        self.unsaved = True
        if self._write_due() and not self._write():
            return True, f"{name} set but not saved"
        return True, ""

    def flush(self, force: bool = False) -> None:
        """Write the unsaved changes if the last write is ``gcs.param_save_s`` old (the daemon calls
        this every loop turn), or now if ``force``."""
        if self.unsaved and (force or self._write_due()):
            self._write()

    def close(self) -> None:
        """Shutdown: write what is not saved yet."""
        self.flush(force=True)

    def _write_due(self) -> bool:
        return self._written_s is None or self.clock() - self._written_s >= self.config.gcs.param_save_s

    def _write(self) -> bool:
        self._written_s = self.clock()
        self.writes += 1
        try:
            self.store.save(dict(self.stored))
        except OSError as exc:  # kept unsaved: tried again after param_save_s
            log.error("%s: cannot save parameters: %s", self.store.path, exc)
            return False
        self.unsaved = False
        return True


class ParamService:
    """Answers the parameter protocol from ``handlers.params()`` / ``handlers.set_param()``.

    ``set_param`` may return a bool or ``(ok, reason)``; ``say(text, severity)`` sends a
    STATUSTEXT (the link's chunking sender); ``rate_hz()`` gives the list's pace."""

    def __init__(self, conn: Any, handlers: Any, say: Callable[[str, int], None] | None = None,
                 rate_hz: Callable[[], float] = lambda: 50.0) -> None:  # fmt: skip
        self.conn = conn
        self.handlers = handlers
        self.say = say or (lambda text, severity: conn.mav.statustext_send(severity, text.encode()[:50], 0, 0))
        self.rate_hz = rate_hz
        self._pending: list[str] = []  # names still to send for a list request, in order
        self._credit = 0.0
        self._last_s: float | None = None
        self._unknown_log = LogLimit(log)
        self._set_log = LogLimit(log, burst=SET_LOG_BURST)

    @property
    def listing(self) -> bool:
        """A list request is being answered."""
        return bool(self._pending)

    def handle(self, msg) -> None:
        kind = msg.get_type()
        if kind == "PARAM_REQUEST_LIST":
            if self._pending:
                return  # the list goes on: another request does not start it over (module docstring)
            self._pending = list(self.handlers.params())
            self._credit = 0.0
            self._last_s = None
        elif kind == "PARAM_REQUEST_READ":
            table = self.handlers.params()
            names = list(table)
            if msg.param_index < 0:
                name = msg.param_id
            else:
                name = names[msg.param_index] if msg.param_index < len(names) else None
            if name in table:
                self._send(name, table, names)
        elif kind == "PARAM_SET":
            name = msg.param_id
            before = self.handlers.params()
            if name not in before:
                self._unknown_log.log(logging.DEBUG, "PARAM_SET of unknown parameter %r ignored", name)
                return
            result = self.handlers.set_param(name, msg.param_value)
            ok, reason = result if isinstance(result, tuple) else (bool(result), "" if result else f"{name}: refused")
            if ok:
                self._set_log.log(logging.INFO, "parameter %s set to %g", name, msg.param_value)
            else:
                self._set_log.log(logging.INFO, "parameter %s: set to %r refused: %s", name, msg.param_value, reason)
            if reason:
                self.say(reason, mav.MAV_SEVERITY_WARNING)
            table = self.handlers.params()  # echo the value in force, as ArduPilot does
            self._send(name, table, list(table))

    def tick(self, now_s: float) -> None:
        """Send what is due of a list request (call every loop turn)."""
        if not self._pending:
            return
        if self._last_s is not None:
            self._credit = min(float(LIST_BURST), self._credit + (now_s - self._last_s) * self.rate_hz())
        else:
            self._credit = float(LIST_BURST)
        self._last_s = now_s
        table = self.handlers.params()
        names = list(table)
        while self._pending and self._credit >= 1.0:
            name = self._pending.pop(0)
            if name in table:
                self._send(name, table, names)
                self._credit -= 1.0

    def _send(self, name: str, table: dict[str, float], names: list[str]) -> None:
        param = BY_NAME.get(name)
        kind = param.mav_type if param is not None else mav.MAV_PARAM_TYPE_REAL32
        self.conn.mav.param_value_send(name.encode(), table[name], kind, len(table), names.index(name))
