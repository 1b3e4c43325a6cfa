"""The application shell: the daemon's loop, ``rover-ctl sim``, reports and logs."""
