"""Telemetry to ground stations: HEARTBEAT, position, GPS, attitude, status and STATUSTEXT.

``Telemetry`` owns the send rates. Each ``send_*`` may be called every loop turn: it sends only
when its message is due at the rate the ground station asked for (REQUEST_DATA_STREAM or
SET_MESSAGE_INTERVAL; defaults in ``GcsParams``) and returns whether it sent. HEARTBEAT and
STATUSTEXT always send. ``now_s`` is the caller's clock; only differences are used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from rover_ctl.config import GcsParams
from rover_ctl.vocabulary import AUTONOMOUS_MODES, mav

TELEMETRY = {
    mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: "position_rate_hz",
    mav.MAVLINK_MSG_ID_GPS_RAW_INT: "gps_rate_hz",
    mav.MAVLINK_MSG_ID_ATTITUDE: "attitude_rate_hz",
    mav.MAVLINK_MSG_ID_SYS_STATUS: "sys_status_rate_hz",
    mav.MAVLINK_MSG_ID_MISSION_CURRENT: "mission_current_rate_hz",
}
"""Telemetry the senders rate-limit, by MAVLink message id -> its default rate in GcsParams."""
STREAMS = {
    mav.MAV_DATA_STREAM_EXTENDED_STATUS: (
        mav.MAVLINK_MSG_ID_SYS_STATUS, mav.MAVLINK_MSG_ID_GPS_RAW_INT, mav.MAVLINK_MSG_ID_MISSION_CURRENT,
    ),
    mav.MAV_DATA_STREAM_POSITION: (mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,),
    mav.MAV_DATA_STREAM_EXTRA1: (mav.MAVLINK_MSG_ID_ATTITUDE,),
    mav.MAV_DATA_STREAM_ALL: tuple(TELEMETRY),
}  # fmt: skip
"""REQUEST_DATA_STREAM stream -> our messages in it (as ArduPilot groups them)."""
STATUSTEXT_CHUNK = 50
"""STATUSTEXT carries 50 characters; longer texts go out in chunks sharing an id (MAVLink 2)."""


@dataclass
class Rates:
    """Per-message send intervals (None = off) and when each was last sent."""

    interval_s: dict[int, float | None] = field(default_factory=dict)
    last_s: dict[int, float] = field(default_factory=dict)

    def pending(self, msg_id: int, now_s: float) -> bool:
        """Whether the message is due now (without taking its slot)."""
        interval = self.interval_s.get(msg_id)
        if interval is None:
            return False
        last = self.last_s.get(msg_id)
        return last is None or now_s - last >= interval

    def due(self, msg_id: int, now_s: float) -> bool:
        """Whether the message is due now; if so, its slot is taken."""
        if not self.pending(msg_id, now_s):
            return False
        self.last_s[msg_id] = now_s
        return True


class Telemetry:
    """The senders of one GCS connection (``conn`` is a pymavlink connection)."""

    def __init__(self, conn: Any, params: GcsParams) -> None:
        self.conn = conn
        self.params = params
        self.rates = Rates({msg_id: self.default_interval(msg_id) for msg_id in TELEMETRY})
        self._statustext_id = 0

    def default_interval(self, msg_id: int) -> float | None:
        rate_hz = getattr(self.params, TELEMETRY[msg_id])
        return 1.0 / rate_hz if rate_hz > 0 else None

    # ---- rate requests from the ground station

    def on_request_data_stream(self, msg) -> None:
        rate = msg.req_message_rate if msg.start_stop else 0
        for msg_id in STREAMS.get(msg.req_stream_id, ()):
            self.rates.interval_s[msg_id] = 1.0 / rate if rate > 0 else None

    def set_interval(self, msg_id: int, interval_us: float) -> int:
        """MAV_CMD_SET_MESSAGE_INTERVAL: 0 default rate, -1 off, else the interval in us."""
        if msg_id not in TELEMETRY:
            return mav.MAV_RESULT_DENIED
        if interval_us == 0:
            self.rates.interval_s[msg_id] = self.default_interval(msg_id)
        elif interval_us < 0:
            self.rates.interval_s[msg_id] = None
        else:
            self.rates.interval_s[msg_id] = interval_us * 1e-6
        return mav.MAV_RESULT_ACCEPTED

    # ---- senders

    def send_heartbeat(self, armed: bool, custom_mode: int, system_status: int) -> None:
        base_mode = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mav.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        if armed:
            base_mode |= mav.MAV_MODE_FLAG_SAFETY_ARMED
        if custom_mode in AUTONOMOUS_MODES:
            base_mode |= mav.MAV_MODE_FLAG_GUIDED_ENABLED | mav.MAV_MODE_FLAG_AUTO_ENABLED
        self.conn.mav.heartbeat_send(mav.MAV_TYPE_GROUND_ROVER, mav.MAV_AUTOPILOT_ARDUPILOTMEGA, base_mode, custom_mode, system_status)

    def pose_due(self, now_s: float) -> bool:
        """Whether GLOBAL_POSITION_INT or ATTITUDE would go out now, so that a caller polling every
        loop turn computes the pose for them only a few times a second."""
        return any(self.rates.pending(m, now_s) for m in (mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, mav.MAVLINK_MSG_ID_ATTITUDE))

    def send_global_position_int(
        self, now_s: float, lat_deg: float, lon_deg: float, alt_m: float, relative_alt_m: float,
        ve_mps: float, vn_mps: float, heading_deg: float, time_boot_ms: int,
    ) -> bool:  # fmt: skip
        """GLOBAL_POSITION_INT from the fused estimate (heading: compass degrees, 0 north)."""
        if not self.rates.due(mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, now_s):
            return False
        self.conn.mav.global_position_int_send(
            time_boot_ms, round(lat_deg * 1e7), round(lon_deg * 1e7), round(alt_m * 1000),
            round(relative_alt_m * 1000), round(vn_mps * 100), round(ve_mps * 100), 0,
            round((heading_deg % 360.0) * 100) % 36000,
        )  # fmt: skip
        return True

    def send_gps_raw_int(self, now_s: float, msg) -> bool:
        """Forward the vehicle's GPS_RAW_INT (a pymavlink message) as ours."""
        if not self.rates.due(mav.MAVLINK_MSG_ID_GPS_RAW_INT, now_s):
            return False
        self.conn.mav.send(msg)
        return True

    def send_attitude(self, now_s: float, yaw_rad_ned: float, yawspeed_radps: float, time_boot_ms: int) -> bool:
        """ATTITUDE with the estimate's heading (NED: 0 north, clockwise positive)."""
        if not self.rates.due(mav.MAVLINK_MSG_ID_ATTITUDE, now_s):
            return False
        yaw = math.remainder(yaw_rad_ned, 2.0 * math.pi)
        self.conn.mav.attitude_send(time_boot_ms, 0.0, 0.0, yaw, 0.0, 0.0, yawspeed_radps)
        return True

    def send_sys_status(self, now_s: float, voltage_v: float, remaining_pct: int, present: int = 0,
                        enabled: int | None = None, failed: int = 0, drop_rate_cpct: int = 0, errors_comm: int = 0) -> bool:
        """SYS_STATUS with the battery (``remaining_pct`` -1 when unknown) and MAV_SYS_STATUS_*
        sensor bits. As ArduPilot reports them, a bit is healthy unless it is in ``failed``, and
        the GEOFENCE bit is healthy whenever the fence is not breached: ground stations (MAVProxy)
        announce a breach when that health bit is clear. ``drop_rate_cpct`` (c%) and
        ``errors_comm``: the vehicle link's lost frames and bad-CRC frames, the daemon's link health."""
        if not self.rates.due(mav.MAVLINK_MSG_ID_SYS_STATUS, now_s):
            return False
        health = (present | mav.MAV_SYS_STATUS_GEOFENCE) & ~failed & 0xFFFFFFFF
        self.conn.mav.sys_status_send(
            present, present if enabled is None else enabled, health, 0, round(voltage_v * 1000), -1, remaining_pct,
            min(drop_rate_cpct, 10_000), min(errors_comm, 65535), 0, 0, 0, 0,
        )  # fmt: skip
        return True

    def send_statustext(self, text: str, severity: int = mav.MAV_SEVERITY_INFO) -> None:
        data = text.encode("utf-8", "replace")
        if len(data) <= STATUSTEXT_CHUNK:
            self.conn.mav.statustext_send(severity, data, 0, 0)
            return
        self._statustext_id = self._statustext_id % 65535 + 1
        chunks = [data[i : i + STATUSTEXT_CHUNK] for i in range(0, len(data), STATUSTEXT_CHUNK)]
        if len(chunks[-1]) == STATUSTEXT_CHUNK:
            chunks.append(b"")  # a full last chunk needs an empty one to end the text
        for index, chunk in enumerate(chunks):
            self.conn.mav.statustext_send(severity, chunk, self._statustext_id, index)


class StatusTextAssembler:
    """Whole texts from STATUSTEXT messages, as ground stations show them: a text longer than one
    message comes in chunks sharing a nonzero ``id`` (``chunk_seq`` 0, 1, ...); a chunk shorter than
    ``STATUSTEXT_CHUNK`` bytes (an empty one after a full last chunk) ends it. ``id`` 0 is a whole
    text. At most ``pending`` texts are assembled at once (the oldest is given up), so a sender
    that never ends its texts costs bounded memory."""

    def __init__(self, pending: int = 8) -> None:
        self._parts: dict[int, list[str]] = {}
        self._pending = pending

    def add(self, msg: Any) -> str | None:
        """The whole text ``msg`` ends, or None while a chunked text is incomplete."""
        text = msg.text if isinstance(msg.text, str) else msg.text.decode("utf-8", "replace")
        text_id = getattr(msg, "id", 0)
        if not text_id:
            return text
        parts = self._parts.pop(text_id, [])  # re-inserted last: the dict's order is the age
        parts.append(text)
        if len(text.encode("utf-8")) < STATUSTEXT_CHUNK:
            return "".join(parts)
        self._parts[text_id] = parts
        while len(self._parts) > self._pending:
            del self._parts[next(iter(self._parts))]
        return None
