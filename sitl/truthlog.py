"""The truth log (``--truth-log FILE.jsonl``): ground truth and sensor error components, as JSON lines.

Records (docs/architecture.md): ``state`` at ``STATE_RATE_HZ`` with the rover's TruthState fields,
``gps`` for each fix sent or dropped (reported position and its error components), ``collision``
and ``fault`` events. Every record carries ``t_s`` (sim time) and ``type``.
"""

from __future__ import annotations

import dataclasses
import json
from typing import IO

STATE_RATE_HZ = 10.0
"""Rate of ``state`` records in sim time."""


class TruthLog:
    """Writes records to a file object; ``close`` flushes (the main loop calls it on any exit)."""

    def __init__(self, stream: IO[str]) -> None:
        self.stream = stream
        self.next_state_s = 0.0

    def write(self, record: dict) -> None:
        self.stream.write(json.dumps(record, separators=(",", ":")) + "\n")

    def state(self, t_s: float, truth) -> None:
        """A ``state`` record if one is due at ``t_s``."""
        if t_s + 1e-9 < self.next_state_s:
            return
        self.next_state_s += 1.0 / STATE_RATE_HZ
        fields = {k: v for k, v in dataclasses.asdict(truth).items() if k != "time_s"}
        self.write({"t_s": t_s, "type": "state", **fields})

    def gps(self, t_s: float, sample) -> None:
        if sample is None:
            self.write({"t_s": t_s, "type": "gps", "dropped": True})
            return
        self.write({
            "t_s": t_s, "type": "gps", "dropped": False, "lat_deg": sample.lat_deg, "lon_deg": sample.lon_deg,
            "err_white_e_m": sample.err_white_en_m[0], "err_white_n_m": sample.err_white_en_m[1],
            "err_bias_e_m": sample.err_bias_en_m[0], "err_bias_n_m": sample.err_bias_en_m[1],
            "err_glitch_e_m": sample.err_glitch_en_m[0], "err_glitch_n_m": sample.err_glitch_en_m[1],
        })

    def event(self, t_s: float, kind: str, detail: dict) -> None:
        self.write({"t_s": t_s, "type": kind, **detail})

    def close(self) -> None:
        self.stream.flush()
        self.stream.close()
