"""MAVLink 2 signing on a GcsLink over a real loopback socket: what gets through, what the link
sends, replays and forgeries, SETUP_SIGNING, the key file and the timestamp across restarts."""

from __future__ import annotations

import hashlib
import os
import socket
import time

import pytest
from mission_protocol.helpers import LinkThread, gcs

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mav  # noqa: E402

from rover_ctl.config import GcsParams  # noqa: E402
from rover_ctl.mavlink.gcs import DefaultHandlers, GcsLink  # noqa: E402
from rover_ctl.mavlink.signing import (  # noqa: E402
    TICKS_PER_S,
    KeyStore,
    SigningError,
    clock_ticks,
    key_from_passphrase,
    setup_client_signing,
)
from rover_ctl.vocabulary import RoverMode  # noqa: E402

KEY = key_from_passphrase("correct horse")
OTHER = key_from_passphrase("battery staple")
LINK = GcsParams(heartbeat_period_s=0.2)
WAIT_S = 3.0


def wait_until(predicate, timeout_s: float = WAIT_S) -> bool:
    """Poll a condition the link thread changes (bounded)."""
    end = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > end:
            return False
        time.sleep(0.01)
    return True


def client(port: int, key: bytes | None = None, sender=(255, 190)):
    conn = gcs(port, sender)
    if key is not None:
        setup_client_signing(conn, key)
    return conn


def arm(conn, value: int = 1) -> None:
    conn.mav.command_long_send(1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, value, 0, 0, 0, 0, 0, 0)


def ack(conn, command: int = mav.MAV_CMD_COMPONENT_ARM_DISARM) -> int | None:
    end = time.monotonic() + WAIT_S
    while time.monotonic() < end:
        msg = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=0.1)
        if msg is not None and msg.command == command:
            return msg.result
    return None


@pytest.fixture
def store(tmp_path) -> KeyStore:
    keys = KeyStore(tmp_path / "signing.key")
    keys.save_key(KEY)
    return keys


def test_unsigned_and_wrongly_signed_frames_change_nothing(store, udp_port):
    handlers = DefaultHandlers()
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=LINK, handlers=handlers, signing=store) as lt:
        stranger, impostor, owner = client(udp_port), client(udp_port, OTHER), client(udp_port, KEY)
        for conn in (stranger, impostor):
            arm(conn)
            conn.mav.command_long_send(1, 1, mav.MAV_CMD_DO_SET_MODE, 0, 1, RoverMode.AUTO, 0, 0, 0, 0, 0)
            conn.mav.set_mode_send(1, 1, RoverMode.AUTO)
            conn.mav.mission_clear_all_send(1, 1, mav.MAV_MISSION_TYPE_ALL)
        assert wait_until(lambda: lt.link.signing.rejected == 8)
        assert not handlers.armed and handlers.custom_mode == RoverMode.HOLD
        arm(owner)
        assert ack(owner) == mav.MAV_RESULT_ACCEPTED and handlers.armed
        for conn in (stranger, impostor, owner):
            conn.close()


def test_everything_the_link_sends_is_signed_with_the_key(store, udp_port):
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=LINK, signing=store):
        owner = client(udp_port, KEY)
        owner.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        seen = []
        end = time.monotonic() + WAIT_S
        while len(seen) < 3 and time.monotonic() < end:
            msg = owner.recv_match(blocking=True, timeout=0.1)
            if msg is not None and msg.get_type() != "BAD_DATA":
                seen.append(msg)
        owner.close()
    assert len(seen) == 3
    for msg in seen:
        buf = bytes(msg.get_msgbuf())
        assert msg.get_signed() and hashlib.sha256(KEY + buf[:-6]).digest()[:6] == buf[-6:]


def _signed_frame(message, key: bytes, timestamp: int, link_id: int = 0, sender=(255, 190)) -> bytes:
    packer = mav.MAVLink(None, srcSystem=sender[0], srcComponent=sender[1])
    packer.signing.secret_key, packer.signing.sign_outgoing = key, True
    packer.signing.link_id, packer.signing.timestamp = link_id, timestamp
    return bytes(message.pack(packer))


