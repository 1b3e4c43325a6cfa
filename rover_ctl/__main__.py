"""``python -m rover_ctl``: the same as the ``rover-ctl`` command."""

import sys

from rover_ctl.cli import main

sys.exit(main())
