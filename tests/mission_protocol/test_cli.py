"""`rover-ctl mission ...` against a GcsLink over UDP."""

from __future__ import annotations

from pathlib import Path

import pytest
from mission_protocol.helpers import LinkThread

from rover_ctl.cli import main
from rover_ctl.config import GcsParams
from rover_ctl.mission.files import load_mission
from rover_ctl.mission.model import Mission
from rover_ctl.mission.store import MissionStore

MISSIONS = Path(__file__).resolve().parents[2] / "missions"
LINK = GcsParams(heartbeat_period_s=0.2)


def test_check_prints_the_summary(capsys):
    assert main(["mission", "check", str(MISSIONS / "boulder_fence.plan")]) == 0
    out = capsys.readouterr().out
    assert "valid plan mission" in out and "1 inclusion / 1 exclusion polygons" in out and "rally points: 1" in out


def test_check_refuses_a_bad_file_with_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.waypoints"
    bad.write_text("QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t-35.3\t149.1\t584\t1\n1\t0\t3\t16\t0\t0\t0\t0\t95.0\t149.1\t0\t1\n")
    assert main(["mission", "check", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("rover-ctl: error: ") and "bad.waypoints:3" in err and "latitude" in err


@pytest.mark.parametrize("name, out_name", [("cmac_loop.waypoints", "back.waypoints"), ("boulder_fence.plan", "back.plan")])
def test_upload_then_download_gives_the_file_back(udp_port, tmp_path, capsys, name, out_name):
    url = f"udpout:127.0.0.1:{udp_port}"
    original = load_mission(MISSIONS / name).mission
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=LINK) as lt:
        assert main(["mission", "upload", str(MISSIONS / name), "--connect", url, "--quiet"]) == 0
        assert lt.link.service.mission.same_as(original)
        out = tmp_path / out_name
        assert main(["mission", "download", str(out), "--connect", url, "--quiet"]) == 0
    assert load_mission(out).mission.same_as(original)
    assert "uploaded" in capsys.readouterr().out


def test_download_to_wpl_keeps_the_mission_and_names_what_it_left_out(udp_port, tmp_path, capsys):
    url = f"udpout:127.0.0.1:{udp_port}"
    plan = load_mission(MISSIONS / "boulder_fence.plan").mission
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=LINK):
        assert main(["mission", "upload", str(MISSIONS / "boulder_fence.plan"), "--connect", url, "--quiet"]) == 0
        assert main(["mission", "download", str(tmp_path / "m.waypoints"), "--connect", url, "--quiet"]) == 0
    assert load_mission(tmp_path / "m.waypoints").mission.same_as(Mission(items=plan.items, home=plan.home))
    note = f"not saved in a WPL file: {len(plan.fence)} fence, {len(plan.rally)} rally items; use .plan"
    assert note in capsys.readouterr().out


def test_clear_by_type(udp_port):
    url = f"udpout:127.0.0.1:{udp_port}"
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=LINK) as lt:
        assert main(["mission", "upload", str(MISSIONS / "boulder_fence.plan"), "--connect", url, "--quiet"]) == 0
        assert main(["mission", "clear", "--type", "fence", "--connect", url, "--quiet"]) == 0
        stored = lt.link.service.mission
        assert stored.fence == [] and stored.items and stored.rally
        assert main(["mission", "clear", "--type", "all", "--connect", url, "--quiet"]) == 0
        assert not (lt.link.service.mission.items or lt.link.service.mission.rally)


def test_no_autopilot_is_a_one_line_timeout_error(udp_port, capsys):
    code = main(["mission", "upload", str(MISSIONS / "cmac_jump.waypoints"), "--connect", f"udpout:127.0.0.1:{udp_port}", "--timeout", "0.5"])
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert err == f"rover-ctl: error: udpout:127.0.0.1:{udp_port}: no autopilot heartbeat within 0.5 s"


def test_a_refused_upload_is_a_one_line_error(udp_port, tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("")
    with LinkThread(f"udpin:127.0.0.1:{udp_port}", params=LINK, store=MissionStore(blocker / "mission.json")):
        code = main(["mission", "upload", str(MISSIONS / "cmac_jump.waypoints"), "--connect", f"udpout:127.0.0.1:{udp_port}", "--quiet"])
    assert code == 2
    assert capsys.readouterr().err.strip() == "rover-ctl: error: mission upload refused by the vehicle: MAV_MISSION_ERROR"
