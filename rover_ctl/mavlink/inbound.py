"""The GCS link's gate: every received message is checked here before a microservice sees it.

The GCS port may be reachable by strangers, so nothing a frame carries is trusted. ``Inbound.check``
looks at every field a microservice reads and returns a ``Verdict``:

* pass: the message is well formed (enums in range, floats finite where they are used, integer
  params whole and within the field they stand for, addressed to us or broadcast). A NaN in an
  optional command param that means "default" (ARM_DISARM's force flag) is read as its default;
* refuse: the protocol has an answer for a malformed request, which the verdict carries
  (COMMAND_ACK MAV_RESULT_DENIED for a command with a bad param; the mission service answers its
  own errors with MISSION_ACK, see ``rover_ctl.mavlink.mission``);
* drop: no answer exists (a SET_MODE to an unknown mode, a message for another component, a frame
  that failed its CRC): counted in ``Inbound.dropped`` by reason.

Counters are keyed by fixed reasons (``DROP_REASONS``), never by what a frame carries: a stranger
sending 100,000 distinct mode numbers makes one key, not 100,000. The offending value goes to a
debug line (``Verdict.detail``), at most one a second (``rover_ctl.mavlink.ratelog``).

PARAM_SET is checked by the parameter service itself (``rover_ctl.parameters``: finite, in range,
settable), which answers a refusal as ArduPilot does: a STATUSTEXT with the reason and the value
kept, echoed in PARAM_VALUE.

``Inbound.failed(msg, exc)`` is the link edge's last resort: a handler that raised anyway is logged
once per (message type, exception type) with the frame in hex, counted, and the link goes on.

On a UDP link each datagram is parsed on its own (``Inbound(params, conn)`` wraps ``conn.recv``):
pymavlink's parser is a byte stream, so the unfinished frame a stray datagram leaves (any 0xFD or
0xFE byte starts one) would swallow the bytes of the next datagram -- of any sender, and after one
random datagram in two. A frame never spans datagrams, so what one leaves unparsed is dropped.

Which params each command reads follows ``rover_ctl.mavlink.commands``; a command it does not
handle is passed through (it answers MAV_RESULT_UNSUPPORTED without reading a param).
"""

from __future__ import annotations

