"""Fixtures shared by every test area."""

from __future__ import annotations

import os
import socket
from pathlib import Path

import pytest
from support import free_port

ROOT = Path(__file__).resolve().parent.parent
SHARED = Path(os.environ.get("ROVER_CTL_SHARED") or ROOT.parent / "shared")
"""../shared beside the checkout, or $ROVER_CTL_SHARED (a git worktree elsewhere), as the firmware launcher."""


@pytest.fixture
def shared_dir() -> Path:
    """../shared beside the checkout or $ROVER_CTL_SHARED (reference data and real mission files), or skip."""
    if not SHARED.is_dir():
        pytest.skip(f"{SHARED} is absent: tests on the shared reference data and missions are skipped")
    return SHARED


@pytest.fixture
def udp_port() -> int:
    return free_port(socket.SOCK_DGRAM)


@pytest.fixture
def tcp_port() -> int:
    return free_port(socket.SOCK_STREAM)
