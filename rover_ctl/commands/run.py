"""``rover-ctl run``: the controller daemon (see rover_ctl.app.daemon and docs/daemon.md).

Exit codes (sysexits): 0 stopped by SIGINT/SIGTERM, 2 a start-up error (bad flag, link URL,
config, rule base or log dir: one line on stderr, nothing started), 69 no vehicle answered or a
link could not be opened, 70 the control loop failed. A service manager restarts on 69/70 and
does not on 2 (docs/rover-ctl.service).
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys

from rover_ctl.config import ConfigError, load_config

EXIT_UNAVAILABLE = 69
"""sysexits EX_UNAVAILABLE: a link could not be opened (may work on a restart)."""


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("run", help="run the controller daemon", description="The controller daemon: vehicle link, GCS link, control loop (docs/daemon.md).")
    parser.add_argument("--vehicle", metavar="URL", help="vehicle link, pymavlink connection string (default: link.vehicle_url, tcp:127.0.0.1:5760)")
    parser.add_argument("--gcs", metavar="URL", help="GCS link (default: link.gcs_url, udpout:127.0.0.1:14550)")
    parser.add_argument("--config", metavar="FILE", help="TOML config file (sections as rover_ctl.config)")
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE", help="override one config value (repeatable)")
    parser.add_argument("--rulebase", default="default", metavar="NAME|FILE", help="fuzzy rule base: shipped name (paper, default) or a TOML file")
    logs = parser.add_mutually_exclusive_group()
    logs.add_argument("--log-dir", metavar="DIR", help="each start writes a new numbered run folder here (vehicle.tlog, gcs.tlog, control.csv, events.jsonl) and DIR/latest (default: daemon.log_dir)")
    logs.add_argument("--log-run", metavar="DIR", help="write this run's logs into DIR itself, no numbering (rover-ctl sim, which numbers its own runs)")
    parser.add_argument("--mission-store", metavar="FILE", help="where the uploaded mission persists (default: gcs.mission_store_path; '' for none)")
    parser.add_argument("--signing-key-file", metavar="FILE", help="MAVLink 2 signing key file (default: gcs.signing_key_path; '' for none; make one with `rover-ctl signing setup`)")
    parser.add_argument("--require-signing", action="store_true", help="refuse to run without a signing key (gcs.require_signing)")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from rover_ctl.cli import UserError, check_url

    overrides = list(args.set)
    if args.vehicle is not None:  # '' is a bad URL, not "the default"
        overrides.append(f"link.vehicle_url={args.vehicle}")
    if args.gcs is not None:
        overrides.append(f"link.gcs_url={args.gcs}")
    if args.mission_store is not None:
        overrides.append(f"gcs.mission_store_path={args.mission_store}")
    if args.signing_key_file is not None:
        overrides.append(f"gcs.signing_key_path={args.signing_key_file}")
    if args.require_signing:
        overrides.append("gcs.require_signing=true")
    try:
        config = load_config(args.config, overrides)
    except ConfigError as exc:
        raise UserError(str(exc)) from None
    except (OSError, UnicodeDecodeError) as exc:  # a directory, no permission, not text
        raise UserError(f"--config {args.config}: cannot read: {getattr(exc, 'strerror', None) or exc}") from None
    check_url(config.link.vehicle_url, "--vehicle")
    check_url(config.link.gcs_url, "--gcs")

    from rover_ctl.app.daemon import Daemon
    from rover_ctl.app.logs import LogDirError, given_run_folder, new_run_folder, quiet_pymavlink
    from rover_ctl.fuzzy import RuleBaseError

    try:
        daemon = Daemon(config, rulebase=args.rulebase)
    except (RuleBaseError, OSError, ValueError) as exc:
        raise UserError(f"--rulebase {args.rulebase}: {exc}") from None
    root = args.log_dir if args.log_dir is not None else config.daemon.log_dir
    try:
        if args.log_run:
            daemon.log_dir = given_run_folder(args.log_run)
        elif root:
            daemon.log_dir = new_run_folder(root, config.daemon.log_max_total_mb)
    except LogDirError as exc:
        raise UserError(str(exc)) from None

    from rover_ctl.mavlink.signing import KeyStore, SigningError

    try:  # a damaged key file or a required key that is missing: a usage error, before any link opens
        key = KeyStore(config.gcs.signing_key_path).load_key() if config.gcs.signing_key_path else None
    except SigningError as exc:
        raise UserError(str(exc)) from None
    if config.gcs.require_signing and key is None:
        raise UserError("--require-signing: no signing key (gcs.signing_key_path); run: rover-ctl signing setup PASSPHRASE")
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    quiet_pymavlink(logging.getLogger("pymavlink"), config.daemon.link_chatter_s)
    if daemon.log_dir:
        logging.getLogger("rover_ctl.app.daemon").info("logs: %s", daemon.log_dir)

    def on_signal(signum, frame) -> None:
        daemon.stop()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    try:
        return daemon.run()
    except OSError as exc:  # the GCS link cannot be opened (port taken, no such address): may work later
        daemon.close()
        print(f"rover-ctl: error: GCS link {config.link.gcs_url}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_UNAVAILABLE

