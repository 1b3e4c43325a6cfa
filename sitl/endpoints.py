"""MAVLink endpoints of the emulator: udpin, udpout, tcpin, tcp (pymavlink connection strings) and a pty.

Each endpoint owns non-blocking file descriptors and one MAVLink parser/packer per peer (a tcpin
endpoint accepts several clients). Reads take whole buffers (``parse_buffer``) rather than the
byte-at-a-time loop of ``mavutil``'s connections, which keeps the emulator's hot path cheap. The
main loop ``select``s on :meth:`Endpoint.fds` and calls :meth:`Endpoint.poll` on readable ones.
"""

from __future__ import annotations

import errno
import os
import socket
import tty
from collections.abc import Callable, Iterator

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from sitl.line import FrameGate, SerialLine  # noqa: E402

READ_SIZE_BYTES = 65536
"""Bytes read per readable descriptor per poll."""
MAX_BACKLOG_BYTES = 1 << 20
"""A stream peer that stops reading loses output beyond this backlog (as a full serial buffer)."""
MAX_DATAGRAM_BYTES = 1400
"""Packets of one frame are joined into datagrams up to this size (below a 1500-byte Ethernet MTU)."""
SYSTEM_ID = 1
COMPONENT_ID = 1
"""The emulated autopilot's MAVLink ids (ArduPilot defaults: SYSID_THISMAV 1, autopilot component 1)."""


class EndpointError(Exception):
    """An endpoint could not be opened; the message is one line naming the endpoint."""


class EndpointBusy(EndpointError):
    """Its address is in use by another socket: the same endpoint on another port may open."""


def _bind_error(url: str, what: str, address: tuple[str, int], exc: OSError) -> EndpointError:
    kind = EndpointBusy if exc.errno == errno.EADDRINUSE else EndpointError
    return kind(f"endpoint {url!r}: cannot {what} {address[0]}:{address[1]}: {exc.strerror}")


def _parser():
    """A MAVLink parser/packer with the vehicle's ids that reports garbage as BAD_DATA, never raises."""
    mav = mavlink.MAVLink(None, srcSystem=SYSTEM_ID, srcComponent=COMPONENT_ID)
    mav.robust_parsing = True
    return mav


class _Peer:
    """One byte stream (or datagram source) with its own MAVLink parser and packer."""

    def __init__(self, fd: int, sock: socket.socket | None, address=None) -> None:
        self.fd = fd
        self.sock = sock
        self.address = address
        self.backlog = b""
        self.outbox: list[bytes] = []
        """Packed messages not yet written."""
        self.mav = _parser()
        self.marker_mav = _parser()
        """Packs the lockstep markers, which number on a sequence of their own (as the serial
        line's, which bypass its queue): a controller skips them, and the vehicle's frames it
        counts must then run without gaps, or it reads every marker as a lost frame."""

    def pack(self, msg, marker: bool = False) -> bytes:
        """``msg`` framed on the vehicle's sequence, or with ``marker`` on the markers' own."""
        mav = self.marker_mav if marker else self.mav
        buf = msg.pack(mav)
        mav.seq = (mav.seq + 1) % 256
        return buf


