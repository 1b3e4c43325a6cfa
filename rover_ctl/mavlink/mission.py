"""The vehicle side of the MAVLink mission protocol, as a pure state machine.

No sockets and no clock: the shell feeds every received message to ``handle(msg, now_s)`` and
calls ``tick(now_s)`` regularly; both return the pymavlink messages to send. Messages are
pymavlink message objects of the ardupilotmega dialect (MAVLink 2); a reply is always addressed
to the requester's own system and component ids.

Behaviour follows mavlink.io (services/mission) and ArduPilot's ``MissionItemProtocol``:

* Mission types MISSION (0), FENCE (1) and RALLY (2). For MISSION, wire seq 0 is home, as
  ArduPilot numbers it: ``count = len(mission.items) + 1``. An uploaded seq 0 becomes
  ``Mission.home`` (lat = lon = 0 means "no home"); a download reports ``vehicle_home`` (the
  daemon's real home, once it has one) or else the stored mission's home at seq 0.
* Upload: MISSION_COUNT -> MISSION_REQUEST_INT(seq) -> MISSION_ITEM_INT (or legacy MISSION_ITEM)
  ... -> MISSION_ACK. Each mission type is its own transaction, as in ArduPilot (one
  ``MissionItemProtocol`` per type): a repeated MISSION_COUNT from the uploading sender restarts
  the upload of that type; any other sender trying to upload, clear or send items of that type
  meanwhile gets MAV_MISSION_DENIED (a clear of all types, if any type is being uploaded by
  another). An out-of-sequence item is not fatal: a later one makes us re-request the expected
  seq at once, an earlier one (a duplicate) is ignored. The expected seq is re-requested every
  ``mission_item_retry_s`` without an answer; after ``mission_upload_timeout_s`` without progress
  the upload is cancelled (MAV_MISSION_OPERATION_CANCELLED) and the stored mission is untouched.
  If the final ACK is lost and the sender repeats the last item, the ACK is repeated.
* Deadline: a transaction must end ``upload_budget_s(count)`` after its first COUNT
  (``count * mission_upload_timeout_s + mission_upload_margin_s``, ``count`` the largest COUNT in
  it: each item may take up to the no-progress timeout, the margin covers resent COUNTs). A
  restart does not extend it beyond that, nor does
  a COUNT from the same sender within ``mission_upload_timeout_s`` of a no-progress cancel (a
  restart too). At the deadline the upload is cancelled as for a timeout, and its sender's COUNTs
  of that type are DENIED for ``mission_upload_holdoff_s`` so that another sender can start:
  resending COUNTs cannot hold the type for ever. (A stranger that changes its system id is not
  held off; MAVLink signing is what keeps strangers out.)
* Validation at the boundary: each item is checked as it arrives with the item rules of
  ``rover_ctl.mission.validate`` (``check_item``), and the complete list with all of them
  (``validate``: DO_JUMP targets, polygon vertex counts and self-intersection, at most one return
  point), the same rules as ``rover-ctl mission check``. The first problem refuses the upload with
  the MAV_MISSION_RESULT of the field it is about (``RESULT_BY_FIELD``: a bad radius or vertex
  count is INVALID_PARAM1, a latitude INVALID_PARAM5_X, a frame UNSUPPORTED_FRAME, a command of
  another list UNSUPPORTED, a fence too complex for the planner NO_SPACE, ...).
* Atomicity: received items go to a scratch list. Only a complete, valid upload is passed to
  ``commit(new_mission, mission_type)`` (the shell persists it there); if ``commit`` raises, the upload is
  refused with MAV_MISSION_ERROR and the stored mission stays the old one.
* Download: MISSION_REQUEST_LIST -> MISSION_COUNT; every MISSION_REQUEST_INT or legacy
  MISSION_REQUEST in range is answered with MISSION_ITEM_INT (stateless, so lost requests are
  simply repeated by the client); out of range gets MAV_MISSION_INVALID_SEQUENCE. A mission type
  other than MISSION, FENCE or RALLY (ALL, 255, only makes sense for a clear) gets
  MAV_MISSION_UNSUPPORTED. A stored value MISSION_ITEM_INT cannot carry (a plan stored by an older
  version) is sent as 0 (NaN x/y) or clamped, never a failure to pack.
* MISSION_CLEAR_ALL (one type or MAV_MISSION_TYPE_ALL) commits an emptied mission and ACKs. A
  clear (or a COUNT of 0) that changes nothing, the list being empty already, is ACCEPTED without
  a commit: no store write, no re-plan (a flood of them costs no disk work).
* MISSION_SET_CURRENT asks ``set_current(seq) -> bool`` (the executor) and answers
  MISSION_CURRENT, or a STATUSTEXT warning when refused. ``mission_current`` and
  ``item_reached`` build the broadcasts the daemon sends as the mission runs.

Coordinates on the wire: for global frames x/y are degrees * 1e7; for local frames metres * 1e4
(MISSION_ITEM_INT spec); otherwise the raw param5/param6 value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable

from pymavlink.dialects.v20 import ardupilotmega as mav

from rover_ctl.config import GcsParams
from rover_ctl.mission.model import FRAME_GLOBAL, Home, Mission, MissionItem, MissionType, xy_scale
from rover_ctl.mission.validate import FLOAT32_MAX, INT32_MAX, check_item as item_problems, validate
from rover_ctl.vocabulary import Cmd

MISSION_TYPE_ALL = mav.MAV_MISSION_TYPE_ALL
MAV_COMP_ID_MISSIONPLANNER = mav.MAV_COMP_ID_MISSIONPLANNER
"""Older ground stations address mission messages to this component; accepted as ours."""
RESULT_BY_FIELD = {
    "command": mav.MAV_MISSION_UNSUPPORTED,
    "frame": mav.MAV_MISSION_UNSUPPORTED_FRAME,
    "param1": mav.MAV_MISSION_INVALID_PARAM1,
    "param2": mav.MAV_MISSION_INVALID_PARAM2,
    "param3": mav.MAV_MISSION_INVALID_PARAM3,
    "param4": mav.MAV_MISSION_INVALID_PARAM4,
    "x": mav.MAV_MISSION_INVALID_PARAM5_X,
    "y": mav.MAV_MISSION_INVALID_PARAM6_Y,
    "z": mav.MAV_MISSION_INVALID_PARAM7,
    "size": mav.MAV_MISSION_NO_SPACE,
}
"""MAV_MISSION_RESULT of a refused upload, by the item field its first problem is about ("size":
the list as a whole; else MAV_MISSION_INVALID)."""

Sender = tuple[int, int]


def _int32(value: float) -> int:
    """A scaled coordinate as MISSION_ITEM_INT's int32: NaN (unused) is 0, beyond int32 clamped
    (validation refuses such values; a plan stored by an older version may still hold them)."""
    if math.isnan(value):
        return 0
    return int(max(-INT32_MAX, min(INT32_MAX, round(value) if math.isfinite(value) else value)))


def _float32(value: float) -> float:
    """A param as float32 can carry it: beyond float32 becomes +-inf (NaN stays NaN)."""
    return value if math.isnan(value) or abs(value) <= FLOAT32_MAX else math.copysign(math.inf, value)


def encode_xy(item: MissionItem) -> tuple[int, int]:
    """Model x/y -> MISSION_ITEM_INT x/y integers (deg*1e7, m*1e4 or raw)."""
    scale = xy_scale(item.frame)
    return _int32(item.x * scale), _int32(item.y * scale)


def decode_xy(frame: int, x: int, y: int) -> tuple[float, float]:
    scale = xy_scale(frame)
    return x / scale, y / scale


def item_from_message(msg) -> MissionItem:
    """MISSION_ITEM_INT or legacy MISSION_ITEM -> MissionItem."""
    if msg.get_type() == "MISSION_ITEM_INT":
        x, y = decode_xy(msg.frame, msg.x, msg.y)
    else:
        x, y = float(msg.x), float(msg.y)
    return MissionItem(
        command=msg.command,
        frame=msg.frame,
        param1=msg.param1,
        param2=msg.param2,
        param3=msg.param3,
        param4=msg.param4,
        x=x,
        y=y,
        z=msg.z,
        autocontinue=bool(msg.autocontinue),
    )


def item_message(item: MissionItem, seq: int, mission_type: int, target: Sender, current: bool = False):
    """MissionItem -> MISSION_ITEM_INT addressed to ``target``."""
    x, y = encode_xy(item)
    params = (_float32(p) for p in (item.param1, item.param2, item.param3, item.param4))
    return mav.MAVLink_mission_item_int_message(
        target[0], target[1], seq, int(item.frame) & 0xFF, int(item.command) & 0xFFFF, int(current),
        int(item.autocontinue), *params, x, y, _float32(item.z), mission_type,
    )  # fmt: skip


def home_item(home: Home | None) -> MissionItem:
    """Seq 0 of a MISSION-type list as ArduPilot sends it (a NAV_WAYPOINT at home, frame GLOBAL)."""
    if home is None:
        return MissionItem(command=Cmd.NAV_WAYPOINT, frame=FRAME_GLOBAL)
    return MissionItem(command=Cmd.NAV_WAYPOINT, frame=FRAME_GLOBAL, x=home.lat_deg, y=home.lon_deg, z=home.alt_m)


def home_from_item(item: MissionItem) -> Home | None:
    if not item.is_global or (item.x == 0.0 and item.y == 0.0) or math.isnan(item.x) or math.isnan(item.y):
        return None
    return Home(item.x, item.y, item.z)


def is_list_type(mission_type: int) -> bool:
    """MISSION, FENCE or RALLY: a list that can be uploaded and downloaded (not ALL, not unknown)."""
    return mission_type in MissionType.__members__.values()


def wire_items(mission: Mission, mission_type: int, vehicle_home: Home | None = None) -> list[MissionItem]:
    """The list a download of ``mission_type`` serves (home first for MISSION; none for a type
    that is not a list)."""
    if mission_type == MissionType.MISSION:
        return [home_item(vehicle_home or mission.home), *mission.items]
    if not is_list_type(mission_type):
        return []
    return list(mission.of_type(MissionType(mission_type)))


def result_of(problems: list) -> int:
    """MAV_MISSION_RESULT for validation problems (MAV_MISSION_ACCEPTED if there are none)."""
    if not problems:
        return mav.MAV_MISSION_ACCEPTED
    return RESULT_BY_FIELD.get(getattr(problems[0], "field", ""), mav.MAV_MISSION_INVALID)


def check_item(item: MissionItem, mission_type: int, seq: int) -> int:
    """MAV_MISSION_RESULT for one received item at wire ``seq`` (MAV_MISSION_ACCEPTED if usable).
    Seq 0 of a MISSION list is home: only its position is checked (lat = lon = 0 is no home)."""
    if mission_type == MissionType.MISSION and seq == 0:
        home = home_from_item(item)
        problems = validate(Mission(home=home), math.inf, parts=(MissionType.MISSION,))[0] if home else []
        return result_of(problems)
    return result_of(item_problems(item, MissionType(mission_type), f"item {seq}"))


def check_list(mission: Mission, mission_type: int) -> int:
    """MAV_MISSION_RESULT for a complete uploaded list inside ``mission`` (all the rules)."""
    return result_of(validate(mission, math.inf, parts=(MissionType(mission_type),))[0])


def with_type(mission: Mission, mission_type: int, wire: list[MissionItem]) -> Mission:
    """A copy of ``mission`` whose ``mission_type`` part is the received wire list."""
    if mission_type == MissionType.MISSION:
        home = home_from_item(wire[0]) if wire else None
        return replace(mission, items=list(wire[1:]), home=home)
    if mission_type == MissionType.FENCE:
        return replace(mission, fence=list(wire))
    return replace(mission, rally=list(wire))


def cleared(mission: Mission, mission_type: int) -> Mission:
    if mission_type == MISSION_TYPE_ALL:
        return Mission(home=mission.home)
    if mission_type == MissionType.MISSION:
        return replace(mission, items=[])
    return with_type(mission, mission_type, [])


@dataclass
class _Upload:
    sender: Sender
    mission_type: int
    count: int
    started_s: float
    """When the transaction's first COUNT came (restarts keep it)."""
    deadline_s: float
    """The transaction ends by then: ``started_s`` plus the budget of the largest COUNT in it, so
    that a restart neither extends it nor cuts short a larger upload that replaced a small one."""
    received: list[MissionItem] = field(default_factory=list)
    last_request_s: float = 0.0
    last_progress_s: float = 0.0


