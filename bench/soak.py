"""Soak: hostile frames against a running daemon over loopback, and what they did.

``python -m bench soak`` (100,000 frames; ``--quick`` 10,000) or ``python -m bench.soak --frames N``.
Starts ``rover-sitl`` (free running, real time) and ``rover-ctl run`` with its GCS link on
``udpin:127.0.0.1:PORT`` and a mission store (empty at the start), then sends from one UDP socket a seeded mix of

* random bytes (1-280 bytes per datagram),
* valid frames of the handled message types corrupted (bytes flipped, truncated),
* valid frames of every handled type with arbitrary field values (NaN, infinities, extremes,
  random targets, commands, mission types; some of them well-formed arm, mode, parameter and
  mission commands, which legitimately take effect),

in batches closed by a sync probe (a REQUEST_MESSAGE from a system id no other frame uses, whose
COMMAND_ACK proves the daemon handled the batch before it). It reports frames handled per second
(wall time, probes included), crashes (the daemon exited, or stopped heartbeating for 3 s: must
be 0), handler exceptions the link edge caught (daemon log), and every command that took effect:
COMMAND_ACK ACCEPTED by command, MISSION_ACK ACCEPTED by mission type, the modes and arming
states the daemon's HEARTBEAT showed, parameters whose value changed, and whether the stored
mission file changed.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import select
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections import Counter
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mav  # noqa: E402

from rover_ctl.mavlink.gcs import HANDLED as GCS_HANDLED  # noqa: E402
from sitl.launch import STOP_TIMEOUT_S, SitlProcess, free_port, stop_process  # noqa: E402
from sitl.launch import start as start_sitl  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
FRAMES = 100_000
QUICK_FRAMES = 10_000
BATCH = 200
"""Frames between sync probes (well inside a UDP receive buffer)."""
PROBE_SYSTEM = 77
"""Source system of the sync probes; no hostile frame uses it."""
PROBE_RETRY_S = 0.5
SILENCE_CRASH_S = 3.0
"""No HEARTBEAT for this long (the period is 1 s) counts as a crash."""
START_TIMEOUT_S = 60.0
HANDLED = GCS_HANDLED
"""Every message type the daemon's GCS link acts on."""
COMMANDS = (mav.MAV_CMD_COMPONENT_ARM_DISARM, mav.MAV_CMD_DO_SET_MODE, mav.MAV_CMD_MISSION_START, mav.MAV_CMD_NAV_RETURN_TO_LAUNCH,
            mav.MAV_CMD_DO_SET_MISSION_CURRENT, mav.MAV_CMD_REQUEST_MESSAGE, mav.MAV_CMD_SET_MESSAGE_INTERVAL,
            mav.MAV_CMD_GET_HOME_POSITION, mav.MAV_CMD_DO_REPOSITION)  # fmt: skip
HOSTILE_FLOATS = (math.nan, math.inf, -math.inf, 0.0, 1.0, -1.0, 3.4e38, -3.4e38, 1e-45, 21196.0, 4.0, 10.0, 0.0, 1.0)
INT_RANGES = {"uint8_t": (0, 255), "int8_t": (-128, 127), "uint16_t": (0, 65535), "int16_t": (-32768, 32767),
              "uint32_t": (0, 2**32 - 1), "int32_t": (-(2**31), 2**31 - 1), "uint64_t": (0, 2**64 - 1),
              "int64_t": (-(2**63), 2**63 - 1)}  # fmt: skip
BIASED = {
    "target_system": (0, 1, 1, 1, 2), "target_component": (0, 1, 1, 190, 100), "mission_type": (0, 0, 1, 2, 3, 255),
    "seq": (0, 1, 2, 3, 65535), "count": (0, 1, 2, 700, 701, 65535), "command": COMMANDS,
    "custom_mode": (0, 4, 10, 11, 15, 99), "frame": (0, 2, 3, 5, 6, 99),
}  # fmt: skip
SENDERS = ((255, 190), (255, 230), (245, 190), (1, 1), (0, 0))


