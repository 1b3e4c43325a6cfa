"""Helpers shared by test areas (importable as ``support`` thanks to pytest's pythonpath)."""

from sitl.launch import free_port

SURE_ECHOES = ("proximity.track_beam_half_deg=0", "proximity.track_pace_sigma=0")
"""Settings for the obstacle tracker as it was before echoes had the beam's cone in their
covariance (2026-11-28): an echo as sure across its beam as along it. The in-process runner's
episodes found before then are chaotic near a miss and take other ways with any change of the
tracks, so the regression tests built on them pin it."""

CONE_SECTORS = ("proximity.edge_sectors=0",)
"""The obstacle memory's front and back sectors as they were before they spanned the rover's whole
width (2026-11-29): the cones from the sensors alone. Some regression episodes found before then
end without contact once the bumper's corners are covered, whatever the mechanism they test; their
counterfactual runs pin the cones."""

__all__ = ["free_port", "SURE_ECHOES", "CONE_SECTORS"]
