"""Missions: the typed model, the file formats, and the MAVLink mission microservice."""

from rover_ctl.mission.model import FenceCircle, FencePolygon, Home, Mission, MissionItem, MissionType

__all__ = ["FenceCircle", "FencePolygon", "Home", "Mission", "MissionItem", "MissionType"]