class Endpoint:
    """A MAVLink endpoint: ``send`` to every peer, ``poll`` for received messages."""

    kind = ""
    max_write_bytes: int | None = None
    """Largest single write (datagrams), cut at packet boundaries; None: unlimited (streams)."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.peers: list[_Peer] = []
        self.bad_frames = 0
        """Undecodable or unknown frames received and ignored."""

    def fds(self) -> list[int]:
        return [peer.fd for peer in self.peers]

    def send(self, msg) -> None:
        """Queue ``msg`` for every peer; :meth:`flush` writes the queue (one system call per peer)."""
        for peer in self.peers:
            peer.outbox.append(peer.pack(msg))

    def send_marker(self, msg, repeat: bool = False) -> None:
        """Queue the lockstep marker (TIMESYNC) for every peer; it goes after what is queued.
        ``repeat``: the same marker again, unanswered after a first repeat too."""
        for peer in self.peers:
            peer.outbox.append(peer.pack(msg, marker=True))

    def arrivals(self) -> Iterator[tuple[object, _Peer]]:
        """Messages that became due without anything to read (a line delivering in sim time)."""
        return iter(())

    def line_stats(self) -> dict | None:
        """The serial line's counters per direction, if this endpoint has one."""
        return None

    def flush(self) -> None:
        for peer in list(self.peers):
            if peer.outbox:
                packets, peer.outbox = peer.outbox, []
                for chunk in _chunks(packets, self.max_write_bytes):
                    self._write(peer, chunk)

    def poll(self, fd: int) -> Iterator[tuple[object, _Peer]]:
        """Read what is waiting on ``fd`` and yield the decoded messages with the peer they came from."""
        peer = next((p for p in self.peers if p.fd == fd), None)
        if peer is None:
            return
        data = self._read(peer)
        if data:
            yield from self._decode(peer, data)

    def _decode(self, peer: _Peer, data: bytes, parser=None) -> Iterator[tuple[object, _Peer]]:
        """The messages in ``data`` (parsed by ``parser``, default the peer's); garbage and unknown
        message ids are counted, never raised."""
        try:
            msgs = (parser or peer.mav).parse_buffer(data) or []
        except mavlink.MAVError:
            self.bad_frames += 1
            return
        for msg in msgs:
            if msg.get_type() == "BAD_DATA" or msg.get_type().startswith("UNKNOWN"):
                self.bad_frames += 1
                continue
            yield msg, peer

    def reply(self, peer: _Peer, msg) -> None:
        """Queue for the one peer a request came from (COMMAND_ACK, PARAM_VALUE)."""
        if peer in self.peers:
            peer.outbox.append(peer.pack(msg))

    def close(self) -> None:
        for peer in self.peers:
            self._close_peer(peer)
        self.peers.clear()

    # transport hooks
    def _read(self, peer: _Peer) -> bytes:
        try:
            data = os.read(peer.fd, READ_SIZE_BYTES)
        except BlockingIOError:
            return b""
        except OSError:
            data = b""
        if not data:
            self._drop(peer)
        return data

    def _write(self, peer: _Peer, buf: bytes) -> None:
        data = peer.backlog + buf
        try:
            sent = os.write(peer.fd, data)
        except BlockingIOError:
            sent = 0
        except OSError:
            self._drop(peer)
            return
        peer.backlog = data[sent:] if len(data) - sent <= MAX_BACKLOG_BYTES else b""

    def _drop(self, peer: _Peer) -> None:
        if peer in self.peers:
            self.peers.remove(peer)
            self._close_peer(peer)

    def _close_peer(self, peer: _Peer) -> None:
        if peer.sock is not None:
            peer.sock.close()
        else:
            os.close(peer.fd)


def _chunks(packets: list[bytes], limit: int | None) -> Iterator[bytes]:
    """Join packets into writes of at most ``limit`` bytes (a lone larger packet goes alone)."""
    if limit is None:
        yield b"".join(packets)
        return
    chunk: list[bytes] = []
    size = 0
    for packet in packets:
        if chunk and size + len(packet) > limit:
            yield b"".join(chunk)
            chunk, size = [], 0
        chunk.append(packet)
        size += len(packet)
    if chunk:
        yield b"".join(chunk)


def _host_port(url: str, rest: str) -> tuple[str, int]:
    host, sep, port = rest.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise EndpointError(f"endpoint {url!r}: expected HOST:PORT after the scheme")
    return host, int(port)


