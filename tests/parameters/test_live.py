"""A parameter set from a ground station takes effect the same way for every parameter: at once,
in the object that uses it, with no stale copy anywhere.

Generic over the table: for every parameter a ground station may set (Access.RW), and every
exercise of an object that reads it, the objects are built by the daemon and its autopilot
(``Daemon.__init__``, ``_set_home``, ``Autopilot.mission_changed``: their real wiring) and

    A  run with the defaults,
    B  built with the defaults, then the parameter set through ``ConfigParams.set_param`` (the
       PARAM_SET path), then run,
    C  built with the new value in the config from the start, then run.

B must equal C (the change reached every use: a value copied at construction would make B
behave like A), and for some new value C must differ from A in at least one exercise (the
exercise really depends on the parameter, so the test cannot pass vacuously)."""

from __future__ import annotations

import dataclasses
import math
from functools import cache
from types import SimpleNamespace

import pytest
from estimator.synthetic import CMAC, Sensors, simulate

import rover_ctl.app.daemon as daemon_module
from rover_ctl.app.daemon import Daemon
from rover_ctl.config import Config, ObstacleMapParams
from rover_ctl.estimation.readings import Attitude, GpsFix, RangeReading, WheelDistance
from rover_ctl.mavlink.params import ConfigParams
from rover_ctl.mission.model import Mission, MissionItem
from rover_ctl.navigation.sensors import BACK
from rover_ctl.navigation.tracks import Track
from rover_ctl.autopilot import prearm
from rover_ctl.autopilot.autopilot import LOG_COLUMNS
from rover_ctl.autopilot.failsafe import Action, FailsafeDecision, FailsafeInputs
from rover_ctl.fuzzy import load_rulebase
from rover_ctl.parameters import TABLE, Access, Kind, Param
from rover_ctl.vocabulary import Cmd, RoverMode

HOME_FIX = GpsFix(0.0, *CMAC.to_geodetic(0.0, 0.0), 584.0, 3, 1.0, 0.0, 0.0, 10)
"""The first fix: the daemon anchors its frame (and builds the estimator) here, at CMAC."""


@cache
def _rulebase(name: str):
    return load_rulebase(name)


def build(config: Config) -> Daemon:
    """The daemon's objects for ``config``, wired by the daemon itself (no links are opened)."""
    original = daemon_module.load_rulebase
    daemon_module.load_rulebase = _rulebase  # parse the rule base once for the whole module
    try:
        daemon = Daemon(config, rulebase="paper")
    finally:
        daemon_module.load_rulebase = original
    # No GCS link: the messages of the autopilot's events go nowhere.
    daemon.gcs = SimpleNamespace(send_statustext=lambda text, severity: None, send_mission_current=lambda seq, state: None,
                                 send_mission_item_reached=lambda seq: None)  # fmt: skip
    return daemon


def with_mission(daemon: Daemon, items: list[MissionItem], fence: list[MissionItem] = ()) -> Daemon:
    daemon._set_home(HOME_FIX)
    daemon.autopilot.mission_changed(Mission(items=items, fence=list(fence)), 0)
    return daemon


def latlon(east_m: float, north_m: float) -> tuple[float, float]:
    return CMAC.to_geodetic(east_m, north_m)


def wp(east_m: float, north_m: float, radius_m: float = 0.0) -> MissionItem:
    lat, lon = latlon(east_m, north_m)
    return MissionItem(Cmd.NAV_WAYPOINT, param2=radius_m, x=lat, y=lon)


# ---- exercises: each drives one object of the daemon and returns what it decided, step by step --


def ex_failsafes(d: Daemon) -> list:
    fs, trace = d.autopilot.failsafes, []
    fs.used_rangefinders = frozenset({0, 1, 2, 4, 6})  # as a rangefinder plan sets them
    position = [0.0, 0.0]
    for k in range(1100):
        t = k * 0.1

        def ramp(start: float, end: float, fresh: float) -> float:
            return t - start if start <= t < end else fresh

        if 80.0 <= t < 83.0:
            position[0] += 0.1  # drives 3 m clear after the back-offs
        inputs = FailsafeInputs(
            vehicle_age_s=ramp(5, 9, 0.02),
            gcs_age_s=ramp(10, 25, 0.5),
            gps_age_s=ramp(28, 55, 0.1),
            range_ages_s=(ages := {0: ramp(62, 65, 0.02), 1: ramp(63, 66, 0.02), 2: 0.02, 4: 0.02, 6: ramp(64, 64.4, 0.02)}),
            range_times_s={o: t - a for o, a in ages.items()},
            estimator_healthy=not 57.0 <= t < 58.5,
            inside_fence=not 60.0 <= t < 61.0,
            driving=t >= 66.0,
            commanded_speed_mps=0.5 if t < 86.0 else 0.25 if t < 92.0 else 0.05,
            wants_progress=t >= 92.0,  # parked by the rule base
            position_en=tuple(position),
            sensor_rates_hz={"ATTITUDE": 2.5 if 70.0 <= t < 72.0 else 25.0, "WHEEL_DISTANCE": 25.0},
        )
        decision = fs.update(t, inputs)
        trace.append((decision.action, decision.reasons, [e.text for e in decision.events], decision.blocked_orientations,
                      decision.dead_reckoning, decision.replan, decision.stuck_tries, decision.speed_limit_mps))  # fmt: skip
    return trace


