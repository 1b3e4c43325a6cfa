"""The vehicle-link failsafe on the wall clock (nothing at all from the vehicle) against a scripted
vehicle on a real UDP socket, with the daemon's and the link's wall clock faked: silence counts up
to the link's latest poll, so a daemon kept from its loop (a blocking write, a starved core) does
not mistake its own stall for the vehicle's silence. A suite run had the vehicle-link failsafe
fire against ArduPilot's firmware at 10x with the machine loaded."""

from __future__ import annotations

import os
import socket
from types import SimpleNamespace

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

import rover_ctl.app.daemon as daemon_module  # noqa: E402
from rover_ctl.app.daemon import Daemon  # noqa: E402
from rover_ctl.config import Config  # noqa: E402
from rover_ctl.mavlink.vehicle import VehicleLink, VehicleStatus  # noqa: E402
from rover_ctl.vocabulary import mav  # noqa: E402
from support import free_port  # noqa: E402

TIMEOUT_S = Config().failsafe.vehicle_timeout_s


@pytest.fixture
def rig(monkeypatch):
    clock = SimpleNamespace(t=100.0)
    port = free_port(socket.SOCK_DGRAM)
    link = VehicleLink(f"udpin:127.0.0.1:{port}", Config().link, wall=lambda: clock.t)
    vehicle = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1, source_component=1, dialect="ardupilotmega")
    daemon = Daemon(Config())
    daemon.link = link
    texts: list[str] = []
    daemon.gcs = SimpleNamespace(send_statustext=lambda text, severity: texts.append(text), send_mission_current=lambda seq, state: None)
    daemon.events = SimpleNamespace(write=lambda t_s, kind, **fields: None)
    monkeypatch.setattr(daemon_module, "time", SimpleNamespace(monotonic=lambda: clock.t, perf_counter=lambda: clock.t))
    heartbeat(vehicle)
    assert isinstance(link.wait_vehicle(2.0), VehicleStatus)
    yield SimpleNamespace(clock=clock, link=link, vehicle=vehicle, daemon=daemon, texts=texts)
    link.close()
    vehicle.close()


def heartbeat(vehicle) -> None:
    vehicle.mav.heartbeat_send(mav.MAV_TYPE_GROUND_ROVER, mav.MAV_AUTOPILOT_ARDUPILOTMEGA, mav.MAV_MODE_FLAG_SAFETY_ARMED, 0, 0)


def link_lost(rig) -> bool:
    return "vehicle link" in rig.daemon.autopilot.state().failsafes


def read_all(link: VehicleLink) -> list:
    link.wait_readable(0.5)
    return link.poll()


def test_a_stall_of_the_daemon_itself_is_not_the_vehicles_silence(rig):
    read_all(rig.link)  # the link last looked at 100.0 s and heard the vehicle then
    rig.clock.t += 3 * TIMEOUT_S  # the daemon kept from its loop; the vehicle went on sending
    heartbeat(rig.vehicle)
    rig.daemon._check_silence()
    assert not link_lost(rig) and rig.texts == []
    assert any(isinstance(item, VehicleStatus) for item in read_all(rig.link))  # the next look hears it
    rig.daemon._check_silence()
    assert not link_lost(rig)


def test_silence_seen_by_the_link_polls_sends_neutral(rig):
    read_all(rig.link)
    rig.clock.t += 0.9 * TIMEOUT_S
    assert rig.link.poll() == []
    rig.daemon._check_silence()
    assert not link_lost(rig)
    rig.clock.t += 0.2 * TIMEOUT_S  # looked again past the timeout, still nothing
    assert rig.link.poll() == []
    rig.daemon._check_silence()
    assert link_lost(rig) and any(t.startswith("FS vehicle link") for t in rig.texts)
