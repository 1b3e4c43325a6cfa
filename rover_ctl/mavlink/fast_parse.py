"""pymavlink's receive path, the same frames and messages for less CPU: for the vehicle link.

The daemon receives about 240 frames a second from the vehicle and pymavlink's parser is pure
Python (its C parser ``mavnative`` was removed in 2022, pymavlink PR 728: it never handled
MAVLink 2; its one native part, the CRC through ``fastcrc``, is already in use). A CPU-time
profile of the daemon driving rover-sitl put pymavlink's ``parse_char`` and ``decode`` at about
60% of the vehicle link's ``poll``. ``install(mav)`` replaces both on one ``MAVLink`` object by
equivalents written for speed:

* ``parse_char``: the same framing as pymavlink's (``__parse_char_legacy``: prefix errors raised
  once per run of junk, or ``BAD_DATA`` with robust parsing; the length from the header, the
  signature block when flagged; the same counters), with the buffer read by index instead of
  through a method call and a slice per step;
* ``decode``: for a message of the dialect on a link without a signing key, the same checks (CRC
  with the message's CRC_EXTRA, length, MAVLink 2 zero-padding) and the same message object,
  with each message type's field layout worked out once instead of on every frame. Anything else
  (a signing key, an unknown message id, a frame that fails a check) goes to pymavlink's own
  ``decode``, which raises the error with its own wording, so what is accepted and what is
  counted as a bad CRC (``rover_ctl.mavlink.link_health``) are pymavlink's.

``tests/fuzz/test_fast_parse.py`` feeds both parsers the same valid, corrupted and random byte
streams, cut at random places, and requires the same messages (every attribute), exceptions and
parser state.
"""

from __future__ import annotations

import struct
from typing import Any

from rover_ctl.vocabulary import mav as dialect

V1 = dialect.PROTOCOL_MARKER_V1
V2 = dialect.PROTOCOL_MARKER_V2
HEADER_V1 = dialect.HEADER_LEN_V1
HEADER_V2 = dialect.HEADER_LEN_V2
SIGNED = dialect.MAVLINK_IFLAG_SIGNED
SIGNATURE_LEN = dialect.MAVLINK_SIGNATURE_BLOCK_LEN
CRC_LEN = 2
V2_HEADER = struct.Struct("<cBBBBBBHB")
CRC_INIT = 0xFFFF


class _Layout:
    """How one message type's unpacked payload becomes its constructor's arguments (pymavlink's
    ``decode`` works this out on every frame)."""

    __slots__ = ("cls", "unpacker", "size", "crc_extra", "slots", "has_arrays", "has_bytes")

    def __init__(self, cls: Any) -> None:
        self.cls = cls
        self.unpacker = cls.unpacker
        self.size = cls.unpacker.size
        self.crc_extra = bytes((cls.crc_extra,))
        lengths, orders = cls.lengths, cls.orders
        self.has_arrays = sum(lengths) != len(lengths)
        # Without arrays: argument i is t[orders[i]]. With arrays: (start, length) in t, as pymavlink.
        self.slots = tuple(orders) if not self.has_arrays else tuple((sum(lengths[:o]), lengths[o]) for o in orders)
        fmt = cls.unpacker.format
        self.has_bytes = "s" in fmt or "c" in fmt

    def arguments(self, t: tuple) -> list:
        if not self.has_arrays:
            args = [t[i] for i in self.slots]
        else:
            args = []
            for start, length in self.slots:
                value = t[start]
                args.append(value if length == 1 or isinstance(value, bytes) else list(t[start : start + length]))
        if self.has_bytes:
            args = [a.rstrip(b"\x00") if isinstance(a, bytes) else a for a in args]
        return args


