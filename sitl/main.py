"""``rover-sitl``: the emulator process (command line, endpoints, main loop).

One thread, one ``select`` loop. Each frame: apply the RC outputs, step the rover to t_k, send the
telemetry due at t_k, then either wait for wall-clock time (real time or ``--speedup N``) or, with
``--lockstep``, send the TIMESYNC marker and serve the endpoints until the controller answers it
(docs/architecture.md, "Lockstep handshake"). Everything received meanwhile is applied at t_k.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import select
import signal
import sys
from pathlib import Path

from sitl.clock import FrameClock, LockstepMarker, Pacer
from sitl.endpoints import Endpoint, EndpointError, PtyEndpoint, mavlink, open_endpoint
from sitl.faults import FAULT_PARAMS, FaultError, check_param
from sitl.mavlink_vehicle import PARAM_NAMES, LinkParams, MavlinkVehicle
from sitl.params import RANGEFINDER_SETS, SitlParams, apply_override
from sitl.truthlog import TruthLog
from sitl.vehicle import SimRover
from sitl.world import Home, World, WorldError, load_world, scatter_obstacles

PROG = "rover-sitl"
DEFAULT_ENDPOINT = "tcpin:127.0.0.1:5760"
"""ArduPilot SITL's SERIAL0 port, where the daemon connects by default."""
DEFAULT_HOME = Home(-35.363261, 149.165230, 584.0, 0.0)
"""ArduPilot's CMAC field, the default home of ArduPilot's own SITL."""
DEFAULT_FRAME_S = 0.02
LINK_RNG_SALT = 0x4C494E4B
"""Mixed into --seed for the link-loss draws, so they do not alias the sensor noise streams."""


