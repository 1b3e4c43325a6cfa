"""Who the GCS link sends to when it listens on UDP (``udpin:``): its ground stations, a few.

pymavlink's ``mavudp`` in udpin mode adds the source address of every datagram it receives to
``conn.clients``, before any signature check or the gate, and sends every frame it writes to every
address in that set, for ever. 20,000 datagrams from distinct source ports (garbage or unsigned
frames do) made 14,420 "clients": one HEARTBEAT then took 75 ms of ``sendto`` calls, the control
loop starved, and every stranger received the telemetry.

``UdpPeers`` takes the connection's ``recv`` and ``write`` instead (the rest of pymavlink's
connection is untouched; ``conn.clients`` stays empty):

* ``recv`` reads one datagram and remembers its source address (``source``); it makes no peer;
* ``admit(now_s)`` makes that source a peer, or refreshes it. The GCS link calls it for a frame
  that passed the signature check (when a key is set: signed with it, not merely accepted
  unsigned as RADIO_STATUS is) and the gate (``rover_ctl.mavlink.inbound``). At most
  ``GcsParams.max_peers``; a newcomer beyond that replaces the peer that has been silent longest.
  A silent peer is not forgotten otherwise: a ground station whose uplink failed (the GCS-loss
  failsafe's case) must go on seeing the rover, as pymavlink's own udpin sends to everyone heard;
* ``write`` sends a frame to each peer, so its cost is bounded by ``max_peers``; inside
  ``only(address)`` to that address alone (the answer to a refused request goes to its sender,
  which is not a peer if that request was all it sent).

``now_s`` is the GCS link's clock (``GcsLink.poll``'s); only differences are used.

The other link kinds have a single peer and are left as pymavlink makes them: ``udpout`` sends
to its one destination, ``tcpin`` serves one accepted connection, ``tcp`` its own connection.
"""

from __future__ import annotations

import errno
import logging
import os
from contextlib import contextmanager
from typing import Any, Iterator

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402  (MAVLINK20 first: mavutil's default dialect is MAVLink 1 without it)

from rover_ctl.config import GcsParams  # noqa: E402

log = logging.getLogger(__name__)

Address = tuple[Any, ...]
"""A socket address as ``recvfrom`` gives it: (host, port) for IPv4."""
NOTHING_WAITING = (errno.EAGAIN, errno.EWOULDBLOCK, errno.ECONNREFUSED)
"""``recvfrom`` errors that mean "no datagram now" (pymavlink's list: an ICMP port-unreachable
for an earlier send surfaces as ECONNREFUSED)."""


def serves_many(conn: Any) -> bool:
    """Whether ``conn`` is a UDP connection that answers whoever sends to it (udpin, or the legacy
    ``udp:`` that means the same), the only kind that needs a peer table."""
    return isinstance(conn, mavutil.mavudp) and bool(conn.udp_server)


class UdpPeers:
    """The peer table of one udpin connection (see the module docstring)."""

    def __init__(self, conn: Any, params: GcsParams) -> None:
        self.conn = conn
        self.params = params
        self._peers: dict[Address, float] = {}
        """Address -> when it last passed (``now_s``), the one silent longest first."""
        self.source: Address | None = None
        """The source address of the datagram read last: the sender of every frame parsed now
        (``inbound.DatagramFraming`` parses each datagram on its own)."""
        self._only: tuple[Address, ...] | None = None
        self.admitted = 0
        """Addresses that became peers (again) over the link's life."""
        self.evicted = 0
        """Peers replaced by a newcomer while the table was full."""
        conn.recv = self.recv
        conn.write = self.write

    @property
    def peers(self) -> tuple[Address, ...]:
        """The current peers, the one silent longest first."""
        return tuple(self._peers)

    def __len__(self) -> int:
        return len(self._peers)

    # ---- the connection's I/O ---------------------------------------------------------------

    def recv(self, n: int | None = None) -> bytes:
        """One datagram (b"" when none is waiting); its source is noted, not admitted."""
        try:
            data, address = self.conn.port.recvfrom(mavutil.UDP_MAX_PACKET_LEN)
        except OSError as exc:
            if exc.errno in NOTHING_WAITING:
                return b""
            raise
        self.source = address
        return data

    def write(self, buf: bytes) -> None:
        """Send ``buf`` to every peer (inside ``only``: to that address alone)."""
        targets = self._only if self._only is not None else tuple(self._peers)
        port = self.conn.port
        for address in targets:
            try:
                port.sendto(buf, address)
            except OSError as exc:  # one unreachable peer does not keep the frame from the others
                log.debug("GCS link: send to %s: %s", address, exc)

    @contextmanager
    def only(self, address: Address | None) -> Iterator[None]:
        """Within the block, frames go to ``address`` alone (None: nowhere)."""
        self._only = (address,) if address is not None else ()
        try:
            yield
        finally:
            self._only = None

    # ---- the table --------------------------------------------------------------------------

    def admit(self, now_s: float) -> None:
        """The frame just parsed passed signing and the gate: its sender is a peer, heard now."""
        address = self.source
        if address is None:
            return
        peers = self._peers
        if peers.pop(address, None) is None:
            while len(peers) >= max(1, self.params.max_peers):
                oldest = next(iter(peers))
                del peers[oldest]
                self.evicted += 1
                if self.evicted == 1 or self.evicted % 1000 == 0:  # a flood must not flood the log
                    log.warning("GCS link: %d ground stations at most (gcs.max_peers): %s replaced the one silent "
                                "longest, %s (%d replaced so far)", self.params.max_peers, _text(address), _text(oldest),
                                self.evicted)  # fmt: skip
            self.admitted += 1
            log.debug("GCS link: ground station %s", _text(address))
        peers[address] = now_s


def _text(address: Address) -> str:
    return ":".join(str(part) for part in address[:2])