def ex_degraded(d: Daemon) -> list:
    """The failsafe run again on a rover whose front rangefinder may fail (not required)."""
    d.config.failsafe.required_rangefinders = [2, 4, 6]
    return ex_failsafes(d)


def mission_for_executor(d: Daemon) -> None:
    unchanged_speed = MissionItem(Cmd.DO_CHANGE_SPEED, param1=1.0, param2=0.0)
    items = [wp(0, 12), unchanged_speed, unchanged_speed, unchanged_speed, wp(10, 12, radius_m=1.0), MissionItem(Cmd.NAV_RETURN_TO_LAUNCH), wp(5, 0)]
    with_mission(d, items)


def ex_executor(d: Daemon) -> list:
    ex = d.autopilot.executor
    trace = [[e.text for e in ex.start()]]
    position = (0.0, 0.0)
    for k in range(700):
        t = k * 0.1
        if k == 450:
            trace.append([e.text for e in ex.rtl()])
            position = (20.0, 20.0)
        out = ex.update(t, position)
        trace.append((out.target_en, out.speed_limit_mps, out.hold, out.acceptance_radius_m, out.current_seq, [e.text for e in out.events]))
        if out.target_en is not None and not out.hold:
            de, dn = out.target_en[0] - position[0], out.target_en[1] - position[1]
            step = min(math.hypot(de, dn), out.speed_limit_mps * 0.1)
            if step > 0:
                scale = step / math.hypot(de, dn)
                position = (position[0] + de * scale, position[1] + dn * scale)
    return trace


def ex_navigator(d: Daemon) -> list:
    nav, trace = d.autopilot.navigator, []
    for heading in (0.0, 1.0, 2.5):
        for target in ((5.0, 0.0), (0.0, 8.0), (-3.0, -2.0)):
            for ranges in ({0: 0.8, 2: 2.0, 4: 3.5, 6: 1.2}, {0: 1.5, 6: 0.6}, {}):
                for limit in (None, 0.3, 2.0):
                    out = nav.step(0.0, 0.0, heading, target[0], target[1], ranges, limit)
                    trace.append((out.left_rpm, out.right_rpm))
    return trace


def ex_wheels(d: Daemon) -> list:
    wheels = d.autopilot.wheels
    trace = [dataclasses.astuple(wheels.neutral())]
    left = right = 0.0
    for k in range(250):
        t = k * 0.02
        speed = 0.3 if t < 2.0 else 0.6  # the wheels turn slower than asked: the integrator grows
        left += speed * 0.02
        right += (speed - 0.1) * 0.02
        if not 3.0 <= t < 3.5:  # a gap in WHEEL_DISTANCE
            wheels.on_wheels(WheelDistance(t, left, right))
        cmd = wheels.step(t, 0.02, 150.0 if k < 200 else -40.0, 120.0 if k < 200 else 40.0)
        trace.append(dataclasses.astuple(cmd) + (wheels.meter.left_rpm, wheels.meter.right_rpm))
    for k in range(30):  # braking from 0.6 m/s at 3 m/s^2
        t = 5.0 + k * 0.02
        speed = max(0.0, 0.6 - 3.0 * k * 0.02)
        left += speed * 0.02
        right += speed * 0.02
        wheels.on_wheels(WheelDistance(t, left, right))
        cmd = wheels.brake(t, 0.02)
        trace.append(None if cmd is None else dataclasses.astuple(cmd))
    return trace


def ex_proximity(d: Daemon) -> list:
    memory, trace = d.autopilot.proximity, []
    for k in range(40):
        t = k * 0.1
        heading = 0.05 * k
        memory.add(t, 0.1 * k, 0.0, heading, k % 8, 1.0 + 0.05 * k)
        memory.add(t, 0.1 * k, 0.0, heading, 0, 2.0)
        if k % 4 == 0:
            ranges = memory.ranges(t + 0.3 * (k % 12), 0.1 * k, 0.05, heading + 0.4, {o: 4.0 for o in range(8)})
            trace.append(sorted(ranges.items()))
    return trace


def predicting(d: Daemon) -> None:
    """Prediction on, unless the parameter under test set its horizon: the tracker's parameters
    change what the navigator sees only then."""
    if d.config.proximity.horizon_s == 0.0:
        d.config.proximity.horizon_s = 2.0


def ex_tracks(d: Daemon) -> list:
    memory, trace = d.autopilot.proximity, []
    for k in range(60):  # a pedestrian crossing 2 m ahead at 0.8 m/s, the front beam following it
        t = k * 0.1
        east, north = 2.0, -3.0 + 0.8 * t
        memory.add(t, 0.0, 0.0, math.atan2(north, east), 0, math.hypot(east, north))
        if k % 7 == 0:
            memory.add(t, 0.0, 0.0, 0.0, 6, 1.0 + 0.1 * k)  # a stray echo on the left now and then
        if k % 5 == 0:
            trace.append(sorted(memory.ranges(t, 0.0, 0.0, 0.0, {o: 4.0 for o in (0, 1, 2, 6, 7)}).items()))
            trace.append([(tr.ident, tr.hits, round(tr.v_east_mps, 9), round(tr.v_north_mps, 9)) for tr in memory.tracker.confirmed(t)])
    for k in range(20):  # then driving east at 1 m/s beside a wall: the left beam's echo slides along it
        t = 6.0 + k * 0.1
        memory.add(t, 0.1 * k, 5.0, 0.0, 6, 1.5)
        trace.append([tr.ident for tr in memory.tracker.moving(t, (1.0, 0.0))])
    return trace


