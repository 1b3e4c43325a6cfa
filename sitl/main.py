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
import time
from pathlib import Path

from sitl.clock import HOLD_TIMEOUT_S, MARKER_RESEND_S, MIN_SPEEDUP, FrameClock, LockstepMarker, Pacer
from sitl.endpoints import Endpoint, EndpointBusy, EndpointError, PtyEndpoint, mavlink, open_endpoint
from sitl.faults import FAULT_PARAMS, FaultError, check_param
from sitl.line import DEFAULT_BUFFER_BYTES, SerialLine
from sitl.mavlink_vehicle import PARAM_NAMES, LinkParams, MavlinkVehicle, check_link_param
from sitl.params import RANGEFINDER_SETS, SitlParams, apply_override, inconsistency
from sitl.truthlog import TruthLog
from sitl.vehicle import SimRover
from sitl.world import Home, World, WorldError, load_world, scatter_obstacles

PROG = "rover-sitl"
DEFAULT_ENDPOINT = "tcpin:127.0.0.1:5760"
EXIT_UNAVAILABLE = os.EX_UNAVAILABLE
"""69, as ``rover-ctl run``: an endpoint's port is in use (a launcher that picked it free may pick
another and start again)."""
"""ArduPilot SITL's SERIAL0 port, where the daemon connects by default."""
DEFAULT_HOME = Home(-35.363261, 149.165230, 584.0, 0.0)
"""ArduPilot's CMAC field, the default home of ArduPilot's own SITL."""
DEFAULT_FRAME_S = 0.02
FRAME_S_RANGE = (0.001, 1.0)
"""From one physics substep (shorter frames only cost wall time) to 1 s (telemetry leaves and
commands apply once a frame: a longer one starves the 50 Hz sensors and the controller)."""
LINK_RNG_SALT = 0x4C494E4B
"""Mixed into --seed for the link-loss draws, so they do not alias the sensor noise streams."""
DOWNLINK_RNG_SALT = 0x444F574E
UPLINK_RNG_SALT = 0x55504C4B
"""Mixed into --seed for the byte errors of the pty line, one stream per direction."""


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
    try:
        return Home(lat, lon, alt, heading)
    except WorldError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: {exc}") from None


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


def _number(kind: type, low: float, high: float, wanted: str):
    """An argparse type: ``kind(text)`` within ``[low, high]`` (NaN never is), else "expected WANTED"."""

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {'a whole number' if kind is int else 'a number'}, got {text!r}") from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"expected {wanted}, got {text!r}")
        return value

    return parse


FINITE_MAX = sys.float_info.max


