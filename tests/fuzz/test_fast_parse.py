"""The vehicle link's fast parser (``rover_ctl.mavlink.fast_parse``) against pymavlink's own: the
same byte stream, cut into the same reads, gives the same messages (every attribute, the header's
too), the same exceptions with the same text, and the same parser state and counters."""

from __future__ import annotations

import math
import os

os.environ.setdefault("MAVLINK20", "1")
from hypothesis import given, strategies as st  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mav  # noqa: E402

from fuzz.conftest import FUZZ  # noqa: E402
from fuzz.frames import message, pack  # noqa: E402
from rover_ctl.mavlink import fast_parse  # noqa: E402

VEHICLE_MESSAGES = ("WHEEL_DISTANCE", "ATTITUDE", "DISTANCE_SENSOR", "GPS_RAW_INT", "SIMSTATE", "SYS_STATUS", "HEARTBEAT",
                    "STATUSTEXT", "COMMAND_ACK", "AUTOPILOT_VERSION", "TIMESYNC", "RADIO_STATUS", "SERVO_OUTPUT_RAW",
                    "RC_CHANNELS", "PARAM_VALUE", "MISSION_ITEM_INT", "ESC_TELEMETRY_1_TO_4")  # fmt: skip
"""What a vehicle sends (and a few with arrays, strings and extensions)."""
STATE = ("buf", "buf_index", "expected_length", "have_prefix_error", "total_bytes_received", "total_packets_received",
         "total_receive_errors")  # fmt: skip


def _same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return type(a) is type(b) and a == b


def _attributes(msg) -> dict:
    if msg is None:
        return {}
    fields = dict(vars(msg))
    fields["_header"] = vars(msg.get_header())
    fields["type"] = type(msg)
    return fields


def _run(parser, reads: list[bytes]) -> list:
    """Every outcome of feeding ``reads`` as VehicleLink does: a read, then more parsing until None."""
    out = []
    for chunk in reads:
        for _ in range(len(chunk) + 2):
            try:
                msg = parser.parse_char(chunk)
            except mav.MAVError as exc:
                out.append(("error", exc.message))
                chunk = b""
                continue
            chunk = b""
            out.append(_attributes(msg))
            if msg is None:
                break
        out.append({k: getattr(parser, k) for k in STATE} | {"sig_count": parser.signing.sig_count})
    return out


def _agree(stream: bytes, cuts: list[int], robust: bool) -> None:
    points = sorted({c % (len(stream) + 1) for c in cuts} | {0, len(stream)})
    reads = [stream[a:b] for a, b in zip(points, points[1:])]
    slow, fast = mav.MAVLink(None), mav.MAVLink(None)
    slow.robust_parsing = fast.robust_parsing = robust
    fast_parse.install(fast)
    expected, got = _run(slow, reads), _run(fast, reads)
    assert len(expected) == len(got)
    for e, g in zip(expected, got):
        if isinstance(e, tuple) or isinstance(g, tuple):
            assert e == g
            continue
        assert e.keys() == g.keys()
        for key in e:
            same = e[key] == g[key] if isinstance(e[key], dict) else _same(e[key], g[key])
            assert same or (isinstance(e[key], dict) and all(_same(e[key][k], g[key][k]) for k in e[key])), (key, e[key], g[key])

frames = st.tuples(st.sampled_from(VEHICLE_MESSAGES).flatmap(message), st.sampled_from([(1, 1), (1, 0), (51, 68), (255, 190)]))


def _packed(frame) -> bytes | None:
    try:
        return pack(*frame)
    except Exception:  # the fuzz strategies' biased values may not fit a narrower field here
        return None


packed = frames.map(_packed).filter(lambda b: b is not None)


def _signed(frame: bytes) -> bytes:
    """The frame with the signed flag and a (meaningless) signature block: the CRC no longer matches."""
    return frame[:2] + bytes([frame[2] | mav.MAVLINK_IFLAG_SIGNED]) + frame[3:] + bytes(range(13))


@FUZZ
@given(st.lists(packed, min_size=1, max_size=12), st.lists(st.integers(0, 2000), max_size=6), st.booleans())
def test_valid_streams_give_the_same_messages(frames_, cuts, robust):
    _agree(b"".join(frames_), cuts, robust)


@FUZZ
@given(st.lists(packed, min_size=1, max_size=8), st.lists(st.tuples(st.integers(0, 4000), st.integers(0, 255)), max_size=6),
       st.lists(st.integers(0, 2000), max_size=6), st.booleans(), st.binary(max_size=40))  # fmt: skip
def test_corrupted_streams_give_the_same_messages_and_errors(frames_, flips, cuts, robust, junk):
    stream = bytearray(junk + b"".join(frames_))
    for at, value in flips:
        stream[at % len(stream)] = value
    _agree(bytes(stream), cuts, robust)


@FUZZ
@given(st.binary(max_size=600), st.lists(st.integers(0, 600), max_size=6), st.booleans())
def test_random_bytes_give_the_same_results(data, cuts, robust):
    _agree(data, cuts, robust)


@FUZZ
@given(st.lists(packed, min_size=1, max_size=4), st.booleans())
def test_signed_and_mavlink1_frames_go_the_same_way(frames_, robust):
    v1 = bytes(mav.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3).pack(mav.MAVLink(None, 1, 1), force_mavlink1=True))
    _agree(b"".join(_signed(f) for f in frames_) + v1 + b"".join(frames_), [], robust)


def test_a_garbled_frame_is_reported_as_pymavlink_reports_it():
    good = pack(mav.MAVLink_attitude_message(1000, 0.0, 0.0, 0.5, 0.0, 0.0, 0.1), (1, 1))
    bad = bytearray(good)
    bad[12] ^= 0xFF
    fast = mav.MAVLink(None)
    fast_parse.install(fast)
    try:
        fast.parse_char(bytes(bad))
    except mav.MAVError as exc:
        assert "CRC" in exc.message
    else:
        raise AssertionError("a bad CRC was accepted")
    msg = fast.parse_char(good)
    assert msg.get_type() == "ATTITUDE" and msg.yaw == 0.5 and msg.get_srcSystem() == 1


def test_a_mavlink1_dialect_parser_is_left_as_it_is():
    from pymavlink.dialects.v10 import ardupilotmega as mav1

    parser = mav1.MAVLink(None)
    assert fast_parse.install(parser) is None and "parse_char" not in vars(parser)