def ex_yielding(d: Daemon) -> list:
    """The rover drives north at 1.2 m/s (when let) past obstacles crossing at several angles and
    speeds; one track is lost halfway and must be waited for as last seen."""
    yielder, trace = d.autopilot.yielder, []
    for ve, vn, speed_limit in ((0.8, 0.0, 1.2), (0.45, -0.45, 1.2), (0.5, -0.3, 1.2), (0.17, 0.0, 1.2), (0.12, 0.0, 1.2),
                                (0.6, 0.3, 1.2), (0.6, 0.0, 0.4)):  # fmt: skip
        yielder._yielding.clear()
        north = 0.0
        for k in range(150):
            t = k * 0.1
            hits, vv = (5 + k, 0.3 / (1 + k)) if k < 40 or ve < 0.5 else (0, 0.0)
            tracks = [Track(1, t, -2.5 + ve * t, 3.5 + vn * t, ve, vn, b=(vv, 0.0, vv), hits=hits, born_en=(-2.5 - 4.0 * ve, 3.5))] if hits else []
            decision = yielder.limit(0.0, north, math.pi / 2, speed_limit, tracks, t, heading_rad=math.pi / 2 - 0.01 * k)
            speed = speed_limit if decision.speed_limit_mps is None else decision.speed_limit_mps
            north += speed * 0.1
            trace.append((decision.speed_limit_mps, decision.track_ident))
    yielder._yielding.clear()  # just back from stepping aside, 40 degrees off the course: the tighter limit for a while
    yielder.evaded(20.0)
    for k in range(40):
        t = 20.0 + 0.1 * k
        track = Track(2, t, -2.0 + 0.8 * k * 0.1, 2.0, 0.8, 0.0, hits=20, born_en=(-4.0, 2.0))
        trace.append(yielder.limit(0.0, 0.0, math.pi / 2, 1.2, [track], t, heading_rad=math.pi / 2 - math.radians(40.0)).speed_limit_mps)
    return trace


def ex_yield_switch(d: Daemon) -> list:
    """Whether echoes are tracked (the yielder's input) and the yielder acts at all."""
    memory = d.autopilot.proximity
    for k in range(20):
        memory.add(k * 0.1, 0.0, 0.0, 0.0, 0, 2.0 + 0.05 * k)
    return [len(memory.tracker.tracks), ex_yielding(d)[:60]]


def ex_evasion(d: Daemon) -> list:
    """The rover drives north at 1.2 m/s (as the evader lets it) towards walkers coming head-on at
    several offsets and speeds: one whose velocity swings sideways mid-manoeuvre, one with the
    right diagonal blocked, one met while slow, one at the edge of the track's maturity, one that
    turns to walk across and away once the rover steps aside; in each, something else read 0.5 m
    ahead for a moment."""
    from rover_ctl.navigation.tracks import Track

    evader, trace = d.autopilot.evader, []
    cases = ((0.0, -0.9, 0, 0.0, 1.2, 20, 0.0, 0), (0.3, -0.5, 0, 0.0, 1.2, 7, 0.1, 0), (-0.2, -0.7, 1, 0.0, 1.2, 20, 0.0, 0),
             (0.0, -0.8, 0, 0.6, 1.2, 20, 0.0, 0), (0.1, -0.3, 0, 0.0, 0.7, 6, 0.1, 0), (0.0, -1.0, 0, 0.0, 1.2, 20, 0.13, 0),
             (0.6, -0.6, 0, 0.0, 1.2, 20, 0.0, 0), (0.0, -0.25, 0, 0.0, 1.2, 20, 0.0, 0), (0.0, -0.9, 0, 0.0, 1.2, 20, 0.0, 1))  # fmt: skip
    for offset, vn, swing, blocked_right, speed0, hits, vv, leaves in cases:
        evader.reset()
        x, y, psi, v = 0.0, 0.0, math.pi / 2 + 0.3 * offset, speed0
        stepped_aside = False
        for k in range(120):
            t = k * 0.05
            stepped_aside |= evader.active
            we, wn = offset + (0.3 * vn if offset > 0.5 else 0.0) * t, 4.5 + vn * t
            v_east = (0.3 * vn if offset > 0.5 else 0.0) + (-0.7 if swing and evader.active else 0.0)
            v_east, v_north = (0.8, 0.3) if leaves and stepped_aside else (v_east, vn)
            tracks = [Track(1, t, we, wn, v_east, v_north, b=(vv, 0.0, vv), hits=hits, born_en=(offset, 4.5 - 0.1 * k * vn))]
            course = math.atan2(30.0 - y, -x)
            out = evader.step(t, x, y, psi, v, course, 1.2, tracks, {0: 0.5 if k % 40 == 20 else 4.0, 1: 4.0 - blocked_right * 5, 7: 4.0}, may_start=k % 40 != 3)
            speed, omega = (1.2, 3.0 * math.remainder(course - psi, math.tau)) if out is None else (out.speed_mps, out.yaw_rate_radps)
            psi += omega * 0.05
            v += max(-0.05, min(0.05, speed - v))
            x, y = x + v * math.cos(psi) * 0.05, y + v * math.sin(psi) * 0.05
            trace.append(None if out is None else (round(out.speed_mps, 9), round(out.yaw_rate_radps, 9)))
    return trace