class UdpEndpoint(Endpoint):
    """udpin (bind, answer every address heard from) or udpout (send to a fixed address).
    Several packets share a datagram, as ArduPilot sends them."""

    max_write_bytes = MAX_DATAGRAM_BYTES

    def __init__(self, url: str, address: tuple[str, int], listen: bool) -> None:
        super().__init__(url)
        self.kind = "udpin" if listen else "udpout"
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        try:
            if listen:
                self.sock.bind(address)
        except OSError as exc:
            self.sock.close()
            raise _bind_error(url, "bind", address, exc) from None
        self.destinations: dict[tuple[str, int], _Peer] = {}
        if not listen:
            self.destinations[address] = _Peer(self.sock.fileno(), None, address)
        self.peers = list(self.destinations.values())

    def fds(self) -> list[int]:
        return [self.sock.fileno()]

    def poll(self, fd: int) -> Iterator[tuple[object, _Peer]]:
        while True:
            try:
                data, address = self.sock.recvfrom(READ_SIZE_BYTES)
            except (BlockingIOError, ConnectionRefusedError):
                return
            peer = self.destinations.get(address)
            if peer is None:
                peer = self.destinations[address] = _Peer(self.sock.fileno(), None, address)
                self.peers = list(self.destinations.values())
            yield from self._decode(peer, data)

    def _write(self, peer: _Peer, buf: bytes) -> None:
        try:
            self.sock.sendto(buf, peer.address)
        except OSError:
            pass  # datagrams are best effort; an absent listener is not an error

    def close(self) -> None:
        self.sock.close()
        self.peers.clear()


class TcpListenEndpoint(Endpoint):
    """tcpin: listen and serve every client that connects (each with its own parser)."""

    kind = "tcpin"

    def __init__(self, url: str, address: tuple[str, int]) -> None:
        super().__init__(url)
        self.listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self.listener.bind(address)
        except OSError as exc:
            self.listener.close()
            raise _bind_error(url, "listen on", address, exc) from None
        self.listener.listen(4)
        self.listener.setblocking(False)

    def fds(self) -> list[int]:
        return [self.listener.fileno(), *super().fds()]

    def poll(self, fd: int) -> Iterator[tuple[object, _Peer]]:
        if fd == self.listener.fileno():
            try:
                sock, address = self.listener.accept()
            except BlockingIOError:
                return
            sock.setblocking(False)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self.peers.append(_Peer(sock.fileno(), sock, address))
            return
        yield from super().poll(fd)

    def close(self) -> None:
        super().close()
        self.listener.close()


class TcpConnectEndpoint(Endpoint):
    """tcp: connect out to a listening peer (e.g. a ground station or controller)."""

    kind = "tcp"

    def __init__(self, url: str, address: tuple[str, int]) -> None:
        super().__init__(url)
        try:
            sock = socket.create_connection(address, timeout=5.0)
        except OSError as exc:
            raise EndpointError(f"endpoint {url!r}: cannot connect to {address[0]}:{address[1]}: {exc.strerror or exc}") from None
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.peers.append(_Peer(sock.fileno(), sock, address))


MAX_FRAME_BYTES = 280
"""The longest MAVLink 2 frame (10 header + 255 payload + 2 CRC + 13 signature)."""


