"""Missions: the typed model, the file formats, and the MAVLink mission microservice."""

from rover_ctl.mission.model import Mission, MissionItem, MissionType

__all__ = ["Mission", "MissionItem", "MissionType"]
