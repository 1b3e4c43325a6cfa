"""Mutation fuzz of every file loader: whatever a file holds, the loader returns or raises its own
one-line error, and ``rover-ctl mission check`` exits 0 or 2 with one error line -- never a
traceback, never a hang.

Seeds: the bundled missions (missions/), the malformed corpus (tests/mission_files/bad/), the
shared real-world missions (../shared/missions; skipped with a message when absent), the shipped
rule bases (TOML) and one in FCL, a config TOML and a mission store. Mutations: byte flips, digit
floods (a number of 400 digits), NaN/inf/1e400 in place of a number, truncation, a huge line,
lines dropped or doubled, invalid UTF-8.
"""

from __future__ import annotations

import math
import os
import re
import signal
import warnings
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from fuzz.conftest import FUZZ
from hypothesis import given
from hypothesis import strategies as st
from mission_protocol.helpers import sample_mission

from rover_ctl.cli import main
from rover_ctl.config import ConfigError, load_config
from rover_ctl.fuzzy.loader import load_rulebase
from rover_ctl.fuzzy.rulebase import RuleBaseError
from rover_ctl.mission.files import MissionFileError, load_mission
from rover_ctl.mission.store import MissionStore, StoreError

ROOT = Path(__file__).resolve().parents[2]
BUNDLED = sorted(p for p in (ROOT / "missions").iterdir() if p.is_file())
BAD = sorted((ROOT / "tests" / "mission_files" / "bad").iterdir())
SHARED_MISSIONS = Path(os.environ.get("ROVER_CTL_SHARED") or ROOT.parent / "shared") / "missions"
SHARED = SHARED_MISSIONS if SHARED_MISSIONS.is_dir() else None
RULEBASES = sorted((ROOT / "rover_ctl" / "fuzzy" / "rulebases").glob("*.toml"))
HANG_S = 20
"""A loader that has not answered in this long is hung (the slowest real file takes milliseconds)."""

CONFIG_TOML = """
[executor]
acceptance_radius_m = 2.0
cruise_speed_mps = 1.0

[gcs]
system_id = 1
heartbeat_period_s = 1.0
mission_store_path = ""

[failsafe]
gcs_timeout_s = 5.0
"""
FCL = (ROOT / "tests" / "fuzzy" / "test_fcl.py").read_text().split('FCL = """', 1)[1].split('"""', 1)[0]
NUMBER = re.compile(rb"-?\d+(\.\d+)?([eE][-+]?\d+)?")
INJECTED = [b"nan", b"NaN", b"inf", b"-inf", b"Infinity", b"-Infinity", b"1e400", b"-1e400", b"9" * 400, b"1" * 5000,
            b"0x10", b"1_000", b"", b"null", b"true", b"\"16\"", b"[]", b"{}"]  # fmt: skip


@st.composite
def mutated(draw, seed: bytes) -> bytes:
    """``seed`` with one to three mutations."""
    data = bytearray(seed)
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["flip", "number", "truncate", "huge_line", "drop_line", "double_line", "utf8", "insert"]))
        if kind == "flip" and data:
            i = draw(st.integers(0, len(data) - 1))
            data[i] ^= draw(st.integers(1, 255))
        elif kind == "number":
            numbers = list(NUMBER.finditer(bytes(data)))
            if numbers:
                m = numbers[draw(st.integers(0, len(numbers) - 1))]
                data[m.start() : m.end()] = draw(st.sampled_from(INJECTED))
        elif kind == "truncate":
            del data[draw(st.integers(0, len(data))) :]
        elif kind in ("huge_line", "drop_line", "double_line"):
            lines = bytes(data).split(b"\n")
            i = draw(st.integers(0, len(lines) - 1))
            if kind == "huge_line":
                lines.insert(i, draw(st.sampled_from([b"1\t" * 200_000, b"x" * 1_000_000, b"[" * 100_000, b"{" * 50_000])))
            elif kind == "drop_line":
                del lines[i]
            else:
                lines.insert(i, lines[i])
            data = bytearray(b"\n".join(lines))
        elif kind == "utf8":
            data[draw(st.integers(0, len(data))) : 0] = b"\xff\xfe\xc3"
        else:
            data[draw(st.integers(0, len(data))) : 0] = draw(st.binary(min_size=1, max_size=20))
    return bytes(data)


