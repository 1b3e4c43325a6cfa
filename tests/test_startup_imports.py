"""What starting the daemon and the command line loads (issue 17, docs/daemon.md "On a companion
computer"): the daemon's import path carries no plotting, report, benchmark or unused scipy code,
and ``rover-ctl --help`` builds its parser without numpy or the engines the subcommands use."""

from __future__ import annotations

import json
import subprocess
import sys

DAEMON_MUST_NOT_LOAD = ("scipy", "filterpy", "matplotlib", "rich", "rover_ctl.app.report", "rover_ctl.app.sim", "bench",
                        "cma", "distributed", "dask", "rover_ctl.tuning")  # fmt: skip
HELP_MUST_NOT_LOAD = ("numpy", "scipy", "matplotlib", "rich", "shapely", "networkx", "pyproj", "rover_ctl.fuzzy", "rover_ctl.app",
                      "cma", "distributed")  # fmt: skip


def _loaded_after(code: str, names: tuple[str, ...]) -> list[str]:
    """The ``names`` present in sys.modules after running ``code`` in a fresh interpreter."""
    probe = f"import sys, json\n{code}\nprint(json.dumps([n for n in {names!r} if n in sys.modules]))"
    return json.loads(subprocess.run([sys.executable, "-c", probe], check=True, capture_output=True, text=True, timeout=120).stdout)


def test_the_daemon_imports_nothing_it_does_not_run():
    assert _loaded_after("import rover_ctl.app.daemon, rover_ctl.commands.run", DAEMON_MUST_NOT_LOAD) == []


def test_help_builds_the_parser_without_the_subcommands_engines():
    assert _loaded_after("from rover_ctl.cli import build_parser; build_parser().format_help()", HELP_MUST_NOT_LOAD) == []


def test_the_help_lists_the_shipped_rule_bases():
    from rover_ctl.commands.fuzzy import shipped_names
    from rover_ctl.fuzzy import shipped

    assert shipped_names() == shipped() and "paper" in shipped()


def test_the_vehicle_link_speaks_mavlink_2_whatever_imported_mavutil_first():
    """gcs.py imports mavutil before anything sets MAVLINK20 (its default dialect is then MAVLink 1's
    "all", without e.g. ESC_TELEMETRY_1_TO_4): the vehicle link must not take that as its dialect."""
    code = "import rover_ctl.mavlink.gcs, rover_ctl.mavlink.vehicle as v; print(v.mavlink.__name__)"
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True, timeout=120).stdout
    assert out.strip() == "pymavlink.dialects.v20.ardupilotmega"
