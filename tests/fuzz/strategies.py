"""Hypothesis strategies shared by the fuzz properties (import as ``fuzz.strategies``)."""

from __future__ import annotations

import math

from hypothesis import strategies as st

from rover_ctl.mission.model import Home, Mission, MissionItem
from rover_ctl.vocabulary import Cmd

HOME = Home(-35.363261, 149.165230, 584.0)
HOSTILE_FLOATS = [math.nan, math.inf, -math.inf, 0.0, -0.0, 1.0, -1.0, 1e-45, 3.4e38, -3.4e38, 1e300, -1e300, 90.0, 180.0, 2**31]

floats = st.one_of(st.sampled_from(HOSTILE_FLOATS), st.floats(allow_nan=True, allow_infinity=True))
"""Any double, with the hostile ones often."""
floats32 = st.one_of(st.sampled_from([v for v in HOSTILE_FLOATS if not math.isfinite(v) or abs(v) < 3.4e38]),
                     st.floats(width=32, allow_nan=True, allow_infinity=True))
"""What a float32 field can carry."""
lats = st.one_of(st.floats(HOME.lat_deg - 1e-3, HOME.lat_deg + 1e-3), floats)
lons = st.one_of(st.floats(HOME.lon_deg - 1e-3, HOME.lon_deg + 1e-3), floats)
commands = st.one_of(st.sampled_from(list(Cmd)), st.integers(-10, 70000), st.integers(-(10**30), 10**30))
frames = st.one_of(st.sampled_from([0, 2, 3, 5, 6, 10, 11, 1]), st.integers(-5, 300))


@st.composite
def items(draw, command=commands) -> MissionItem:
    return MissionItem(
        command=draw(command), frame=draw(frames), param1=draw(st.one_of(st.integers(-3, 12).map(float), floats)),
        param2=draw(floats), param3=draw(floats), param4=draw(floats), x=draw(lats), y=draw(lons), z=draw(floats),
        autocontinue=draw(st.booleans()),
    )  # fmt: skip


fence_commands = st.one_of(st.sampled_from([5000, 5001, 5002, 5003, 5004]), commands)
homes = st.one_of(st.none(), st.just(HOME), st.builds(Home, lats, lons, floats))
missions = st.builds(
    Mission,
    items=st.lists(items(), max_size=8),
    home=homes,
    fence=st.lists(items(fence_commands), max_size=8),
    rally=st.lists(items(st.one_of(st.just(5100), commands)), max_size=3),
)
"""Any mission the store can hold: every field of any value its JSON can carry."""
