"""Start ``rover-sitl`` as a separate process for a test, on free loopback ports, and stop it.

    with rover_sitl("--lockstep", "--seed", "3") as sitl:
        client = LockstepClient(sitl.url)          # the controller side of the first endpoint
        ...
    # stopped with SIGTERM (then killed if it hangs); sitl.returncode and sitl.output are kept

The emulator's stdout is read by a thread; the context manager returns once the process printed
``rover-sitl: ready`` (every endpoint is open), and fails with the process's stderr otherwise.
"""

from __future__ import annotations

import queue
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from support import free_port

READY_PREFIX = "rover-sitl: ready"
START_TIMEOUT_S = 15.0
STOP_TIMEOUT_S = 5.0
CLIENT_SCHEME = {"tcpin": "tcp", "udpin": "udpout", "udpout": "udpin"}
"""The client-side pymavlink scheme for each emulator endpoint scheme."""


@dataclass
class SitlProcess:
    proc: subprocess.Popen
    endpoints: list[str]
    """The emulator's endpoint strings, in order (the first is the controller's)."""
    output: list[str] = field(default_factory=list)
    """stdout lines so far."""
    pty_device: str | None = None
    returncode: int | None = None
    stderr: str = ""

    @property
    def url(self) -> str:
        """pymavlink connection string for a client of the first endpoint (or the pty)."""
        if not self.endpoints:
            return self.pty_device or ""
        return client_url(self.endpoints[0])


def client_url(endpoint: str) -> str:
    scheme, _, rest = endpoint.partition(":")
    return f"{CLIENT_SCHEME[scheme]}:{rest}"


def _pump(stream, lines: "queue.Queue[str | None]") -> None:
    for line in stream:
        lines.put(line.rstrip("\n"))
    lines.put(None)


@contextmanager
def rover_sitl(*flags: str, endpoints: list[str] | None = None, start_timeout_s: float = START_TIMEOUT_S) -> Iterator[SitlProcess]:
    """Run ``python -m sitl *flags`` with ``endpoints`` (default: one tcpin on a free port)."""
    if endpoints is None and "--pty" not in flags:
        endpoints = [f"tcpin:127.0.0.1:{free_port(socket.SOCK_STREAM)}"]
    endpoints = endpoints or []
    argv = [sys.executable, "-m", "sitl", *flags]
    for endpoint in endpoints:
        argv += ["--endpoint", endpoint]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    sitl = SitlProcess(proc, endpoints)
    lines: queue.Queue[str | None] = queue.Queue()
    errors: queue.Queue[str | None] = queue.Queue()
    threading.Thread(target=_pump, args=(proc.stdout, lines), daemon=True).start()
    # stderr is drained all along so a chatty emulator never blocks on a full pipe
    stderr_reader = threading.Thread(target=_pump, args=(proc.stderr, errors), daemon=True)
    stderr_reader.start()

    def stderr_text() -> str:
        stderr_reader.join(STOP_TIMEOUT_S)
        return "\n".join(iter(lambda: errors.get_nowait() if not errors.empty() else None, None)).strip()

    try:
        deadline = time.monotonic() + start_timeout_s
        while True:
            try:
                line = lines.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                line = None
            if line is None:
                proc.kill()
                raise RuntimeError(f"rover-sitl {' '.join(argv[3:])} did not become ready: "
                                   f"exit {proc.wait()}, stderr: {stderr_text()}")
            sitl.output.append(line)
            if line.startswith("PTY "):
                sitl.pty_device = line.split(" ", 1)[1]
            if line.startswith(READY_PREFIX):
                break
        threading.Thread(target=lambda: [sitl.output.append(x) for x in iter(lines.get, None)], daemon=True).start()
        yield sitl
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        sitl.returncode = proc.returncode
        sitl.stderr = stderr_text()


def lockstep_client(url: str, **kwargs):
    """A bench.lockstep_client.LockstepClient (the repository root is on pytest's pythonpath)."""
    from bench.lockstep_client import LockstepClient

    return LockstepClient(url, **kwargs)


def collect(client, seconds_sim: float, command=None) -> list[tuple[float, object]]:
    """Run ``client`` for ``seconds_sim``; ``command(t_s)`` -> (throttle_us, steering_us) or None.
    Returns every message received as (frame time, message)."""
    received: list[tuple[float, object]] = []

    def on_frame(t_s: float, msgs: list):
        received.extend((t_s, m) for m in msgs)
        return command(t_s) if command is not None else None

    client.run(seconds_sim, on_frame)
    return received


def of_type(received: list[tuple[float, object]], kind: str) -> list:
    return [m for _, m in received if m.get_type() == kind]
