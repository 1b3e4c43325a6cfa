"""Each benchmark result names the machine: its CPU and a reference workload's CPU time."""

from __future__ import annotations

import json
import re
import sys
import types

import bench.__main__ as bench_main
from bench import machine


def test_the_reference_workload_is_fixed_work():
    assert machine.reference_workload(1000) == machine.reference_workload(1000)
    assert machine.reference_ms(min_cpu_s=0.0) > 0.0 and machine.fresh_reference_ms() > 0.0


def test_a_run_names_the_cpu_and_its_reference_time(tmp_path, monkeypatch):
    fake = types.ModuleType("bench.bench_fake")
    fake.run = lambda quick: {"title": "Fake", "markdown": "| run | 1 |"}
    monkeypatch.setitem(sys.modules, "bench.bench_fake", fake)
    monkeypatch.setattr(bench_main, "available", lambda: ["fake"])
    monkeypatch.setattr(bench_main, "RESULTS", tmp_path / "results")
    monkeypatch.setattr(bench_main, "DOC", tmp_path / "BENCHMARKS.md")

    assert bench_main.main(["fake"]) == 0
    named = json.loads((tmp_path / "results" / "fake.json").read_text())["machine"]
    assert machine.cpu_model() in named
    assert re.search(r"reference \d+(\.\d+)? / \d+(\.\d+)? ms before / after", named)
    assert named in (tmp_path / "BENCHMARKS.md").read_text()