def random_message(rng: random.Random, kind: str):
    """A ``kind`` message with every field drawn from what its wire type carries, hostile values
    and the values the daemon acts on often."""
    cls = mav.mavlink_map[getattr(mav, f"MAVLINK_MSG_ID_{kind}")]
    lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths))

    def value(name: str, kind: str):
        if name in BIASED and rng.random() < 0.7:
            return rng.choice(BIASED[name])
        if kind == "char":
            return bytes(rng.randrange(256) for _ in range(rng.randint(0, lengths[name])))
        if kind in ("float", "double"):
            return rng.choice(HOSTILE_FLOATS) if rng.random() < 0.6 else rng.uniform(-1e6, 1e6)
        low, high = INT_RANGES[kind]
        return rng.choice((low, high, 0, 1)) if rng.random() < 0.3 else rng.randint(low, high)

    fields = []
    for name, kind_ in zip(cls.fieldnames, cls.fieldtypes):
        n = lengths[name]
        fields.append([value(name, kind_) for _ in range(n)] if n and kind_ != "char" else value(name, kind_))
    return cls(*fields)


def pack(msg, sender: tuple[int, int]) -> bytes:
    return bytes(msg.pack(mav.MAVLink(None, srcSystem=sender[0], srcComponent=sender[1])))


def hostile_frames(rng: random.Random, count: int, keep: Callable[[object], bool] = lambda msg: True) -> Iterator[bytes]:
    """``count`` datagrams of the mix in the module docstring; ``keep(msg)`` filters the valid ones."""
    sent = 0
    while sent < count:
        roll = rng.random()
        if roll < 0.4:
            yield bytes(rng.randrange(256) for _ in range(rng.randint(1, 280)))
            sent += 1
            continue
        msg = random_message(rng, rng.choice(HANDLED))
        if not keep(msg):
            continue
        frame = bytearray(pack(msg, rng.choice(SENDERS)))
        if roll < 0.7:
            for _ in range(rng.randint(1, 4)):
                frame[rng.randrange(len(frame))] ^= rng.randrange(1, 256)
            if rng.random() < 0.3:
                frame = frame[: rng.randrange(1, len(frame) + 1)]
        yield bytes(frame)
        sent += 1


class Rig:
    """rover-sitl and rover-ctl run as processes; ``port`` is the daemon's GCS udpin port."""

    def __init__(self, workdir: Path, store_text: str | None = None) -> None:
        self.workdir = workdir
        self.store = workdir / "mission.json"
        if store_text is not None:
            self.store.write_text(store_text)
        self.log = workdir / "daemon.log"
        self.port = free_port(socket.SOCK_DGRAM)
        self.vehicle_port = free_port(socket.SOCK_STREAM)
        self.sitl: SitlProcess | None = None
        self.daemon: subprocess.Popen | None = None
        self.files = []

    def start(self) -> None:
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
        self.sitl = start_sitl(endpoints=[f"tcpin:127.0.0.1:{self.vehicle_port}"], stderr_path=self.workdir / "sitl.log",
                               start_timeout_s=START_TIMEOUT_S)  # fmt: skip
        daemon_log = open(self.log, "w")
        self.files.append(daemon_log)
        self.daemon = subprocess.Popen(
            [sys.executable, "-m", "rover_ctl", "run", "--vehicle", f"tcp:127.0.0.1:{self.vehicle_port}",
             "--gcs", f"udpin:127.0.0.1:{self.port}", "--mission-store", str(self.store), "--log-run", str(self.workdir / "logs")],
            stdout=daemon_log, stderr=subprocess.STDOUT, cwd=ROOT, env=env,
        )  # fmt: skip

    def stop(self) -> None:
        if self.daemon is not None:
            stop_process(self.daemon, signal.SIGTERM, STOP_TIMEOUT_S)
        if self.sitl is not None:
            self.sitl.stop(STOP_TIMEOUT_S)
        for f in self.files:
            f.close()


@contextmanager
def rig(workdir: Path, store_text: str | None = None) -> Iterator[Rig]:
    r = Rig(workdir, store_text)
    try:
        r.start()
        yield r
    finally:
        r.stop()


