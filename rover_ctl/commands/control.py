"""``rover-ctl arm [--force]``, ``disarm [--force]``, ``mode NAME``: the autopilot over the GCS link.

Each sends one command (MAV_CMD_COMPONENT_ARM_DISARM, MAV_CMD_DO_SET_MODE) to the autopilot at
``--connect`` (same connection options as ``rover-ctl mission``), prints the result and, on a
refusal, the autopilot's reason (its STATUSTEXT, e.g. "PreArm: no position (waiting for GPS)").
Exit status: 0 accepted, 1 refused, 2 usage or connection error. ``rover-ctl mission start``
(MAV_CMD_MISSION_START) lives with the other mission actions and uses the same code.
"""

from __future__ import annotations

import argparse
import sys

from rover_ctl.cli import UserError
from rover_ctl.vocabulary import ARM_FORCE_MAGIC, RoverMode, mav

EXIT_ACCEPTED = 0
EXIT_REFUSED = 1


def add_parser(subparsers) -> None:
    from rover_ctl.commands.mission import link_options

    arm = subparsers.add_parser("arm", help="arm the rover (pre-arm checks apply unless --force)")
    arm.add_argument("--force", action="store_true", help="skip the pre-arm checks (ARM_FORCE_MAGIC)")
    link_options(arm)
    arm.set_defaults(func=cmd_arm)

    disarm = subparsers.add_parser("disarm", help="disarm the rover")
    disarm.add_argument("--force", action="store_true", help="force (ARM_FORCE_MAGIC)")
    link_options(disarm)
    disarm.set_defaults(func=cmd_disarm)

    mode = subparsers.add_parser("mode", help="change the autopilot's mode: " + ", ".join(m.name for m in RoverMode))
    mode.add_argument("name", help="mode name (case-insensitive)")
    link_options(mode)
    mode.set_defaults(func=cmd_mode)


def run_command(args: argparse.Namespace, what: str, command: int, *params: float) -> int:
    """Send one command and report it; returns the exit status."""
    from rover_ctl.commands.mission import _client
    from rover_ctl.mavlink.command_client import send_command
    from rover_ctl.mavlink.mission_client import MissionClientError

    with _client(args) as client:
        try:
            client.connect()
            reply = send_command(client, command, *params)
        except MissionClientError as exc:
            raise UserError(str(exc)) from None
    if reply.accepted:
        print(f"{what}: accepted")
        return EXIT_ACCEPTED
    reason = "; ".join(reply.texts) or "no reason given"
    print(f"{what}: refused ({reply.result_name}): {reason}", file=sys.stderr)
    return EXIT_REFUSED


def cmd_arm(args: argparse.Namespace) -> int:
    force = float(ARM_FORCE_MAGIC) if args.force else 0.0
    return run_command(args, "arm", mav.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, force)


def cmd_disarm(args: argparse.Namespace) -> int:
    force = float(ARM_FORCE_MAGIC) if args.force else 0.0
    return run_command(args, "disarm", mav.MAV_CMD_COMPONENT_ARM_DISARM, 0.0, force)


def cmd_mode(args: argparse.Namespace) -> int:
    try:
        mode = RoverMode.named(args.name)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    return run_command(args, f"mode {mode.name}", mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, int(mode))