def test_a_replayed_frame_is_dropped(store, udp_port):
    handlers = DefaultHandlers()
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=LINK, handlers=handlers, signing=store) as lt:
        raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        now = clock_ticks()
        arm_msg = mav.MAVLink_command_long_message(1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        disarm_msg = mav.MAVLink_command_long_message(1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 0, 0, 0, 0, 0, 0)
        recorded = _signed_frame(arm_msg, KEY, now)
        raw.sendto(recorded, ("127.0.0.1", udp_port))
        assert wait_until(lambda: handlers.armed)
        raw.sendto(_signed_frame(disarm_msg, KEY, now + 10), ("127.0.0.1", udp_port))
        assert wait_until(lambda: not handlers.armed)
        raw.sendto(recorded, ("127.0.0.1", udp_port))  # the recording again: its timestamp is old
        assert wait_until(lambda: lt.link.signing.rejected == 1)
        assert not handlers.armed
        raw.close()


def test_a_forged_far_future_timestamp_does_not_lock_out_the_ground_station(store, udp_port):
    """pymavlink's own check records the timestamp before the signature: one such frame would make
    every later genuine frame of that stream "old". The link checks the signature first."""
    handlers = DefaultHandlers()
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=LINK, handlers=handlers, signing=store) as lt:
        raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        forged = bytearray(_signed_frame(mav.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3), OTHER, 2**48 - 2))
        raw.sendto(bytes(forged), ("127.0.0.1", udp_port))
        assert wait_until(lambda: lt.link.signing.rejected == 1)
        arm_msg = mav.MAVLink_command_long_message(1, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        raw.sendto(_signed_frame(arm_msg, KEY, clock_ticks()), ("127.0.0.1", udp_port))
        assert wait_until(lambda: handlers.armed)
        raw.close()


def test_radio_status_is_the_only_unsigned_frame_accepted(store, udp_port):
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=LINK, signing=store) as lt:
        radio = client(udp_port, sender=(51, 68))  # a SiK radio cannot sign
        radio.mav.radio_status_send(200, 190, 100, 40, 38, 0, 0)
        radio.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        assert wait_until(lambda: lt.link.signing.rejected == 1)  # the heartbeat, sent after the RADIO_STATUS
        assert lt.link.last_gcs_heartbeat_s is None
        radio.close()


def _setup_signing(conn, key: bytes) -> None:
    conn.mav.setup_signing_send(1, 1, list(key), clock_ticks())


def test_setup_signing_from_a_stranger_is_refused(store, udp_port):
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=LINK, signing=store) as lt:
        stranger = client(udp_port)
        _setup_signing(stranger, OTHER)
        assert wait_until(lambda: lt.link.signing.rejected == 1)
        stranger.close()
    assert store.load_key() == KEY


def test_a_key_holder_replaces_the_key(store, udp_port):
    handlers = DefaultHandlers()
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=LINK, handlers=handlers, signing=store) as lt:
        owner = client(udp_port, KEY)
        _setup_signing(owner, OTHER)
        assert wait_until(lambda: store.load_key() == OTHER)
        arm(owner)  # the old key no longer works
        assert wait_until(lambda: lt.link.signing.rejected == 1) and not handlers.armed
        owner.close()
        rotated = client(udp_port, OTHER)
        arm(rotated)
        assert ack(rotated) == mav.MAV_RESULT_ACCEPTED and handlers.armed
        rotated.close()