def ex_side_guard(d: Daemon) -> list:
    """The rule base's wheels along a leg north, with something at the left or right flank at
    several ranges (the side guard turns the rover away from it), then turned 35 degrees right of
    the leg (the rule base slows to turn back; the guard keeps the passing speed while the front
    reads clear), the last with something ahead too; then its target behind and a walker tracked
    behind its left rear quarter (it drives on instead of pivoting towards it)."""
    from rover_ctl.estimation.readings import RangeReading

    ap, trace = d.autopilot, []
    clear = FailsafeDecision(Action.NONE, (), (), frozenset(), False, False)
    cases = ((4.0, 4.0, 4.0, 0), (0.2, 4.0, 4.0, 0), (0.3, 4.0, 4.0, 0), (4.0, 0.25, 4.0, 0), (0.45, 0.3, 4.0, 0), (0.2, 0.2, 4.0, 0),
             (0.25, 4.0, 4.0, -35), (0.25, 4.0, 1.2, -35))  # fmt: skip
    for k, (left_m, right_m, front_m, off_deg) in enumerate(cases):
        pose = SimpleNamespace(east_m=0.0, north_m=0.0, heading_rad=math.pi / 2 + math.radians(off_deg), speed_mps=1.0)
        ap._ranges = {o: RangeReading(k * 10.0, o, o, r, 0.2, 4.0) for o, r in ((6, left_m), (2, right_m), (0, front_m))}
        row = dict.fromkeys(LOG_COLUMNS, "")
        ap._drive(k * 10.0, 0.04, pose, (0.0, 20.0), 1.2, 1, clear, row)  # 10 s apart: the memory forgets
        trace.append((round(row["left_set_rpm"], 9), round(row["right_set_rpm"], 9), row["side_turn_radps"], row["side_pass_mps"]))
    # Its target behind, a walker behind its left rear quarter (1.3 m off, 0.6 m from its first echo).
    pose = SimpleNamespace(east_m=0.0, north_m=0.0, heading_rad=math.pi / 2, speed_mps=0.2)
    ap._ranges = {o: RangeReading(100.0, o, o, 4.0, 0.2, 4.0) for o in (0, 1, 2, 6, 7)}
    ap.proximity.tracker.tracks = [Track(1, 100.0, -0.9, -0.9, 0.3, 0.3, hits=20, last_echo_s=100.0, born_en=(-1.3, -1.35))]
    row = dict.fromkeys(LOG_COLUMNS, "")
    ap._drive(100.0, 0.04, pose, (-3.0, -20.0), 1.2, 1, clear, row)
    trace.append((round(row["left_set_rpm"], 9), round(row["right_set_rpm"], 9), row["side_rear"]))
    return trace


def ex_rejoin(d: Daemon) -> list:
    """The carrot and the wheels of a rover 1.5 m off its leg north, 1 s, 5.9 s and 8 s after a
    manoeuvre of the evader: rejoining the path, then not."""
    from rover_ctl.estimation.readings import RangeReading

    ap, trace = d.autopilot, []
    clear = FailsafeDecision(Action.NONE, (), (), frozenset(), False, False)
    for k, since_s in enumerate((1.0, 5.9, 8.0)):
        t_s = 100.0 * (k + 1)
        ap.follower.reset()
        for east_m, north_m in ((0.0, 0.0), (-1.5, 4.0)):  # the path planned from the leg's start, then 1.5 m off it
            ap._evaded_s = t_s - since_s
            pose = SimpleNamespace(east_m=east_m, north_m=north_m, heading_rad=math.pi / 2, speed_mps=1.0)
            ap._ranges = {o: RangeReading(t_s, o, o, 4.0, 0.2, 4.0) for o in (0, 1, 2, 6, 7)}
            row = dict.fromkeys(LOG_COLUMNS, "")
            ap._drive(t_s, 0.04, pose, (0.0, 20.0), 1.2, 1, clear, row)
        trace.append((round(row["target_east_m"], 9), round(row["target_north_m"], 9), round(row["left_set_rpm"], 9), round(row["right_set_rpm"], 9)))
    return trace


def mapping(d: Daemon) -> None:
    """A mission ahead, and the persistent-obstacle map on (whatever the default)."""
    mission_ahead(d)
    d.config.obstacle_map.enabled = True


