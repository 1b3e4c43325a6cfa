"""The ground-station side of the MAVLink mission protocol (what `rover-ctl mission` uses).

``MissionClient(url)`` connects with pymavlink as system 255 component 190 (configurable), waits
for an autopilot's HEARTBEAT and then uploads, downloads or clears missions, fences and rally
points of that autopilot, one mission type at a time:

* upload: MISSION_COUNT, then answer every MISSION_REQUEST_INT / MISSION_REQUEST with the item
  asked for (so a lost item is simply asked for again), until MISSION_ACK. The final ACK counts
  only once every item has been sent in this transfer (a stale ACK, or a late request of an
  earlier upload, cannot end an upload early).
* download: MISSION_REQUEST_LIST -> MISSION_COUNT, MISSION_REQUEST_INT for each seq -> item,
  then MISSION_ACK.
* clear: MISSION_CLEAR_ALL -> MISSION_ACK.

Timeouts and retries follow the protocol (mavlink.io services/mission): MISSION_COUNT,
MISSION_REQUEST_LIST and MISSION_CLEAR_ALL are resent after ``client_retry_s`` (1.5 s) without an
answer, an uploaded item or a download's item request after ``client_item_retry_s`` (0.25 s), each
at most ``client_retries`` (5) times in a row; then, or on a refusing ACK, ``MissionClientError``
says what failed in one line. A refusal or a timeout before the last item was sent leaves the
vehicle's list as it was; a timeout after it (``MissionClientError.maybe_stored``) cannot tell
whether the vehicle stored the upload: download to check.
``upload(mission)`` sends each non-empty part: the mission items (with home at seq 0), the fence
and the rally points. The protocol waits are blocking (it is a command-line client).
"""

from __future__ import annotations

import os
import time
from typing import Callable

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402  (MAVLINK20 must be set before the import)
from pymavlink.dialects.v20 import ardupilotmega as mav  # noqa: E402

from rover_ctl.config import GcsParams  # noqa: E402
from rover_ctl.mission.model import Mission, MissionItem, MissionType  # noqa: E402
from rover_ctl.mavlink.mission import item_from_message, item_message, wire_items, with_type  # noqa: E402
from rover_ctl.mavlink.signing import setup_client_signing  # noqa: E402

Progress = Callable[[MissionType, int, int], None]
"""progress(mission_type, items_done, items_total)"""

TYPE_NAMES = {MissionType.MISSION: "mission", MissionType.FENCE: "fence", MissionType.RALLY: "rally"}


class MissionClientError(Exception):
    """A refused or timed-out mission transfer; the message is one line. ``maybe_stored``: an
    upload timed out after its last item went out, so the vehicle may have stored it."""

    def __init__(self, message: str, maybe_stored: bool = False) -> None:
        super().__init__(message)
        self.maybe_stored = maybe_stored


def result_name(result: int) -> str:
    entry = mav.enums["MAV_MISSION_RESULT"].get(result)
    return entry.name if entry else f"MAV_MISSION_RESULT {result}"


