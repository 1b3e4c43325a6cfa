"""The MAVLink parameter microservice on the GCS link: PARAM_REQUEST_LIST, PARAM_REQUEST_READ
(by name or index) and PARAM_SET with the PARAM_VALUE echo of the value in force.

The table itself belongs to the autopilot handlers (``params()`` / ``set_param()``);
``ConfigParams`` maps ArduPilot parameter names onto the daemon's ``Config``.
"""

from __future__ import annotations

import logging
import math
from typing import Any

from rover_ctl.config import Config
from rover_ctl.vocabulary import mav

log = logging.getLogger(__name__)

HANDLED = ("PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_SET")


_FS_ACTIONS = {0: "continue", 1: "rtl", 2: "hold"}


class ConfigParams:
    """ArduPilot-named parameters backed by the daemon's ``Config``.

    SYSID_THISMAV (read-only here: it takes a restart), WP_RADIUS (executor.acceptance_radius_m),
    WP_SPEED (executor.cruise_speed_mps), RTL_SPEED (executor.rtl_speed_mps), FS_GCS_TIMEOUT
    (failsafe.gcs_timeout_s), FS_ACTION (failsafe.gcs_action: 0 continue, 1 RTL, 2 hold).
    """

    def __init__(self, config: Config) -> None:
        self.config = config
        ex, fs = config.executor, config.failsafe
        self._fields: dict[str, tuple[object, str]] = {
            "WP_RADIUS": (ex, "acceptance_radius_m"),
            "WP_SPEED": (ex, "cruise_speed_mps"),
            "RTL_SPEED": (ex, "rtl_speed_mps"),
            "FS_GCS_TIMEOUT": (fs, "gcs_timeout_s"),
        }

    def params(self) -> dict[str, float]:
        values = {"SYSID_THISMAV": float(self.config.gcs.system_id)}
        values.update({name: float(getattr(obj, attr)) for name, (obj, attr) in self._fields.items()})
        actions = {v: k for k, v in _FS_ACTIONS.items()}
        values["FS_ACTION"] = float(actions.get(self.config.failsafe.gcs_action, 0))
        return values

    def set_param(self, name: str, value: float) -> bool:
        if not math.isfinite(value):
            return False
        if name in self._fields:
            if value < 0:
                return False
            obj, attr = self._fields[name]
            setattr(obj, attr, value)
            return True
        if name == "FS_ACTION" and int(value) == value and int(value) in _FS_ACTIONS:
            self.config.failsafe.gcs_action = _FS_ACTIONS[int(value)]
            return True
        return False


class ParamService:
    """Answers the parameter protocol from ``handlers.params()`` / ``handlers.set_param()``."""

    def __init__(self, conn: Any, handlers: Any) -> None:
        self.conn = conn
        self.handlers = handlers

    def handle(self, msg) -> None:
        kind = msg.get_type()
        if kind == "PARAM_REQUEST_LIST":
            table = self.handlers.params()
            for index, name in enumerate(table):
                self._send(name, table, index)
        elif kind == "PARAM_REQUEST_READ":
            table = self.handlers.params()
            names = list(table)
            name = msg.param_id if msg.param_index < 0 else (names[msg.param_index] if msg.param_index < len(names) else None)
            if name in table:
                self._send(name, table)
        elif kind == "PARAM_SET":
            if self.handlers.set_param(msg.param_id, msg.param_value):
                log.info("parameter %s set to %g", msg.param_id, msg.param_value)
            table = self.handlers.params()  # echo the value in force, as ArduPilot does
            if msg.param_id in table:
                self._send(msg.param_id, table)

    def _send(self, name: str, table: dict[str, float], index: int | None = None) -> None:
        if index is None:
            index = list(table).index(name)
        self.conn.mav.param_value_send(name.encode(), table[name], mav.MAV_PARAM_TYPE_REAL32, len(table), index)
