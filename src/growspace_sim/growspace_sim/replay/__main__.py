"""``python -m growspace_sim.replay``: the ``growspace-replay`` command."""

import sys

from growspace_sim.replay.cli import main

sys.exit(main())
