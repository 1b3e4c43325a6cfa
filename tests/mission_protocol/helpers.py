"""Helpers for the mission-protocol tests (import as ``mission_protocol.helpers``): messages as they arrive from a given sender."""

from __future__ import annotations

import os
import select
import socket
import threading
import time

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mav  # noqa: E402

from rover_ctl.mavlink.gcs import GcsLink  # noqa: E402
from rover_ctl.mission.model import Home, Mission, MissionItem  # noqa: E402

HOME = Home(-35.363261, 149.165230, 584.0)
MAVPROXY = (255, 230)
MAVSDK = (245, 190)


def from_sender(msg, sender: tuple[int, int] = MAVPROXY):
    """``msg`` packed by ``sender`` and parsed back, as the service receives it."""
    tx = mav.MAVLink(None, srcSystem=sender[0], srcComponent=sender[1])
    rx = mav.MAVLink(None)
    return rx.decode(bytearray(msg.pack(tx)))


def sample_mission(n: int = 4) -> Mission:
    """``n`` waypoints north of CMAC home, one DO_CHANGE_SPEED, a fence and a rally point."""
    items = [MissionItem(16, x=HOME.lat_deg + 1e-4 * (i + 1), y=HOME.lon_deg + 5e-5 * i, z=0.0) for i in range(n)]
    items.insert(1, MissionItem(178, frame=2, param1=1.0, param2=1.5, param3=-1.0))
    fence = [MissionItem(5001, frame=0, param1=4.0, x=HOME.lat_deg + dy, y=HOME.lon_deg + dx)
             for dy, dx in ((-1e-3, -1e-3), (1e-3, -1e-3), (1e-3, 1e-3), (-1e-3, 1e-3))]  # fmt: skip
    rally = [MissionItem(5100, x=HOME.lat_deg, y=HOME.lon_deg + 2e-4, z=5.0)]
    return Mission(items=items, home=HOME, fence=fence, rally=rally)


class LinkThread:
    """A GcsLink polled by its own thread, which creates and owns the link's socket.

    ``with LinkThread(url, store=...) as lt:`` starts it and waits until it listens; ``lt.link``
    is the GcsLink (read its state from the test thread; do not send on it).
    """

    def __init__(self, url: str, **kwargs) -> None:
        self.url = url
        self.kwargs = kwargs
        self.link = None
        self._ready = threading.Event()
        self._stop = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="gcs-link", daemon=True)

    def _run(self) -> None:
        try:
            self.link = GcsLink(self.url, **self.kwargs)
            self._ready.set()
            conn = self.link.conn
            while not self._stop.is_set():
                self.link.poll(time.monotonic())
                # udp: the socket; tcpin: the accepted connection, or the listening socket before it
                sock = conn.port if isinstance(getattr(conn, "port", None), socket.socket) else conn.fd
                select.select([sock], [], [], POLL_WAIT_S)  # wakes on data, or for timeouts
        except BaseException as exc:  # surfaced by __enter__/__exit__
            self._error = exc
            self._ready.set()
        finally:
            if self.link is not None:
                self.link.close()

    def __enter__(self) -> "LinkThread":
        self._thread.start()
        assert self._ready.wait(5.0), "GcsLink did not start"
        if self._error:
            raise self._error
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(5.0)
        if self._error:
            raise self._error


POLL_WAIT_S = 0.01
"""Longest the link thread sleeps in select() between polls (heartbeat and retry timers)."""


def gcs(port: int, sender: tuple[int, int] = MAVPROXY):
    """A raw pymavlink ground station sending to the link's udpin port."""
    conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=sender[0], source_component=sender[1], dialect="ardupilotmega")
    conn.mav.WIRE_PROTOCOL_VERSION = "2.0"
    return conn


def expect(conn, kind: str, timeout_s: float = 3.0, **fields):
    """The next ``kind`` message whose fields match ``fields`` (fails the test after timeout_s)."""
    end = time.monotonic() + timeout_s
    while (left := end - time.monotonic()) > 0:
        msg = conn.recv_match(type=kind, blocking=True, timeout=left)
        if msg is not None and all(getattr(msg, k) == v for k, v in fields.items()):
            return msg
    raise AssertionError(f"no {kind} {fields or ''} within {timeout_s} s")