def ex_obstacle_map(d: Daemon) -> list:
    """A rover driving north up to a wall across its leg with a short one in front of it, that
    one taken away halfway (the beams see through where it was) and another put up on the left,
    then 40 s without echoes:
    what the map hands the planner, and the path, at each step."""
    ap, trace = d.autopilot, []
    walls = [((-2.0, 6.0), (2.0, 6.0)), ((0.8, 4.2), (1.6, 5.6)), ((-1.5, 4.5), (-0.8, 5.2))]
    odo = ap.odometry  # the wheels' frame: turned and shifted against the pose's (its cells fall elsewhere)
    odo.on_gyro(0.0, 0.0)
    odo.east_m, odo.north_m, odo.heading_rad = 0.13, 0.21, 0.3
    for k in range(500):
        t = k * 0.04
        north = min(0.02 * k, 3.0)
        odo.on_wheels(north, north)
        pose = SimpleNamespace(east_m=0.0, north_m=north, heading_rad=math.pi / 2, speed_mps=0.5)
        axis = math.pi / 2 + 0.7 * math.sin(k * 0.37)
        r = math.inf
        for (ax, ay), (bx, by) in walls[:2] if t < 12.0 else walls[:1] + walls[2:]:
            # beam (0, north) + s (cos, sin) against the segment a + u (b - a)
            dx, dy, ex, ey = math.cos(axis), math.sin(axis), bx - ax, by - ay
            det = ex * dy - ey * dx
            if abs(det) > 1e-9:
                s = (ex * (ay - north) - ey * ax) / det
                u = (dx * (ay - north) - dy * ax) / det
                if 0.0 <= u <= 1.0 and 0.0 < s <= 4.0:
                    r = min(r, s)
        ap._map_add(t, (0.0, north), axis, r, 4.0)
        row: dict = {}
        ap._update_obstacle_map(t, pose, row)
        g = ap.follower.update(t, (0.0, north), (0.0, 20.0))
        trace.append((row.get("map_obstacles"), ap._map_obstacles, g.path.points if g.path else None))
    ap.proximity.tracker.tracks = [Track(k + 1, 20.0, east, north, 0.6, 0.0, hits=20, last_echo_s=20.0) for k, (east, north) in
                                   enumerate(((0.3, 5.6), (0.3, 5.2), (1.0, 3.5)))]  # fmt: skip
    trace.append([t.ident for t in ap._movers(20.0, pose)])  # tracks on the wall's face (0.1, 0.5 m from it) and clear of it
    pose = SimpleNamespace(east_m=0.0, north_m=-30.0, heading_rad=math.pi / 2, speed_mps=0.5)
    for t in (40.0, 55.0, 70.0):  # far away, no echoes: the cells age
        ap._map_handed_s = -math.inf
        ap._update_obstacle_map(t, pose, {})
        trace.append((len(ap.obstacle_map.cells), ap._map_obstacles))
    return trace


def ex_map_switch(d: Daemon) -> list:
    """Whether the map's obstacles reach the planner at all."""
    return ex_obstacle_map(d)[::25]


def mission_for_planner(d: Daemon) -> None:
    lat, lon = latlon(15.0, 0.5)
    circle = MissionItem(Cmd.NAV_FENCE_CIRCLE_EXCLUSION, frame=0, param1=3.0, x=lat, y=lon)
    with_mission(d, [wp(30, 0)], [circle])


def ex_passage(d: Daemon) -> list:
    """A 1.5x-width gap beside the rover (tests/proximity/gap_world.py) driven past with the
    autopilot's passage, if on; then with it on: passed, the same gap again (rejected), a gap
    0.3 m along (another one unless ``match_m`` says otherwise), something in the way, a gap
    the sweep placed 0.12 m off (the front beam's scan, the guard), and a gap in a wall the
    obstacle map does not hold."""
    from proximity.gap_world import drive_past_gap

    from rover_ctl.navigation.odometry import Odometry

    passage = d.autopilot.passage

    def run(**options) -> list:
        passage.odometry = Odometry()  # the scene starts over where the odometry's frame began
        result, _ = drive_past_gap(d.config.passage, passage=passage, **options)
        return [result.trace, result.events, [tuple(round(v, 3) for v in p) for p in result.path[::10]]]

    trace = run() if d.config.passage.enabled else []
    enabled, d.config.passage.enabled = d.config.passage.enabled, True
    passage.reset()
    trace += run(t0_s=1000.0) + run(t0_s=1030.0) + run(t0_s=1060.0, gap_x=1.3) + run(t0_s=2000.0, behind_m=0.9)
    passage.reset()
    trace += run(t0_s=3000.0, side_lead_m=0.12, blocking=True)  # lined up 0.12 m off the centre line: scanned, lined up again
    scan, d.config.passage.scan_max_deg = d.config.passage.scan_max_deg, 0.0
    passage.reset()
    trace += run(t0_s=4000.0, side_lead_m=0.12, blocking=True)  # the same not scanned: the guard backs out
    d.config.passage.scan_max_deg = scan
    passage.reset()
    trace += run(t0_s=5000.0, map_holds_walls=False)  # a wall the map does not hold: not inspected (wall_mapped_m)
    d.config.passage.enabled = enabled
    return trace