class FastParser:
    """``parse_char`` and ``decode`` for one pymavlink ``MAVLink`` object (see the module doc)."""

    def __init__(self, mav: Any) -> None:
        self.mav = mav
        self.module = __import__(type(mav).__module__, fromlist=["MAVLink"])
        self._decode_slow = type(mav).decode.__get__(mav)
        self._layouts: dict[int, _Layout | None] = {}
        crc = getattr(self.module, "mcrf4xx", None)
        self._crc = crc if crc is not None else (lambda data, init: self.module.x25crc(data).crc)

    def install(self) -> None:
        self.mav.parse_char = self.parse_char
        self.mav.decode = self.decode

    # ---- framing (pymavlink's parse_char and __parse_char_legacy) ---------------------------

    def parse_char(self, c: Any) -> Any:
        mav = self.mav
        mav.buf.extend(c)
        mav.total_bytes_received += len(c)
        m = self._frame()
        if m is not None:
            mav.total_packets_received += 1
            if mav.callback is not None and mav.callback_args is not None and mav.callback_kwargs is not None:
                mav.callback(m, *mav.callback_args, **mav.callback_kwargs)
        if mav.buf_index != 0 and len(mav.buf) == mav.buf_index:
            mav.buf = bytearray()
            mav.buf_index = 0
        return m

    def _frame(self) -> Any:
        mav = self.mav
        buf, i = mav.buf, mav.buf_index
        left = len(buf) - i
        header_len = HEADER_V1
        if left >= 1:
            first = buf[i]
            if first == V2:
                header_len = HEADER_V2
            elif first != V1:
                return self._bad_prefix(first, header_len)
        mav.have_prefix_error = False
        magic = incompat_flags = 0
        if left >= 3:
            magic, length, incompat_flags = buf[i], buf[i + 1], buf[i + 2]
            if magic == V2 and incompat_flags & SIGNED:
                length += SIGNATURE_LEN
            mav.expected_length = length + header_len + CRC_LEN
        expected = mav.expected_length
        if expected < header_len + CRC_LEN or left < expected:
            return None
        mbuf = buf[i : i + expected]
        mav.buf_index = i + expected
        mav.expected_length = header_len + CRC_LEN
        flags_bad = magic == V2 and (incompat_flags & ~SIGNED) != 0
        if mav.robust_parsing:
            try:
                if flags_bad:
                    raise self.module.MAVError("invalid incompat_flags 0x%x 0x%x %u" % (incompat_flags, magic, mav.expected_length))
                return mav.decode(mbuf)
            except self.module.MAVError as reason:
                mav.total_receive_errors += 1
                return self.module.MAVLink_bad_data(mbuf, reason.message)
        if flags_bad:
            raise self.module.MAVError("invalid incompat_flags 0x%x 0x%x %u" % (incompat_flags, magic, mav.expected_length))
        return mav.decode(mbuf)

    def _bad_prefix(self, magic: int, header_len: int) -> Any:
        mav = self.mav
        mav.buf_index += 1
        if mav.robust_parsing:
            buf, start, j = mav.buf, mav.buf_index - 1, mav.buf_index
            while j < len(buf) and buf[j] != V1 and buf[j] != V2:
                j += 1
            mav.buf_index = j
            mav.expected_length = header_len + CRC_LEN
            mav.total_receive_errors += 1
            return self.module.MAVLink_bad_data(buf[start:j], "Bad prefix")
        if mav.have_prefix_error:
            return None
        mav.have_prefix_error = True
        mav.total_receive_errors += 1
        raise self.module.MAVError("invalid MAVLink prefix '%s'" % magic)

    # ---- decoding (pymavlink's decode) --------------------------------------------------------

    def _layout(self, msg_id: int) -> _Layout | None:
        try:
            return self._layouts[msg_id]
        except KeyError:
            cls = self.module.mavlink_map.get(msg_id)
            layout = self._layouts[msg_id] = _Layout(cls) if cls is not None else None
            return layout

    def decode(self, msgbuf: bytearray) -> Any:
        mav = self.mav
        if msgbuf[0] != V2 or len(msgbuf) < HEADER_V2 + CRC_LEN or mav.signing.secret_key is not None:
            return self._decode_slow(msgbuf)  # MAVLink 1, a runt, or signing: pymavlink's own
        magic, mlen, incompat_flags, compat_flags, seq, src_system, src_component, low, high = V2_HEADER.unpack_from(msgbuf)
        msg_id = low | (high << 16)
        signature_len = SIGNATURE_LEN if incompat_flags & SIGNED else 0
        end = len(msgbuf) - CRC_LEN - signature_len
        layout = self._layout(msg_id)
        if layout is None or mlen != end - HEADER_V2:
            return self._decode_slow(msgbuf)  # unknown message, or a length error: pymavlink says which
        crc = msgbuf[end] | (msgbuf[end + 1] << 8)
        if crc != self._crc(bytes(msgbuf[1:end]) + layout.crc_extra, CRC_INIT) and not self.module.MAVLINK_IGNORE_CRC:
            return self._decode_slow(msgbuf)  # raises pymavlink's "invalid MAVLink CRC ..."
        payload = msgbuf[HEADER_V2:end]
        if len(payload) < layout.size:
            payload.extend(bytes(layout.size - len(payload)))  # MAVLink 2 trims trailing zeros
        try:
            t = layout.unpacker.unpack(payload[: layout.size])
        except struct.error:
            return self._decode_slow(msgbuf)
        if signature_len:
            mav.signing.sig_count += 1
        try:
            m = layout.cls(*layout.arguments(t))
        except Exception:
            return self._decode_slow(msgbuf)
        m._signed = False
        m._msgbuf = msgbuf
        m._payload = msgbuf[6 : -(CRC_LEN + signature_len)]  # sic: pymavlink's offset, kept identical
        m._crc = crc
        m._header = self.module.MAVLink_header(msg_id, incompat_flags, compat_flags, mlen, seq, src_system, src_component)
        return m


def install(mav: Any) -> FastParser | None:
    """Give pymavlink ``MAVLink`` object ``mav`` the fast ``parse_char`` and ``decode``; only a
    MAVLink 2 dialect's (the parser copied here is that generator's), else ``mav`` keeps its own."""
    if ".v20." not in type(mav).__module__:
        return None
    parser = FastParser(mav)
    parser.install()
    return parser
