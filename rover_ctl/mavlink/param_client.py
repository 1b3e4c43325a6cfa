"""The ground-station side of the MAVLink parameter protocol (what ``rover-ctl params --connect`` uses).

``ParamClient(url)`` connects with pymavlink (system 255, component 190 by default), waits for an
autopilot's HEARTBEAT, then

* ``fetch()``: PARAM_REQUEST_LIST, then every PARAM_VALUE until ``param_count`` distinct indices
  arrived; missing ones are asked for by index (PARAM_REQUEST_READ), as MAVProxy does;
* ``set(name, value)``: PARAM_SET, resent until the PARAM_VALUE echo of that name arrives; returns
  the value in force and the STATUSTEXT that came with a refusal.

A request without an answer is resent every ``client_retry_s``, up to ``client_retries`` times in
a row; then ``ParamClientError`` says what failed in one line. Blocking (a command-line client).
"""

from __future__ import annotations

import os

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402  (MAVLINK20 must be set before the import)
from pymavlink.dialects.v20 import ardupilotmega as mav  # noqa: E402

from rover_ctl.config import GcsParams  # noqa: E402


class ParamClientError(Exception):
    """A parameter transfer that timed out; the message is one line."""


class ParamClient:
    def __init__(self, url: str, params: GcsParams | None = None, source_system: int = 255, source_component: int = 190) -> None:
        self.url = url
        self.params = params or GcsParams()
        self.conn = mavutil.mavlink_connection(url, source_system=source_system, source_component=source_component, dialect="ardupilotmega")
        self.conn.mav.WIRE_PROTOCOL_VERSION = "2.0"
        self.target: tuple[int, int] | None = None

    def close(self) -> None:
        self.conn.close()

    def __enter__(self) -> "ParamClient":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def connect(self) -> tuple[int, int]:
        """Wait for an autopilot's HEARTBEAT; returns its (system, component)."""
        timeout_s = self.params.client_connect_timeout_s
        for _ in range(max(1, round(timeout_s / self.params.client_retry_s))):
            # On udpout the autopilot learns our address from our first packet, so speak first.
            self.conn.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            msg = self.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=self.params.client_retry_s)
            if msg is not None and msg.autopilot != mav.MAV_AUTOPILOT_INVALID:
                self.target = (msg.get_srcSystem(), msg.get_srcComponent())
                return self.target
        raise ParamClientError(f"{self.url}: no autopilot heartbeat within {timeout_s:g} s")

    def fetch(self) -> dict[str, float]:
        """Every parameter, in the autopilot's index order."""
        by_index: dict[int, tuple[str, float]] = {}
        count: int | None = None
        self.conn.mav.param_request_list_send(*self.target)
        silent = 0
        while count is None or len(by_index) < count:
            msg = self.conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=self.params.client_retry_s)
            if msg is None or msg.get_srcSystem() != self.target[0]:
                silent += 1
                if silent > self.params.client_retries:
                    have = f"{len(by_index)} of {count}" if count is not None else "none"
                    raise ParamClientError(f"{self.url}: parameter download timed out ({have} received)")
                if count is None:
                    self.conn.mav.param_request_list_send(*self.target)
                else:
                    for index in sorted(set(range(count)) - set(by_index))[:10]:
                        self.conn.mav.param_request_read_send(*self.target, b"", index)
                continue
            silent = 0
            count = msg.param_count
            if 0 <= msg.param_index < count:
                by_index[msg.param_index] = (msg.param_id, float(msg.param_value))
        return dict(by_index[i] for i in sorted(by_index))

    def set(self, name: str, value: float) -> tuple[float, str]:
        """PARAM_SET ``name``; returns (the value in force, the refusal's STATUSTEXT or "")."""
        said, said_id = "", 0
        for _ in range(self.params.client_retries + 1):
            self.conn.mav.param_set_send(*self.target, name.encode(), float(value), mav.MAV_PARAM_TYPE_REAL32)
            while (msg := self.conn.recv_match(type=["PARAM_VALUE", "STATUSTEXT"], blocking=True, timeout=self.params.client_retry_s)) is not None:
                if msg.get_type() == "STATUSTEXT":
                    if msg.text.startswith(name):  # a refusal names the parameter and precedes the echo
                        said, said_id = msg.text, msg.id
                    elif said and msg.id and msg.id == said_id and msg.chunk_seq > 0:  # the rest of a long text
                        said += msg.text
                elif msg.param_id == name:
                    return float(msg.param_value), said
        raise ParamClientError(f"{self.url}: no PARAM_VALUE echo for {name} after {self.params.client_retries + 1} tries")
