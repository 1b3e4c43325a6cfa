"""``rover-ctl mission check|upload|download|clear``: mission files and the GCS link.

* ``check FILE [--all]``: load and validate; print the summary and warnings. Exit 0 if valid, 2
  if not, with the first error and the count of the others on one line (``--all``: every error,
  one per line). Whatever the file holds, that is the outcome: never a traceback.
* ``upload FILE --connect URL``: send each non-empty part of the file (mission items with home at
  seq 0, fence, rally points) to the autopilot over the mission protocol.
* ``download OUT --connect URL``: fetch mission, fence and rally; the format follows OUT's
  extension: ``.plan`` holds all three; ``.waypoints``/``.txt`` hold one list, so they get the
  mission (a fence-only or rally-only vehicle gives a fence or rally WPL) and the parts left out
  are named.
* ``clear --connect URL [--type mission|fence|rally|all]``.
* ``start --connect URL``: MAV_CMD_MISSION_START (AUTO from the first item); exit 0 accepted, 1
  refused with the autopilot's reason (see ``rover_ctl.commands.control``).

``--connect`` is a pymavlink connection string; the default listens where the daemon sends by
default (``udpin:127.0.0.1:14550``). Transfers show a progress bar on stderr; a timeout or a
refusal is a one-line error and exit status 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from rover_ctl.cli import UserError, check_url, mavlink_id, wait_seconds
from rover_ctl.config import GcsParams

DEFAULT_CONNECT = "udpin:127.0.0.1:14550"
CLEAR_TYPES = {"mission": 0, "fence": 1, "rally": 2, "all": 255}


def link_options(p: argparse.ArgumentParser) -> None:
    """--connect and the client's options (also used by `rover-ctl arm|disarm|mode`)."""
    p.add_argument("--connect", default=DEFAULT_CONNECT, metavar="URL",
                   help=f"pymavlink connection string of the autopilot (default {DEFAULT_CONNECT})")  # fmt: skip
    p.add_argument("--source-system", type=mavlink_id, default=255, metavar="ID", help="our MAVLink system id (255)")
    p.add_argument("--source-component", type=mavlink_id, default=190, metavar="ID", help="our component id (190)")
    p.add_argument("--timeout", type=wait_seconds, default=None, metavar="S",
                   help="give up after this long without an answer (default 5 s)")  # fmt: skip
    p.add_argument("--quiet", action="store_true", help="no progress display")
    p.add_argument("--signing-key", metavar="PASSPHRASE|@FILE",
                   help="sign with the MAVLink 2 key of this passphrase, or of @FILE (a key file or a passphrase on its first line)")  # fmt: skip


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("mission", help="check mission files; upload, download, clear or start over MAVLink")
    sub = parser.add_subparsers(dest="mission_command", metavar="ACTION", required=True)

    check = sub.add_parser("check", help="validate a mission file and print its summary")
    check.add_argument("file", help=".waypoints / .txt (QGC WPL 110) or .plan (QGroundControl)")
    check.add_argument("--all", action="store_true", help="list every error, not only the first")
    check.set_defaults(func=cmd_check)

    upload = sub.add_parser("upload", help="upload a mission file (mission, fence, rally) to the autopilot")
    upload.add_argument("file")
    link_options(upload)
    upload.set_defaults(func=cmd_upload)

    download = sub.add_parser("download", help="download the autopilot's mission to a file")
    download.add_argument("out", help="output file; format from the extension (.plan, .waypoints, .txt)")
    link_options(download)
    download.set_defaults(func=cmd_download)

    clear = sub.add_parser("clear", help="clear the autopilot's mission, fence, rally points or all")
    clear.add_argument("--type", choices=sorted(CLEAR_TYPES), default="mission", help="what to clear (mission)")
    link_options(clear)
    clear.set_defaults(func=cmd_clear)

    start = sub.add_parser("start", help="start the mission from its first item (MAV_CMD_MISSION_START)")
    link_options(start)
    start.set_defaults(func=cmd_start)


def _load(path: str, every_error: bool = False):
    from rover_ctl.mission.files import MissionFileError, load_mission

    try:
        return load_mission(path)
    except MissionFileError as exc:
        first, rest = exc.errors[0], exc.errors[1:]
        if every_error or not rest:
            raise UserError("\n".join(exc.errors)) from None
        more = f"{len(rest)} more error{'s' if len(rest) > 1 else ''}"
        raise UserError(f"{first} (and {more}; 'rover-ctl mission check --all' lists them)") from None


