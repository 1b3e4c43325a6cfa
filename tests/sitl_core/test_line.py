"""The serial line model (sitl/line.py): rate, bounded buffer, tail drop, byte errors, counters."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sitl.line import FrameGate, LineError, SerialLine

BAUD = 57600
RATE = BAUD / 10  # 8N1


def conserved(line: SerialLine) -> bool:
    s = line.stats
    return s.offered == s.delivered + s.dropped_overflow + s.buffered and s.buffered == line.buffered


def test_a_byte_takes_ten_bit_times():
    line = SerialLine(BAUD)
    line.offer(b"abc", 1.0)
    assert line.take(1.0 + 2.9 / RATE) == b"ab"
    assert line.next_departure_s() == pytest.approx(1.0 + 3 / RATE)
    assert line.take(1.0 + 3 / RATE) == b"c"
    assert line.next_departure_s() is None


def test_an_idle_line_starts_sending_when_offered_not_before():
    line = SerialLine(BAUD)
    line.offer(b"x", 0.0)
    assert line.take(10.0) == b"x"
    line.offer(b"yz", 20.0)  # idle since 0.0 + 1/RATE: nothing "saved up"
    assert line.take(20.0 + 1.5 / RATE) == b"y"


def test_overflow_drops_the_tail_and_counts_it():
    line = SerialLine(BAUD, buffer_bytes=100)
    assert line.offer(bytes(150), 0.0) == 100
    assert (line.stats.offered, line.stats.dropped_overflow, line.stats.peak_buffer_bytes) == (150, 50, 100)
    assert line.offer(bytes(10), 5 / RATE) == 5  # 5 bytes left meanwhile: room for 5
    assert conserved(line)


def test_a_whole_offer_is_all_or_nothing():
    line = SerialLine(BAUD, buffer_bytes=100)
    assert line.offer(bytes(60), 0.0, whole=True) == 60
    assert line.offer(bytes(60), 0.0, whole=True) == 0
    assert line.offer(bytes(40), 0.0, whole=True) == 40
    assert (line.stats.dropped_overflow, line.buffered) == (60, 100) and conserved(line)


def test_byte_errors_change_bytes_at_the_drawn_rate_and_are_counted():
    line = SerialLine(BAUD, byte_error=0.01, buffer_bytes=1_000_000, seed=7)
    data = bytes(range(256)) * 400
    line.offer(data, 0.0)
    out = line.take(1e6)
    changed = sum(a != b for a, b in zip(data, out))
    assert len(out) == len(data) and changed == line.stats.corrupted
    assert 0.008 * len(data) < changed < 0.012 * len(data)  # 1024 expected, sd 32


def test_same_seed_same_errors_and_no_errors_at_zero():
    def run(seed: int, p: float) -> bytes:
        line = SerialLine(BAUD, byte_error=p, buffer_bytes=10_000, seed=seed)
        line.offer(bytes(5000), 0.0)
        return line.take(10.0)

    assert run(3, 0.01) == run(3, 0.01) != run(4, 0.01)
    assert run(3, 0.0) == bytes(5000)


@pytest.mark.parametrize(("baud", "p", "buffer"), [(0, 0, 1), (-5, 0, 1), (float("nan"), 0, 1), (BAUD, 1.0, 1),
                                                   (BAUD, -0.1, 1), (BAUD, 0, 0)])  # fmt: skip
def test_bad_parameters_are_refused(baud, p, buffer):
    with pytest.raises(LineError):
        SerialLine(baud, p, buffer)


events = st.lists(st.tuples(st.floats(0, 0.5), st.binary(max_size=600), st.booleans()), max_size=60)
"""(time step s, bytes offered then, take after offering?)"""


@given(events, st.integers(1, 3000), st.sampled_from([1200, 9600, 57600, 921600]))
@settings(max_examples=150, deadline=None)
def test_rate_order_and_conservation(steps, buffer_bytes, baud):
    line = SerialLine(baud, buffer_bytes=buffer_bytes)
    rate = baud / 10
    t = t0 = 1.0
    kept = bytearray()
    got = bytearray()
    for dt, data, take in steps:
        t += dt
        kept += data[: line.offer(data, t)]
        assert conserved(line)
        assert line.buffered <= buffer_bytes
        if take:
            got += line.take(t)
            assert len(got) <= (t - t0) * rate + 1e-6  # never faster than the line
    got += line.take(t + 1e6)
    assert bytes(got) == bytes(kept)  # nothing reordered, nothing lost once accepted
    assert line.stats.delivered == len(kept) and conserved(line) and line.buffered == 0


@given(st.lists(st.tuples(st.integers(1, 1024), st.floats(1.0, 3.0)), max_size=50), st.sampled_from([9600, 57600, 115200]))
@settings(max_examples=150, deadline=None)
def test_no_drop_while_offered_under_the_line_rate(chunks, baud):
    """Chunks up to half the buffer, each followed by at least the time the line needs for it."""
    line = SerialLine(baud, buffer_bytes=2048)
    t = 0.0
    for size, slack in chunks:
        line.offer(bytes(size), t)
        line.take(t)
        t += slack * size / (baud / 10)
    assert line.stats.dropped_overflow == 0


def test_frame_gate_releases_only_whole_frames():
    gate = FrameGate()
    for size in (3, 0, 2, 4):
        gate.accepted(size)
    assert gate.release(b"ab") == b""
    assert gate.release(b"cd") == b"abc"
    assert gate.release(b"efg") == b"de"
    assert gate.release(b"hi") == b"fghi"
    assert gate.release(b"") == b""
