"""The tree shows the architecture: the pure core packages import nothing from the shell ones,
and the autopilot touches no sockets, clocks, processes or files (docs/architecture.md)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "rover_ctl"
CORE = ("autopilot", "navigation", "estimation", "fuzzy", "mission")
CORE_MODULES = ("config.py", "vocabulary.py", "parameters.py", "param_store.py")
SHELL = ("rover_ctl.mavlink", "rover_ctl.app", "rover_ctl.commands", "rover_ctl.cli")
IO_MODULES = {"socket", "select", "time", "subprocess", "threading", "os", "pathlib", "io", "signal",
              "tempfile", "shutil", "logging", "pymavlink.mavutil"}


def _imports(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    names: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.append(node.module)
            names += [f"{node.module}.{alias.name}" for alias in node.names]
    return names


def _core_files() -> list[Path]:
    files = [p for pkg in CORE for p in sorted((PACKAGE / pkg).rglob("*.py"))]
    return files + [PACKAGE / name for name in CORE_MODULES]


@pytest.mark.parametrize("path", _core_files(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_core_imports_no_shell(path: Path) -> None:
    bad = [name for name in _imports(path) if name.startswith(SHELL)]
    assert not bad, f"{path.relative_to(PACKAGE)} imports shell modules: {bad}"


@pytest.mark.parametrize("path", sorted((PACKAGE / "autopilot").rglob("*.py")), ids=lambda p: p.name)
def test_autopilot_has_no_io(path: Path) -> None:
    bad = [name for name in _imports(path) if name in IO_MODULES or name.split(".")[0] in IO_MODULES]
    assert not bad, f"autopilot/{path.name} imports I/O: {bad}"
    assert "open(" not in path.read_text(encoding="utf-8"), f"autopilot/{path.name} opens a file"
