"""The log budget during a run (``rover_ctl.app.logs.LogBudget``): once the run's folder holds more
than ``daemon.log_max_total_mb``, the tlogs stop with one warning and one call back (the daemon's
``log_budget`` event); a tlog whose write fails stops too. Sizes, not timings, are asserted."""

from __future__ import annotations

import logging
import os
from pathlib import Path

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mav

from rover_ctl.app.logs import TLOG_STAMP, LogBudget, TlogWriter

FRAME = mav.MAVLink_named_value_float_message(0, b"x" * 10, 1.0)
FRAME.pack(mav.MAVLink(None, srcSystem=255, srcComponent=190))
RECORD = TLOG_STAMP.size + len(FRAME.get_msgbuf())


def test_the_tlogs_stop_once_the_run_folder_exceeds_the_budget(tmp_path, caplog):
    (tmp_path / "control.csv").write_bytes(b"c" * 20_000)  # the folder, not only the tlogs, counts
    full = []
    budget = LogBudget(tmp_path, max_total_mb=0.05, on_full=full.append, measure_every_bytes=4_000)
    tlogs = [TlogWriter(tmp_path / "vehicle.tlog", budget=budget), TlogWriter(tmp_path / "gcs.tlog", budget=budget)]
    with caplog.at_level(logging.WARNING, logger="rover_ctl.app.logs"):
        for k in range(5_000):
            tlogs[k % 2].write(FRAME)
    for tlog in tlogs:
        tlog.close()
    written = sum(t.frames for t in tlogs)
    assert budget.full and len(full) == 1 and full[0] > 50_000
    assert 20_000 + written * RECORD <= 50_000 < 20_000 + (written + 1) * RECORD  # stopped at the budget, not before
    assert sum(t.unwritten for t in tlogs) == 5_000 - written
    assert sum(p.stat().st_size for p in tmp_path.iterdir()) <= 50_000
    assert len([r for r in caplog.records if "log budget" in r.getMessage()]) == 1
    log = mavutil.mavlink_connection(str(tlogs[0].path))
    assert log.recv_msg().get_type() == "NAMED_VALUE_FLOAT"  # what was written is a readable tlog


def test_growth_outside_the_tlogs_is_seen_at_the_next_measurement(tmp_path):
    budget = LogBudget(tmp_path, max_total_mb=0.01, measure_every_bytes=1_000)
    tlog = TlogWriter(tmp_path / "gcs.tlog", budget=budget)
    tlog.write(FRAME)
    (tmp_path / "control.csv").write_bytes(b"c" * 20_000)
    for _ in range(1_000 // RECORD + 1):
        tlog.write(FRAME)
    assert budget.full and tlog.frames <= 1_000 // RECORD + 1
    tlog.close()


@pytest.mark.parametrize("max_mb", [0.0, -1.0])
def test_no_budget_is_no_limit(tmp_path, max_mb):
    budget = LogBudget(tmp_path, max_total_mb=max_mb)
    tlog = TlogWriter(tmp_path / "gcs.tlog", budget=budget)
    for _ in range(1_000):
        tlog.write(FRAME)
    tlog.close()
    assert tlog.frames == 1_000 and not budget.full


def test_a_failed_write_stops_the_tlog_with_one_warning(tmp_path, caplog):
    class FullDisk:
        closed = False

        def write(self, data):
            raise OSError(28, "No space left on device")

        def close(self):
            self.closed = True

    tlog = TlogWriter(tmp_path / "gcs.tlog")
    tlog._file.close()
    tlog._file = FullDisk()
    with caplog.at_level(logging.WARNING, logger="rover_ctl.app.logs"):
        for _ in range(10):
            tlog.write(FRAME)  # never raises: the link it hangs on goes on
    assert tlog.frames == 0 and tlog.unwritten == 10 and "No space" in tlog.failed
    assert len([r for r in caplog.records if "No space" in r.getMessage()]) == 1


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full (Linux) to stand for a full disk")
def test_on_a_full_disk_every_log_stops_quietly_and_closes(caplog):
    """/dev/full fails every write as a full disk does: control.csv and events.jsonl raised into the
    control loop (the daemon exited with 70), and a tlog's close raised at shutdown."""
    from rover_ctl.app.daemon import EventLog
    from rover_ctl.app.logs import CsvLog

    full = Path("/dev/full")
    csv_log, events, tlog = CsvLog(full, ["t_s", "x"]), EventLog(full), TlogWriter(full)
    with caplog.at_level(logging.WARNING):
        for step in range(2000):  # past the CSV's buffer: its writes reach the disk
            csv_log.write({"t_s": step * 0.04, "x": 1.0})
            events.write(step * 0.04, "mode", mode="AUTO")
            tlog.write(FRAME)
        csv_log.flush()
        for log_file in (csv_log, events, tlog):
            log_file.close()  # never raises
    assert csv_log.failed and tlog.failed
    warnings = [r.getMessage() for r in caplog.records if "No space" in r.getMessage()]
    assert 3 <= len(warnings) <= 6, warnings  # a write's and at most a close's per log, not one per step
