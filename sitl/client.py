"""The lockstep client: a minimal pymavlink controller for ``rover-sitl --lockstep``.

The other half of the emulator's lockstep contract, shared by the tests, the benchmarks and
``python -m sitl.demo`` (the daemon has its own, ``rover_ctl.mavlink.vehicle``).

It answers the emulator's end-of-frame TIMESYNC markers (docs/architecture.md, "Lockstep
handshake"), sends a GCS heartbeat every sim second, can arm, and asks a callback each frame for
the RC override to send::

    client = LockstepClient("tcp:127.0.0.1:5760")   # or sitl.launch.rover_sitl(...).url
    client.arm()
    client.run(10.0, on_frame=lambda t_s, msgs: (1700, 1500))   # (throttle_us, steering_us) or None
    client.close()

Messages are read in whole buffers and parsed with ``parse_buffer`` (pymavlink's ``recv_msg``
reads a few bytes per system call, too slow for a controller at 20x real time).
"""

from __future__ import annotations

import os
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from sitl.mavlink_vehicle import FORCE_ARM_MAGIC  # noqa: E402  (ArduPilot's arm-without-checks param2)

mavlink = mavutil.mavlink
READ_SIZE_BYTES = 65536
IGNORE = 65535
"""RC_CHANNELS_OVERRIDE "leave this channel alone" (UINT16_MAX)."""

OnFrame = Callable[[float, list], "tuple[int, int] | None"]


class LockstepError(RuntimeError):
    """The emulator did not answer in time, or refused a command."""


@dataclass
class RunStats:
    frames: int
    sim_s: float
    wall_s: float
    messages: int

    @property
    def realtime_factor(self) -> float:
        return self.sim_s / self.wall_s if self.wall_s > 0 else float("inf")


class LockstepClient:
    """A controller on one pymavlink connection string (``tcp:``, ``udpout:``, ``udpin:`` or a serial device)."""

    def __init__(self, url: str, sysid: int = 255, compid: int = 190, timeout_s: float = 10.0) -> None:
        self.conn = mavutil.mavlink_connection(url, source_system=sysid, source_component=compid,
                                               dialect="ardupilotmega", autoreconnect=False)
        self.timeout_s = timeout_s
        self.t_s: float | None = None
        """Sim time of the last frame answered."""
        self._answered_ns = -1
        self._inbox: list = []
        self._parsed: deque = deque()
        """Messages read but not yet sorted into frames (one read can span several frames)."""
        self._pending: tuple[int, list] | None = None
        self._next_heartbeat_s = 0.0
        self.heartbeat()  # a udp client must speak first to be heard

    # ---- reading ---------------------------------------------------------------------
    def _read(self, wait_s: float) -> list:
        if self.conn.select(wait_s) is False:
            return []
        data = self.conn.recv(READ_SIZE_BYTES)
        if not data:
            return []
        return self.conn.mav.parse_buffer(data if isinstance(data, bytes) else bytes(data)) or []

    def next_frame(self) -> tuple[int, list]:
        """Block until the next unanswered marker; return (t_ns, messages received since the last)."""
        if self._pending is not None:
            frame, self._pending = self._pending, None
            return frame
        deadline = time.monotonic() + self.timeout_s
        while True:
            while self._parsed:
                msg = self._parsed.popleft()
                if msg.get_type() == "TIMESYNC" and msg.tc1 == 0:
                    if msg.ts1 > self._answered_ns:
                        frame, self._inbox = self._inbox, []
                        return msg.ts1, frame
                elif msg.get_type() != "BAD_DATA":
                    self._inbox.append(msg)
            self._parsed.extend(self._read(min(0.5, max(0.0, deadline - time.monotonic()))))
            if not self._parsed and time.monotonic() > deadline:
                raise LockstepError(f"no lockstep marker within {self.timeout_s:g} s on {self.conn.address}")

    def answer(self, t_ns: int) -> None:
        """Release frame ``t_ns`` (send after this frame's commands)."""
        self.conn.mav.timesync_send(time.monotonic_ns(), t_ns)
        self._answered_ns = t_ns
        self.t_s = t_ns / 1e9

    # ---- commands --------------------------------------------------------------------
    def heartbeat(self) -> None:
        self.conn.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)

    def override(self, throttle_us: int, steering_us: int) -> None:
        self.conn.mav.rc_channels_override_send(1, 1, steering_us, IGNORE, throttle_us, IGNORE, IGNORE, IGNORE, IGNORE, IGNORE)

    def command(self, command: int, *params: float) -> int:
        """Send a COMMAND_LONG and step frames until its COMMAND_ACK; return the MAV_RESULT."""
        # Wait for a frame first: the link is then up (a tcpin client has accepted the emulator).
        t_ns, carried = self._pending if self._pending is not None else self.next_frame()
        self._pending = None
        values = list(params) + [0.0] * (7 - len(params))
        self.conn.mav.command_long_send(1, 1, command, 0, *values)
        self.answer(t_ns)
        carried = list(carried)  # messages of the frames stepped here, handed to the caller's next frame
        deadline = time.monotonic() + self.timeout_s
        while time.monotonic() < deadline:
            t_ns, msgs = self.next_frame()
            carried += msgs
            acks = [m.result for m in msgs if m.get_type() == "COMMAND_ACK" and m.command == command]
            if acks:
                self._pending = (t_ns, carried)  # the frame stays unanswered for the caller's loop
                return acks[0]
            self.answer(t_ns)
        raise LockstepError(f"no COMMAND_ACK for command {command} within {self.timeout_s:g} s")

    def arm(self, force: bool = False) -> None:
        result = self.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1, FORCE_ARM_MAGIC if force else 0)
        if result != mavlink.MAV_RESULT_ACCEPTED:
            raise LockstepError(f"arming refused (MAV_RESULT {result})")

    def set_param(self, name: str, value: float) -> None:
        self.conn.mav.param_set_send(1, 1, name.encode(), value, mavlink.MAV_PARAM_TYPE_REAL32)

    # ---- the loop --------------------------------------------------------------------
    def run(self, seconds_sim: float, on_frame: OnFrame | None = None) -> RunStats:
        """Answer frames for ``seconds_sim`` of sim time, sending ``on_frame``'s override each frame."""
        started = time.perf_counter()
        frames = messages = 0
        first_s = None
        while True:
            t_ns, msgs = self.next_frame()
            t_s = t_ns / 1e9
            first_s = t_s if first_s is None else first_s
            frames += 1
            messages += len(msgs)
            command = on_frame(t_s, msgs) if on_frame is not None else None
            if command is not None:
                self.override(*command)
            if t_s >= self._next_heartbeat_s:
                self.heartbeat()
                self._next_heartbeat_s = t_s + 1.0
            self.answer(t_ns)
            if t_s - first_s >= seconds_sim - 1e-9:
                return RunStats(frames, t_s - first_s, time.perf_counter() - started, messages)

    def close(self) -> None:
        self.conn.close()