class MissionClient:
    def __init__(
        self,
        url: str,
        params: GcsParams | None = None,
        source_system: int = 255,
        source_component: int = 190,
        signing_key: bytes | None = None,
    ) -> None:
        self.url = url
        self.params = params or GcsParams()
        self.conn = mavutil.mavlink_connection(
            url, source_system=source_system, source_component=source_component, dialect="ardupilotmega"
        )
        self.conn.mav.WIRE_PROTOCOL_VERSION = "2.0"
        if signing_key is not None:  # an autopilot with a key drops unsigned frames
            setup_client_signing(self.conn, signing_key)
        self.me = (source_system, source_component)
        self.target: tuple[int, int] | None = None

    def close(self) -> None:
        self.conn.close()

    def __enter__(self) -> "MissionClient":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def connect(self) -> tuple[int, int]:
        """Wait for an autopilot's HEARTBEAT; returns its (system, component)."""
        # On udpout the autopilot learns our address from our first packet, so speak first.
        self.conn.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        timeout_s = self.params.client_connect_timeout_s
        tries = max(1, round(timeout_s / self.params.client_retry_s))
        for _ in range(tries):
            msg = self.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=self.params.client_retry_s)
            if msg is not None and msg.autopilot != mav.MAV_AUTOPILOT_INVALID:
                self.target = (msg.get_srcSystem(), msg.get_srcComponent())
                return self.target
            self.conn.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        raise MissionClientError(f"{self.url}: no autopilot heartbeat within {timeout_s:g} s")

    # ---------------------------------------------------------------- operations

    def upload(self, mission: Mission, progress: Progress | None = None) -> list[MissionType]:
        """Upload every non-empty part of ``mission``; returns the types sent."""
        sent = []
        for mission_type in MissionType:
            if mission.of_type(mission_type):
                self.upload_items(mission_type, wire_items(mission, mission_type), progress)
                sent.append(mission_type)
        return sent

    def download(self, progress: Progress | None = None) -> Mission:
        mission = Mission()
        for mission_type in MissionType:
            mission = with_type(mission, mission_type, self.download_items(mission_type, progress))
        return mission

    def upload_items(self, mission_type: MissionType, items: list[MissionItem], progress: Progress | None = None) -> None:
        """Upload the wire list ``items`` (for MISSION, seq 0 is home) of one mission type."""
        target = self._target()
        what = f"{TYPE_NAMES[mission_type]} upload"
        last = mav.MAVLink_mission_count_message(*target, len(items), mission_type)
        self.conn.mav.send(last)
        sent: set[int] = set()
        last_sent = False
        retry_s = self.params.client_retry_s
        while True:
            try:
                msg = self._await(("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"), mission_type, last, what, retry_s)
            except MissionClientError as exc:
                if last_sent:
                    raise MissionClientError(
                        f"{what}: every item sent but no acknowledgement came: the vehicle may or may not have "
                        "stored it (download to check)", maybe_stored=True,
                    ) from None  # fmt: skip
                raise exc from None
            if msg.get_type() == "MISSION_ACK":
                if msg.type != mav.MAV_MISSION_ACCEPTED:
                    raise MissionClientError(f"{what} refused by the vehicle: {result_name(msg.type)}")
                if last_sent or not items:
                    return
                continue  # a stale ACK of an earlier transfer
            if not 0 <= msg.seq < len(items):
                raise MissionClientError(f"{what}: vehicle asked for item {msg.seq} of {len(items)}")
            last = item_message(items[msg.seq], msg.seq, mission_type, target)
            self.conn.mav.send(last)
            retry_s = self.params.client_item_retry_s
            # The vehicle asks in order, so its ACK can only be this transfer's once every item went
            # out in it: a late request of an earlier upload must not make a stale ACK count.
            sent.add(msg.seq)
            last_sent = len(sent) == len(items)
            if progress:
                progress(mission_type, msg.seq + 1, len(items))

    def download_items(self, mission_type: MissionType, progress: Progress | None = None) -> list[MissionItem]:
        """The wire list of one mission type (for MISSION, seq 0 is home)."""
        target = self._target()
        what = f"{TYPE_NAMES[mission_type]} download"
        request = mav.MAVLink_mission_request_list_message(*target, mission_type)
        self.conn.mav.send(request)
        count = self._await(("MISSION_COUNT",), mission_type, request, what, self.params.client_retry_s).count
        items = []
        for seq in range(count):
            request = mav.MAVLink_mission_request_int_message(*target, seq, mission_type)
            self.conn.mav.send(request)
            while True:
                msg = self._await(("MISSION_ITEM_INT", "MISSION_ITEM", "MISSION_ACK"), mission_type, request, what,
                                  self.params.client_item_retry_s)  # fmt: skip
                if msg.get_type() == "MISSION_ACK":
                    if msg.type != mav.MAV_MISSION_ACCEPTED:
                        raise MissionClientError(f"{what} refused by the vehicle: {result_name(msg.type)}")
                elif msg.seq == seq:
                    break
            items.append(item_from_message(msg))
            if progress:
                progress(mission_type, seq + 1, count)
        self.conn.mav.send(mav.MAVLink_mission_ack_message(*target, mav.MAV_MISSION_ACCEPTED, mission_type))
        return items

    def clear(self, mission_type: int) -> None:
        """MISSION_CLEAR_ALL of one type, or of all (255)."""
        target = self._target()
        request = mav.MAVLink_mission_clear_all_message(*target, mission_type)
        self.conn.mav.send(request)
        what = "clear"
        msg = self._await(("MISSION_ACK",), mission_type, request, what, self.params.client_retry_s)
        if msg.type != mav.MAV_MISSION_ACCEPTED:
            raise MissionClientError(f"{what} refused by the vehicle: {result_name(msg.type)}")

    # ---------------------------------------------------------------- plumbing

    def _target(self) -> tuple[int, int]:
        if self.target is None:
            self.connect()
        return self.target

    def _await(self, kinds: tuple[str, ...], mission_type: int, resend, what: str, retry_s: float):
        """The next message of ``kinds`` for us from the target, resending ``resend`` after each
        ``retry_s`` of silence, ``client_retries`` times at most."""
        for _ in range(self.params.client_retries + 1):
            msg = self._receive(kinds, mission_type, retry_s)
            if msg is not None:
                return msg
            self.conn.mav.send(resend)
        waited_s = (self.params.client_retries + 1) * retry_s
        raise MissionClientError(f"{what}: no answer from the vehicle within {waited_s:g} s ({self.url})")

    def _receive(self, kinds: tuple[str, ...], mission_type: int, retry_s: float):
        """A matching message within ``retry_s``, or None."""
        end = time.monotonic() + retry_s
        while (left := end - time.monotonic()) > 0:
            msg = self.conn.recv_match(type=list(kinds), blocking=True, timeout=left)
            if msg is None:
                return None
            if (msg.get_srcSystem(), msg.get_srcComponent()) != self.target:
                continue
            if getattr(msg, "target_system", 0) not in (0, self.me[0]):
                continue
            if getattr(msg, "target_component", 0) not in (0, self.me[1]):
                continue
            if msg.mission_type != mission_type:
                continue
            return msg
        return None
