"""``rover-ctl signing``: the daemon's MAVLink 2 signing key (docs/gcs.md, "Signing").

``setup PASSPHRASE`` writes the key (SHA-256 of the passphrase, as MAVProxy's ``signing setup``
and QGroundControl make it) to ``gcs.signing_key_path`` (mode 0600, atomically); ``remove``
deletes it. Both refuse a path that holds anything but a key (a mission file given by mistake).
A running daemon reads the key when it starts.
"""

from __future__ import annotations

import argparse

from rover_ctl.cli import UserError
from rover_ctl.config import ConfigError, load_config


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("signing", help="set up the MAVLink 2 signing key of the GCS link",
                                   description="The daemon's MAVLink 2 signing key (docs/gcs.md).")  # fmt: skip
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)

    def key_options(p: argparse.ArgumentParser) -> None:
        p.add_argument("--key-file", metavar="FILE", help="the key file (default: gcs.signing_key_path)")
        p.add_argument("--config", metavar="FILE", help="TOML config file (for gcs.signing_key_path)")

    setup = sub.add_parser("setup", help="make the key from a passphrase (as MAVProxy `signing setup` does)")
    setup.add_argument("passphrase", metavar="PASSPHRASE")
    key_options(setup)
    setup.set_defaults(func=cmd_setup)
    remove = sub.add_parser("remove", help="delete the key: the GCS link runs without signing")
    key_options(remove)
    remove.set_defaults(func=cmd_remove)


def _store(args: argparse.Namespace):
    from rover_ctl.mavlink.signing import KeyStore

    if args.key_file is not None:
        path = args.key_file
    else:
        try:
            path = load_config(args.config).gcs.signing_key_path
        except ConfigError as exc:
            raise UserError(str(exc)) from None
    if not path:
        raise UserError("no key file: gcs.signing_key_path is empty (give --key-file)")
    return KeyStore(path)


def cmd_setup(args: argparse.Namespace) -> int:
    from rover_ctl.mavlink.signing import SigningError, key_from_passphrase

    store = _store(args)
    try:
        store.save_key(key_from_passphrase(args.passphrase))
    except SigningError as exc:
        raise UserError(str(exc)) from None
    print(f"signing key written to {store.key_path}; restart the daemon to use it")
    return 0


def cmd_remove(args: argparse.Namespace) -> int:
    from rover_ctl.mavlink.signing import SigningError

    store = _store(args)
    try:
        removed = store.remove_key()
    except SigningError as exc:
        raise UserError(str(exc)) from None
    except OSError as exc:
        raise UserError(f"{store.key_path}: {exc}") from None
    print(f"signing key removed: {store.key_path}" if removed else f"no signing key at {store.key_path}: nothing to remove")
    return 0
