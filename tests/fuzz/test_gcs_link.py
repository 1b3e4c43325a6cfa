"""Fuzz the GCS link through a real loopback socket: arbitrary messages of every type it handles
(Hypothesis over pymavlink's message classes, NaN/inf/extreme field values), random bytes and
corrupted valid frames. Each example runs a fresh ``GcsLink`` with a stored mission and proves:

* the link stays up (no exception out of ``poll``) and keeps sending HEARTBEAT;
* the stored mission file is byte-identical unless the example took a mission change that the
  protocol allows (a clear, an empty upload, a complete upload), and what is stored then passes
  the rules of ``rover-ctl mission check``;
* no autopilot handler call happened that the message did not legitimately ask for
  (``fuzz.frames.well_formed_effects``), so the rover moves only on a well-formed command.

``ROVER_FUZZ_EXAMPLES=N`` runs N examples per property (see conftest).
"""

from __future__ import annotations

import json
import math
import random
import select
import socket

from fuzz.conftest import FUZZ
from fuzz.frames import any_message, pack, senders, well_formed_effects
from hypothesis import given
from hypothesis import strategies as st
from mission_protocol.helpers import sample_mission
from pymavlink.dialects.v20 import ardupilotmega as mav
from support import free_port

from rover_ctl.config import GcsParams
from rover_ctl.mavlink.gcs import DefaultHandlers, GcsLink
from rover_ctl.mavlink.inbound import DROP_REASONS
from rover_ctl.mission.store import MissionStore, to_json
from rover_ctl.mission.validate import validate

PARAMS = GcsParams(heartbeat_period_s=1.0, mission_store_path="")
"""(The harness's clock jumps by 10 s to make a heartbeat due: its ground station must not expire.)"""
STORED = json.dumps(to_json(sample_mission()), indent=1).encode()
"""The store file each example starts with (written without the store's fsyncs: speed)."""
EFFECTS = ("arm", "set_mode", "mission_start", "return_to_launch", "set_current", "set_param", "mission_changed")


class Recording(DefaultHandlers):
    """DefaultHandlers that record every call that could change the vehicle or its plan."""

    def __init__(self) -> None:
        super().__init__()
        self.calls: list[str] = []

    def __getattribute__(self, name):
        attr = object.__getattribute__(self, name)
        if name in EFFECTS:
            object.__getattribute__(self, "calls").append(name)
        return attr


class Harness:
    """A GcsLink on udpin, polled in this thread, and a raw UDP socket speaking to it."""

    def __init__(self, tmp_path) -> None:
        self.store = MissionStore(tmp_path / "mission.json")
        self.store.path.write_bytes(STORED)
        self.handlers = Recording()
        port = free_port()
        self.link = GcsLink(f"udpin:127.0.0.1:{port}", PARAMS, handlers=self.handlers, store=self.store)
        self.handlers.calls.clear()  # the stored mission handed over at start
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.addr = ("127.0.0.1", port)
        self.now_s = 0.0
        self.parser = mav.MAVLink(None)
        self.parser.robust_parsing = True
        # A ground station first (udpin sends only to senders of frames that passed): what follows
        # must not cut it off.
        self.send(pack(mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3), (255, 190)))
        assert len(self.link.peers) == 1

    def close(self) -> None:
        self.link.close()
        self.sock.close()

    def send(self, data: bytes) -> None:
        self.sock.sendto(data, self.addr)
        self.pump()

    def pump(self) -> None:
        """Poll until the link has read everything sent to it."""
        self.link.poll(self.now_s)
        while select.select([self.link.conn.port], [], [], 0.0)[0]:
            self.link.poll(self.now_s)

    def received(self, wait_s: float = 0.0) -> list:
        out = []
        while select.select([self.sock], [], [], wait_s)[0]:
            out += self.parser.parse_buffer(self.sock.recv(65535)) or []
            wait_s = 0.0
        return out

    def heartbeats_go_on(self) -> bool:
        """A HEARTBEAT comes once its period is due (within a second of wall time)."""
        self.received()
        self.now_s += 10 * PARAMS.heartbeat_period_s
        self.link.poll(self.now_s)
        for _ in range(20):
            if any(m.get_type() == "HEARTBEAT" for m in self.received(0.05)):
                return True
        return False


def check_message(h: Harness, msg, sender) -> None:
    before = h.store.path.read_bytes()
    uploading = h.link.service.uploading
    h.handlers.calls.clear()
    h.send(pack(msg, sender))
    allowed = well_formed_effects(msg)
    assert set(h.handlers.calls) <= allowed, (msg, h.handlers.calls)
    if h.store.path.read_bytes() != before:
        kind = msg.get_type()
        assert "mission_changed" in h.handlers.calls, msg
        if kind in ("MISSION_ITEM_INT", "MISSION_ITEM"):
            assert uploading, msg  # an item changes the plan only by completing an upload
        stored = h.store.load()
        assert validate(stored, math.inf, parts=[msg.mission_type] if msg.mission_type < 3 else ())[0] == []


@FUZZ
@given(messages=st.lists(st.tuples(any_message, senders), min_size=1, max_size=12))
def test_arbitrary_messages_of_every_handled_type(tmp_path_factory, messages):
    h = Harness(tmp_path_factory.mktemp("link"))
    try:
        for msg, sender in messages:
            check_message(h, msg, sender)
        assert h.heartbeats_go_on()
        assert not h.link.inbound.failures, h.link.inbound.failures
        assert set(h.link.inbound.dropped) <= set(DROP_REASONS), h.link.inbound.dropped  # no key from a frame
    finally:
        h.close()


@FUZZ
@given(
    seed=st.integers(0, 2**32 - 1),
    datagrams=st.lists(st.binary(min_size=1, max_size=300), max_size=8),
    valid=st.lists(st.tuples(any_message, senders), min_size=1, max_size=6),
)
def test_random_bytes_and_corrupted_frames(tmp_path_factory, seed, datagrams, valid):
    h = Harness(tmp_path_factory.mktemp("link"))
    rng = random.Random(seed)
    before = h.store.path.read_bytes()
    try:
        for data in datagrams:
            h.send(data)
        for msg, sender in valid:
            frame = bytearray(pack(msg, sender))
            for _ in range(rng.randint(1, 4)):
                frame[rng.randrange(len(frame))] ^= rng.randrange(1, 256)
            if rng.random() < 0.3:
                frame = frame[: rng.randrange(1, len(frame) + 1)]
            h.send(bytes(frame))
        # A corrupted frame would pass its CRC with chance 2**-16 (then it is an arbitrary message,
        # the first property's case); the examples are derandomized, so this cannot flake.
        assert h.handlers.calls == []
        assert h.store.path.read_bytes() == before
        assert h.heartbeats_go_on()
        assert not h.link.inbound.failures, h.link.inbound.failures
        assert set(h.link.inbound.dropped) <= set(DROP_REASONS), h.link.inbound.dropped
    finally:
        h.close()