def ex_planner(d: Daemon) -> list:
    follower, trace = d.autopilot.follower, []
    for k in range(120):
        t = k * 0.5
        along = min(2.0 * k, 28.0)
        position = (along, 4.0 * math.sin(k / 3.0))
        if k == 5:
            follower.block(t, (along + 2.0, 0.0))
        g = follower.update(t, position, (30.0, 0.0))
        trace.append((g.target_en, g.cross_track_m, g.remaining_m, g.replanned, g.error, g.path.points if g.path else None))
    trace.append(d.autopilot.planner.is_inside_fence((15.0, 0.5)))
    return trace


def ex_estimator(d: Daemon) -> list:
    est = d.estimator
    sensors = Sensors(gps_white_m=1.5, glitches=[(12.0, 22.0, 40.0, 0.0)], outages=[(24.0, 27.0)], imu_period_s=0.04,
                      slides=[(3.0, 11.0, 1.5, 0.0)])  # a slide the wheels do not see: a gradual disagreement
    run = simulate(30.0, lambda t: 1.0 if t < 20 else 0.3, lambda t: 0.2 if 8 < t < 12 else 0.0, seed=3, sensors=sensors)
    readings = [r for r in run.readings if not (isinstance(r, Attitude) and 9.0 <= r.time_s < 10.5)]  # gyro silent in a turn
    extra = {
        2.0: GpsFix(2.0 + 1.8, *latlon(2.0, 0.0), 584.0, 3, 1.0, 1.0, 90.0, 10),  # stamped ahead (another clock)
        3.0: GpsFix(2.9, *latlon(3.0, 0.0), 584.0, 3, math.nan, 1.0, 90.0, 10),  # late, no eph
        4.0: GpsFix(4.0, *latlon(4.0, 0.0), 584.0, 3, 0.05, 1.0, 90.0, 10),  # claims 5 cm
        28.0: Attitude(28.0 - 4.0, 0.0, 0.0),  # 4 s older: a vehicle reboot?
    }
    trace = []
    for r in readings:
        if isinstance(r, WheelDistance) and abs(r.time_s - 7.0) < 1e-9:
            r = WheelDistance(r.time_s, r.left_m + 0.2, r.right_m)  # a counter glitch
        for at in [a for a in extra if r.time_s >= a]:
            reading = extra.pop(at)
            (est.on_gps if isinstance(reading, GpsFix) else est.on_attitude)(reading)
        if isinstance(r, GpsFix):
            trace.append(est.on_gps(r))
        elif isinstance(r, Attitude):
            est.on_attitude(r)
        else:
            est.on_wheels(r)
            p = est.pose()
            trace.append((p.east_m, p.north_m, p.heading_rad, p.speed_mps, p.yaw_rate_radps, p.healthy, p.gps_ok,
                          p.position_sigma_m, p.heading_sigma_rad))  # fmt: skip
            ahead = est.pose(r.time_s + 0.1)  # a control step between two odometry readings
            trace.append((ahead.time_s, ahead.east_m, ahead.heading_rad))
    return trace


def ex_daemon(d: Daemon) -> list:
    """The loop period, the hold's braking threshold, the back-off speed and its stop short of
    something behind."""
    steps: list = []
    d.link = SimpleNamespace(last_rx_vehicle_s=None)
    d.control_step = lambda t_s, vehicle_age_s: steps.append(round(t_s, 6))
    for k in range(300):
        d._maybe_step(k * 0.01)
    ap = d.autopilot
    ap.on_wheels(WheelDistance(-0.04, 0.0, 0.0))
    ap.on_wheels(WheelDistance(0.0, 0.02, 0.02))  # rolling at 0.5 m/s
    holds = [ap._hold(0.0, 0.04, SimpleNamespace(speed_mps=v)) for v in (0.0, 0.03, 0.08, 0.5)]
    ap.on_vehicle(True)
    ap._enter(RoverMode.AUTO, "test")
    pose = SimpleNamespace(east_m=0.0, north_m=0.0, heading_rad=1.57, speed_mps=0.0)
    back_off = FailsafeDecision(Action.BACK_OFF, ("stuck",), (), frozenset(), False, False, 1)
    command = ap._decide(0.04, 0.04, pose, back_off, dict.fromkeys(LOG_COLUMNS, ""))
    ap._ranges[BACK] = RangeReading(0.04, 4, BACK, 0.2, 0.2, 4.0)  # something behind
    held = ap._decide(0.08, 0.04, pose, back_off, dict.fromkeys(LOG_COLUMNS, ""))
    return [steps, [dataclasses.astuple(h) for h in holds], dataclasses.astuple(command), dataclasses.astuple(held)]


def ex_loop_rate(d: Daemon) -> list:
    """The autopilot's loop-rate monitor through a slow stretch (window, threshold, speed limit)."""
    monitor, trace, t_s = d.autopilot.loop_rate, [], 0.0
    for rate_hz, seconds in ((25.0, 3.0), (21.0, 3.0), (12.0, 3.0), (23.0, 6.0)):
        for _ in range(round(rate_hz * seconds)):
            trace.append(dataclasses.astuple(monitor.step(t_s)))
            t_s += 1.0 / rate_hz
    return trace


