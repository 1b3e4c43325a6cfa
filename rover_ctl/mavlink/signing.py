"""MAVLink 2 message signing on the GCS link, as ArduPilot does it (docs/gcs.md, "Signing").

* The secret key is 32 bytes, kept in the state directory (``GcsParams.signing_key_path``, 64 hex
  digits, mode 0600, written atomically). ``rover-ctl signing setup PASSPHRASE`` makes it the
  SHA-256 of the passphrase, as MAVProxy's ``signing setup`` and QGroundControl's signing key
  field do, so the same passphrase works in all three.
* The timestamp (10 us units since 2015-01-01) never goes backwards across restarts: it is saved
  beside the key every ``signing_timestamp_save_s`` and on close, and a start takes the larger
  of the clock and the saved value plus that period (a crash may have lost up to one period).
* With a key every frame must carry a good signature; unsigned or wrongly signed frames are
  dropped before any handler sees them, except RADIO_STATUS and RADIO, which SiK radios inject
  and cannot sign (ArduPilot's accept list). ArduPilot does the same once a key is set, so the key
  alone enforces; ``require_signing`` additionally refuses to run without a key and refuses a
  SETUP_SIGNING that would turn signing off. Everything the daemon sends is signed.
* SETUP_SIGNING (a new key) is accepted only from a holder of the current key (the frame got
  through the signature check), or, while no key is set, only when ``signing_setup_from_loopback``
  is on and the GCS link is loopback-only (bound to 127.0.0.1 or ::1, or a TCP connection to
  it). A stranger can neither set nor replace the key.

pymavlink's own ``check_signature`` records a frame's timestamp before comparing its signature,
so one forged frame with a far-future timestamp would lock a genuine ground station out of its
stream; ``check_signature`` here verifies the signature first, as the MAVLink C library does.
"""

from __future__ import annotations

import hashlib
import hmac
import ipaddress
import logging
import os
import socket
import time
from pathlib import Path
from typing import Callable

from pymavlink.dialects.v20.ardupilotmega import MAVLinkSigning

from rover_ctl.config import GcsParams
from rover_ctl.inputfile import FileTooLarge, read_text
from rover_ctl.vocabulary import Severity, mav

log = logging.getLogger(__name__)

KEY_BYTES = 32
_NOT_A_KEY = object()
"""``KeyStore._read_key``'s answer for a file that holds something else."""
KEY_FILE_MAX_BYTES = 4096
"""A key file is 65 bytes (64 hex digits and a newline); more is not one. Reads stop here, so a
device or a huge file given as the key file cannot stall a command."""
EPOCH_2015_UNIX_S = 1420070400
"""MAVLink signing timestamps count from 2015-01-01 00:00 UTC."""
TICKS_PER_S = 100_000
"""Signing timestamp units: 10 us."""
NEW_STREAM_MAX_AGE_TICKS = 60 * TICKS_PER_S
"""A stream not seen before is accepted only if its timestamp is at most one minute behind ours
(the MAVLink C library's rule; it stops replays of recordings older than that)."""
MAX_STREAMS = 16
"""MAVLINK_MAX_SIGNING_STREAMS of the C library: (link id, system, component) tuples tracked."""
UNSIGNED_ALLOWED = frozenset({mav.MAVLINK_MSG_ID_RADIO_STATUS, mav.MAVLINK_MSG_ID_RADIO})
"""Accepted without a signature: telemetry radios insert these and cannot sign."""
LINK_ID = 0
"""Our signing link id: the daemon has one GCS channel (ArduPilot uses the channel number)."""


class SigningError(ValueError):
    """A key file or passphrase that cannot be used; the message is one line and names the file."""


def key_from_passphrase(passphrase: str) -> bytes:
    """SHA-256 of the passphrase, as MAVProxy's ``signing setup`` and QGroundControl make it
    (MAVProxy encodes ASCII; UTF-8 is the same for an ASCII passphrase)."""
    if not passphrase:
        raise SigningError("signing passphrase: must not be empty")
    try:
        encoded = passphrase.encode("utf-8")
    except UnicodeEncodeError:  # bytes from the command line that are not UTF-8 (surrogate escapes)
        raise SigningError("signing passphrase: not valid UTF-8 text (a ground station could not type it)") from None
    return hashlib.sha256(encoded).digest()