class PtyEndpoint(Endpoint):
    """A pseudo-terminal pair in raw mode: MAVLink on the master, clients open ``device`` as a serial port.

    With ``downlink`` and ``uplink`` lines (``rover-sitl --pty --baud``) both directions go through
    the serial line model in sim time (``now_s``): what the vehicle sends is offered to the
    downlink frame by frame, each whole or not at all (as ArduPilot checks a port's room before
    it sends), and written to the pty as the line delivers it, whole frames only (``FrameGate``);
    what the client writes is parsed, offered frame by frame to the uplink the same way, and
    parsed again as the line delivers it, corrupted bytes and all (a bad CRC is a bad frame).
    The lockstep marker and its answer are not traffic of a real vehicle: they bypass the line
    (else a full line would stop sim time, and with it the line) and the marker has a sequence
    counter of its own, so the vehicle's MAVLink ``seq`` stays gap-free for a link-health count.
    """

    kind = "pty"

    def __init__(self, downlink: SerialLine | None = None, uplink: SerialLine | None = None,
                 now_s: Callable[[], float] | None = None) -> None:  # fmt: skip
        master_fd, slave_fd = os.openpty()
        tty.setraw(slave_fd)
        os.set_blocking(master_fd, False)
        self.device = os.ttyname(slave_fd)
        super().__init__(f"pty:{self.device}")
        # Keeping the slave open means a client closing it does not hang up the master (EIO).
        self.slave_fd = slave_fd
        self.peers.append(_Peer(master_fd, None))
        if (downlink is None) != (uplink is None) or (downlink is not None and now_s is None):
            raise ValueError("a pty line needs a downlink, an uplink and a clock")
        self.downlink, self.uplink, self.now_s = downlink, uplink, now_s
        self.bypass: Callable[[object], bool] | None = None
        """Received messages that skip the uplink (the emulator sets it to "is the marker's answer")."""
        self._gate = FrameGate()
        self._express: list[bytes] = []
        self._marker_mav = _parser()
        self._line_parser = _parser()

    def send_marker(self, msg, repeat: bool = False) -> None:
        if self.downlink is None:
            return super().send_marker(msg, repeat)
        if repeat:
            # A byte error in a length byte can leave the client's parser waiting for the rest of
            # a frame that the stopped line will never bring, with the marker inside it. Zeros
            # complete that frame (it fails its CRC) and start none: the repeat is then read.
            self._express.append(bytes(MAX_FRAME_BYTES))
        self._express.append(msg.pack(self._marker_mav))
        self._marker_mav.seq = (self._marker_mav.seq + 1) % 256

    def flush(self) -> None:
        if self.downlink is None:
            return super().flush()
        t_s = self.now_s()
        for peer in list(self.peers):
            for packet in peer.outbox:
                self._gate.accepted(self.downlink.offer(packet, t_s, whole=True))
            peer.outbox = []
            out = self._gate.release(self.downlink.take(t_s)) + b"".join(self._express)
            self._express = []
            if out:
                self._write(peer, out)

    def poll(self, fd: int) -> Iterator[tuple[object, _Peer]]:
        if self.uplink is None:
            yield from super().poll(fd)
            return
        peer = next((p for p in self.peers if p.fd == fd), None)
        data = self._read(peer) if peer is not None else b""
        t_s = self.now_s()
        for msg, _ in self._decode(peer, data) if data else ():
            if self.bypass is not None and self.bypass(msg):
                yield msg, peer
            else:
                self.uplink.offer(bytes(msg.get_msgbuf()), t_s, whole=True)
        yield from self.arrivals()

    def arrivals(self) -> Iterator[tuple[object, _Peer]]:
        if self.uplink is None or not self.peers:
            return
        data = self.uplink.take(self.now_s())
        if data:
            yield from self._decode(self.peers[0], data, self._line_parser)

    def line_stats(self) -> dict | None:
        if self.downlink is None or self.uplink is None:
            return None
        return {"downlink": self.downlink.stats.as_dict(), "uplink": self.uplink.stats.as_dict()}

    def close(self) -> None:
        super().close()
        os.close(self.slave_fd)


def open_endpoint(url: str) -> Endpoint:
    """Open one endpoint from a pymavlink-style connection string; raise EndpointError on failure."""
    scheme, sep, rest = url.partition(":")
    if not sep:
        raise EndpointError(f"endpoint {url!r}: expected udpin:, udpout:, tcpin: or tcp: followed by HOST:PORT")
    if scheme in ("udpin", "udp"):  # pymavlink's plain "udp:" listens too
        return UdpEndpoint(url, _host_port(url, rest), listen=True)
    if scheme == "udpout":
        return UdpEndpoint(url, _host_port(url, rest), listen=False)
    if scheme == "tcpin":
        return TcpListenEndpoint(url, _host_port(url, rest))
    if scheme == "tcp":
        return TcpConnectEndpoint(url, _host_port(url, rest))
    raise EndpointError(f"endpoint {url!r}: unknown scheme {scheme!r} (use udpin, udpout, tcpin or tcp)")


def close_all(endpoints: list[Endpoint]) -> None:
    for endpoint in endpoints:
        endpoint.close()

