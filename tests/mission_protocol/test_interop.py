"""Third-party ground stations against a GcsLink: MAVProxy (a process) and MAVSDK-Python 4."""

from __future__ import annotations

import asyncio
import queue
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from mission_protocol.helpers import LinkThread

from rover_ctl.config import GcsParams
from rover_ctl.mavlink.gcs import DefaultHandlers
from rover_ctl.vocabulary import RoverMode
from rover_ctl.mission.files import load_mission, save_mission
from rover_ctl.mission.model import Mission, MissionItem
from rover_ctl.mavlink.mission import decode_xy

pytestmark = pytest.mark.interop

MISSIONS = Path(__file__).resolve().parents[2] / "missions"
VENV_BIN = Path(sys.executable).parent
LINK = GcsParams(heartbeat_period_s=0.2)
MAVPROXY_STARTUP_S = 60.0
"""Wall seconds allowed for MAVProxy's first line (the wait returns as soon as it comes)."""


class MavProxy:
    """MAVProxy as a child process, driven through its stdin (``--cmd`` runs before the link is up)."""

    def __init__(self, port: int, workdir: Path, modules: str = "wp,fence,rally,mode,arm") -> None:
        mavproxy = VENV_BIN / "mavproxy.py"
        if not mavproxy.exists():
            pytest.skip(f"{mavproxy} is not installed")
        self.proc = subprocess.Popen(
            [sys.executable, str(mavproxy), f"--master=udpout:127.0.0.1:{port}", f"--state-basedir={workdir}",
             f"--default-modules={modules}", "--nowait"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=workdir,
        )  # fmt: skip
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.put(line)

    def send(self, command: str) -> None:
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()

    def wait_for(self, text: str, timeout_s: float = 10.0) -> str:
        if not self.seen:  # its first line comes after its own start-up, seconds on a loaded 2-core host
            timeout_s = max(timeout_s, MAVPROXY_STARTUP_S)
        end = time.monotonic() + timeout_s
        while (left := end - time.monotonic()) > 0:
            try:
                line = self.lines.get(timeout=left)
            except queue.Empty:
                break
            self.seen.append(line.rstrip())
            if text in line:
                return line
        raise AssertionError(f"MAVProxy never printed {text!r}; its output:\n" + "\n".join(self.seen[-30:]))

    def close(self) -> None:
        """End of input makes MAVProxy stop (its exit status is 1 even then, so it is not checked)."""
        self.proc.stdin.close()
        try:
            self.proc.wait(5.0)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def test_mavproxy_uploads_reads_back_and_starts_a_mission(udp_port, tmp_path):
    mission = load_mission(MISSIONS / "cmac_loop.waypoints").mission
    fence_source = load_mission(MISSIONS / "boulder_fence.plan").mission
    fence_file = tmp_path / "fence.waypoints"
    save_mission(Mission(fence=fence_source.fence), fence_file)
    handlers = DefaultHandlers()
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=LINK, handlers=handlers) as lt:
        mp = MavProxy(udp_port, tmp_path)
        try:
            mp.wait_for("Detected vehicle 1:1")
            mp.send(f"wp load {MISSIONS / 'cmac_loop.waypoints'}")
            mp.wait_for("TYPE_MISSION: ACCEPTED")
            mp.send(f"wp save {tmp_path / 'back.waypoints'}")
            mp.wait_for("Saved")
            mp.send(f"fence load {fence_file}")
            mp.wait_for("TYPE_FENCE: ACCEPTED")
            mp.send("arm throttle")
            mp.wait_for("ARM_DISARM: ACCEPTED")
            mp.send("mode AUTO")
            mp.wait_for("AUTO>")
        finally:
            mp.close()
        stored = lt.link.service.mission
    assert stored.same_as(Mission(items=mission.items, home=mission.home, fence=fence_source.fence))
    assert load_mission(tmp_path / "back.waypoints").mission.same_as(mission)
    assert handlers.armed and handlers.custom_mode == RoverMode.AUTO


def _model(item) -> MissionItem:
    """A MAVSDK MissionRaw item -> our model (x/y scaled by frame as on the wire)."""
    x, y = decode_xy(item.frame, item.x, item.y)
    return MissionItem(item.command, item.frame, item.param1, item.param2, item.param3, item.param4, x, y, item.z, bool(item.autocontinue))


def test_mavsdk_imports_a_plan_uploads_and_reads_it_back(udp_port):
    mavsdk = pytest.importorskip("mavsdk")
    from mavsdk.asyncio.mavsdk import Configuration, Mavsdk
    from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync

    plan = load_mission(MISSIONS / "boulder_fence.plan").mission

    async def session() -> tuple:
        config = Configuration.create_with_component_type(mavsdk.ComponentType.GROUND_STATION)
        async with Mavsdk(config) as sdk:
            await sdk.add_any_connection(f"udpout://127.0.0.1:{udp_port}")
            system = await sdk.first_autopilot(timeout_s=5.0)
            assert system is not None, "MAVSDK found no autopilot"
            raw = MissionRawAsync(system)
            try:
                data = await raw.import_qgroundcontrol_mission(str(MISSIONS / "boulder_fence.plan"))
                await raw.upload_mission(data.mission_items)
                await raw.upload_geofence(data.geofence_items)
                await raw.upload_rally_points(data.rally_items)
                back = (await raw.download_mission(), await raw.download_geofence(), await raw.download_rallypoints())
                return data, back
            finally:
                raw.destroy()

    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=LINK) as lt:
        data, (items, fence, rally) = asyncio.run(asyncio.wait_for(session(), 30.0))
        stored = lt.link.service.mission
    assert stored.same_as(plan)
    sent = [_model(i) for i in data.mission_items]
    got = [_model(i) for i in items]
    assert len(got) == len(sent) == len(plan.items) + 1
    assert all(a.same_as(b) for a, b in zip(got[1:], sent[1:]))
    assert (got[0].x, got[0].y, got[0].z) == pytest.approx((sent[0].x, sent[0].y, sent[0].z))  # home (frame may differ)
    assert all(a.same_as(b) for a, b in zip([_model(i) for i in fence], plan.fence)) and len(fence) == len(plan.fence)
    assert [_model(i).same_as(p) for i, p in zip(rally, plan.rally)] == [True] * len(plan.rally)
