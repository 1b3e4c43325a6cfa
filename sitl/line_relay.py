"""``python -m sitl.line_relay``: ArduPilot's SITL firmware behind a serial line, served on a pty.

    python -m sitl.line_relay --udpin 127.0.0.1:PORT --baud 57600 [--byte-error P] [--speedup S]
                              [--buffer-bytes N] [--seed N] [--stats FILE]

It listens on loopback UDP for the firmware's ``--serial0 udpclient:127.0.0.1:PORT``, opens a
pseudo-terminal, prints ``PTY /dev/pts/N`` and then ``line-relay: ready (...)``, and relays both
ways through the serial line model (``sitl/line.py``): firmware -> pty is the downlink, pty ->
firmware the uplink, each with its own buffer, byte errors and counters. The line runs in the
firmware's time: the boot time its messages carry (``time_boot_ms`` of ATTITUDE, SYSTEM_TIME,
DISTANCE_SENSOR, ...); only after ``STAMP_STALE_S`` of wall time without one does it run on wall
time x ``--speedup``. A firmware that falls behind its speed-up on a loaded machine, then catches
up in a burst, so gets the line it would have had in its own time, not a wall-clock line that a
catch-up burst would overflow; before its first timestamp, wall time x ``--speedup``.
SIGTERM or SIGINT stops it; it then prints the counters and writes them to ``--stats`` as JSON.

One thread, one ``select``: the timeout is when the next byte leaves either line, but never less
than ``TICK_S`` of wall time (a UART driver also hands bytes over in small bursts), so a fast line
costs at most 1 / TICK_S wake-ups a second, not one per byte.
"""

from __future__ import annotations

import argparse
import ipaddress
import json
import math
import os
import select
import signal
import socket
import sys
import time
import tty
from pathlib import Path

from sitl.endpoints import _parser
from sitl.line import DEFAULT_BUFFER_BYTES, SerialLine, check_line

PROG = "line-relay"
READY_PREFIX = f"{PROG}: ready"
TICK_S = 0.002
"""Shortest wall-clock wait between deliveries (bytes due meanwhile go together)."""
IDLE_WAIT_S = 1.0
"""Wall-clock wait when both lines are empty (a signal or a datagram wakes it sooner)."""
STAMP_STALE_S = 1.0
"""Wall seconds without a timestamp from the firmware after which the line runs on the wall clock
(x speedup) again: a firmware sending only untimed messages (heartbeats)."""
READ_SIZE_BYTES = 65536
MAX_DATAGRAM_BYTES = 1400
"""Uplink bytes are sent to the firmware in datagrams of at most this size."""
PTY_BACKLOG_MAX_BYTES = 65536
"""Delivered bytes the pty's reader has not taken yet; beyond this they are lost (``pty_overrun``),
as a serial port's receive buffer overruns when nobody reads it."""
DOWNLINK_SEED_SALT = 0x444F574E
UPLINK_SEED_SALT = 0x55504C4B
"""Mixed into --seed: one byte-error stream per direction (the values rover-sitl uses)."""


