"""The one way to start ``rover-sitl`` as a child process and stop it.

Used by ``rover-ctl sim``, the tests, the benchmarks and ``python -m sitl.demo``::

    with rover_sitl("--lockstep", "--seed", "3") as sitl:   # one tcpin endpoint on a free port
        client = LockstepClient(sitl.url)                    # sitl.client: the controller side
        ...
    # stopped with SIGTERM (then killed if it hangs); sitl.returncode, sitl.output, sitl.stderr kept

``start`` returns once the emulator printed its ``rover-sitl: ready`` line (every endpoint is
open) and raises ``SitlError`` with the emulator's last stderr line if it exits or stays silent
for ``start_timeout_s``. Both pipes are drained by threads for the whole run, so a chatty
emulator never blocks on a full pipe; each can also be copied to a file as it comes.

``line_relay`` starts ``python -m sitl.line_relay`` (ArduPilot's firmware behind a serial line on
a pty) the same way.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Collection, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

READY_PREFIX = "rover-sitl: ready"
"""The line ``sitl.main`` prints once every endpoint is open."""
PTY_PREFIX = "PTY "
"""The line naming the pseudo-terminal of ``--pty``."""
START_TIMEOUT_S = 30.0
"""Wall seconds for the ready line (a loaded 2-core machine imports shapely and numpy slowly)."""
STOP_TIMEOUT_S = 5.0
"""Wall seconds a child gets to exit after its stop signal before it is killed."""
STDERR_TAIL_LINES = 200
"""stderr lines kept in memory (all of them go to the file, if one is given)."""
CLIENT_SCHEME = {"tcpin": "tcp", "tcp": "tcpin", "udpin": "udpout", "udpout": "udpin"}
"""The client-side pymavlink scheme for each emulator endpoint scheme."""


START_ATTEMPTS = 3
"""Starts on freshly picked ports when one was taken between picking and binding."""


class SitlError(RuntimeError):
    """The emulator did not start; one line. ``returncode``: its exit status if it exited."""

    def __init__(self, message: str, returncode: int | None = None) -> None:
        super().__init__(message)
        self.returncode = returncode

    @property
    def port_busy(self) -> bool:
        """It exited because a port it was to bind is in use: another port may do."""
        return self.returncode == os.EX_UNAVAILABLE  # sitl.main's exit status for it


def free_port(kind: int = socket.SOCK_DGRAM, avoid: Collection[int] = ()) -> int:
    """A loopback port that is free right now (UDP by default) and none of ``avoid``: the kernel
    may hand out again a port whose socket it just closed, and two ports picked one after the
    other for one run came out the same (a daemon's vehicle and GCS links on one UDP port)."""
    while True:
        with socket.socket(socket.AF_INET, kind) as sock:
            sock.bind(("127.0.0.1", 0))
            port = sock.getsockname()[1]
        if port not in avoid:
            return port


def client_url(endpoint: str) -> str:
    """The pymavlink connection string that talks to the emulator endpoint ``endpoint``."""
    scheme, _, rest = endpoint.partition(":")
    return f"{CLIENT_SCHEME[scheme]}:{rest}"


@contextmanager
def signals_held() -> Iterator[None]:
    """Hold Ctrl-C and SIGTERM while a child process is created and recorded, then deliver them.

    Either one unwinds the launcher (KeyboardInterrupt, or SystemExit from a handler) wherever it
    lands; landing inside ``subprocess.Popen`` after the fork, it unwinds before the caller has the
    Popen to stop, and the child outlives the launcher. Only the main thread receives signals (and
    may set handlers): elsewhere this does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    previous = {sig: signal.signal(sig, lambda signum, frame: caught.append(signum)) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)
        for sig in caught:
            signal.raise_signal(sig)


def stop_process(proc: subprocess.Popen, sig: int = signal.SIGTERM, timeout_s: float = STOP_TIMEOUT_S) -> int:
    """Send ``sig``, wait up to ``timeout_s``, then kill. Returns the exit status."""
    if proc.poll() is None:
        proc.send_signal(sig)
        try:
            proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
    return proc.wait()


class SitlProcess:
    """A running ``python -m sitl``: its endpoints, its output so far, and how to stop it."""

    name = "rover-sitl"
    ready_prefix = READY_PREFIX

    def __init__(self, argv: list[str], endpoints: list[str], stdout_path: Path | None = None,
                 stderr_path: Path | None = None) -> None:  # fmt: skip
        self.argv = argv
        self.endpoints = endpoints
        """The emulator's endpoint strings, in order (the first is the controller's)."""
        self.output: list[str] = []
        """stdout lines so far."""
        self.line_times: list[float] = []
        """``time.perf_counter()`` at which each stdout line arrived."""
        self.pty_device: str | None = None
        self.returncode: int | None = None
        self._stderr_tail: deque[str] = deque(maxlen=STDERR_TAIL_LINES)
        self._ready = threading.Event()
        self._ended = threading.Event()
        self.proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self._pumps = [
            threading.Thread(target=self._pump_stdout, args=(self._open(stdout_path),), daemon=True),
            threading.Thread(target=self._pump_stderr, args=(self._open(stderr_path),), daemon=True),
        ]
        for pump in self._pumps:
            pump.start()

    @staticmethod
    def _open(path: Path | None) -> IO[str] | None:
        return open(path, "w", encoding="utf-8") if path is not None else None

    def _pump_stdout(self, copy: IO[str] | None) -> None:
        for line in self.proc.stdout:
            line = line.rstrip("\n")
            self.line_times.append(time.perf_counter())
            self.output.append(line)
            if copy:
                copy.write(line + "\n")
                copy.flush()
            if line.startswith(PTY_PREFIX):
                self.pty_device = line[len(PTY_PREFIX):]
            elif line.startswith(self.ready_prefix):
                self._ready.set()
        if copy:
            copy.close()
        self._ended.set()
        self._ready.set()

    def _pump_stderr(self, copy: IO[str] | None) -> None:
        for line in self.proc.stderr:
            self._stderr_tail.append(line.rstrip("\n"))
            if copy:
                copy.write(line)
                copy.flush()
        if copy:
            copy.close()

    # ---- what a caller reads -------------------------------------------------------------------

    @property
    def url(self) -> str:
        """pymavlink connection string for a client of the first endpoint (or the pty)."""
        if not self.endpoints:
            return self.pty_device or ""
        return client_url(self.endpoints[0])

    @property
    def stderr(self) -> str:
        return "\n".join(self._stderr_tail).strip()

    @property
    def ready_at(self) -> float | None:
        """``time.perf_counter()`` of the ready line."""
        return self.line_time(self.ready_prefix)

    def line_time(self, prefix: str) -> float | None:
        """When the first stdout line starting with ``prefix`` arrived (None: not yet)."""
        return next((t for t, line in zip(self.line_times, self.output) if line.startswith(prefix)), None)

    def last_error(self) -> str:
        """The emulator's last stderr line (its one-line errors end there)."""
        return self._stderr_tail[-1] if self._stderr_tail else "no output"

    def poll(self) -> int | None:
        """The exit status once the process ended, else None."""
        code = self.proc.poll()
        if code is not None:
            self._join()
            self.returncode = code
        return code

    # ---- lifecycle -----------------------------------------------------------------------------

    def wait_ready(self, timeout_s: float = START_TIMEOUT_S) -> None:
        if self._ready.wait(timeout_s) and not self._ended.is_set():
            return
        self.stop()
        raise SitlError(f"{self.name} did not start (exit {self.returncode}): {self.last_error()}", self.returncode)

    def wait(self, timeout_s: float = STOP_TIMEOUT_S) -> int:
        """Wait for the emulator to exit by itself (``--duration-s``, a kill); kill it after ``timeout_s``."""
        try:
            self.proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
        self.returncode = self.proc.wait()
        self._join()
        return self.returncode

    def kill(self) -> None:
        """SIGKILL: the vehicle vanishes without closing anything (tests of a lost link)."""
        self.proc.kill()

    def stop(self, timeout_s: float = STOP_TIMEOUT_S) -> int:
        """SIGTERM (the emulator closes its endpoints and logs), then kill after ``timeout_s``."""
        self.returncode = stop_process(self.proc, signal.SIGTERM, timeout_s)
        self._join()
        return self.returncode

    def _join(self) -> None:
        for pump in self._pumps:
            pump.join(STOP_TIMEOUT_S)


