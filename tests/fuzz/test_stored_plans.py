"""The daemon's core never raises on a plan its store can hold (one an older version may have
written without checking it): invalid parts are left out with a warning, the rest runs.

The core is built as ``rover_ctl.app.daemon.Daemon._load_mission_into_core`` builds it: the fence
for the planner, the path follower, the mission executor; then driven for a few steps in AUTO and
RTL, as the control step would."""

from __future__ import annotations

from fuzz.conftest import FUZZ
from fuzz.strategies import HOME, missions
from hypothesis import given
from mission_protocol.helpers import from_sender
from pymavlink.dialects.v20 import ardupilotmega as mav

from rover_ctl.autopilot.executor import MissionExecutor
from rover_ctl.config import Config
from rover_ctl.estimation.frame import LocalFrame
from rover_ctl.mavlink.mission import MissionService, wire_items
from rover_ctl.mission.model import Mission, MissionType
from rover_ctl.mission.store import MissionStore
from rover_ctl.navigation.planner import Fence, PathFollower, Planner

CONFIG = Config()
FRAME = LocalFrame(HOME.lat_deg, HOME.lon_deg, HOME.alt_m)
STEPS = 6


def build_core(mission: Mission):
    """What the daemon builds for a mission once it has a home (see the module docstring)."""
    fence = Fence.from_items(mission.fence, FRAME.to_enu) if mission.fence else Fence()
    planner = Planner(CONFIG.planner, CONFIG.robot, fence=fence)
    follower = PathFollower(planner, CONFIG.planner)
    executor = MissionExecutor(mission.items, FRAME.to_enu, CONFIG.executor, CONFIG.robot.max_speed_mps)
    return planner, follower, executor


def drive(planner, follower, executor) -> None:
    position = (0.0, 0.0)
    executor.start()
    for step in range(STEPS):
        t_s = step * 0.5
        out = executor.update(t_s, position)
        planner.is_inside_fence(position)
        if out.target_en is not None:
            guidance = follower.update(t_s, position, out.target_en)
            if guidance.target_en is not None:
                position = guidance.target_en
    executor.rtl()
    out = executor.update(STEPS * 0.5, position)
    follower.update(STEPS * 0.5, position, out.target_en)


@FUZZ
@given(mission=missions)
def test_the_core_runs_any_plan_the_store_can_hold(tmp_path_factory, mission):
    store = MissionStore(tmp_path_factory.mktemp("store") / "mission.json")
    store.save(mission)
    stored = store.load()  # what a restarted daemon reads
    drive(*build_core(stored))
    # ... and what a ground station downloads from it
    service = MissionService(stored)
    for kind in MissionType:
        for seq, _ in enumerate(wire_items(stored, kind)):
            (reply,) = service.handle(from_sender(mav.MAVLink_mission_request_int_message(1, 1, seq, kind)), 0.0)
            assert reply.get_type() == "MISSION_ITEM_INT"
            reply.pack(mav.MAVLink(None))  # what the link sends must fit its fields
