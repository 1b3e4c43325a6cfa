"""Tuning rule bases by machine (``rover-ctl tune``, docs/tuning.md): the seeded scenarios, the
in-process episode runner, the genome of a rule base's membership functions, the objective, and
the task a Dask worker runs. No sockets or files; the Dask and file side is ``rover_ctl.app.tune``.
"""