def test_without_a_key_setup_signing_needs_loopback_and_the_option(tmp_path, udp_port):
    keys = KeyStore(tmp_path / "signing.key")
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=LINK, signing=keys) as lt:
        conn = client(udp_port)
        _setup_signing(conn, KEY)
        arm(conn)  # processed after SETUP_SIGNING: proves it was seen and refused
        assert ack(conn) == mav.MAV_RESULT_ACCEPTED
        assert not lt.link.signing.enabled and keys.load_key() is None
        conn.close()
    params = GcsParams(heartbeat_period_s=0.2, signing_setup_from_loopback=True)
    handlers = DefaultHandlers()
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=params, handlers=handlers, signing=keys) as lt:
        conn = client(udp_port)
        _setup_signing(conn, KEY)
        assert wait_until(lambda: keys.load_key() == KEY)
        arm(conn)  # unsigned, now refused
        assert wait_until(lambda: lt.link.signing.rejected == 1) and not handlers.armed
        conn.close()


def test_switching_signing_off_keeps_it_on_when_the_key_file_cannot_be_removed(store, udp_port):
    """The key file replaced by something else while running: removing it is refused (it is not a
    key), which escaped the link's handler unannounced; signing stays on and the GCS is told."""
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=LINK, signing=store) as lt:
        store.key_path.write_text("not a key\n")
        owner = client(udp_port, KEY)
        owner.mav.setup_signing_send(1, 1, [0] * 32, 0)
        text = owner.recv_match(type="STATUSTEXT", blocking=True, timeout=WAIT_S)
        assert text is not None and text.text.startswith("Signing not disabled")
        assert lt.link.signing.enabled and store.key_path.read_text() == "not a key\n"
        assert not lt.link.inbound.failures
        owner.close()


def test_required_signing_cannot_be_switched_off(store, udp_port):
    params = GcsParams(heartbeat_period_s=0.2, require_signing=True)
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=params, signing=store) as lt:
        owner = client(udp_port, KEY)
        owner.mav.setup_signing_send(1, 1, [0] * 32, 0)
        arm(owner)
        assert ack(owner) == mav.MAV_RESULT_ACCEPTED
        assert lt.link.signing.enabled and store.load_key() == KEY
        owner.close()
    with pytest.raises(SigningError, match="no signing key"):
        GcsLink(f"udpin:127.0.0.1:{udp_port}", params, signing=KeyStore(store.key_path.with_name("none.key")))


def test_the_timestamp_never_goes_backwards_across_restarts(store, udp_port, monkeypatch):
    url = f"udpin:127.0.0.1:{udp_port}"
    future = clock_ticks() + 3600 * TICKS_PER_S  # e.g. the clock was right last run, wrong now
    store.save_timestamp(future)
    link = GcsLink(url, LINK, signing=store)
    margin = int(LINK.signing_timestamp_save_s * TICKS_PER_S)
    first = link.conn.mav.signing.timestamp
    assert first >= future + margin
    link.send_heartbeat()
    link.close()
    saved = store.load_timestamp()
    assert saved > first
    monkeypatch.setattr(time, "time", lambda: 1420070400.0 + 10.0)  # a Pi without RTC: 2015
    link = GcsLink(url, LINK, signing=store)
    assert link.conn.mav.signing.timestamp >= saved + margin
    link.close()


def test_the_key_file(tmp_path):
    keys = KeyStore(tmp_path / "state" / "signing.key")
    assert keys.load_key() is None
    keys.save_key(KEY)
    assert keys.load_key() == KEY
    assert keys.key_path.stat().st_mode & 0o777 == 0o600
    assert sorted(p.name for p in keys.key_path.parent.iterdir()) == ["signing.key"]  # no temp file left
    os.chmod(keys.key_path, 0o644)
    with pytest.raises(SigningError, match="readable by others"):
        keys.load_key()
    keys.key_path.write_text("not hex\n")
    os.chmod(keys.key_path, 0o600)
    with pytest.raises(SigningError, match="not a signing key"):
        keys.load_key()


def test_the_key_is_made_as_mavproxy_makes_it():
    signing = pytest.importorskip("MAVProxy.modules.mavproxy_signing")
    assert key_from_passphrase("correct horse") == signing.SigningModule.passphrase_to_key(None, "correct horse")
    assert len(KEY) == 32
