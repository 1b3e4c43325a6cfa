"""What the vehicle link measures (rover_ctl.mavlink.link_health): rates over a window of vehicle
time, bytes, frames lost from sequence gaps, bad CRCs."""

from __future__ import annotations

import pytest

from rover_ctl.mavlink.link_health import LinkHealth


def feed(health: LinkHealth, name: str, rate_hz: float, seconds: float, start_s: float = 0.0, seq0: int = 0,
         source=(1, 1), size: int = 40, skip_every: int = 0) -> int:  # fmt: skip
    seq, n = seq0, 0
    while n / rate_hz < seconds:
        if not (skip_every and n % skip_every == skip_every - 1):
            health.frame(start_s + n / rate_hz, name, source, seq % 256, size)
        seq += 1
        n += 1
    return seq


def test_rates_over_the_window_and_none_before_half_a_window():
    health = LinkHealth(2.0)
    health.frame(0.0, "ATTITUDE", (1, 1), 0, 40)
    assert health.rate_hz("ATTITUDE", 0.5) is None and health.rate_hz("GPS_RAW_INT", 5.0) is None
    feed(health, "ATTITUDE", 25.0, 10.0, seq0=1)
    assert health.rate_hz("ATTITUDE", 10.0) == pytest.approx(25.0, rel=0.03)
    assert health.rate_hz("ATTITUDE", 11.0) == pytest.approx(12.5, rel=0.05)  # nothing for the last second
    stats = health.stats(10.0)
    assert stats.rx_bytes_per_s == pytest.approx(25 * 40, rel=0.05) and stats.lost == 0 and stats.loss_pct == 0.0


def test_sequence_gaps_count_lost_frames_per_source_across_the_wrap():
    health = LinkHealth(2.0)
    feed(health, "ATTITUDE", 50.0, 10.0, seq0=200, skip_every=10)  # one frame in ten never arrives
    feed(health, "HEARTBEAT", 1.0, 10.0, source=(1, 0))  # another component: its own counter
    stats = health.stats(10.0)
    assert stats.lost == pytest.approx(50, abs=1) and stats.loss_pct == pytest.approx(10.0, abs=0.5)


def test_duplicates_and_reordering_are_not_counted_as_losses():
    health = LinkHealth(2.0)
    for seq in (10, 11, 11, 10, 12):
        health.frame(0.0, "ATTITUDE", (1, 1), seq, 40)
    assert health.lost == 0


def test_a_long_dropout_is_counted_and_the_counter_follows_it():
    health = LinkHealth(2.0)
    for seq in [*range(0, 50), *range(200, 256), *range(0, 10)]:  # 150 frames never arrived
        health.frame(0.0, "ATTITUDE", (1, 1), seq, 40)
    assert health.lost == 150


def test_bad_crcs_and_garbage_are_counted():
    health = LinkHealth(2.0)
    feed(health, "ATTITUDE", 10.0, 1.0)
    health.bad_crc()
    health.bad_bytes()
    stats = health.stats(1.0)
    assert (stats.crc_errors, stats.garbage) == (1, 1) and stats.loss_pct == 0.0  # no gap: nothing lost
    assert "bad CRC 1" in stats.describe()


def test_mean_frame_size_per_message():
    health = LinkHealth(2.0)
    health.frame(0.0, "DISTANCE_SENSOR", (1, 1), 0, 25)
    health.frame(0.1, "DISTANCE_SENSOR", (1, 1), 1, 27)
    assert health.mean_size("DISTANCE_SENSOR") == 26 and health.mean_size("ATTITUDE") is None


def test_the_window_is_read_live():
    window = [2.0]
    health = LinkHealth(lambda: window[0])
    feed(health, "ATTITUDE", 10.0, 8.0)
    feed(health, "ATTITUDE", 20.0, 2.0, start_s=8.0, seq0=80)
    assert health.rate_hz("ATTITUDE", 10.0) == pytest.approx(20.0, rel=0.05)
    window[0] = 4.0  # half the window at 10 Hz, half at 20 Hz (frames older than a window are gone)
    health2 = LinkHealth(lambda: window[0])
    feed(health2, "ATTITUDE", 10.0, 8.0)
    feed(health2, "ATTITUDE", 20.0, 2.0, start_s=8.0, seq0=80)
    assert health2.window_s == 4.0 and health2.rate_hz("ATTITUDE", 10.0) == pytest.approx(15.0, rel=0.05)