def ex_link(d: Daemon) -> list:
    """The daemon's vehicle-link housekeeping on a fake wall clock: overrides thinned while the
    radio's buffer is low, the link-health report period, the measured-rate window."""
    from rover_ctl.autopilot.autopilot import StepOutput
    from rover_ctl.mavlink.link_health import LinkHealth
    from rover_ctl.mavlink.vehicle import RadioStatus
    from rover_ctl.navigation.wheel_control import WheelCommand

    clock = [0.0]
    sent: list = []
    records: list = []
    d.link = SimpleNamespace(radio=RadioStatus(180, 170, 40, 0, 0, 0.0), vehicle_time_s=0.0, url="udpin:127.0.0.1:1",
                             health=LinkHealth(lambda: d.config.link.rate_window_s),
                             send_override=lambda steering, throttle: sent.append(round(clock[0], 3)))  # fmt: skip
    d.events = SimpleNamespace(write=lambda t_s, kind, **fields: records.append((round(clock[0], 3), kind)))
    real_time = daemon_module.time
    daemon_module.time = SimpleNamespace(monotonic=lambda: clock[0], perf_counter=real_time.perf_counter)
    try:
        for k in range(400):
            clock[0] = d.link.vehicle_time_s = k * 0.04
            d.link.health.frame(clock[0], "ATTITUDE", (1, 1), k % 256, 40)
            d._send_command(StepOutput(WheelCommand(1500, 1600, 0.1, 0.1), (), {}))
            d._report_link()
        rates = [d.link.health.rate_hz("ATTITUDE", t) for t in (16.0, 17.0, 18.0)]
    finally:
        daemon_module.time = real_time
    return [sent, records, rates]


def ex_autopilot(d: Daemon) -> list:
    """LOITER's station keeping (pushed out and back) and the pre-arm distance check."""
    ap = d.autopilot
    trace = [prearm.failures(ap._arming_inputs())]
    ap._station_en, ap._guided_target_en, ap._returning = (0.0, 0.0), None, False
    for k in range(60):
        trace.append(ap._station_goal((0.1 * min(k, 60 - k), 0.0)))
    ap.executor.set_current(2)
    ap._enter(RoverMode.AUTO, "test")  # MIS_RESTART: resume at item 2 or start over
    trace.append(ap.executor.current_seq)
    return trace


def two_ahead(d: Daemon) -> None:
    with_mission(d, [wp(0, 20), wp(10, 20)])


def no_mission(d: Daemon) -> None:
    pass


def home_only(d: Daemon) -> None:
    d._set_home(HOME_FIX)


def ex_pivot(d: Daemon) -> list:
    """A sluggish rover (it turns at a tenth of the rate it is told) with its target north, 170
    degrees to its left, for 12 s: the pivot's yaw rates (it pivots, times out, rests, is pushed
    1.5 m along its leg and pivots again); then one as nimble as told, facing east (90 degrees), for 4 s (it ends near the target's
    direction); then single steps facing east: something close to a flank, the front-left
    diagonal reading 1.2 m, the rover 1.5 m off its path, a walker 4 m away (no pivot in each, by
    default)."""
    from rover_ctl.estimation.readings import RangeReading

    ap, trace = d.autopilot, []
    clear = FailsafeDecision(Action.NONE, (), (), frozenset(), False, False)

    def step(t_s: float, east_m: float, heading_rad: float, ranges: dict[int, float], north_m: float = 0.0):
        pose = SimpleNamespace(east_m=east_m, north_m=north_m, heading_rad=heading_rad, speed_mps=0.0)
        ap._ranges = {o: RangeReading(t_s, o, o, r, 0.2, 4.0) for o, r in ranges.items()}
        row = dict.fromkeys(LOG_COLUMNS, "")
        ap._drive(t_s, 0.04, pose, (0.0, 20.0), 1.2, 1, clear, row)
        return row["pivot_radps"]

    free = dict.fromkeys((0, 1, 2, 4, 6, 7), math.inf)  # no echo (echoes swept by the turn would read as movers)
    for t0_s, heading, steps, agility in ((10.0, math.radians(-80.0), 300, 0.1), (50.0, 0.0, 100, 1.0)):
        ap.pivot.reset()
        ap.follower.reset()
        for k in range(steps):  # the rule base's turns left out; after 7 s the rover was pushed 1.5 m along its leg
            rate = step(t0_s + k * 0.04, 0.0, heading, free, 1.5 if k >= 175 else 0.0)
            heading += (rate or 0.0) * agility * 0.04
            trace.append(None if rate == "" else round(rate, 9))
    for k, (east_m, ranges, walker) in enumerate(((0.0, {**free, 2: 0.25}, False), (0.0, {**free, 7: 1.2}, False),
                                                  (-1.5, free, False), (0.0, free, True))):  # fmt: skip
        t_s = 100.0 * (k + 1)
        ap.pivot.reset()
        ap.follower.reset()
        step(t_s - 50.0, 0.0, math.pi / 2, free)  # the path planned from the leg's start
        ap.proximity.tracker.tracks = [Track(1, t_s, 4.0, 0.0, 0.0, 0.5, hits=20, last_echo_s=t_s, born_en=(4.0, -1.0))] if walker else []
        rate = step(t_s, east_m, 0.0, ranges)
        trace.append(None if rate == "" else round(rate, 9))
    return trace


def mission_ahead(d: Daemon) -> None:
    with_mission(d, [wp(0, 20)])