import logging
import math
import os
from collections import Counter
from dataclasses import dataclass
from typing import Any, Callable

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402  (MAVLINK20 first: mavutil's default dialect is MAVLink 1 without it)

from rover_ctl.config import GcsParams
from rover_ctl.mavlink.ratelog import LogLimit
from rover_ctl.vocabulary import mav

log = logging.getLogger(__name__)

MAX_MSG_ID = 2**24 - 1
"""MAVLink 2 message ids are 24 bits (REQUEST_MESSAGE, SET_MESSAGE_INTERVAL param1)."""
MAX_SEQ = 0xFFFF
"""Mission sequence numbers are uint16 (DO_SET_MISSION_CURRENT param1)."""
ROVER_MODES = frozenset(value for value, entry in mav.enums["ROVER_MODE"].items() if not entry.name.endswith("_ENUM_END"))
"""ArduPilot Rover's custom modes (the dialect's enum, without its generated ``_ENUM_END``)."""
ARM_VALUES = (0.0, 1.0)
"""ARM_DISARM param1: 0 disarm, 1 arm; anything else is not a request to do either."""
COMMANDS = ("COMMAND_LONG", "COMMAND_INT")
UNFINISHED = "unfinished frame at the end of a datagram"
BAD_DATA = "bad data (CRC, length or unknown message)"
OTHER_COMPONENT = "command for another component"
UNKNOWN_MODE = "SET_MODE to an unknown mode"
BAD_PARAM = "command param not what the command needs"
DROP_REASONS = (BAD_DATA, OTHER_COMPONENT, UNKNOWN_MODE, UNFINISHED)
"""Every key ``Inbound.dropped`` can have (reasons carry no values: a frame cannot add keys)."""


@dataclass(frozen=True)
class Verdict:
    ok: bool
    reason: str = ""
    reply: Any = None
    """The protocol's refusal to send back, when it has one."""
    detail: str = ""
    """The offending value, for the (rate-limited) debug line only."""


PASS = Verdict(True)


def _whole_in(value: float, low: float, high: float) -> bool:
    return math.isfinite(value) and value == int(value) and low <= value <= high


# One rule per (command, param slot): a predicate on the value and what it must be. A rule with a
# default replaces a NaN (MAVLink's "use the default") by it before the predicate.
Rule = tuple[str, Callable[[float], bool], str, "float | None"]
PARAM_RULES: dict[int, tuple[Rule, ...]] = {
    mav.MAV_CMD_COMPONENT_ARM_DISARM: (
        ("param1", lambda v: v in ARM_VALUES, "0 (disarm) or 1 (arm)", None),
        ("param2", math.isfinite, "a finite number (21196 forces)", 0.0),
    ),
    mav.MAV_CMD_DO_SET_MODE: (("param2", lambda v: _whole_in(v, 0, 2**32 - 1) and int(v) in ROVER_MODES, "a Rover mode", None),),
    mav.MAV_CMD_DO_SET_MISSION_CURRENT: (("param1", lambda v: _whole_in(v, 0, MAX_SEQ), f"a sequence number 0-{MAX_SEQ}", None),),
    mav.MAV_CMD_REQUEST_MESSAGE: (("param1", lambda v: _whole_in(v, 0, MAX_MSG_ID), "a message id", None),),
    mav.MAV_CMD_DO_REPOSITION: (("param2", lambda v: _whole_in(v, 0, 2**32 - 1), "MAV_DO_REPOSITION_FLAGS", 0.0),),
    mav.MAV_CMD_SET_MESSAGE_INTERVAL: (
        ("param1", lambda v: _whole_in(v, 0, MAX_MSG_ID), "a message id", None),
        ("param2", math.isfinite, "a finite interval in us (-1 off, 0 default)", None),
    ),
}


class Inbound:
    """Checks messages for one GCS link (``params``: our system and component ids; ``conn``: its
    pymavlink connection, parsed a datagram at a time when it is UDP)."""

    def __init__(self, params: GcsParams, conn: Any = None) -> None:
        self.params = params
        if isinstance(conn, mavutil.mavudp):
            conn.recv = DatagramFraming(conn.recv, conn.mav, lambda: self._drop(UNFINISHED))
        self.dropped: Counter[str] = Counter()
        """Messages dropped without an answer, by reason (one of ``DROP_REASONS``)."""
        self.refused = 0
        """Messages answered with the protocol's refusal."""
        self.failures: Counter[tuple[str, str]] = Counter()
        """Handler exceptions caught at the link edge, by (message type, exception type): bounded by
        the dialect's message names and the exception classes the handlers can raise."""
        self._drop_log = LogLimit(log)
        self._refusal_log = LogLimit(log)

    def check(self, msg) -> Verdict:
        kind = msg.get_type()
        if kind == "BAD_DATA":
            return self._drop(BAD_DATA)
        if kind in COMMANDS:
            verdict = self._command(msg)
        elif kind == "SET_MODE":
            verdict = PASS if msg.custom_mode in ROVER_MODES else Verdict(False, UNKNOWN_MODE, detail=f"custom_mode {msg.custom_mode}")
        else:
            verdict = PASS
        if verdict.ok:
            return verdict
        if verdict.reply is not None:
            self.refused += 1
            self._refusal_log.log(logging.DEBUG, "refused %s: %s (%s)", kind, verdict.reason, verdict.detail)
        else:
            self._drop(verdict.reason, verdict.detail)
        return verdict

    def _drop(self, reason: str, detail: str = "") -> Verdict:
        self.dropped[reason] += 1
        self._drop_log.log(logging.DEBUG, "dropped: %s%s", reason, f" ({detail})" if detail else "")
        return Verdict(False, reason)

    def _command(self, msg) -> Verdict:
        if getattr(msg, "target_component", 0) not in (0, self.params.component_id):
            return Verdict(False, OTHER_COMPONENT)
        for slot, valid, wanted, default in PARAM_RULES.get(msg.command, ()):
            value = getattr(msg, slot)
            if default is not None and math.isnan(value):
                setattr(msg, slot, default)
                continue
            if not valid(value):
                ack = mav.MAVLink_command_ack_message(
                    msg.command, mav.MAV_RESULT_DENIED, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
                )
                return Verdict(False, BAD_PARAM, ack, f"command {msg.command}: {slot} {value!r} is not {wanted}")
        return PASS

    def failed(self, msg, exc: BaseException) -> None:
        """A handler raised on ``msg``: log it once per (type, exception type), count it."""
        key = (msg.get_type(), type(exc).__name__)
        self.failures[key] += 1
        if self.failures[key] == 1:
            frame = bytes(msg.get_msgbuf() or b"").hex()
            log.error("GCS link: %s raised %s: %s (frame %s); ignored, the link goes on", key[0], key[1], exc, frame,
                      exc_info=exc)  # fmt: skip


class DatagramFraming:
    """``conn.recv`` of a UDP connection, such that no frame is parsed across two datagrams.

    Before a new datagram is read, whatever the parser still holds from the last one is offered to
    it once more (returning no new bytes: a datagram may carry several frames); if that yields
    nothing, it is an unfinished frame and is dropped."""

    def __init__(self, recv: Callable[..., Any], parser: Any, dropped: Callable[[], Any]) -> None:
        self._recv = recv
        self._parser = parser
        self._dropped = dropped
        self._offered: int | None = None

    def __call__(self, n: int | None = None):
        left = self._parser.buf_len()
        if left and left != self._offered:
            self._offered = left
            return b""
        if left:
            self._parser.buf = bytearray()
            self._parser.buf_index = 0
            self._parser.expected_length = mav.HEADER_LEN_V1 + 2
            self._dropped()
        self._offered = None
        return self._recv(n)