class Observer:
    """The hostile sender's socket: sends datagrams, and reads what the daemon answers."""

    def __init__(self, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.addr = ("127.0.0.1", port)
        self.parser = mav.MAVLink(None)
        self.parser.robust_parsing = True
        self.last_heartbeat_wall: float | None = None
        self.heartbeats = 0
        self.longest_silence_s = 0.0
        self.states: Counter[tuple[bool, int]] = Counter()
        self.accepted_commands: Counter[int] = Counter()
        self.accepted_missions: Counter[int] = Counter()
        self.params: dict[str, float] = {}
        self.changed_params: set[str] = set()
        self.probes_answered = 0

    def close(self) -> None:
        self.sock.close()

    def send(self, data: bytes) -> None:
        self.sock.sendto(data, self.addr)

    def read(self, wait_s: float = 0.0) -> None:
        while select.select([self.sock], [], [], wait_s)[0]:
            wait_s = 0.0
            for msg in self.parser.parse_buffer(self.sock.recv(65535)) or []:
                self._note(msg)

    def _note(self, msg) -> None:
        kind = msg.get_type()
        now = time.monotonic()
        if kind == "HEARTBEAT" and msg.get_srcComponent() == 1:
            if self.last_heartbeat_wall is not None:
                self.longest_silence_s = max(self.longest_silence_s, now - self.last_heartbeat_wall)
            self.last_heartbeat_wall = now
            self.heartbeats += 1
            self.states[(bool(msg.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED), msg.custom_mode)] += 1
        elif kind == "COMMAND_ACK" and msg.result == mav.MAV_RESULT_ACCEPTED:
            if msg.target_system == PROBE_SYSTEM:
                self.probes_answered += 1
            else:
                self.accepted_commands[msg.command] += 1
        elif kind == "MISSION_ACK" and msg.type == mav.MAV_MISSION_ACCEPTED:
            self.accepted_missions[msg.mission_type] += 1
        elif kind == "PARAM_VALUE":
            if msg.param_id in self.params and self.params[msg.param_id] != msg.param_value:
                self.changed_params.add(msg.param_id)
            self.params[msg.param_id] = msg.param_value

    def sync(self, deadline_wall: float) -> bool:
        """Probe until the daemon answers (everything sent before the probe is handled then)."""
        target = self.probes_answered + 1
        probe = mav.MAVLink_command_long_message(1, 1, mav.MAV_CMD_REQUEST_MESSAGE, 0,
                                                 mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0)  # fmt: skip
        while time.monotonic() < deadline_wall:
            self.send(pack(probe, (PROBE_SYSTEM, 190)))
            end = time.monotonic() + PROBE_RETRY_S
            while time.monotonic() < end:
                self.read(max(0.0, end - time.monotonic()))
                if self.probes_answered >= target:
                    return True
        return False


def soak(frames: int, seed: int, workdir: Path, keep: Callable[[object], bool] = lambda msg: True,
         store_text: str | None = None) -> dict:  # fmt: skip
    """Run the soak; returns the figures (see the module docstring)."""
    rng = random.Random(seed)
    with rig(workdir, store_text) as r:
        obs = Observer(r.port)
        try:
            gcs_hb = pack(mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3), (PROBE_SYSTEM, 190))
            deadline = time.monotonic() + START_TIMEOUT_S
            while obs.heartbeats == 0 and time.monotonic() < deadline and r.daemon.poll() is None:
                obs.send(gcs_hb)  # udpin learns where to send from our first datagram
                obs.read(0.5)
            if obs.heartbeats == 0:
                raise RuntimeError(f"daemon never heartbeated on its GCS link; see {r.log}")
            obs.send(pack(mav.MAVLink_param_request_list_message(1, 1), (PROBE_SYSTEM, 190)))
            obs.read(0.5)
            store_before = r.store.read_bytes() if r.store.exists() else None
            obs.longest_silence_s = 0.0
            started = time.monotonic()
            unsynced, sent = 0, 0
            for data in hostile_frames(rng, frames, keep):
                obs.send(data)
                sent += 1
                unsynced += 1
                if unsynced == BATCH:
                    obs.send(gcs_hb)
                    if not obs.sync(time.monotonic() + SILENCE_CRASH_S * 3):
                        break
                    unsynced = 0
            synced = obs.sync(time.monotonic() + SILENCE_CRASH_S * 3)
            elapsed_s = time.monotonic() - started
            obs.send(pack(mav.MAVLink_param_request_list_message(1, 1), (PROBE_SYSTEM, 190)))
            obs.read(1.5)  # heartbeats after the last batch, the parameter table
            alive = r.daemon.poll() is None
            store_after = r.store.read_bytes() if r.store.exists() else None
        finally:
            obs.close()
    log_text = r.log.read_text(errors="replace")
    crashes = int(not alive or not synced or obs.longest_silence_s > SILENCE_CRASH_S)
    return {
        "frames": sent,
        "seed": seed,
        "elapsed_s": round(elapsed_s, 2),
        "frames_per_s": round(sent / elapsed_s, 1),
        "crashes": crashes,
        "daemon_alive": alive,
        "exit_code": r.daemon.returncode,
        "longest_heartbeat_gap_s": round(obs.longest_silence_s, 2),
        "handler_exceptions_caught": log_text.count("GCS link: "),
        "tracebacks_in_log": log_text.count("Traceback"),
        "accepted_commands": {_command_name(c): n for c, n in sorted(obs.accepted_commands.items())},
        "accepted_mission_acks": {str(t): n for t, n in sorted(obs.accepted_missions.items())},
        "heartbeat_states": {f"{'armed' if a else 'disarmed'} {_mode_name(m)}": n for (a, m), n in sorted(obs.states.items())},
        "changed_params": sorted(obs.changed_params),
        "store_changed": store_before != store_after,
    }