class UsageError(Exception):
    """A bad flag or value; main prints it as one line and exits 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, no usage dump
        raise UsageError(message)


def _home(text: str) -> Home:
    parts = text.split(",")
    try:
        lat, lon, alt, heading = (float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LAT,LON,ALT,HEADING (4 numbers), got {text!r}") from None
    if not (-90 <= lat <= 90 and -180 <= lon <= 180 and 0 <= heading < 360 and math.isfinite(alt)):
        raise argparse.ArgumentTypeError(f"{text!r}: need -90<=LAT<=90, -180<=LON<=180, 0<=HEADING<360")
    return Home(lat, lon, alt, heading)


def _latlon_list(text: str) -> list[tuple[float, float]]:
    points = []
    for part in text.split(";"):
        try:
            lat, lon = (float(v) for v in part.split(","))
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected \"LAT,LON;LAT,LON;...\", got {part!r}") from None
        if not (-90 <= lat <= 90 and -180 <= lon <= 180):
            raise argparse.ArgumentTypeError(f"{part!r} is not a valid LAT,LON")
        points.append((lat, lon))
    if len(points) < 2:
        raise argparse.ArgumentTypeError("--along needs at least two points")
    return points


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value > 0 or math.isnan(value):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def _non_negative(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value >= 0 or math.isinf(value):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text!r}")
    return value


def _param(text: str) -> tuple[str, float]:
    name, sep, value = text.partition("=")
    known = [*PARAM_NAMES, *FAULT_PARAMS]
    if not sep or name not in known:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE with NAME one of {', '.join(known)}, got {text!r}")
    try:
        number = check_param(name, value) if name in FAULT_PARAMS else float(value)
    except (FaultError, ValueError) as exc:
        raise argparse.ArgumentTypeError(str(exc) if isinstance(exc, FaultError) else f"{name}: expected a number") from None
    return name, number


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=PROG, description="Skid-steer rover emulator on MAVLink (behaves like ArduPilot Rover in MANUAL).")
    parser.add_argument("--home", type=_home, help="LAT,LON,ALT,HEADING (default: the world's home, else CMAC)")
    parser.add_argument("--world", type=Path, help="GeoJSON world file (obstacles, optional home and fault schedule)")
    parser.add_argument("--scatter", type=int, metavar="N", help="add N seeded random obstacles along --along")
    parser.add_argument("--along", type=_latlon_list, metavar='"LAT,LON;..."', help="the legs --scatter places obstacles on")
    parser.add_argument("--write-world", type=Path, metavar="OUT.geojson", help="write the world in use (with --scatter's obstacles)")
    parser.add_argument("--seed", type=int, default=1, help="seed of every random draw (default 1)")
    parser.add_argument("--endpoint", action="append", default=[], metavar="URL",
                        help=f"udpin:|udpout:|tcpin:|tcp:HOST:PORT, repeatable; the first is the controller's (default {DEFAULT_ENDPOINT})")
    parser.add_argument("--pty", action="store_true", help="also serve MAVLink on a pseudo-terminal and print 'PTY /dev/pts/N'")
    timing = parser.add_mutually_exclusive_group()
    timing.add_argument("--speedup", type=_positive, default=1.0, metavar="N", help="run at N x real time ('inf': as fast as possible)")
    timing.add_argument("--lockstep", action="store_true", help="advance a frame only when the controller answers its TIMESYNC marker")
    parser.add_argument("--frame-s", type=_positive, default=DEFAULT_FRAME_S, metavar="S", help=f"frame length in sim seconds (default {DEFAULT_FRAME_S})")
    parser.add_argument("--truth-log", type=Path, metavar="FILE", help="write ground truth as JSON lines")
    parser.add_argument("--duration-s", type=_non_negative, metavar="S", help="stop after S sim seconds")
    parser.add_argument("--param", type=_param, action="append", default=[], metavar="NAME=VALUE",
                        help="set a parameter at start (SYSID_MYGCS, RC_OVERRIDE_TIME, ARMING_CHECK, SIM_*)")
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.FIELD=VALUE", dest="overrides",
                        help="override an emulator model parameter of sitl/params.py, e.g. gps.white_std_m=2.5")
    parser.add_argument("--rangefinders", choices=sorted(RANGEFINDER_SETS), default="default",
                        help="rangefinder layout: default (six, with front-left/right at 45 deg) or paper (the four)")
    return parser


def _world(args) -> World:
    world = load_world(args.world) if args.world else World()
    if args.scatter is not None:
        if args.along is None:
            raise UsageError("--scatter needs --along \"LAT,LON;LAT,LON;...\"")
        if args.scatter < 0:
            raise UsageError(f"--scatter: expected a count >= 0, got {args.scatter}")
        world.obstacles.extend(scatter_obstacles(args.along, args.scatter, args.seed).obstacles)
    return world


class Emulator:
    """The running process: rover + vehicle state + endpoints + clock."""

    def __init__(self, rover: SimRover, vehicle: MavlinkVehicle, endpoints: list[Endpoint], clock: FrameClock,
                 lockstep: bool, speedup: float, truth: TruthLog | None, seed: int) -> None:
        self.rover, self.vehicle, self.endpoints, self.clock = rover, vehicle, endpoints, clock
        self.controller = endpoints[0]
        self.lockstep = lockstep
        vehicle.lockstep = lockstep
        self.pacer = Pacer(speedup)
        self.marker = LockstepMarker()
        self.truth = truth
        self.link_rng = random.Random(seed ^ LINK_RNG_SALT)
        self.stop = False
        self.wake_r, self.wake_w = os.pipe()
        os.set_blocking(self.wake_w, False)
        if truth is not None:
            vehicle.on_gps = lambda sample: truth.gps(self.clock.t_s, sample)

    # ---- signals -----------------------------------------------------------------------
    def install_signals(self) -> None:
        signal.set_wakeup_fd(self.wake_w)
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, self._on_signal)

    def _on_signal(self, signum, frame) -> None:
        self.stop = True

    # ---- link ----------------------------------------------------------------------------
    def _lost(self, endpoint: Endpoint, outgoing: bool) -> bool:
        """Whether a controller-link message is lost to the SIM_LINK_* faults. SIM_LINK_LOSS drops
        both ways, SIM_LINK_QUIET silences the vehicle only (so a PARAM_SET can end it); the
        lockstep marker and its answer are never lost (callers skip TIMESYNC)."""
        if endpoint is not self.controller:
            return False
        faults = self.rover.faults
        if outgoing and faults.link_quiet:
            return True
        return faults.link_loss_pct > 0 and self.link_rng.random() * 100.0 < faults.link_loss_pct

    def broadcast(self, msgs: list) -> None:
        for endpoint in self.endpoints:
            for msg in msgs:
                if not self._lost(endpoint, outgoing=True):
                    endpoint.send(msg)

    def flush(self) -> None:
        for endpoint in self.endpoints:
            endpoint.flush()

    def send_marker(self) -> None:
        marker = mavlink.MAVLink_timesync_message(0, self.clock.t_ns)
        for endpoint in self.endpoints:
            endpoint.send(marker)
        self.flush()
        self.marker.sent(self.clock.t_ns)

    def serve(self, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` for input, apply what arrived; True if the marker was answered."""
        fds = {self.wake_r: None}
        for endpoint in self.endpoints:
            for fd in endpoint.fds():
                fds[fd] = endpoint
        try:
            readable, _, _ = select.select(list(fds), [], [], max(0.0, timeout_s))
        except InterruptedError:
            return False
        answered = False
        t_s = self.clock.t_s
        for fd in readable:
            endpoint = fds[fd]
            if endpoint is None:
                os.read(self.wake_r, 512)
                continue
            peers_before = len(endpoint.peers)
            for msg, peer in endpoint.poll(fd):
                if msg.get_type() == "TIMESYNC" and endpoint is self.controller and self.marker.is_answer(msg):
                    answered = True
                    continue
                if msg.get_type() != "TIMESYNC" and self._lost(endpoint, outgoing=False):
                    continue
                for reply in self.vehicle.handle(msg, t_s):
                    if not self._lost(endpoint, outgoing=True):
                        endpoint.reply(peer, reply)
            if self.lockstep and endpoint is self.controller and len(endpoint.peers) > peers_before:
                self.send_marker()  # a controller that just connected gets the marker at once
        self.flush()
        return answered

    # ---- main loop -------------------------------------------------------------------------
    def run(self, duration_s: float | None) -> None:
        while not self.stop:
            t_s = self.clock.t_s
            if self.clock.k > 0:
                for event in self.rover.step(self.clock.frame_s):
                    self._event(event)
            self.vehicle.sample_sensors(t_s)
            if self.truth is not None:
                self.truth.state(t_s, self.rover.truth())
            self.broadcast(self.vehicle.due(t_s))
            if duration_s is not None and t_s >= duration_s - 1e-9:
                self.flush()
                break
            if self.lockstep:
                self.send_marker()
                while not self.stop and not self.serve(self.marker.resend_in_s()):
                    if self.marker.resend_in_s() <= 0:
                        self.send_marker()
            else:
                self.flush()
                next_s = t_s + self.clock.frame_s
                while not self.stop:
                    self.serve(self.pacer.wait_s(next_s))
                    if self.pacer.wait_s(next_s) <= 0:
                        break
            if self.stop:
                break
            self.vehicle.apply_outputs(t_s)
            self.clock.advance()

    def _event(self, event) -> None:
        detail = event.detail
        if self.truth is not None:
            self.truth.event(event.time_s, event.kind, detail)
        if event.kind == "collision":
            self.vehicle.say(mavlink.MAV_SEVERITY_WARNING, f"Collision with {detail.get('obstacle')}")
        elif event.kind == "fault":
            state = "on" if detail.get("active") else "off"
            self.vehicle.say(mavlink.MAV_SEVERITY_NOTICE, f"Fault {detail.get('name')} {state}")

    def close(self) -> None:
        for endpoint in self.endpoints:
            endpoint.close()
        if self.truth is not None:
            self.truth.close()
        os.close(self.wake_r)
        os.close(self.wake_w)


