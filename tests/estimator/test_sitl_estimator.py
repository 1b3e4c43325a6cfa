"""The estimator on the real emulator's wire (separate process, lockstep): the sensor conventions
(NED yaw and yaw rate, cumulative wheel distances, GPS_RAW_INT units) and the glitch gate hold
against SIMSTATE truth."""

from __future__ import annotations

import json
import math

import pytest
from support.sitl import lockstep_client, rover_sitl

from rover_ctl.config import EstimatorParams, RobotParams
from rover_ctl.estimation.estimator import GpsVerdict, PoseEstimator
from rover_ctl.estimation.frame import LocalFrame, compass_to_enu_rad, wrap_pi
from rover_ctl.mavlink.vehicle import decode_gps
from rover_ctl.estimation.readings import Attitude, WheelDistance

pytestmark = pytest.mark.sitl

HOME = (-35.363261, 149.165230, 584.0)
GLITCH = (20.0, 3.0)  # start, duration: a 30 m jump north-east


def test_estimator_tracks_the_emulator_and_rejects_its_glitch(tmp_path):
    world = tmp_path / "glitch.geojson"
    world.write_text(json.dumps({"type": "FeatureCollection", "features": [], "faults": [
        {"name": "gps_glitch", "start_s": GLITCH[0], "duration_s": GLITCH[1], "north_m": 21.0, "east_m": 21.0}]}))
    frame = LocalFrame(*HOME)
    estimator = PoseEstimator(frame, EstimatorParams(), RobotParams().track_m)
    verdicts, errors_m, heading_errors_rad, healthy = [], [], [], []

    def on_frame(t_s, msgs):
        truth = None
        for msg in msgs:
            kind = msg.get_type()
            if kind == "WHEEL_DISTANCE":
                estimator.on_wheels(WheelDistance(msg.time_usec / 1e6, msg.distance[0], msg.distance[1]))
            elif kind == "ATTITUDE":
                estimator.on_attitude(Attitude(msg.time_boot_ms / 1000.0, msg.yaw, msg.yawspeed))
            elif kind == "GPS_RAW_INT":
                verdicts.append((t_s, estimator.on_gps(decode_gps(msg))))
            elif kind == "SIMSTATE":
                truth = msg
        if truth is not None and t_s >= 5.0:
            pose = estimator.pose()
            east, north = frame.to_enu(truth.lat / 1e7, truth.lng / 1e7)
            errors_m.append(math.hypot(pose.east_m - east, pose.north_m - north))
            heading_errors_rad.append(abs(wrap_pi(pose.heading_rad - compass_to_enu_rad(truth.yaw))))
            healthy.append(pose.healthy)
        return (1500, 1500) if t_s < 1.0 else (1850, 1600)  # a wide circle

    flags = ["--lockstep", "--seed", "7", f"--home={HOME[0]},{HOME[1]},{HOME[2]},0", "--world", str(world)]
    with rover_sitl(*flags) as sitl:
        client = lockstep_client(sitl.url)
        client.arm()
        client.run(35.0, on_frame)
        client.close()
    in_glitch = [v for t, v in verdicts if GLITCH[0] + 0.05 < t < sum(GLITCH) - 0.05]
    assert in_glitch and all(v is GpsVerdict.REJECTED for v in in_glitch)
    assert sum(v is GpsVerdict.ACCEPTED for t, v in verdicts if t > sum(GLITCH) + 0.5) > 50
    assert max(errors_m) < 3.0
    assert math.degrees(max(heading_errors_rad)) < 5.0
    assert all(healthy)