def clock_ticks(unix_s: float | None = None) -> int:
    """The wall clock as a signing timestamp (0 before 2015: a Pi without RTC or NTP yet)."""
    now = time.time() if unix_s is None else unix_s
    return int(max(now - EPOCH_2015_UNIX_S, 0.0) * TICKS_PER_S)


def _write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` so that a crash leaves the old or the new content, mode 0600."""
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        try:
            os.fchmod(fd, 0o600)
            os.write(fd, text.encode("ascii"))
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException:  # a key must not stay behind in a stray file (path is a folder, the disk is full)
        tmp.unlink(missing_ok=True)
        raise
    dir_fd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)


class KeyStore:
    """The key file and its timestamp file (``<key file>.timestamp``)."""

    def __init__(self, key_path: str | Path) -> None:
        self.key_path = Path(key_path).expanduser()
        self.timestamp_path = self.key_path.with_name(self.key_path.name + ".timestamp")

    def load_key(self) -> bytes | None:
        """The key, or None if there is no key file. A damaged file is an error, never "no key":
        that would silently turn authentication off."""
        key = self._read_key()
        if key is None:
            return None
        if key is _NOT_A_KEY:
            raise SigningError(f"{self.key_path}: not a signing key (expected {2 * KEY_BYTES} hex digits)")
        mode = self.key_path.stat().st_mode & 0o777
        if mode & 0o077:
            raise SigningError(f"{self.key_path}: signing key readable by others (mode {mode:o}); chmod 600 it")
        return key

    def _read_key(self) -> bytes | object | None:
        """The key file's key; None if there is no file, _NOT_A_KEY if it holds something else."""
        try:
            text = read_text(self.key_path, KEY_FILE_MAX_BYTES, encoding="ascii")
        except FileNotFoundError:
            return None
        except (FileTooLarge, UnicodeDecodeError):
            return _NOT_A_KEY
        except OSError as exc:
            raise SigningError(f"{self.key_path}: cannot read signing key: {exc}") from None
        try:
            key = bytes.fromhex(text.strip())
        except ValueError:
            return _NOT_A_KEY
        return key if len(key) == KEY_BYTES else _NOT_A_KEY

    def _refuse_unless_key(self, doing: str) -> bool:
        """False if there is no file; raises if the path holds anything but a signing key (a
        mission, a config given by mistake): it is not ours to overwrite or delete."""
        if not self.key_path.exists() and not self.key_path.is_symlink():
            return False
        if self.key_path.is_dir():
            raise SigningError(f"{self.key_path}: is a directory, not a signing key")
        if self._read_key() is _NOT_A_KEY:
            raise SigningError(f"{self.key_path}: exists and is not a signing key ({2 * KEY_BYTES} hex digits): refusing to {doing} it")
        return True

    def save_key(self, key: bytes) -> None:
        """Write ``key``, replacing an older key; a file there that is not a key is refused."""
        if len(key) != KEY_BYTES:
            raise SigningError(f"signing key must be {KEY_BYTES} bytes, got {len(key)}")
        self._refuse_unless_key("overwrite")
        try:
            _write_atomic(self.key_path, key.hex() + "\n")
        except OSError as exc:
            raise SigningError(f"{self.key_path}: cannot write signing key: {exc}") from None

    def remove_key(self) -> bool:
        """Delete the key file; False if there was none. A file that is not a key is refused."""
        if not self._refuse_unless_key("delete"):
            return False
        try:
            self.key_path.unlink()
        except FileNotFoundError:
            return False
        return True

    def load_timestamp(self) -> int:
        """The last saved timestamp; 0 if none or unreadable (the clock then rules)."""
        try:
            return max(int(self.timestamp_path.read_text(encoding="ascii").strip()), 0)
        except (OSError, ValueError, UnicodeDecodeError):
            return 0

    def save_timestamp(self, ticks: int) -> None:
        _write_atomic(self.timestamp_path, f"{int(ticks)}\n")


class _SigningState(MAVLinkSigning):
    """pymavlink's signing state whose timestamp reports each change, so that it is saved
    periodically from wherever it advances (every signed send and every good signed frame)."""

    def __init__(self, on_timestamp: Callable[[], None]) -> None:
        self._ticks = 0
        self._on_timestamp: Callable[[], None] | None = None
        super().__init__()
        self._on_timestamp = on_timestamp

    @property
    def timestamp(self) -> int:
        return self._ticks

    @timestamp.setter
    def timestamp(self, value: int) -> None:
        self._ticks = int(value)
        if self._on_timestamp is not None:
            self._on_timestamp()


def _link_is_local(conn) -> bool:
    """Only processes on this machine can reach the link: a socket bound to a loopback address
    (``udpin:127.0.0.1:...``, ``tcpin:127.0.0.1:...``) or a TCP connection to one. pymavlink does
    not say which peer sent a frame, so the link as a whole must be local; ``udpout`` is not (its
    socket takes datagrams from anyone)."""
    sock = getattr(conn, "port", None)
    try:
        local = ipaddress.ip_address(sock.getsockname()[0])
        if local.is_loopback:
            return True
        if sock.type == socket.SOCK_STREAM:
            return ipaddress.ip_address(sock.getpeername()[0]).is_loopback
    except (AttributeError, OSError, ValueError, IndexError, TypeError):
        pass
    return False


class LinkSigning:
    """Signing on one pymavlink connection: the key, the accept policy, the timestamp, SETUP_SIGNING.

    ``notify(text, severity)`` reports key changes to the ground station (STATUSTEXT)."""

    def __init__(self, conn, store: KeyStore | None, params: GcsParams, notify: Callable[[str, int], None] | None = None) -> None:
        self.conn = conn
        self.store = store
        self.params = params
        self.notify = notify or (lambda text, severity: None)
        self.rejected = 0
        """Frames dropped for a missing or bad signature."""
        self._next_save_s = 0.0
        key = store.load_key() if store is not None else None
        if params.require_signing and key is None:
            where = store.key_path if store is not None else "gcs.signing_key_path is empty"
            raise SigningError(f"--require-signing: no signing key ({where}); run: rover-ctl signing setup PASSPHRASE")
        self.state = _SigningState(self._timestamp_advanced)
        conn.mav.signing = self.state
        conn.mav.check_signature = self.check_signature  # the instance's, used by decode()
        conn.message_hooks.append(self._on_message)
        if key is not None:
            self._enable(key, self._start_ticks())

    @property
    def enabled(self) -> bool:
        return self.state.secret_key is not None

    # ---- policy ------------------------------------------------------------------------------

    def accept_unsigned(self, mav_obj, msg_id: int) -> bool:
        """pymavlink's allow_unsigned_callback: called for unsigned and wrongly signed frames."""
        if msg_id in UNSIGNED_ALLOWED:
            return True
        self.rejected += 1
        if self.rejected == 1 or self.rejected % 1000 == 0:  # a flood must not flood the log
            log.warning("GCS link: dropped an unsigned or wrongly signed frame (msgid %d; %d so far)", msg_id, self.rejected)
        return False

    def check_signature(self, msgbuf: bytearray, src_system: int, src_component: int) -> bool:
        """The MAVLink C library's check: signature first, then the stream's timestamp."""
        signing = self.state
        expected = hashlib.sha256(signing.secret_key + bytes(msgbuf[:-6])).digest()[:6]
        if not hmac.compare_digest(expected, bytes(msgbuf[-6:])):
            return False
        link_id = msgbuf[-13]
        timestamp = int.from_bytes(bytes(msgbuf[-12:-6]), "little")
        stream = (link_id, src_system, src_component)
        last = signing.stream_timestamps.get(stream)
        if last is None:
            if len(signing.stream_timestamps) >= MAX_STREAMS:
                return False
            if timestamp + NEW_STREAM_MAX_AGE_TICKS < signing.timestamp:
                return False
        elif timestamp <= last:
            return False  # a replay
        signing.stream_timestamps[stream] = timestamp
        if timestamp > signing.timestamp:
            signing.timestamp = timestamp
        return True

    # ---- key changes -------------------------------------------------------------------------

    def _on_message(self, conn, msg) -> None:
        if msg.get_type() != "SETUP_SIGNING" or msg.target_system != self.params.system_id:
            return
        key = bytes(msg.secret_key)
        if self.enabled:
            trusted = msg.get_signed()  # it passed check_signature: our callback never lets it in unsigned
            why = "not signed with the current key"
        else:
            trusted = self.params.signing_setup_from_loopback and _link_is_local(conn)
            why = ("no key is set and gcs.signing_setup_from_loopback is off" if not self.params.signing_setup_from_loopback
                   else "no key is set and the GCS link is not loopback-only")  # fmt: skip
        if not trusted:
            log.warning("GCS link: SETUP_SIGNING refused: %s", why)
            return
        if not any(key):
            if self.params.require_signing:
                log.warning("GCS link: SETUP_SIGNING with an all-zero key refused: signing is required")
                self.notify("Signing required: cannot disable", int(Severity.WARNING))
                return
            self._disable()
            return
        try:
            if self.store is not None:
                self.store.save_key(key)
        except SigningError as exc:
            log.error("%s", exc)
            self.notify("Signing key not saved", int(Severity.ERROR))
            return
        self._enable(key, max(self.state.timestamp, int(msg.initial_timestamp), clock_ticks()))
        log.info("GCS link: new signing key set by %d/%d", msg.get_srcSystem(), msg.get_srcComponent())
        self.notify("Signing key set", int(Severity.INFO))

    def _enable(self, key: bytes, ticks: int) -> None:
        s = self.state
        s.secret_key = key
        s.sign_outgoing = True
        s.allow_unsigned_callback = self.accept_unsigned
        s.link_id = LINK_ID
        s.stream_timestamps = {}
        s.timestamp = ticks
        self._save_timestamp()

    def _disable(self) -> None:
        if self.store is not None:
            try:
                self.store.remove_key()
            except (SigningError, OSError) as exc:  # the file is not ours to delete, or cannot be
                # Signing stays on: off for this run only would come back on at the next start.
                log.warning("GCS link: all-zero SETUP_SIGNING refused: %s", exc)
                self.notify("Signing not disabled: the key file cannot be removed", int(Severity.WARNING))
                return
        s = self.state
        s.secret_key, s.sign_outgoing, s.allow_unsigned_callback = None, False, None
        log.warning("GCS link: signing disabled by a key holder (all-zero SETUP_SIGNING)")
        self.notify("Signing disabled", int(Severity.WARNING))

    # ---- timestamp ---------------------------------------------------------------------------

    def _start_ticks(self) -> int:
        margin = int(self.params.signing_timestamp_save_s * TICKS_PER_S)
        saved = self.store.load_timestamp() if self.store is not None else 0
        return max(clock_ticks(), saved + margin if saved else 0)

    def _timestamp_advanced(self) -> None:
        if self.enabled and time.monotonic() >= self._next_save_s:
            self._save_timestamp()

    def _save_timestamp(self) -> None:
        self._next_save_s = time.monotonic() + self.params.signing_timestamp_save_s
        s = self.state
        s._ticks = max(s._ticks, clock_ticks())  # an idle link keeps up with the clock
        if self.store is None:
            return
        try:
            self.store.save_timestamp(s._ticks)
        except OSError as exc:
            log.warning("%s: cannot save the signing timestamp: %s", self.store.timestamp_path, exc)

    def close(self) -> None:
        """Save the timestamp (on shutdown)."""
        if self.enabled:
            self._save_timestamp()


def setup_client_signing(conn, key: bytes) -> None:
    """Sign a client connection (``rover-ctl mission``, ``rover-ctl sim``) with ``key``: signed
    sends from the clock's timestamp, unsigned frames accepted only for the radio messages."""
    conn.setup_signing(key, sign_outgoing=True, allow_unsigned_callback=lambda mav_obj, msg_id: msg_id in UNSIGNED_ALLOWED,
                       initial_timestamp=clock_ticks(), link_id=LINK_ID)  # fmt: skip


def client_key(value: str | None) -> bytes | None:
    """A client's ``--signing-key``: a passphrase, or ``@FILE`` naming a key file (64 hex digits,
    e.g. the daemon's, or a file holding the passphrase on its first line)."""
    if value is None:
        return None
    if value.startswith("@"):
        path = Path(value[1:]).expanduser()
        try:
            text = read_text(path, KEY_FILE_MAX_BYTES, encoding="utf-8").splitlines()
        except FileTooLarge:
            raise SigningError(f"--signing-key {value}: not a key file (larger than {KEY_FILE_MAX_BYTES} bytes)") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise SigningError(f"--signing-key {value}: cannot read: {exc}") from None
        first = text[0].strip() if text else ""
        if not first:
            raise SigningError(f"--signing-key {value}: the file's first line is empty (it must hold a key or a passphrase)")
        try:
            key = bytes.fromhex(first)
        except ValueError:
            key = b""
        return key if len(key) == KEY_BYTES else key_from_passphrase(first)
    return key_from_passphrase(value)