def start(*flags: str, endpoints: list[str] | None = None, repick: Callable[[], list[str]] | None = None,
          stdout_path: Path | None = None, stderr_path: Path | None = None,
          start_timeout_s: float = START_TIMEOUT_S) -> SitlProcess:  # fmt: skip
    """Start ``python -m sitl *flags`` with ``endpoints`` and wait for its ready line.

    ``repick`` gives new endpoints when the emulator exits because a port is in use (one picked
    free was taken before it bound it): up to ``START_ATTEMPTS`` starts. Without ``endpoints``
    (and without ``--pty``): one tcpin on a free loopback port, picked again so."""
    if endpoints is None and repick is None and "--pty" not in flags:
        repick = lambda: [f"tcpin:127.0.0.1:{free_port(socket.SOCK_STREAM)}"]  # noqa: E731
    if endpoints is None:
        endpoints = repick() if repick else []
    attempt = 1
    while True:
        argv = [sys.executable, "-m", "sitl", *flags]
        for endpoint in endpoints:
            argv += ["--endpoint", endpoint]
        sitl: SitlProcess | None = None
        try:
            with signals_held():  # delivered once ``sitl`` is known, so the handler below stops it
                sitl = SitlProcess(argv, list(endpoints), stdout_path, stderr_path)
            sitl.wait_ready(start_timeout_s)
            return sitl
        except SitlError as exc:
            if repick is None or not exc.port_busy or attempt == START_ATTEMPTS:
                raise
            attempt += 1
            endpoints = repick()
        except BaseException:  # Ctrl-C, SIGTERM: the caller never gets it to stop
            if sitl is not None:
                sitl.stop()
            raise