def parse_param(text: str) -> tuple[str, float]:
    """``--param NAME=VALUE`` (also checked by ``rover-ctl sim --sitl-param`` before it starts us)."""
    name, sep, value = text.partition("=")
    known = [*PARAM_NAMES, *FAULT_PARAMS]
    if not sep or name not in known:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE with NAME one of {', '.join(known)}, got {text!r}")
    try:
        number = check_param(name, value) if name in FAULT_PARAMS else check_link_param(name, value)
    except FaultError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return name, number


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=PROG, description="Skid-steer rover emulator on MAVLink (behaves like ArduPilot Rover in MANUAL).")
    parser.add_argument("--home", type=_home, help="LAT,LON,ALT,HEADING (default: the world's home, else CMAC)")
    parser.add_argument("--world", type=Path, help="GeoJSON world file (obstacles, optional home and fault schedule)")
    parser.add_argument("--scatter", type=_number(int, 0, math.inf, "a whole number >= 0"), metavar="N", help="add N seeded random obstacles along --along")
    parser.add_argument("--along", type=_latlon_list, metavar='"LAT,LON;..."', help="the legs --scatter places obstacles on")
    parser.add_argument("--write-world", type=Path, metavar="OUT.geojson", help="write the world in use (with --scatter's obstacles)")
    parser.add_argument("--seed", type=_number(int, 0, math.inf, "a whole number >= 0"), default=1,  # numpy's generators take no negative seed
                        help="seed of every random draw, >= 0 (default 1)")
    parser.add_argument("--endpoint", action="append", default=[], metavar="URL",
                        help=f"udpin:|udpout:|tcpin:|tcp:HOST:PORT, repeatable; the first is the controller's (default {DEFAULT_ENDPOINT})")
    parser.add_argument("--pty", action="store_true", help="also serve MAVLink on a pseudo-terminal and print 'PTY /dev/pts/N'")
    line = parser.add_argument_group("serial line of --pty (docs/sitl.md, 'Serial line')")
    line.add_argument("--baud", type=_number(float, math.ulp(0.0), FINITE_MAX, "a positive number"), metavar="N",
                      help="carry the pty at N baud, 8N1 (N/10 bytes per sim second each way); default: no limit")
    line.add_argument("--byte-error", type=_number(float, 0.0, math.nextafter(1.0, 0.0), "a probability 0 <= P < 1"), default=0.0, metavar="P",
                      help="probability that a byte on the line arrives changed (needs --baud)")
    line.add_argument("--line-buffer-bytes", type=_number(int, 1, math.inf, "a whole number >= 1"), default=DEFAULT_BUFFER_BYTES, metavar="N",
                      help=f"bytes the line buffers each way before it drops (default {DEFAULT_BUFFER_BYTES}, a SiK radio)")
    line.add_argument("--line-stats", type=Path, metavar="FILE", help="write the line's counters as JSON at exit")
    timing = parser.add_mutually_exclusive_group()
    timing.add_argument("--speedup", type=_number(float, MIN_SPEEDUP, math.inf, f"a number >= {MIN_SPEEDUP:g}"), default=1.0, metavar="N",
                        help=f"run at N x real time, N >= {MIN_SPEEDUP:g} ('inf': as fast as possible)")
    timing.add_argument("--lockstep", action="store_true", help="advance a frame only when the controller answers its TIMESYNC marker")
    parser.add_argument("--hold-at-s", type=_number(float, 0.0, FINITE_MAX, "a finite number >= 0"), metavar="S",
                        help=f"with --lockstep: stop the clock at sim time S until the vehicle is armed (at most {HOLD_TIMEOUT_S:g} wall s), "
                             "so that a ground station arms it at the same frame in every run")
    parser.add_argument("--frame-s", type=_number(float, *FRAME_S_RANGE, "a number from {:g} to {:g}".format(*FRAME_S_RANGE)), default=DEFAULT_FRAME_S, metavar="S",
                        help="frame length in sim seconds, {:g} to {:g} (default {:g})".format(*FRAME_S_RANGE, DEFAULT_FRAME_S))
    parser.add_argument("--truth-log", type=Path, metavar="FILE", help="write ground truth as JSON lines")
    parser.add_argument("--duration-s", type=_number(float, 0.0, FINITE_MAX, "a finite number >= 0"), metavar="S", help="stop after S sim seconds")
    parser.add_argument("--param", type=parse_param, action="append", default=[], metavar="NAME=VALUE",
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
        world.obstacles.extend(scatter_obstacles(args.along, args.scatter, args.seed).obstacles)
    return world


class Emulator:
    """The running process: rover + vehicle state + endpoints + clock."""

    def __init__(self, rover: SimRover, vehicle: MavlinkVehicle, endpoints: list[Endpoint], clock: FrameClock,
                 lockstep: bool, speedup: float, truth: TruthLog | None, seed: int, hold_at_s: float | None = None) -> None:
        self.rover, self.vehicle, self.endpoints, self.clock = rover, vehicle, endpoints, clock
        self.hold_at_s = hold_at_s
        """Lockstep: the sim time at which the clock stops until the vehicle is armed (``hold``)."""
        self.clock_started = False
        """The first frame went out (in lockstep only once the controller is there)."""
        self.controller = endpoints[0]
        self.lockstep = lockstep
        vehicle.lockstep = lockstep
        self.pacer = Pacer(speedup)
        self.marker = LockstepMarker()
        self.truth = truth
        self.link_rng = random.Random(seed ^ LINK_RNG_SALT)
        self.stop = False
        self.markers_repeated = 0
        """Lockstep markers sent again because no answer came within MARKER_RESEND_S."""
        self.wake_r, self.wake_w = os.pipe()
        os.set_blocking(self.wake_w, False)
        if lockstep:  # the marker's answer skips a serial line (PtyEndpoint)
            for endpoint in endpoints:
                if isinstance(endpoint, PtyEndpoint):
                    endpoint.bypass = self.marker.is_answer
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

    def send_marker(self, repeat: bool = False) -> None:
        marker = mavlink.MAVLink_timesync_message(0, self.clock.t_ns)
        for endpoint in self.endpoints:
            endpoint.send_marker(marker, repeat)
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
        for fd in readable:
            endpoint = fds[fd]
            if endpoint is None:
                os.read(self.wake_r, 512)
                continue
            peers_before = len(endpoint.peers)
            answered = self.receive(endpoint, endpoint.poll(fd)) or answered
            if self.lockstep and self.clock_started and endpoint is self.controller and len(endpoint.peers) > peers_before:
                self.send_marker()  # a controller that just connected gets the marker at once
        self.flush()
        return answered

    def hold(self) -> None:
        """``--hold-at-s``: the frame is done and answered; time stands still until the vehicle is
        armed, or ``HOLD_TIMEOUT_S`` wall seconds. Messages are applied at this frame's time as
        they come (a ground station's MISSION_START and arming, through the controller), so the
        arming and everything after it happen at the same frame in every run, however long the
        ground station took. The marker is repeated at once, then as for an unanswered one: a
        watching ground station that sees a frame's marker twice knows the controller is done
        with the frame; the controller answers without stepping again, and hears from the vehicle."""
        deadline = time.monotonic() + HOLD_TIMEOUT_S
        self.send_marker()
        while not self.stop and not self.vehicle.armed and time.monotonic() < deadline:
            self.serve(min(self.marker.resend_in_s(), deadline - time.monotonic()))
            if self.marker.resend_in_s() <= 0:
                self.send_marker()

    def receive(self, endpoint: Endpoint, received) -> bool:
        """Apply the (message, peer) pairs of ``endpoint`` at the frame's time; True if one of
        them answered the lockstep marker."""
        answered = False
        t_s = self.clock.t_s
        for msg, peer in received:
            if msg.get_type() == "TIMESYNC" and endpoint is self.controller and self.marker.is_answer(msg):
                answered = True
                continue
            if msg.get_type() != "TIMESYNC" and self._lost(endpoint, outgoing=False):
                continue
            for reply in self.vehicle.handle(msg, t_s):
                if not self._lost(endpoint, outgoing=True):
                    endpoint.reply(peer, reply)
        return answered

    # ---- main loop -------------------------------------------------------------------------
    def run(self, duration_s: float | None) -> None:
        if self.lockstep:  # the first frame waits for the controller: from its first message on, it sees every frame
            while not self.stop and not self.controller.peers:
                self.serve(MARKER_RESEND_S)
        self.clock_started = True
        while not self.stop:
            t_s = self.clock.t_s
            for endpoint in self.endpoints:  # what a serial line delivered by t_k
                self.receive(endpoint, endpoint.arrivals())
            if self.vehicle.armed:
                self.rover.world.armed(t_s)
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
                repeats = 0
                while not self.stop and not self.serve(self.marker.resend_in_s()):
                    if self.marker.resend_in_s() <= 0:
                        self.markers_repeated += 1
                        repeats += 1
                        self.send_marker(repeat=repeats > 1)  # a second repeat: the first was not read either
                if self.hold_at_s is not None and t_s >= self.hold_at_s - 1e-9:
                    self.hold_at_s = None
                    self.hold()
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


def _check_timing_flags(args) -> None:
    if args.hold_at_s is not None and not args.lockstep:
        raise UsageError("--hold-at-s needs --lockstep (only a lockstep clock can wait for the ground station)")


def _check_line_flags(args) -> None:
    if args.baud is not None and not args.pty:
        raise UsageError("--baud: only the --pty endpoint has a serial line; add --pty")
    if args.baud is None:
        for flag, given in (("--byte-error", args.byte_error != 0.0), ("--line-stats", args.line_stats),
                            ("--line-buffer-bytes", args.line_buffer_bytes != DEFAULT_BUFFER_BYTES)):  # fmt: skip
            if given:
                raise UsageError(f"{flag} needs --baud (the pty has no line without it)")


def _pty(args, clock: FrameClock) -> PtyEndpoint:
    """The --pty endpoint, behind a serial line in sim time when --baud is given."""
    if args.baud is None:
        return PtyEndpoint()
    return PtyEndpoint(SerialLine(args.baud, args.byte_error, args.line_buffer_bytes, args.seed ^ DOWNLINK_RNG_SALT),
                       SerialLine(args.baud, args.byte_error, args.line_buffer_bytes, args.seed ^ UPLINK_RNG_SALT),
                       lambda: clock.t_s)  # fmt: skip


def _line_summary(stats: dict) -> str:
    return "; ".join(f"{direction} offered {s['offered']} delivered {s['delivered']} dropped {s['dropped_overflow']} "
                     f"corrupted {s['corrupted']} peak {s['peak_buffer_bytes']}" for direction, s in stats.items())  # fmt: skip


def _write_line_stats(args, endpoints: list[Endpoint], t_s: float, markers_repeated: int) -> None:
    """``--line-stats``: the line's parameters, the sim time, bad frames received, lockstep
    markers repeated and each direction's counters."""
    stats = next((s for e in endpoints if (s := e.line_stats()) is not None), None)
    record = {"baud": args.baud, "byte_error": args.byte_error, "buffer_bytes": args.line_buffer_bytes,
              "sim_s": t_s, "bad_frames": sum(e.bad_frames for e in endpoints),
              "markers_repeated": markers_repeated, **(stats or {})}  # fmt: skip
    try:
        args.line_stats.write_text(json.dumps(record) + "\n")
    except OSError as exc:
        raise EndpointError(f"--line-stats {args.line_stats}: {exc.strerror or exc}") from None


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(_join_negative_values(sys.argv[1:] if argv is None else argv))
        _check_line_flags(args)
        _check_timing_flags(args)
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
    if (why := inconsistency(params)) is not None:
        print(f"{PROG}: error: --set {why}", file=sys.stderr)
        return 2
    rover = SimRover(params, world, home, args.seed)
    vehicle = MavlinkVehicle(rover, LinkParams(), fault_params=FAULT_PARAMS)
    for name, value in args.param:
        vehicle.set_param(name, value)

    clock = FrameClock(args.frame_s)
    endpoints: list[Endpoint] = []
    try:
        for url in args.endpoint or ([] if args.pty else [DEFAULT_ENDPOINT]):
            endpoints.append(open_endpoint(url))
        if args.pty:  # behind a serial line it is the controller's link (lockstep gating, link faults)
            endpoints.insert(0 if args.baud is not None else len(endpoints), _pty(args, clock))
        truth = None
        if args.truth_log:
            try:
                truth = TruthLog(open(args.truth_log, "w", encoding="utf-8"))
            except OSError as exc:
                raise EndpointError(f"--truth-log {args.truth_log}: {exc.strerror or exc}") from None
        if args.line_stats:
            _write_line_stats(args, endpoints, 0.0, 0)  # an unwritable file fails now, not at exit
    except EndpointError as exc:
        for endpoint in endpoints:
            endpoint.close()
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_UNAVAILABLE if isinstance(exc, EndpointBusy) else 2

    emulator = Emulator(rover, vehicle, endpoints, clock, args.lockstep, args.speedup, truth, args.seed, args.hold_at_s)
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
    for endpoint in endpoints:
        if (stats := endpoint.line_stats()) is not None:
            print(f"{PROG}: line {args.baud:g} baud: {_line_summary(stats)}", flush=True)
    if args.line_stats:
        try:
            _write_line_stats(args, endpoints, emulator.clock.t_s, emulator.markers_repeated)
        except EndpointError as exc:
            print(f"{PROG}: error: {exc}", file=sys.stderr)
    print(f"{PROG}: stopped at t={emulator.clock.t_s:.2f} s, {sum(e.bad_frames for e in endpoints)} bad frames ignored", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