def _command_name(command: int) -> str:
    entry = mav.enums["MAV_CMD"].get(command)
    return entry.name.removeprefix("MAV_CMD_") if entry else str(command)


def _mode_name(mode: int) -> str:
    entry = mav.enums["ROVER_MODE"].get(mode)
    return entry.name.removeprefix("ROVER_MODE_") if entry else str(mode)


def run(quick: bool = False, frames: int | None = None, seed: int = 1) -> dict:
    """The benchmark entry point of ``python -m bench`` (see bench/__main__.py)."""
    frames = frames or (QUICK_FRAMES if quick else FRAMES)
    with tempfile.TemporaryDirectory(prefix="rover-soak-") as tmp:
        result = soak(frames, seed, Path(tmp))
    effects = ", ".join(f"{k} x{v}" for k, v in result["accepted_commands"].items()) or "none"
    missions = ", ".join(f"type {k} x{v}" for k, v in result["accepted_mission_acks"].items()) or "none"
    states = ", ".join(f"{k} ({v})" for k, v in result["heartbeat_states"].items())
    result["title"] = "Soak: hostile frames against a running daemon"
    result["markdown"] = "\n".join([
        f"{result['frames']:,} datagrams (40% random bytes, 30% corrupted frames, 30% valid frames of every handled "
        f"type with arbitrary fields), seed {seed}, one loopback UDP socket, sync probe every {BATCH} frames; "
        "`rover-sitl` free running in real time, `rover-ctl run` with a mission store, empty at the start.",
        "",
        "| frames | frames/s handled | crashes | longest heartbeat gap | handler exceptions caught | store changed |",
        "|---|---|---|---|---|---|",
        f"| {result['frames']:,} | {result['frames_per_s']:,.0f} | {result['crashes']} | {result['longest_heartbeat_gap_s']} s "
        f"| {result['handler_exceptions_caught']} | {'yes' if result['store_changed'] else 'no'} |",
        "",
        f"Commands that took effect (COMMAND_ACK ACCEPTED, all from the well-formed frames of the mix): {effects}.",
        f"MISSION_ACK ACCEPTED (clears and empty uploads, by mission type): {missions}.",
        f"Parameters changed: {', '.join(result['changed_params']) or 'none'}. HEARTBEAT states seen: {states}.",
    ])  # fmt: skip
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.soak", description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=FRAMES)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)
    result = run(frames=args.frames, seed=args.seed)
    print(json.dumps({k: v for k, v in result.items() if k != "markdown"}, indent=2))
    return 0 if result["crashes"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
