"""``rover-ctl``: the command line. Each subcommand lives in ``rover_ctl/commands/<name>.py`` and
exposes ``add_parser(subparsers)``, which registers its parser and sets ``func(args) -> int``.

Errors meant for the user are raised as ``UserError`` or ``ConfigError`` (one-line messages) and
printed as ``rover-ctl: error: ...`` with exit status 2; a bad flag is one such line too (no usage
block: under a service manager every start-up error is one line in the journal). Run it as
``rover-ctl`` or ``python -m rover_ctl``.
"""

from __future__ import annotations

import argparse
import importlib
import math
import os
import re
import stat
import sys
from typing import Any, Callable

from rover_ctl import __version__
from rover_ctl.config import ConfigError

# Subcommand modules, in the order shown by --help.
COMMANDS = ("run", "sim", "mission", "control", "params", "signing", "fuzzy", "tune")


class UserError(Exception):
    """A problem the user can fix (bad flag value, unreadable file, refused request)."""


class Parser(argparse.ArgumentParser):
    """argparse with its errors on one line (subcommand parsers inherit the class)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def number_type(kind: type, low: float, high: float, what: str, bounds: str) -> Callable[[str], Any]:
    """An argparse type: ``kind(text)`` within ``[low, high]`` (NaN never is), else a one-line
    refusal "expected WHAT BOUNDS, got TEXT"."""

    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"expected {what} {bounds}, got {text!r}")
        return value

    return parse


NET_SCHEMES = ("tcp", "tcpin", "udp", "udpin", "udpout", "udpbcast")
"""pymavlink connection-string schemes taking HOST:PORT."""
SERIAL_DEVICE = re.compile(r"^(/|\./|\.\./|COM\d+)[^,]*(,\d+)?$")
"""A serial device path with an optional baud rate (``/dev/ttyACM0,115200``)."""


def check_url(url: str, flag: str) -> None:
    """Refuse a connection string pymavlink would misread before anything opens it: ``bogus``
    would be opened as a serial port, ``nonsense:`` as UDP, a regular file as a log to replay
    (and written to), ``ws:`` needs a package we do not ship, port 99999 raises in ``bind``.
    Whether the peer is there is the link's business: that may change by the next try, and a
    serial adapter not plugged in yet is not refused here."""
    scheme, sep, rest = url.partition(":")
    if sep and scheme in NET_SCHEMES:
        host, sep, port = rest.rpartition(":")
        if sep and host and port.isdigit() and 0 < int(port) < 65536:
            return
        raise UserError(f"{flag} {url}: expected {scheme}:HOST:PORT with PORT in 1..65535")
    if SERIAL_DEVICE.match(url):
        device = url.split(",", 1)[0]
        try:
            mode = os.stat(device).st_mode
        except OSError:
            return
        if not stat.S_ISCHR(mode):
            raise UserError(f"{flag} {url}: {device} is not a serial device (a character device such as /dev/ttyUSB0)")
        return
    raise UserError(f"{flag} {url!r}: expected SCHEME:HOST:PORT ({', '.join(NET_SCHEMES)}) or a serial device /dev/...[,BAUD]")


MAX_WAIT_S = 86400.0
"""The longest ``--timeout`` a client command takes (a day): beyond it, clock arithmetic overflows."""
wait_seconds = number_type(float, math.ulp(0.0), MAX_WAIT_S, "seconds", f"in (0, {MAX_WAIT_S:g}]")
mavlink_id = number_type(int, 1, 255, "a whole number", "in 1..255 (a MAVLink id; 0 addresses everyone)")
seed = number_type(int, 0, math.inf, "a whole number", ">= 0 (a random seed)")
count = number_type(int, 1, math.inf, "a whole number", ">= 1")
positive = number_type(float, math.ulp(0.0), math.inf, "a number", "> 0")


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="rover-ctl",
        description="Controller for GPS-guided skid-steer rovers over MAVLink.",
    )
    parser.add_argument("--version", action="version", version=f"rover-ctl {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        try:
            module = importlib.import_module(f"rover_ctl.commands.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"rover_ctl.commands.{name}":
                raise
            continue  # a subcommand not built yet
        module.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130
    except (UserError, ConfigError) as exc:
        print(f"rover-ctl: error: {exc}", file=sys.stderr)
        return 2