def cmd_check(args: argparse.Namespace) -> int:
    from rover_ctl.mission.files import summarize

    loaded = _load(args.file, args.all)
    print(f"{args.file}: valid {loaded.format} mission")
    print(summarize(loaded.mission))
    for warning in loaded.warnings:
        print(f"warning: {warning}")
    return 0


def _client(args: argparse.Namespace):
    from rover_ctl.mavlink.mission_client import MissionClient

    check_url(args.connect, "--connect")
    params = GcsParams()
    if args.timeout is not None:
        if args.timeout <= 0:
            raise UserError(f"--timeout {args.timeout:g}: must be positive")
        params.client_connect_timeout_s = args.timeout
        params.client_retry_s = args.timeout / (params.client_retries + 1)
        params.client_item_retry_s = min(params.client_item_retry_s, params.client_retry_s)
    from rover_ctl.mavlink.signing import SigningError, client_key

    try:
        key = client_key(args.signing_key)
    except SigningError as exc:
        raise UserError(str(exc)) from None
    try:
        return MissionClient(args.connect, params, args.source_system, args.source_component, signing_key=key)
    except (OSError, ValueError) as exc:
        raise UserError(f"--connect {args.connect}: {exc}") from None


def _run(args: argparse.Namespace, action):
    """Run ``action(client, progress)`` with a progress bar, turning protocol failures into UserError."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    from rover_ctl.mavlink.mission_client import TYPE_NAMES, MissionClientError

    with _client(args) as client, Progress(
        TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
        disable=args.quiet, transient=True, console=Console(stderr=True),
    ) as bar:  # fmt: skip
        tasks: dict[int, int] = {}

        def progress(mission_type, done: int, total: int) -> None:
            if mission_type not in tasks:
                tasks[mission_type] = bar.add_task(TYPE_NAMES[mission_type], total=total)
            bar.update(tasks[mission_type], completed=done, total=total)

        try:
            client.connect()
            return action(client, progress)
        except MissionClientError as exc:
            raise UserError(str(exc)) from None


def cmd_upload(args: argparse.Namespace) -> int:
    loaded = _load(args.file)
    mission = loaded.mission
    if not (mission.items or mission.fence or mission.rally):
        raise UserError(f"{args.file}: nothing to upload (no mission items, fence or rally points)")
    sent = _run(args, lambda client, progress: client.upload(mission, progress))
    parts = ", ".join(f"{len(mission.of_type(t))} {t.name.lower()}" for t in sent)
    print(f"uploaded {args.file}: {parts} items")
    return 0


def cmd_download(args: argparse.Namespace) -> int:
    from rover_ctl.mission.files import MissionFileError, save_mission
    from rover_ctl.mission.model import Mission

    out = Path(args.out)
    if out.suffix.lower() not in (".plan", ".waypoints", ".txt"):
        raise UserError(f"{out}: unknown extension {out.suffix!r}: use .plan, .waypoints or .txt")
    if out.is_dir():  # checked before the transfer, not after it
        raise UserError(f"{out}: is a folder; give a file name")
    if not out.parent.is_dir():
        raise UserError(f"{out}: {out.parent} is not an existing folder")
    mission = _run(args, lambda client, progress: client.download(progress))
    saved, left_out = mission, []
    if out.suffix.lower() != ".plan" and mission.items:
        saved = Mission(items=mission.items, home=mission.home)
        left_out = [f"{len(part)} {name}" for name, part in (("fence", mission.fence), ("rally", mission.rally)) if part]
    elif out.suffix.lower() != ".plan" and (mission.fence or mission.rally):
        saved = Mission(fence=mission.fence) if mission.fence else Mission(rally=mission.rally)
        left_out = [f"{len(mission.rally)} rally"] if mission.fence and mission.rally else []
    try:
        save_mission(saved, out)
    except MissionFileError as exc:
        raise UserError(str(exc)) from None
    except OSError as exc:
        raise UserError(f"{out}: cannot write: {exc.strerror}") from None
    note = f" (not saved in a WPL file: {', '.join(left_out)} items; use .plan)" if left_out else ""
    print(f"downloaded to {out}: {len(saved.items)} mission, {len(saved.fence)} fence, {len(saved.rally)} rally items{note}")
    return 0


def cmd_clear(args: argparse.Namespace) -> int:
    _run(args, lambda client, progress: client.clear(CLEAR_TYPES[args.type]))
    print(f"cleared {args.type}")
    return 0



def cmd_start(args: argparse.Namespace) -> int:
    from rover_ctl.commands.control import run_command
    from rover_ctl.vocabulary import mav

    return run_command(args, "mission start", mav.MAV_CMD_MISSION_START, 0.0, 0.0)
