"""What strangers' datagrams can cost the GCS link, bounded (docs/gcs.md, "The gate"):

* on udpin the daemon sends to its peer table only: an address joins when a frame from it passed
  signing (with a key: signed with it) and the gate, at most ``max_peers``, the one silent longest
  giving way, and a silent one expires. Thousands of source ports leave the table at its cap and
  a send's targets at most that many (pymavlink's own udpin sent to every address ever heard);
* frames are read without pymavlink's per-message tables, so a flood of new NAMED_VALUE_FLOAT
  names or PARAM_VALUE ids leaves them as they were;
* the tlog records the frames that passed; the refused ones are counted, not logged.

The link is polled in this thread with a simulated clock; the strangers are real sockets on
127.0.0.1, each with its own source port. Counts, not timings, are asserted.
"""

from __future__ import annotations

import select
import socket

import pytest
from fuzz.frames import pack
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mav
from support import free_port

from rover_ctl.app.logs import TlogWriter
from rover_ctl.config import GcsParams
from rover_ctl.mavlink.gcs import GcsLink
from rover_ctl.mavlink.signing import KeyStore, clock_ticks, key_from_passphrase

KEY = key_from_passphrase("correct horse")
PARAMS = GcsParams(heartbeat_period_s=1.0, mission_store_path="", max_peers=8)
GCS = (255, 190)
STRANGER = (254, 190)
BATCH = 50
"""Datagrams sent before the link reads them (the socket's receive buffer holds a few hundred)."""


def heartbeat():
    return mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)


def signed(msg, key: bytes = KEY, sender=GCS, timestamp: int | None = None) -> bytes:
    packer = mav.MAVLink(None, srcSystem=sender[0], srcComponent=sender[1])
    packer.signing.secret_key, packer.signing.sign_outgoing = key, True
    packer.signing.link_id, packer.signing.timestamp = 0, clock_ticks() if timestamp is None else timestamp
    return bytes(msg.pack(packer))


class Sends:
    """The link socket's ``sendto``, counted: (datagram, address) per call."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self.calls: list[tuple[bytes, tuple]] = []

    def sendto(self, data: bytes, address) -> int:
        self.calls.append((bytes(data), address))
        return self.sock.sendto(data, address)

    def __getattr__(self, name):
        return getattr(self.sock, name)


class Link:
    """A udpin GcsLink polled in this thread, its sends counted."""

    def __init__(self, tmp_path, params: GcsParams = PARAMS, signing: KeyStore | None = None) -> None:
        self.port = free_port()
        self.link = GcsLink(f"udpin:127.0.0.1:{self.port}", params, signing=signing)
        self.sends = Sends(self.link.conn.port)
        self.link.conn.port = self.sends
        self.now_s = 0.0
        self.tlog = TlogWriter(tmp_path / "gcs.tlog")
        self.tlog.attach(self.link.conn)  # as the daemon does
        self.sockets: list[socket.socket] = []

    def close(self) -> None:
        self.tlog.close()
        self.link.close()
        for sock in self.sockets:
            sock.close()

    def socket(self) -> socket.socket:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        self.sockets.append(sock)
        return sock

    def pump(self) -> None:
        """Poll until the link has read everything sent to it."""
        self.link.poll(self.now_s)
        while select.select([self.sends.sock], [], [], 0.0)[0]:
            self.link.poll(self.now_s)

    def flood(self, frames, count: int, keep: bool = False) -> set:
        """``count`` datagrams, each from a new socket (its own source port); returns the ports.
        ``keep``: the sockets stay open (they are sent to), else each closes after its datagram."""
        ports = set()
        for k in range(count):
            sock = self.socket() if keep else socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sock.sendto(frames(k), ("127.0.0.1", self.port))
            ports.add(sock.getsockname()[1])
            if not keep:
                sock.close()
            if k % BATCH == BATCH - 1:
                self.pump()
        self.pump()
        return ports

    def send_heartbeat_now(self) -> list[tuple[bytes, tuple]]:
        """The link's next HEARTBEAT: the sendto calls it took."""
        before = len(self.sends.calls)
        self.link.send_heartbeat()
        return self.sends.calls[before:]