VALUE_FLAGS_MAY_START_WITH_MINUS = ("--home", "--along")
"""Flags whose value is often negative (southern/western coordinates), which argparse takes for an option."""


def _join_negative_values(argv: list[str]) -> list[str]:
    """``--home -35.3,149.1,584,0`` -> ``--home=-35.3,149.1,584,0``."""
    out: list[str] = []
    for token in argv:
        if out and out[-1] in VALUE_FLAGS_MAY_START_WITH_MINUS and token.startswith("-"):
            out[-1] = f"{out[-1]}={token}"
        else:
            out.append(token)
    return out


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(_join_negative_values(sys.argv[1:] if argv is None else argv))
        world = _world(args)
    except (UsageError, WorldError) as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    home = args.home or world.home or DEFAULT_HOME
    if args.write_world:
        try:
            args.write_world.write_text(json.dumps(world.to_geojson(), indent=1) + "\n")
        except OSError as exc:
            print(f"{PROG}: error: --write-world {args.write_world}: {exc.strerror or exc}", file=sys.stderr)
            return 2

    params = SitlParams()
    params.rangefinder.sensors = RANGEFINDER_SETS[args.rangefinders]()
    for assignment in args.overrides:
        try:
            apply_override(params, assignment)
        except ValueError as exc:
            print(f"{PROG}: error: --set {exc}", file=sys.stderr)
            return 2
    rover = SimRover(params, world, home, args.seed)
    vehicle = MavlinkVehicle(rover, LinkParams(), fault_params=FAULT_PARAMS)
    for name, value in args.param:
        vehicle.set_param(name, value)

    endpoints: list[Endpoint] = []
    try:
        for url in args.endpoint or ([] if args.pty else [DEFAULT_ENDPOINT]):
            endpoints.append(open_endpoint(url))
        if args.pty:
            endpoints.append(PtyEndpoint())
        truth = None
        if args.truth_log:
            try:
                truth = TruthLog(open(args.truth_log, "w", encoding="utf-8"))
            except OSError as exc:
                raise EndpointError(f"--truth-log {args.truth_log}: {exc.strerror or exc}") from None
    except EndpointError as exc:
        for endpoint in endpoints:
            endpoint.close()
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2

    emulator = Emulator(rover, vehicle, endpoints, FrameClock(args.frame_s), args.lockstep,
                        args.speedup, truth, args.seed)
    emulator.install_signals()
    for endpoint in endpoints:
        if isinstance(endpoint, PtyEndpoint):
            print(f"PTY {endpoint.device}", flush=True)
        print(f"{PROG}: {'connected' if endpoint.kind in ('tcp', 'udpout') else 'listening'} {endpoint.url}", flush=True)
    mode = "lockstep" if args.lockstep else ("free running" if math.isinf(args.speedup) else f"{args.speedup:g}x real time")
    print(f"{PROG}: ready ({mode}, frame {emulator.clock.frame_s:g} s, seed {args.seed})", flush=True)
    try:
        emulator.run(args.duration_s)
    finally:
        emulator.close()
    print(f"{PROG}: stopped at t={emulator.clock.t_s:.2f} s, {sum(e.bad_frames for e in endpoints)} bad frames ignored", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
