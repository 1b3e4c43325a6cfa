"""``rover-ctl params [show|export FILE|import FILE]``: the parameter table (docs/gcs.md).

Two sources, as MAVProxy and Mission Planner have a vehicle and a file:

* without ``--connect``: the parameters the daemon would start with on this machine: defaults <
  ``--config FILE`` < the values stored from ground stations (``params.parm`` beside
  ``--mission-store``, default ``~/.local/state/rover-ctl/``) < ``--set``. ``import`` writes into
  that store (for a stopped daemon: a running one keeps its own copy and would overwrite it).
* with ``--connect URL``: a running daemon over MAVLink (PARAM_REQUEST_LIST; ``import`` sends
  PARAM_SET and checks each echo).

``show`` prints name, value, default, units, range and description (``*`` marks a value that is
not the default); ``--markdown`` prints the table of docs/gcs.md instead. ``export FILE.parm``
writes NAME VALUE lines (MAVProxy / Mission Planner format). ``import FILE.parm`` checks every
line first (known name, number, range; a read-only parameter may only repeat its value in force)
and applies all or nothing; a bad line is a one-line error and exit status 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from rover_ctl import inputfile
from rover_ctl.cli import UserError, check_url, wait_seconds
from rover_ctl.config import ConfigError, GcsParams, load_config

DEFAULT_CONNECT = "udpin:127.0.0.1:14550"


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("params", help="show, export or import the daemon's parameters",
                                   description="The parameter table: the daemon's tunables as a ground station sees them.")  # fmt: skip
    parser.add_argument("action", nargs="?", choices=("show", "export", "import"), default="show", help="show (default), export FILE, import FILE")
    parser.add_argument("file", nargs="?", help=".parm file for export/import (NAME VALUE per line)")
    parser.add_argument("--connect", metavar="URL", help=f"a running daemon's GCS link (e.g. {DEFAULT_CONNECT}); default: this machine's files")
    parser.add_argument("--config", metavar="FILE", help="TOML config file the daemon runs with")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="as rover-ctl run --set (repeatable)")
    parser.add_argument("--mission-store", metavar="FILE", help="as rover-ctl run: the stored parameters are params.parm beside it")
    parser.add_argument("--markdown", action="store_true", help="show: the documentation table (docs/gcs.md)")
    parser.add_argument("--timeout", type=wait_seconds, default=5.0, metavar="S", help="--connect: give up after this long without an answer")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from rover_ctl import parameters

    if args.markdown:
        print(parameters.markdown(), end="")
        return 0
    if args.action in ("export", "import") and not args.file:
        raise UserError(f"params {args.action}: a .parm file is needed")
    if args.action == "show" and args.file:
        raise UserError(f"params show takes no file (did you mean: params export {args.file}?)")
    if args.action == "import":
        return _import(args)
    values = _fetch(args) if args.connect else _local(args).params()
    if args.action == "export":
        _write(Path(args.file), parameters.format_parm(values, _header(args)))
        print(f"exported {len(values)} parameters to {args.file}")
        return 0
    print(_table(values))
    return 0


def _header(args: argparse.Namespace) -> str:
    source = args.connect or "this machine's config and stored parameters"
    return f"rover-ctl parameters from {source}"


def _config(args: argparse.Namespace):
    overrides = list(args.set)
    if args.mission_store is not None:
        overrides.append(f"gcs.mission_store_path={args.mission_store}")
    try:
        return load_config(args.config, overrides)
    except ConfigError as exc:
        raise UserError(str(exc)) from None


def _local(args: argparse.Namespace):
    from rover_ctl.mavlink.params import ConfigParams

    table = ConfigParams.persistent(_config(args), read_only=True)
    if table.store_error:
        raise UserError(table.store_error)
    return table


def _client(args: argparse.Namespace):
    from rover_ctl.mavlink.param_client import ParamClient

    if args.timeout <= 0:
        raise UserError(f"--timeout {args.timeout:g}: must be positive")
    check_url(args.connect, "--connect")
    params = GcsParams(client_connect_timeout_s=args.timeout)
    params.client_retries = max(1, round(args.timeout / params.client_retry_s) - 1)
    try:
        return ParamClient(args.connect, params)
    except (OSError, ValueError) as exc:
        raise UserError(f"--connect {args.connect}: {exc}") from None


def _fetch(args: argparse.Namespace) -> dict[str, float]:
    from rover_ctl.mavlink.param_client import ParamClientError

    with _client(args) as client:
        try:
            client.connect()
            return client.fetch()
        except ParamClientError as exc:
            raise UserError(str(exc)) from None


def _table(values: dict[str, float]) -> str:
    from rover_ctl.parameters import BY_NAME, TABLE, Access

    def number(value: float) -> str:
        return f"{value:g}"

    rows = [("name", "value", "default", "units", "range", "description")]
    for p in TABLE:
        if p.name not in values:
            continue  # config-only settings are not the daemon's parameters
        value = values[p.name]
        mark = "*" if value != p.default else ""
        access = {Access.RW: "", Access.START: "[read-only: start] "}.get(p.access, "")
        rows.append((p.name, number(value) + mark, number(p.default), p.units, p.range_text(), access + p.description))
    rows += [(name, number(value), "", "", "", "(not in this version's table)") for name, value in values.items() if name not in BY_NAME]
    widths = [max(len(r[i]) for r in rows) for i in range(5)]
    return "\n".join("  ".join(cell.ljust(w) for cell, w in zip(r[:5], widths)) + "  " + r[5] for r in rows)


def _write(path: Path, text: str) -> None:
    try:
        path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise UserError(f"{path}: cannot write: {exc.strerror or exc}") from None


def _import(args: argparse.Namespace) -> int:
    from rover_ctl.parameters import Access, ParamError, parse_parm

    path = Path(args.file)
    try:
        text = inputfile.read_text(path)
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"{path}: cannot read: {getattr(exc, 'strerror', None) or exc}") from None
    try:
        parsed = parse_parm(text, str(path))
    except ParamError as exc:
        raise UserError(str(exc)) from None
    current = _fetch(args) if args.connect else _local(args).params()
    changes: dict[str, float] = {}
    for name, (param, field_value) in parsed.items():
        number = param.encode(field_value)
        if param.access is Access.CONFIG or name not in current:
            raise UserError(f"{path}: {name} is not a daemon parameter (set it in the config file)")
        if number == current[name]:
            continue
        if param.access is not Access.RW and args.connect:
            raise UserError(f"{path}: {name} is read-only over MAVLink (set at start): {current[name]:g} in force, file says {number:g}")
        changes[name] = number
    if args.connect:
        _send(args, changes)
    else:
        _store(args, changes)
    print(f"imported {path}: {len(changes)} changed, {len(parsed) - len(changes)} already in force")
    return 0


def _send(args: argparse.Namespace, changes: dict[str, float]) -> None:
    from rover_ctl.mavlink.param_client import ParamClientError

    with _client(args) as client:
        try:
            client.connect()
            for name, value in changes.items():
                in_force, said = client.set(name, value)
                if in_force != value and abs(in_force - value) > 1e-6 * max(1.0, abs(value)):
                    raise UserError(f"{name}: the vehicle kept {in_force:g}: {said or 'refused'}")
        except ParamClientError as exc:
            raise UserError(str(exc)) from None


def _store(args: argparse.Namespace, changes: dict[str, float]) -> None:
    table = _local(args)
    if table.store is None:
        raise UserError("no parameter store: the mission store is off (--mission-store '')")
    if not changes:
        return
    try:
        table.store.save({**table.stored, **changes})
    except OSError as exc:
        raise UserError(f"{table.store.path}: cannot write: {exc.strerror or exc}") from None
