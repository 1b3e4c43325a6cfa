"""The ground-station side of the MAVLink command protocol, for `rover-ctl arm|disarm|mode|mission start`.

``send_command(client, command, *params)`` sends COMMAND_LONG to the autopilot a ``MissionClient``
is connected to (the same connection handling and retry settings), resends it with an increasing
``confirmation`` every ``client_retry_s`` until a COMMAND_ACK for that command arrives, and
returns the MAV_RESULT with every STATUSTEXT the autopilot sent meanwhile (a refusal's reason:
the daemon, as ArduPilot, says it before the ACK). No answer at all raises ``MissionClientError``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from rover_ctl.mavlink.mission_client import MissionClient, MissionClientError
from rover_ctl.vocabulary import mav

STATUSTEXT_GRACE_S = 0.2
"""After a refusal, listen this long for a reason that arrived late (another autopilot's order)."""


@dataclass
class CommandReply:
    result: int
    texts: list[str] = field(default_factory=list)

    @property
    def accepted(self) -> bool:
        return self.result == mav.MAV_RESULT_ACCEPTED

    @property
    def result_name(self) -> str:
        entry = mav.enums["MAV_RESULT"].get(self.result)
        return entry.name if entry else f"MAV_RESULT {self.result}"


def send_command(client: MissionClient, command: int, *params: float) -> CommandReply:
    target = client.target or client.connect()
    padded = [float(p) for p in params] + [0.0] * (7 - len(params))
    texts: list[str] = []
    for confirmation in range(client.params.client_retries + 1):
        client.conn.mav.command_long_send(target[0], target[1], command, confirmation, *padded)
        end = time.monotonic() + client.params.client_retry_s
        while (left := end - time.monotonic()) > 0:
            msg = client.conn.recv_match(type=["COMMAND_ACK", "STATUSTEXT"], blocking=True, timeout=left)
            if msg is None or (msg.get_srcSystem(), msg.get_srcComponent()) != target:
                continue
            if msg.get_type() == "STATUSTEXT":
                texts.append(msg.text)
            elif msg.command == command and msg.result != mav.MAV_RESULT_IN_PROGRESS:
                reply = CommandReply(msg.result, texts)
                if not reply.accepted and not texts:
                    late = client.conn.recv_match(type="STATUSTEXT", blocking=True, timeout=STATUSTEXT_GRACE_S)
                    if late is not None:
                        texts.append(late.text)
                return reply
    waited_s = (client.params.client_retries + 1) * client.params.client_retry_s
    raise MissionClientError(f"no COMMAND_ACK from the vehicle within {waited_s:g} s ({client.url})")