class UsageError(Exception):
    """A bad flag or value: one line, exit 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):
        raise UsageError(message)


def _number(kind, check):
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not check(value):
            raise argparse.ArgumentTypeError(f"{text!r} is out of range")
        return value
    return parse


def _loopback(text: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit() or not 0 < int(port) < 65536:
        raise argparse.ArgumentTypeError(f"expected 127.0.0.1:PORT, got {text!r}")
    try:
        loopback = ipaddress.ip_address(host).is_loopback and ipaddress.ip_address(host).version == 4
    except ValueError:
        loopback = False
    if not loopback:
        raise argparse.ArgumentTypeError(f"{host!r}: the relay listens on IPv4 loopback only (127.0.0.1)")
    return host, int(port)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="python -m sitl.line_relay", description="Serve ArduPilot SITL's serial0 on a pty through a serial line model.")
    parser.add_argument("--udpin", type=_loopback, required=True, metavar="127.0.0.1:PORT",
                        help="where the firmware's --serial0 udpclient:127.0.0.1:PORT sends")
    parser.add_argument("--baud", type=_number(float, lambda v: math.isfinite(v) and v > 0), required=True, metavar="N",
                        help="line rate, 8N1: N/10 bytes per second of vehicle time each way")
    parser.add_argument("--byte-error", type=_number(float, lambda v: 0 <= v < 1), default=0.0, metavar="P",
                        help="probability that a byte arrives changed (default 0)")
    parser.add_argument("--speedup", type=_number(float, lambda v: math.isfinite(v) and v > 0), default=1.0, metavar="S",
                        help="the firmware's --speedup: line time = wall time x S (default 1)")
    parser.add_argument("--buffer-bytes", type=_number(int, lambda v: v >= 1), default=DEFAULT_BUFFER_BYTES, metavar="N",
                        help=f"bytes buffered each way before the line drops (default {DEFAULT_BUFFER_BYTES}, a SiK radio)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the byte errors (default 1)")
    parser.add_argument("--stats", type=Path, metavar="FILE", help="write the counters as JSON at exit")
    return parser


class Relay:
    """The UDP socket, the pty and the two lines."""

    def __init__(self, args) -> None:
        self.args = args
        self.downlink = SerialLine(args.baud, args.byte_error, args.buffer_bytes, args.seed ^ DOWNLINK_SEED_SALT)
        self.uplink = SerialLine(args.baud, args.byte_error, args.buffer_bytes, args.seed ^ UPLINK_SEED_SALT)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind(args.udpin)
        except OSError as exc:
            self.sock.close()
            raise UsageError(f"--udpin {args.udpin[0]}:{args.udpin[1]}: {exc.strerror or exc}") from None
        self.sock.setblocking(False)
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)  # no echo, no line editing, before any client opens it
        os.set_blocking(self.master, False)
        self.device = os.ttyname(self.slave)
        self.firmware: tuple[str, int] | None = None
        """Where the firmware sends from (learnt from its first datagram)."""
        self.backlog = b""
        self.pty_overrun = 0
        self.no_firmware = 0
        """Uplink bytes delivered before the firmware was first heard from (lost)."""
        self.stop = False
        self.wake_r, self.wake_w = os.pipe()
        os.set_blocking(self.wake_w, False)
        self.wall0 = time.monotonic()
        self._stamps = _parser()
        self._stamp: tuple[float, float] | None = None
        """(the firmware's latest boot time in seconds, the wall time it arrived)."""
        self._now_s = 0.0
        self._offset_s = 0.0
        """Line time minus the firmware's boot time, fixed at its first timestamp (no jump then)."""

    def now_s(self) -> float:
        """The line's time in the firmware's seconds (module doc); never goes back."""
        wall = time.monotonic()
        if self._stamp is None:
            now = (wall - self.wall0) * self.args.speedup
        else:
            vehicle_s, at = self._stamp
            # The firmware's clock alone moves the line; only a firmware silent on time for
            # STAMP_STALE_S gets the wall-clock line (heartbeats still have to cross it).
            stale_s = wall - at - STAMP_STALE_S
            now = self._offset_s + vehicle_s + (stale_s * self.args.speedup if stale_s > 0 else 0.0)
        self._now_s = max(self._now_s, now)
        return self._now_s

    def _note_time(self, data: bytes) -> None:
        """The newest ``time_boot_ms`` in a datagram from the firmware (whole frames)."""
        try:
            frames = self._stamps.parse_buffer(data) or []
        except Exception:  # not MAVLink after all: the clock just does not move
            return
        stamps = [f.time_boot_ms for f in frames if hasattr(f, "time_boot_ms")]
        if stamps:
            vehicle_s = max(stamps) / 1000.0
            wall = time.monotonic()
            if self._stamp is None or wall - self._stamp[1] >= STAMP_STALE_S or vehicle_s < self._stamp[0] - STAMP_STALE_S:
                # (Back) on the firmware's clock, or a rebooted one's, without a jump.
                self._offset_s = self.now_s() - vehicle_s
                self._stamp = (vehicle_s, wall)
            if self._stamp is None or vehicle_s > self._stamp[0]:
                self._stamp = (vehicle_s, wall)

    def install_signals(self) -> None:
        signal.set_wakeup_fd(self.wake_w)
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, self._on_signal)

    def _on_signal(self, signum, frame) -> None:
        self.stop = True

    def run(self) -> None:
        while not self.stop:
            now = self.now_s()
            self._to_pty(self.downlink.take(now))
            self._to_firmware(self.uplink.take(now))
            due = [t for t in (self.downlink.next_departure_s(), self.uplink.next_departure_s()) if t is not None]
            wait_s = max(TICK_S, (min(due) - now) / self.args.speedup) if due else IDLE_WAIT_S
            try:
                readable, writable, _ = select.select([self.sock, self.master, self.wake_r],
                                                      [self.master] if self.backlog else [], [], min(wait_s, IDLE_WAIT_S))  # fmt: skip
            except InterruptedError:
                continue
            if self.wake_r in readable:
                os.read(self.wake_r, 512)
            if self.sock in readable:
                self._from_firmware()
            if self.master in readable:
                self._from_pty()
            if writable:
                self._to_pty(b"")

    def _from_firmware(self) -> None:
        while True:
            try:
                data, address = self.sock.recvfrom(READ_SIZE_BYTES)
            except (BlockingIOError, ConnectionRefusedError):
                return
            self.firmware = address
            self._note_time(data)  # first: a catch-up burst is offered at its own time
            self.downlink.offer(data, self.now_s())

    def _from_pty(self) -> None:
        try:
            data = os.read(self.master, READ_SIZE_BYTES)
        except (BlockingIOError, OSError):
            return
        if data:
            self.uplink.offer(data, self.now_s())

    def _to_pty(self, data: bytes) -> None:
        data = self.backlog + data
        if not data:
            return
        try:
            sent = os.write(self.master, data)
        except (BlockingIOError, OSError):
            sent = 0
        rest = data[sent:]
        if len(rest) > PTY_BACKLOG_MAX_BYTES:
            self.pty_overrun += len(rest) - PTY_BACKLOG_MAX_BYTES
            rest = rest[-PTY_BACKLOG_MAX_BYTES:]
        self.backlog = rest

    def _to_firmware(self, data: bytes) -> None:
        if self.firmware is None:  # no far end yet: what the line carried is lost
            self.no_firmware += len(data)
            return
        for start in range(0, len(data), MAX_DATAGRAM_BYTES):
            try:
                self.sock.sendto(data[start:start + MAX_DATAGRAM_BYTES], self.firmware)
            except OSError:
                return  # the firmware went away; datagrams are best effort

    def stats(self) -> dict:
        a = self.args
        return {"baud": a.baud, "byte_error": a.byte_error, "buffer_bytes": a.buffer_bytes, "speedup": a.speedup,
                "vehicle_s": self.now_s(), "pty_overrun": self.pty_overrun, "no_firmware": self.no_firmware,
                "downlink": self.downlink.stats.as_dict(), "uplink": self.uplink.stats.as_dict()}  # fmt: skip

    def close(self) -> None:
        for fd in (self.master, self.slave, self.wake_r, self.wake_w):
            os.close(fd)
        self.sock.close()