@contextmanager
def rover_sitl(*flags: str, **options) -> Iterator[SitlProcess]:
    """``start(*flags, **options)`` as a context manager that stops the emulator on exit."""
    sitl = start(*flags, **options)
    try:
        yield sitl
    finally:
        sitl.stop()


LINE_RELAY_READY_PREFIX = "line-relay: ready"
"""The line ``sitl.line_relay`` prints once its pty and its UDP port are open."""


class LineRelayProcess(SitlProcess):
    """A running ``python -m sitl.line_relay``: ``pty_device``, ``port`` (the firmware's
    ``--serial0 udpclient:127.0.0.1:PORT``), and ``stats()``, the counters it wrote at exit."""

    name = "line-relay"
    ready_prefix = LINE_RELAY_READY_PREFIX

    def __init__(self, argv: list[str], port: int, stats_path: Path) -> None:
        super().__init__(argv, [])
        self.port = port
        self.stats_path = stats_path

    def stats(self) -> dict:
        """The counters of ``--stats`` (written at start, then at exit: read them after ``stop``)."""
        return json.loads(self.stats_path.read_text())


@contextmanager
def line_relay(baud: float, stats_path: Path, *, byte_error: float = 0.0, speedup: float = 1.0,
               buffer_bytes: int | None = None, seed: int = 1, port: int | None = None) -> Iterator[LineRelayProcess]:  # fmt: skip
    """Start the relay from ArduPilot's SITL firmware to a pty (docs/sitl.md, "Serial line") and
    stop it on exit, so its counters are in ``stats_path``::

        with line_relay(57600, tmp / "line.json", speedup=10) as relay:
            firmware = start_firmware(..., "--serial0", f"udpclient:127.0.0.1:{relay.port}")
            conn = mavutil.mavlink_connection(relay.pty_device, baud=57600)
        relay.stats()["downlink"]["dropped_overflow"]
    """
    port = port or free_port(socket.SOCK_DGRAM)
    argv = [sys.executable, "-m", "sitl.line_relay", "--udpin", f"127.0.0.1:{port}", "--baud", f"{baud:g}",
            "--byte-error", repr(byte_error), "--speedup", repr(speedup), "--seed", str(seed), "--stats", str(stats_path)]  # fmt: skip
    if buffer_bytes is not None:
        argv += ["--buffer-bytes", str(buffer_bytes)]
    relay = LineRelayProcess(argv, port, stats_path)
    relay.wait_ready(START_TIMEOUT_S)
    try:
        yield relay
    finally:
        relay.stop()