@contextmanager
def no_hang(what: str):
    def hung(signum, frame):
        raise AssertionError(f"{what}: no answer within {HANG_S} s")

    previous = signal.signal(signal.SIGALRM, hung)
    signal.alarm(HANG_S)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def seeds_from(paths: list[Path]) -> st.SearchStrategy:
    return st.sampled_from(paths).flatmap(lambda p: st.tuples(st.just(p.name), mutated(p.read_bytes())))


def check_mission_file(tmp_path: Path, name: str, data: bytes, capsys) -> None:
    path = tmp_path / name
    path.write_bytes(data)
    with no_hang(name):
        try:
            load_mission(path)
        except MissionFileError as exc:
            assert exc.errors and all("\n" not in e for e in exc.errors)
        status = main(["mission", "check", str(path)])
    out, err = capsys.readouterr()
    assert status in (0, 2), (status, err)
    if status == 2:
        assert err.startswith("rover-ctl: error: ") and err.count("\n") == 1, err[:500]
    assert "Traceback" not in out + err


@FUZZ
@given(case=seeds_from(BUNDLED + BAD))
def test_mission_check_on_mutated_bundled_files(tmp_path_factory, capsys, case):
    check_mission_file(tmp_path_factory.mktemp("m"), *case, capsys)


@pytest.mark.skipif(SHARED is None, reason=f"{SHARED_MISSIONS} is absent: shared missions not fuzzed")
@FUZZ
@given(data=st.data())
def test_mission_check_on_mutated_shared_files(tmp_path_factory, capsys, data):
    paths = sorted(p for p in SHARED.iterdir() if p.suffix in (".txt", ".plan", ".waypoints"))
    check_mission_file(tmp_path_factory.mktemp("m"), *data.draw(seeds_from(paths)), capsys)


@FUZZ
@given(data=st.data(), fcl=st.booleans())
def test_rule_base_loaders(tmp_path_factory, data, fcl):
    seed = FCL.encode() if fcl else data.draw(st.sampled_from(RULEBASES)).read_bytes()
    path = tmp_path_factory.mktemp("rb") / ("mutated.fcl" if fcl else "mutated.toml")
    path.write_bytes(data.draw(mutated(seed)))
    with no_hang(path.name):
        try:
            rulebase = load_rulebase(path)
        except RuleBaseError as exc:
            assert "\n" not in str(exc).strip()
            return
    # What loads is usable: finite outputs, no numpy warnings, across and beyond the universes.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for fraction in (-0.5, 0.0, 0.37, 1.0, 2.0):
            row = {v.name: v.low + fraction * (v.high - v.low) for v in rulebase.inputs}
            batch = rulebase.evaluate({name: np.array([x]) for name, x in row.items()})
            for name, value in rulebase.evaluate_one(**row).items():
                assert math.isfinite(value) and math.isfinite(batch[name][0]), (row, name, value, batch[name][0])


@FUZZ
@given(data=mutated(CONFIG_TOML.encode()))
def test_config_loader(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("cfg") / "rover.toml"
    path.write_bytes(data)
    with no_hang(path.name):
        try:
            load_config(path)
        except ConfigError as exc:
            assert "\n" not in str(exc).strip()


@FUZZ
@given(data=st.data())
def test_mission_store_loader(tmp_path_factory, data):
    store = MissionStore(tmp_path_factory.mktemp("store") / "mission.json")
    store.save(sample_mission())
    store.path.write_bytes(data.draw(mutated(store.path.read_bytes())))
    with no_hang(store.path.name):
        try:
            store.load()
        except StoreError as exc:
            assert "\n" not in str(exc).strip()


def test_a_config_number_beyond_any_float_is_a_config_error(tmp_path):
    """TOML keeps integers exact: a 400-digit one reached the parameter table's float checks and
    ended in OverflowError (a traceback, and a service restart loop on exit 1)."""
    path = tmp_path / "rover.toml"
    path.write_text(CONFIG_TOML.replace("cruise_speed_mps = 1.0", "cruise_speed_mps = 1" + "0" * 400))
    with pytest.raises(ConfigError, match=r"executor.cruise_speed_mps: a 401-digit number is out of range"):
        load_config(path)