@dataclass(frozen=True)
class _Lapsed:
    """The last cancelled upload of a mission type: a COUNT from ``sender`` before
    ``restart_until_s`` restarts it (keeping ``deadline_s``); before ``barred_until_s`` it is DENIED."""

    sender: Sender
    started_s: float
    deadline_s: float
    restart_until_s: float = -math.inf
    barred_until_s: float = -math.inf


@dataclass
class _Completed:
    """The last finished upload, to repeat its ACK if the sender did not get it: only to the same
    last item (seq and content) and only until another transfer starts, so that the resent last
    item of a later upload that was cancelled can never collect this one's ACK."""

    sender: Sender
    mission_type: int
    count: int
    result: int
    last: MissionItem | None


class MissionService:
    """Vehicle side of the mission protocol (see the module docstring).

    ``commit(mission, mission_type)`` is called with the complete new mission before an upload or
    clear of ``mission_type`` (255 for all) is acknowledged (raise to refuse it);
    ``set_current(seq) -> bool`` asks the executor to jump to wire seq ``seq``. Messages addressed
    to another system or component than ``params.system_id``/``component_id`` are ignored.
    """

    HANDLED = frozenset(
        {
            "MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_ITEM", "MISSION_REQUEST_INT", "MISSION_REQUEST",
            "MISSION_REQUEST_LIST", "MISSION_CLEAR_ALL", "MISSION_SET_CURRENT", "MISSION_ACK",
        }
    )  # fmt: skip

    def __init__(
        self,
        mission: Mission | None = None,
        params: GcsParams | None = None,
        commit: Callable[[Mission, int], None] | None = None,
        set_current: Callable[[int], bool] | None = None,
    ) -> None:
        self.mission = mission if mission is not None else Mission()
        self.params = params or GcsParams()
        self.vehicle_home: Home | None = None
        """The daemon's real home; reported at seq 0 of a download when set."""
        self.current_seq = 0
        self.mission_state = mav.MISSION_STATE_UNKNOWN
        """MISSION_CURRENT.mission_state as the autopilot reports it."""
        self._commit = commit or (lambda mission, mission_type: None)
        self._set_current = set_current or (lambda seq: True)
        self._uploads: dict[int, _Upload] = {}
        """Open uploads by mission type (a list type: three keys at most)."""
        self._lapsed: dict[int, _Lapsed] = {}
        """The last cancelled upload by mission type (a list type: three keys at most)."""
        self._completed: _Completed | None = None

    @property
    def uploading(self) -> bool:
        return bool(self._uploads)

    def upload_budget_s(self, count: int) -> float:
        """How long an upload of ``count`` items may take from its first COUNT (module docstring)."""
        return count * self.params.mission_upload_timeout_s + self.params.mission_upload_margin_s

    def count(self, mission_type: int) -> int:
        """Number of wire items of ``mission_type`` (MISSION counts home)."""
        return len(wire_items(self.mission, mission_type, self.vehicle_home))

    # ---------------------------------------------------------------- input

    def handle(self, msg, now_s: float) -> list:
        """Process one received message; return the replies."""
        kind = msg.get_type()
        if kind not in self.HANDLED or not self._for_us(msg):
            return []
        sender = (msg.get_srcSystem(), msg.get_srcComponent())
        if kind == "MISSION_COUNT":
            return self._on_count(msg, sender, now_s)
        if kind in ("MISSION_ITEM_INT", "MISSION_ITEM"):
            return self._on_item(msg, sender, now_s)
        if kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            return self._on_request(msg, sender)
        if kind == "MISSION_REQUEST_LIST":
            if not is_list_type(msg.mission_type):
                return [self._ack(sender, mav.MAV_MISSION_UNSUPPORTED, msg.mission_type)]
            return [mav.MAVLink_mission_count_message(*sender, self.count(msg.mission_type), msg.mission_type)]
        if kind == "MISSION_CLEAR_ALL":
            return self._on_clear(msg, sender)
        if kind == "MISSION_SET_CURRENT":
            return self.request_current(msg.seq)
        return []  # MISSION_ACK: the end of a download, nothing to do

    def tick(self, now_s: float) -> list:
        """Cancel the uploads past their deadline or without progress for ``mission_upload_timeout_s``;
        re-request the missing items of the others. (Only here: the shell reads what arrived first,
        so a late loop turn does not cancel an upload whose item is waiting in the socket.)"""
        replies = []
        for mission_type, up in list(self._uploads.items()):
            if now_s >= up.deadline_s:
                lapsed = _Lapsed(up.sender, up.started_s, up.deadline_s, barred_until_s=now_s + self.params.mission_upload_holdoff_s)
            elif now_s - up.last_progress_s >= self.params.mission_upload_timeout_s:
                lapsed = _Lapsed(up.sender, up.started_s, up.deadline_s, restart_until_s=now_s + self.params.mission_upload_timeout_s)
            else:
                continue
            del self._uploads[mission_type]
            self._lapsed[mission_type] = lapsed
            self._completed = None
            replies.append(self._ack(up.sender, mav.MAV_MISSION_OPERATION_CANCELLED, mission_type))
        for up in self._uploads.values():
            if now_s - up.last_request_s >= self.params.mission_item_retry_s:
                replies.append(self._request(up, now_s))
        return replies

    # ---------------------------------------------------------------- daemon side

    def set_current(self, seq: int) -> None:
        """The executor moved to wire seq ``seq``."""
        self.current_seq = seq

    def mission_current(self, mission_state: int | None = None):
        """MISSION_CURRENT broadcast: current wire seq, the number of items after home, and the
        mission state (default: ``self.mission_state``, which the shell keeps up to date)."""
        state = self.mission_state if mission_state is None else mission_state
        return mav.MAVLink_mission_current_message(self.current_seq, len(self.mission.items), state, 0)

    @staticmethod
    def item_reached(seq: int):
        return mav.MAVLink_mission_item_reached_message(seq)

    # ---------------------------------------------------------------- handlers

    def _for_us(self, msg) -> bool:
        target = (getattr(msg, "target_system", 0), getattr(msg, "target_component", 0))
        components = (0, self.params.component_id, MAV_COMP_ID_MISSIONPLANNER)
        return target[0] in (0, self.params.system_id) and target[1] in components

    def _ack(self, target: Sender, result: int, mission_type: int):
        return mav.MAVLink_mission_ack_message(target[0], target[1], result, mission_type)

    def _request(self, up: _Upload, now_s: float):
        up.last_request_s = now_s
        return mav.MAVLink_mission_request_int_message(*up.sender, len(up.received), up.mission_type)

    def _busy_for(self, sender: Sender, mission_type: int) -> bool:
        """Whether another sender is uploading ``mission_type`` (any type, for MISSION_TYPE_ALL)."""
        types = self._uploads if mission_type == MISSION_TYPE_ALL else (mission_type,)
        return any(t in self._uploads and self._uploads[t].sender != sender for t in types)

    def _on_count(self, msg, sender: Sender, now_s: float) -> list:
        mission_type = msg.mission_type
        if not is_list_type(mission_type):
            return [self._ack(sender, mav.MAV_MISSION_UNSUPPORTED, mission_type)]
        lapsed = self._lapsed.get(mission_type)
        mine = lapsed is not None and lapsed.sender == sender
        if self._busy_for(sender, mission_type) or (mine and now_s < lapsed.barred_until_s):
            return [self._ack(sender, mav.MAV_MISSION_DENIED, mission_type)]
        # A repeated COUNT from the uploader restarts, as does one just after a no-progress cancel:
        # either keeps the transaction's deadline.
        previous = self._uploads.pop(mission_type, None)
        kept = previous if previous is not None else lapsed if mine and now_s < lapsed.restart_until_s else None
        self._completed = None
        if msg.count > self.params.mission_max_items:
            return [self._ack(sender, mav.MAV_MISSION_NO_SPACE, mission_type)]
        if msg.count == 0:
            return [self._finish(sender, mission_type, [], 0)]
        started_s = kept.started_s if kept is not None else now_s
        deadline_s = started_s + self.upload_budget_s(msg.count)
        if kept is not None:
            deadline_s = max(deadline_s, kept.deadline_s)
        self._lapsed.pop(mission_type, None)
        up = self._uploads[mission_type] = _Upload(sender, mission_type, msg.count, started_s, deadline_s, last_progress_s=now_s)
        return [self._request(up, now_s)]

    def _on_item(self, msg, sender: Sender, now_s: float) -> list:
        up = self._uploads.get(msg.mission_type)
        if up is None:
            done = self._completed
            if (
                done and done.sender == sender and done.mission_type == msg.mission_type and msg.seq == done.count - 1
                and done.last is not None and item_from_message(msg).same_as(done.last)
            ):  # fmt: skip
                return [self._ack(sender, done.result, done.mission_type)]
            return []
        if up.sender != sender:
            return [self._ack(sender, mav.MAV_MISSION_DENIED, msg.mission_type)]
        expected = len(up.received)
        if msg.seq < expected:
            return []  # duplicate
        if msg.seq > expected:
            return [self._request(up, now_s)]
        item = item_from_message(msg)
        result = check_item(item, up.mission_type, msg.seq)
        if result != mav.MAV_MISSION_ACCEPTED:
            del self._uploads[up.mission_type]
            return [self._ack(sender, result, up.mission_type)]
        up.received.append(item)
        up.last_progress_s = now_s
        if len(up.received) < up.count:
            return [self._request(up, now_s)]
        del self._uploads[up.mission_type]
        return [self._finish(sender, up.mission_type, up.received, up.count)]

    def _finish(self, sender: Sender, mission_type: int, wire: list[MissionItem], count: int):
        """Validate and commit a complete upload (or an empty one) and build its ACK."""
        new = with_type(self.mission, mission_type, wire)
        result = check_list(new, mission_type)
        if result == mav.MAV_MISSION_ACCEPTED:
            result = self._store(new, mission_type) if wire else self._store_if_changed(new, mission_type)
        self._completed = _Completed(sender, mission_type, count, result, wire[-1] if wire else None)
        return self._ack(sender, result, mission_type)

    def _store(self, new: Mission, mission_type: int) -> int:
        try:
            self._commit(new, mission_type)
        except Exception:  # the shell could not persist it: refuse, keep the old mission
            return mav.MAV_MISSION_ERROR
        self.mission = new
        return mav.MAV_MISSION_ACCEPTED

    def _store_if_changed(self, new: Mission, mission_type: int) -> int:
        """A clear or an empty upload: committed only if it changes the mission (a list already
        empty is ACCEPTED with no store write and no re-plan)."""
        return mav.MAV_MISSION_ACCEPTED if new == self.mission else self._store(new, mission_type)

    def _on_request(self, msg, sender: Sender) -> list:
        if not is_list_type(msg.mission_type):
            return [self._ack(sender, mav.MAV_MISSION_UNSUPPORTED, msg.mission_type)]
        wire = wire_items(self.mission, msg.mission_type, self.vehicle_home)
        if not 0 <= msg.seq < len(wire):
            return [self._ack(sender, mav.MAV_MISSION_INVALID_SEQUENCE, msg.mission_type)]
        current = msg.mission_type == MissionType.MISSION and msg.seq == self.current_seq
        return [item_message(wire[msg.seq], msg.seq, msg.mission_type, sender, current)]

    def _on_clear(self, msg, sender: Sender) -> list:
        mission_type = msg.mission_type
        if not (is_list_type(mission_type) or mission_type == MISSION_TYPE_ALL):
            return [self._ack(sender, mav.MAV_MISSION_UNSUPPORTED, mission_type)]
        if self._busy_for(sender, mission_type):
            return [self._ack(sender, mav.MAV_MISSION_DENIED, mission_type)]
        for t in list(self._uploads) if mission_type == MISSION_TYPE_ALL else (mission_type,):
            self._uploads.pop(t, None)  # the uploader's own clear ends its upload
        return [self._ack(sender, self._store_if_changed(cleared(self.mission, mission_type), mission_type), mission_type)]

    def request_current(self, seq: int) -> list:
        """A ground station asks to continue at wire seq ``seq`` (MISSION_SET_CURRENT or
        MAV_CMD_DO_SET_MISSION_CURRENT): MISSION_CURRENT if the executor agreed, else a warning."""
        if not 0 < seq < self.count(MissionType.MISSION) or not self._set_current(seq):
            text = f"Mission seq {seq} cannot be made current (mission has {len(self.mission.items)} items)"
            return [mav.MAVLink_statustext_message(mav.MAV_SEVERITY_WARNING, text.encode()[:50], 0, 0)]
        self.current_seq = seq
        return [self.mission_current()]
