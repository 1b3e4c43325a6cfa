"""Uploads through a lossy UDP proxy: the stored mission is the complete upload or unchanged."""

from __future__ import annotations

import random
import select
import socket
import threading
import time
from dataclasses import replace

from mission_protocol.helpers import MAVPROXY, LinkThread, expect, gcs, sample_mission
from pymavlink.dialects.v20 import ardupilotmega as mav
from support import free_port

from rover_ctl.config import GcsParams
from rover_ctl.mavlink.mission_client import MissionClient, MissionClientError
from rover_ctl.mission.model import Mission, MissionType
from rover_ctl.mavlink.mission import item_message, wire_items

LINK = GcsParams(mission_item_retry_s=0.05, mission_upload_timeout_s=1.0, heartbeat_period_s=0.2)
CLIENT = GcsParams(client_retry_s=0.05, client_retries=40, client_connect_timeout_s=3.0)
UPLOADS = 5


class LossyProxy:
    """Forwards UDP datagrams between a client and ``127.0.0.1:target_port``, misbehaving.

    Each datagram, either way, is dropped with probability ``p_drop``, else sent twice with
    ``p_dup``, else held back with ``p_hold`` and released after the next datagram in the same
    direction (reordered: counted as ``reordered``) or, when none comes within ``hold_s``, late
    (``delayed``). Seeded, so a failure can be replayed.
    """

    def __init__(self, target_port: int, seed: int, p_drop=0.2, p_dup=0.2, p_hold=0.2, hold_s=0.05) -> None:
        self.port = free_port()
        self.target = ("127.0.0.1", target_port)
        self.rng = random.Random(seed)
        self.p_drop, self.p_dup, self.p_hold, self.hold_s = p_drop, p_dup, p_hold, hold_s
        self.stats = {"forwarded": 0, "dropped": 0, "duplicated": 0, "reordered": 0, "delayed": 0}
        self._stop = threading.Event()
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._run, name="lossy-proxy", daemon=True)

    def __enter__(self) -> "LossyProxy":
        self._thread.start()
        assert self._ready.wait(5.0)
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(5.0)

    def _run(self) -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as front, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as back:
            front.bind(("127.0.0.1", self.port))
            back.bind(("127.0.0.1", 0))
            client = None
            held: dict[int, tuple[bytes, float]] = {}
            self._ready.set()
            while not self._stop.is_set():
                readable, _, _ = select.select([front, back], [], [], self.hold_s)
                now = time.monotonic()
                for sock in readable:
                    data, addr = sock.recvfrom(65535)
                    if sock is front:
                        client = addr
                        out, dest = back, self.target
                    elif client is None:
                        continue
                    else:
                        out, dest = front, client
                    self._forward(out, dest, data, held, now)
                for key, (data, since) in list(held.items()):
                    if now - since >= self.hold_s:
                        del held[key]
                        self.stats["delayed"] += 1
                        (back if key == 0 else front).sendto(data, self.target if key == 0 else client)

    def _forward(self, out, dest, data: bytes, held: dict, now: float) -> None:
        key = 0 if dest == self.target else 1
        roll = self.rng.random()
        if roll < self.p_drop:
            self.stats["dropped"] += 1
            return
        if roll < self.p_drop + self.p_hold and key not in held:
            held[key] = (data, now)
            return
        out.sendto(data, dest)
        self.stats["forwarded"] += 1
        if self.rng.random() < self.p_dup:
            out.sendto(data, dest)
            self.stats["duplicated"] += 1
        if key in held:  # release the held one after this newer datagram: reordered
            out.sendto(held.pop(key)[0], dest)
            self.stats["reordered"] += 1


def settled(lt: LinkThread, timeout_s: float = 5.0) -> None:
    """Wait until the link has no upload in progress (finished or timed out)."""
    end = time.monotonic() + timeout_s
    while lt.link.service.uploading:
        assert time.monotonic() < end, "upload never settled"
        time.sleep(0.01)


def same_items(a: list, b: list) -> bool:
    return len(a) == len(b) and all(x.same_as(y) for x, y in zip(a, b))


def variant(k: int) -> Mission:
    base = sample_mission(3 + k)
    return replace(base, items=[replace(i, z=float(k)) for i in base.items])


def test_uploads_through_20pct_loss_dup_reorder_are_all_or_nothing(udp_port):
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=LINK) as lt, LossyProxy(udp_port, seed=1) as proxy:
        previous = lt.link.service.mission
        successes = 0
        with MissionClient(f"udpout:127.0.0.1:{proxy.port}", CLIENT) as client:
            client.connect()
            for k in range(UPLOADS):
                new = variant(k)
                try:
                    client.upload(new)
                    ok = True
                except MissionClientError:
                    ok = False
                settled(lt)
                stored = lt.link.service.mission
                if ok:
                    successes += 1
                    assert stored.same_as(new), f"upload {k} acknowledged but stored mission differs"
                else:  # each part (mission, fence, rally) is its own atomic upload
                    for kind in MissionType:
                        part = stored.of_type(kind)
                        assert same_items(part, new.of_type(kind)) or same_items(part, previous.of_type(kind))
                previous = stored
            assert client.download().same_as(stored)  # the download path through the same proxy
    print(f"{successes}/{UPLOADS} uploads acknowledged through the proxy: {proxy.stats}")
    assert successes >= UPLOADS - 1, proxy.stats
    # Real reorders need the next datagram within hold_s (19 of 72 holds here): fewer on a loaded machine.
    assert min(proxy.stats["dropped"], proxy.stats["duplicated"]) > 10 and proxy.stats["reordered"] > 5, proxy.stats