@pytest.fixture
def link(tmp_path):
    lk = Link(tmp_path)
    yield lk
    lk.close()


def address(sock: socket.socket):
    return sock.getsockname()


def test_thousands_of_source_ports_leave_the_peer_table_at_its_cap(link):
    ground = link.socket()
    ground.sendto(pack(heartbeat(), GCS), ("127.0.0.1", link.port))
    link.pump()
    assert link.link.peers.peers == (address(ground),)

    # Garbage and frames that fail their CRC from 2,000 ports: nobody joins.
    frame = bytearray(pack(heartbeat(), STRANGER))
    frame[-1] ^= 0xFF
    link.flood(lambda k: bytes(frame) if k % 2 else b"\xfd\x01garbage" + bytes([k % 256]), 2000)
    assert link.link.peers.peers == (address(ground),)
    assert [target for _, target in link.send_heartbeat_now()] == [address(ground)]

    # Valid frames from 300 ports (no key: any valid frame passes): the table stays at its cap, the
    # ground station silent longest gives way, and a send goes to 8 addresses, not 300.
    ports = link.flood(lambda k: pack(heartbeat(), STRANGER), 300, keep=True)
    assert len(ports) == 300
    assert len(link.link.peers) == PARAMS.max_peers
    assert link.link.peers.evicted == 1 + 300 - PARAMS.max_peers
    assert address(ground) not in link.link.peers.peers
    targets = [target for _, target in link.send_heartbeat_now()]
    assert len(targets) == PARAMS.max_peers and set(targets) == set(link.link.peers.peers)
    assert not link.link.conn.clients  # pymavlink's own table is never filled

    # The ground station speaks again: it is back, and the one silent longest gave way.
    ground.sendto(pack(heartbeat(), GCS), ("127.0.0.1", link.port))
    link.pump()
    assert len(link.link.peers) == PARAMS.max_peers and link.link.peers.peers[-1] == address(ground)


def test_with_a_key_only_frames_signed_with_it_make_a_peer(tmp_path):
    keys = KeyStore(tmp_path / "signing.key")
    keys.save_key(KEY)
    lk = Link(tmp_path, signing=keys)
    try:
        owner = lk.socket()
        owner.sendto(signed(heartbeat()), ("127.0.0.1", lk.port))
        lk.pump()
        assert lk.link.peers.peers == (address(owner),)
        other_key = key_from_passphrase("battery staple")
        radio = mav.MAVLink_radio_status_message(200, 190, 0, 90, 80, 0, 0)
        kinds = (lambda k: pack(heartbeat(), STRANGER),  # unsigned
                 lambda k: signed(heartbeat(), other_key, STRANGER),  # another key
                 lambda k: pack(radio, STRANGER))  # accepted unsigned (SiK radios), but not a peer  # fmt: skip
        lk.flood(lambda k: kinds[k % 3](k), 1500)
        assert lk.link.peers.peers == (address(owner),)
        assert lk.link.signing.rejected == 1000
        sent = lk.send_heartbeat_now()
        assert [target for _, target in sent] == [address(owner)]
        assert not lk.link.conn.clients
    finally:
        lk.close()


def test_a_silent_peer_keeps_receiving_until_a_newcomer_needs_its_place(link):
    """A ground station whose uplink failed (the GCS-loss failsafe's case) must go on seeing the
    rover: silence alone does not drop a peer; a newcomer beyond max_peers replaces the one
    silent longest, and one that speaks again is back."""
    first = link.socket()
    first.sendto(pack(heartbeat(), GCS), ("127.0.0.1", link.port))
    link.pump()
    link.now_s = 3600.0
    link.pump()
    assert [target for _, target in link.send_heartbeat_now()] == [address(first)]
    others = [link.socket() for _ in range(PARAMS.max_peers)]
    for sock in others:
        sock.sendto(pack(heartbeat(), (255, 191)), ("127.0.0.1", link.port))
        link.pump()
    assert address(first) not in link.link.peers.peers and len(link.link.peers) == PARAMS.max_peers
    first.sendto(pack(heartbeat(), GCS), ("127.0.0.1", link.port))
    link.pump()
    assert link.link.peers.peers[-1] == address(first) and address(others[0]) not in link.link.peers.peers

