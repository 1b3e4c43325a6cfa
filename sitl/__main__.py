"""``python -m sitl``: the same as the ``rover-sitl`` console script."""

import sys

from sitl.main import main

sys.exit(main())
