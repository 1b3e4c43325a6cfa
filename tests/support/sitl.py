"""The emulator in tests: ``sitl.launch`` starts it, ``sitl.client`` drives it in lockstep.

    with rover_sitl("--lockstep", "--seed", "3") as sitl:
        client = lockstep_client(sitl.url)          # the controller side of the first endpoint
        received = collect(client, 5.0, command=lambda t_s: (1700, 1500))
"""

from __future__ import annotations

from sitl.client import LockstepClient
from sitl.launch import SitlProcess, rover_sitl

__all__ = ["SitlProcess", "collect", "lockstep_client", "of_type", "rover_sitl"]


def lockstep_client(url: str, **kwargs) -> LockstepClient:
    return LockstepClient(url, **kwargs)


def collect(client: LockstepClient, seconds_sim: float, command=None) -> list[tuple[float, object]]:
    """Run ``client`` for ``seconds_sim``; ``command(t_s)`` -> (throttle_us, steering_us) or None.
    Returns every message received as (frame time, message)."""
    received: list[tuple[float, object]] = []

    def on_frame(t_s: float, msgs: list):
        received.extend((t_s, m) for m in msgs)
        return command(t_s) if command is not None else None

    client.run(seconds_sim, on_frame)
    return received


def of_type(received: list[tuple[float, object]], kind: str) -> list:
    return [m for _, m in received if m.get_type() == kind]
