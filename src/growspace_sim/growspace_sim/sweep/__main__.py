"""``python -m growspace_sim.sweep``: the ``growspace-sweep`` command."""

import sys

from growspace_sim.sweep.cli import main

sys.exit(main())