def test_a_refused_request_is_answered_to_its_sender_alone(link):
    ground, stranger = link.socket(), link.socket()
    ground.sendto(pack(heartbeat(), GCS), ("127.0.0.1", link.port))
    link.pump()
    bad = mav.MAVLink_command_long_message(1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 7, 0, 0, 0, 0, 0, 0)
    before = len(link.sends.calls)
    stranger.sendto(pack(bad, STRANGER), ("127.0.0.1", link.port))
    link.pump()
    answers = [(data, target) for data, target in link.sends.calls[before:] if data[7] == mav.MAVLINK_MSG_ID_COMMAND_ACK]
    assert [target for _, target in answers] == [address(stranger)]
    ack = mav.MAVLink(None).decode(bytearray(answers[0][0]))
    assert ack.result == mav.MAV_RESULT_DENIED and ack.target_system == STRANGER[0]
    assert link.link.peers.peers == (address(ground),)  # a refused frame makes no peer
    assert link.link.inbound.refused == 1


@pytest.mark.parametrize("kind", ["NAMED_VALUE_FLOAT", "PARAM_VALUE"])
def test_a_flood_of_new_names_leaves_pymavlinks_tables_as_they_were(link, kind):
    conn = link.link.conn
    sender = link.socket()

    def tables():
        return (sum(len(state.messages) for state in conn.sysid_state.values()), len(conn.sysid_state),
                sum(len(state.params) for state in conn.param_state.values()), len(conn.last_seq))  # fmt: skip

    before = tables()
    for k in range(3000):
        name = f"N{k:06d}".encode()
        if kind == "NAMED_VALUE_FLOAT":
            msg = mav.MAVLink_named_value_float_message(k, name, float(k))
        else:
            msg = mav.MAVLink_param_value_message(name, float(k), mav.MAV_PARAM_TYPE_REAL32, 3000, k)
        sender.sendto(pack(msg, (k % 250 + 2, 1)), ("127.0.0.1", link.port))
        if k % BATCH == BATCH - 1:
            link.pump()
    link.pump()
    assert link.tlog.frames >= 3000  # they were read (and passed: the gate lets unknown types by)
    assert tables() == before
    assert isinstance(conn, mavutil.mavudp)


def test_the_tlog_holds_what_passed_and_counts_what_was_refused(tmp_path):
    keys = KeyStore(tmp_path / "signing.key")
    keys.save_key(KEY)
    lk = Link(tmp_path, signing=keys)
    try:
        owner, stranger = lk.socket(), lk.socket()
        to = ("127.0.0.1", lk.port)
        timestamp = clock_ticks()
        owner.sendto(signed(heartbeat(), timestamp=timestamp), to)
        refused = [
            mav.MAVLink_command_long_message(1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 7, 0, 0, 0, 0, 0, 0),  # DENIED
            mav.MAVLink_command_long_message(1, 100, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0),  # other component
            mav.MAVLink_set_mode_message(1, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 99),  # unknown mode
        ]
        for k, msg in enumerate(refused, 1):
            owner.sendto(signed(msg, timestamp=timestamp + k), to)
        for _ in range(20):
            stranger.sendto(pack(mav.MAVLink_named_value_float_message(0, b"spam", 1.0), STRANGER), to)  # unsigned
        stranger.sendto(b"\xfe\x03no frame", to)
        owner.sendto(signed(mav.MAVLink_named_value_float_message(0, b"ok", 2.0), timestamp=timestamp + 10), to)
        lk.pump()
        lk.tlog.close()
        inbound = lk.link.inbound
        assert inbound.refused == 1 and lk.link.signing.rejected == 20
        assert sum(inbound.dropped.values()) >= 2 + 20 + 1
        log = mavutil.mavlink_connection(str(lk.tlog.path), dialect="ardupilotmega")
        received = []
        while (msg := log.recv_msg()) is not None:
            if msg.get_srcSystem() != PARAMS.system_id:  # what the link sent is logged too
                received.append(msg.get_type())
        assert received == ["HEARTBEAT", "NAMED_VALUE_FLOAT"]
    finally:
        lk.close()
