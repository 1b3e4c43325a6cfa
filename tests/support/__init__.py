"""Helpers shared by test areas (importable as ``support`` thanks to pytest's pythonpath)."""

from sitl.launch import free_port

SURE_ECHOES = ("proximity.track_beam_half_deg=0", "proximity.track_pace_sigma=0")
"""Settings for the obstacle tracker as it was before echoes had the beam's cone in their
covariance (2026-11-28): an echo as sure across its beam as along it. The in-process runner's
episodes found before then are chaotic near a miss and take other ways with any change of the
tracks, so the regression tests built on them pin it."""

__all__ = ["free_port", "SURE_ECHOES"]
