"""rover_ctl: a MAVLink controller for GPS-guided skid-steer rovers.

The tree shows the layers (docs/architecture.md has the module map):

Pure core, no sockets, clocks or processes:
    :mod:`rover_ctl.autopilot` (modes, mission executor, failsafes, the decision step),
    :mod:`rover_ctl.navigation` (planner, fuzzy navigator, obstacle memory, wheel control),
    :mod:`rover_ctl.estimation` (pose filter, local frame, sensor readings),
    :mod:`rover_ctl.fuzzy` (the Mamdani engine and rule bases),
    :mod:`rover_ctl.mission` (the mission model, file formats, validation, the store),
    :mod:`rover_ctl.config` (the one config object), :mod:`rover_ctl.vocabulary` (MAVLink names).
Shell, I/O at the edges:
    :mod:`rover_ctl.mavlink` (the vehicle link and the GCS-side microservices),
    :mod:`rover_ctl.app` (the daemon loop, ``rover-ctl sim``, reports, logs),
    :mod:`rover_ctl.cli` and :mod:`rover_ctl.commands` (the command line).
A core package imports nothing from a shell one (tests/test_layers.py checks it).
"""

__version__ = "0.1.0"
