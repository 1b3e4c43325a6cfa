"""Hypothesis settings of the fuzz suite: fast by default, longer on request.

``ROVER_FUZZ_EXAMPLES=N`` sets the examples per property (default 60, a few seconds in all);
e.g. ``ROVER_FUZZ_EXAMPLES=5000 pytest tests/fuzz`` for a long run. No deadline: the socket
properties time a real link on a shared machine.
"""

from __future__ import annotations

import os

from hypothesis import HealthCheck, settings

EXAMPLES = int(os.environ.get("ROVER_FUZZ_EXAMPLES", "60"))

settings.register_profile(
    "fuzz",
    max_examples=EXAMPLES,
    deadline=None,
    derandomize=os.environ.get("ROVER_FUZZ_SEED") is None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.function_scoped_fixture],
)
FUZZ = settings.get_profile("fuzz")
