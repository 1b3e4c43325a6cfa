"""rover_ctl: a MAVLink controller for GPS-guided skid-steer rovers.

Pure core (no I/O): :mod:`rover_ctl.fuzzy`, :mod:`rover_ctl.estimator`, :mod:`rover_ctl.planner`,
:mod:`rover_ctl.navigator`, :mod:`rover_ctl.mission` (model and formats).
Shell (I/O at the edges): :mod:`rover_ctl.link`, :mod:`rover_ctl.gcs`, :mod:`rover_ctl.daemon`,
:mod:`rover_ctl.cli`. See docs/architecture.md.
"""

__version__ = "0.1.0"