EXERCISES = {
    # name: (what the daemon has built before the change, the exercise after it, keys it reads)
    "failsafes": (no_mission, ex_failsafes, ("failsafe.",)),
    "degraded": (no_mission, ex_degraded, ("failsafe.degraded_speed_mps",)),
    "executor": (mission_for_executor, ex_executor, ("executor.", "robot.max_wheel_rpm", "robot.wheel_radius_m")),
    "navigator": (no_mission, ex_navigator, ("navigator.", "robot.max_wheel_rpm", "robot.wheel_radius_m")),
    "wheels": (no_mission, ex_wheels, ("wheel_control.", "robot.wheel_radius_m")),
    "proximity": (no_mission, ex_proximity, ("proximity.", "robot.footprint_length_m", "robot.footprint_width_m")),
    "tracks": (predicting, ex_tracks, ("proximity.",)),
    "planner": (mission_for_planner, ex_planner, ("planner.", "robot.footprint_width_m")),
    "passage": (no_mission, ex_passage, ("passage.", "robot.footprint_length_m", "robot.footprint_width_m")),
    "estimator": (home_only, ex_estimator, ("estimator.", "robot.track_m")),
    "daemon": (mission_ahead, ex_daemon, ("daemon.", "failsafe.back_off_speed_mps", "failsafe.back_off_clear_m")),
    "autopilot": (two_ahead, ex_autopilot, ("autopilot.",)),
    "link": (no_mission, ex_link, ("link.radio_txbuf_low_pct", "link.override_min_hz", "link.health_period_s", "link.rate_window_s",
                                   "link.radio_status_timeout_s")),
    "yielding": (no_mission, ex_yielding, ("yielding.", "robot.footprint_length_m", "robot.footprint_width_m")),
    "yield_switch": (no_mission, ex_yield_switch, ("yielding.enabled",)),
    "evasion": (no_mission, ex_evasion, ("evasion.", "robot.footprint_width_m")),
    "rejoin": (mission_ahead, ex_rejoin, ("evasion.rejoin_s", "evasion.rejoin_lookahead_m", "planner.lookahead_m")),
    "loop_rate": (no_mission, ex_loop_rate, ("daemon.loop_rate_window_s", "daemon.slow_loop_fraction", "daemon.max_step_travel_m")),
    "obstacle_map": (mapping, ex_obstacle_map, tuple(f"obstacle_map.{f.name}" for f in dataclasses.fields(ObstacleMapParams) if f.name != "enabled")),
    "map_switch": (mission_ahead, ex_map_switch, ("obstacle_map.enabled",)),
    "side_guard": (mission_ahead, ex_side_guard, ("side_guard.", "robot.track_m", "robot.wheel_radius_m")),
    "pivot": (mission_ahead, ex_pivot, ("pivot.",)),
}
SETTABLE = [p for p in TABLE if p.access is Access.RW]


def exercises_of(param: Param) -> list[str]:
    return [name for name, (_, _, keys) in EXERCISES.items() if any(param.key == k or (k.endswith(".") and param.key.startswith(k)) for k in keys)]


def candidates(param: Param) -> list[float]:
    """New values to try, in the parameter's range and unlike the default."""
    if param.kind is Kind.CHOICE:
        return [float(n) for n in param.choices if n != param.default]
    if param.kind is Kind.MASK:
        return [float(m) for m in (0, 1, 3, 255) if m != param.default]
    if param.kind is Kind.BOOL:
        return [0.0 if param.default else 1.0]
    d, lo, hi = param.default, param.minimum, param.maximum
    raw = [d * 2, d / 2, hi, lo, (lo + hi) / 2, d + 1, d - 1]
    out = []
    for v in raw:
        v = min(max(v, lo), hi)
        if param.kind is Kind.INT:
            v = float(round(v))
        if v != d and v not in out:
            out.append(v)
    return out


def fresh_config() -> Config:
    config = Config()
    config.gcs.mission_store_path = ""  # no state files
    return config


def built(name: str, config: Config) -> Daemon:
    daemon = build(config)
    EXERCISES[name][0](daemon)
    return daemon


@cache
def baseline(name: str) -> list:
    return EXERCISES[name][1](built(name, fresh_config()))


def test_every_settable_parameter_has_an_exercise():
    missing = [p.name for p in SETTABLE if not exercises_of(p)]
    assert not missing, f"parameters a GCS may set but no exercise reads: {missing}"


@pytest.mark.parametrize("param", SETTABLE, ids=lambda p: p.name)
def test_a_change_reaches_every_use(param: Param):
    names = exercises_of(param)
    for value in candidates(param):
        differs = False
        for name in names:
            run = EXERCISES[name][1]
            changed_later = built(name, fresh_config())
            ok, reason = ConfigParams(changed_later.config).set_param(param.name, value)
            assert ok, reason
            from_start = fresh_config()
            param.set(from_start, param.decode(value))
            b, c = run(changed_later), run(built(name, from_start))
            assert b == c, f"{param.name}={value:g} set after construction is not used like one set before ({name})"
            differs |= c != baseline(name)
        if differs:
            return
    pytest.fail(f"no exercise ({', '.join(names)}) depends on {param.name} for any of {candidates(param)}")