def write_stats(path: Path, stats: dict) -> None:
    try:
        path.write_text(json.dumps(stats) + "\n")
    except OSError as exc:
        raise UsageError(f"--stats {path}: {exc.strerror or exc}") from None


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(sys.argv[1:] if argv is None else argv)
        check_line(args.baud, args.byte_error, args.buffer_bytes)
        relay = Relay(args)
    except (UsageError, ValueError) as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    try:
        if args.stats:
            write_stats(args.stats, relay.stats())  # an unwritable file fails now, not at exit
    except UsageError as exc:
        relay.close()
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    relay.install_signals()
    print(f"PTY {relay.device}", flush=True)
    host, port = args.udpin
    print(f"{READY_PREFIX} (udpin {host}:{port}, {args.baud:g} baud, byte error {args.byte_error:g}, "
          f"speedup {args.speedup:g})", flush=True)  # fmt: skip
    try:
        relay.run()
    finally:
        stats = relay.stats()
        relay.close()
    down, up = stats["downlink"], stats["uplink"]
    print(f"{PROG}: stopped at vehicle t={stats['vehicle_s']:.2f} s; " + "; ".join(
        f"{name} offered {s['offered']} delivered {s['delivered']} dropped {s['dropped_overflow']} corrupted {s['corrupted']}"
        for name, s in (("downlink", down), ("uplink", up))) + f"; pty overrun {stats['pty_overrun']}", flush=True)  # fmt: skip
    if args.stats:
        try:
            write_stats(args.stats, stats)
        except UsageError as exc:
            print(f"{PROG}: error: {exc}", file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