def test_an_abandoned_upload_times_out_and_keeps_the_stored_mission(udp_port, mission):
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=LINK) as lt:
        lt.link.service.mission = mission
        conn = gcs(udp_port, MAVPROXY)
        other = sample_mission(9)
        wire = wire_items(other, MissionType.MISSION)
        conn.mav.mission_count_send(1, 1, len(wire), 0)
        for seq in range(3):
            expect(conn, "MISSION_REQUEST_INT", seq=seq)
            conn.mav.send(item_message(wire[seq], seq, 0, (1, 1)))
        expect(conn, "MISSION_REQUEST_INT", seq=3)  # re-requested every retry period, then given up
        ack = expect(conn, "MISSION_ACK", timeout_s=LINK.mission_upload_timeout_s + 2.0)
        assert ack.type == mav.MAV_MISSION_OPERATION_CANCELLED
        assert lt.link.service.mission is mission


TIME_SCALE = 0.1
"""The protocol's timeouts (1500 ms, 250 ms item, 5 retries: GcsParams' defaults) run 10x faster
here so that 30 lossy uploads take seconds; the ratios between them are the real ones."""
DEFAULTS = GcsParams()
SCALED_LINK = GcsParams(
    mission_item_retry_s=DEFAULTS.mission_item_retry_s * TIME_SCALE,
    mission_upload_timeout_s=DEFAULTS.mission_upload_timeout_s * TIME_SCALE,
    heartbeat_period_s=0.2,
)
SCALED_CLIENT = GcsParams(
    client_retry_s=DEFAULTS.client_retry_s * TIME_SCALE,
    client_item_retry_s=DEFAULTS.client_item_retry_s * TIME_SCALE,
    client_connect_timeout_s=3.0,
)


def sixty_items(k: int) -> Mission:
    """A 60-item mission (59 waypoints after home... plus speed), different for every k."""
    base = sample_mission(58)
    return Mission(items=[replace(i, z=float(k)) for i in base.items], home=base.home)


def test_protocol_timeouts_are_the_specs():
    # mavlink.io services/mission, "Timeouts and Retries": 1500 ms default, 250 ms items, 5 retries
    assert (DEFAULTS.client_retry_s, DEFAULTS.client_item_retry_s, DEFAULTS.client_retries) == (1.5, 0.25, 5)
    assert (DEFAULTS.mission_item_retry_s, DEFAULTS.mission_upload_timeout_s) == (0.25, 1.5)


def test_30_uploads_of_60_items_through_loss_duplication_and_reordering_are_never_partial(udp_port):
    outcomes = {"stored": 0, "refused": 0, "unknown": 0}
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=SCALED_LINK) as lt, LossyProxy(
        udp_port, seed=30, p_drop=0.2, p_dup=0.1, p_hold=0.2, hold_s=0.02
    ) as proxy:
        previous = lt.link.service.mission
        with MissionClient(f"udpout:127.0.0.1:{proxy.port}", SCALED_CLIENT) as client:
            client.connect()
            for k in range(30):
                new = sixty_items(k)
                assert len(wire_items(new, MissionType.MISSION)) == 60
                try:
                    client.upload(new)
                    error = None
                except MissionClientError as exc:
                    error = exc
                settled(lt)
                stored = lt.link.service.mission
                if error is None:
                    outcomes["stored"] += 1
                    assert stored.same_as(new), f"upload {k} acknowledged but the stored mission differs"
                elif error.maybe_stored:
                    outcomes["unknown"] += 1
                    assert stored.same_as(new) or stored.same_as(previous), f"upload {k}: partial ({error})"
                else:
                    outcomes["refused"] += 1
                    assert stored.same_as(previous), f"upload {k} refused ({error}) but the stored mission changed"
                previous = stored
    print(f"30 uploads of 60 items: {outcomes}; proxy {proxy.stats}")
    assert outcomes["stored"] >= 20, (outcomes, proxy.stats)  # the retries do carry most uploads through
    assert min(proxy.stats["dropped"], proxy.stats["duplicated"], proxy.stats["reordered"]) > 100, proxy.stats


def test_a_late_request_and_ack_of_the_previous_upload_do_not_end_the_next_one(udp_port):
    """The race the lossy run found: the previous upload's last request (held back by the network)
    and its repeated ACK reach the client at the start of the next upload."""
    vehicle = gcs(udp_port, (1, 1))  # plays the vehicle on a udpout socket; the client listens
    new = sixty_items(1)
    with MissionClient(f"udpin:127.0.0.1:{udp_port}", SCALED_CLIENT) as client:
        client.target = (1, 1)
        vehicle.mav.heartbeat_send(mav.MAV_TYPE_GROUND_ROVER, mav.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0)
        client.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=2)
        last = len(wire_items(new, MissionType.MISSION)) - 1
        vehicle.mav.mission_request_int_send(255, 190, last, 0)  # the earlier upload's last request
        vehicle.mav.mission_ack_send(255, 190, mav.MAV_MISSION_ACCEPTED, 0)  # its repeated ACK
        try:
            client.upload_items(MissionType.MISSION, wire_items(new, MissionType.MISSION))
            ended = "acknowledged"
        except MissionClientError:
            ended = "timed out"
    vehicle.close()
    assert ended == "timed out"  # this vehicle never asked for items 0..58: nothing was stored
