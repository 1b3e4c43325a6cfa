"""What the autopilot reports: typed events the shell turns into MAVLink messages and log lines.

The autopilot never sends or writes anything itself. Each step (and each ground-station request)
returns these; the daemon applies them in order: STATUSTEXT, MISSION_CURRENT and
MISSION_ITEM_REACHED on the GCS link, ARM_DISARM on the vehicle link, one line each in the event
log (``log_record``: the ``type`` and fields ``rover_ctl.app.report`` reads).
"""

from __future__ import annotations

from dataclasses import dataclass

from rover_ctl.vocabulary import MissionState, RoverMode, Severity

EN = tuple[float, float]


@dataclass(frozen=True)
class StatusText:
    """A STATUSTEXT for the ground station (refusal reasons, failsafes, mission progress)."""

    text: str
    severity: Severity = Severity.INFO

    def log_record(self) -> tuple[str, dict]:
        return "statustext", {"text": self.text, "severity": int(self.severity)}


@dataclass(frozen=True)
class ModeChanged:
    mode: RoverMode
    previous: RoverMode
    reason: str
    """Who changed it: "gcs", "failsafe", "mission complete", "guided target"."""

    def log_record(self) -> tuple[str, dict]:
        return "mode", {"mode": int(self.mode), "name": self.mode.name, "previous": self.previous.name, "reason": self.reason}


@dataclass(frozen=True)
class MissionCurrent:
    """MISSION_CURRENT now (the current item or the mission state changed)."""

    seq: int
    state: MissionState

    def log_record(self) -> tuple[str, dict]:
        return "current", {"seq": self.seq, "mission_state": self.state.name}


@dataclass(frozen=True)
class ItemReached:
    """MISSION_ITEM_REACHED(seq)."""

    seq: int

    def log_record(self) -> tuple[str, dict]:
        return "reached", {"seq": self.seq}


@dataclass(frozen=True)
class MissionComplete:
    seq: int

    def log_record(self) -> tuple[str, dict]:
        return "complete", {"seq": self.seq}


@dataclass(frozen=True)
class MissionLoaded:
    """A mission (or the home it is placed against) was taken into the autopilot."""

    waypoints_total: int
    items: int
    waypoints_en: tuple[EN, ...]

    def log_record(self) -> tuple[str, dict]:
        return "mission", {"waypoints_total": self.waypoints_total, "items": self.items,
                           "waypoints_en": [[float(e), float(n)] for e, n in self.waypoints_en]}  # fmt: skip


@dataclass(frozen=True)
class PlanMade:
    """The path follower planned a path to goal ``goal_seq`` (0: a GUIDED, LOITER or RTL goal)."""

    goal_seq: int
    length_m: float
    path_en: tuple[EN, ...]

    def log_record(self) -> tuple[str, dict]:
        return "plan", {"goal_seq": self.goal_seq, "length_m": round(self.length_m, 3),
                        "path_en": [[round(e, 3), round(n, 3)] for e, n in self.path_en]}  # fmt: skip


@dataclass(frozen=True)
class FailsafeChanged:
    """The set of active failsafes changed; ``action`` is the resulting Action's name."""

    reasons: tuple[str, ...]
    action: str

    def log_record(self) -> tuple[str, dict]:
        return "failsafe", {"reasons": list(self.reasons), "action": self.action}


@dataclass(frozen=True)
class ArmRequest:
    """Ask the vehicle to arm or disarm (MAV_CMD_COMPONENT_ARM_DISARM on the vehicle link)."""

    arm: bool
    force: bool

    def log_record(self) -> tuple[str, dict]:
        return "arm_request", {"arm": self.arm, "force": self.force}


Event = StatusText | ModeChanged | MissionCurrent | ItemReached | MissionComplete | MissionLoaded | PlanMade | FailsafeChanged | ArmRequest
