"""Where the colcon-installed executables are (what ``ros2 run`` starts), for the scripts."""

from __future__ import annotations

import os
from pathlib import Path
import shutil


def sim_node_executable() -> str:
    """``install/growspace_sim/lib/growspace_sim/sim_node`` of the sourced workspace."""
    prefix = os.environ.get('COLCON_PREFIX_PATH', '').split(os.pathsep)[0] or 'install'
    exe = Path(prefix) / 'growspace_sim' / 'lib' / 'growspace_sim' / 'sim_node'
    return str(exe) if exe.exists() else (shutil.which('sim_node') or str(exe))
