"""Hand-written notes in a benchmark's results survive its rerun and reach docs/BENCHMARKS.md."""

from __future__ import annotations

import json
import sys
import types

import bench.__main__ as bench_main


def test_a_rerun_keeps_the_notes_and_the_doc_shows_them_after_the_figures(tmp_path, monkeypatch):
    figures = iter(["| run | 1 |", "| run | 2 |"])
    fake = types.ModuleType("bench.bench_fake")
    fake.run = lambda quick: {"title": "Fake", "markdown": next(figures)}
    monkeypatch.setitem(sys.modules, "bench.bench_fake", fake)
    monkeypatch.setattr(bench_main, "available", lambda: ["fake"])
    monkeypatch.setattr(bench_main, "RESULTS", tmp_path / "results")
    monkeypatch.setattr(bench_main, "DOC", tmp_path / "BENCHMARKS.md")

    assert bench_main.main(["fake"]) == 0
    path = tmp_path / "results" / "fake.json"
    result = json.loads(path.read_text())
    path.write_text(json.dumps(dict(result, notes=["Run 1 was on a loaded machine (2026-11-26)."])))
    assert bench_main.main(["fake"]) == 0

    result = json.loads(path.read_text())
    assert result["markdown"] == "| run | 2 |" and result["notes"] == ["Run 1 was on a loaded machine (2026-11-26)."]
    doc = (tmp_path / "BENCHMARKS.md").read_text()
    assert doc.index("| run | 2 |") < doc.index("Run 1 was on a loaded machine") and "| run | 1 |" not in doc
