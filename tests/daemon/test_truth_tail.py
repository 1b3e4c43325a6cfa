"""`rover-ctl sim` counts collisions from the emulator's truth log as it grows (no STATUSTEXT wording)."""

from __future__ import annotations

from rover_ctl.app.sim import TruthTail


def test_reads_whole_new_records_only(tmp_path):
    path = tmp_path / "truth.jsonl"
    tail = TruthTail(path)
    assert tail.read() == []  # not written yet
    with open(path, "w") as handle:
        handle.write('{"t_s":1.0,"type":"state"}\n{"t_s":1.5,"type":"collision","obstacle":"drum"}\n{"t_s":2')
    records = tail.read()
    assert [r["type"] for r in records] == ["state", "collision"]
    with open(path, "a") as handle:
        handle.write('.0,"type":"collision","obstacle":"wall"}\n')
    assert tail.read() == [{"t_s": 2.0, "type": "collision", "obstacle": "wall"}]
    assert tail.read() == []
