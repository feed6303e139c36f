"""What the ROS benchmark scripts share: where ``sim_node`` is, and a process's CPU time."""

from __future__ import annotations

import os
from pathlib import Path
import shutil


def sim_node_executable() -> str:
    """``install/growspace_sim/lib/growspace_sim/sim_node`` of the sourced workspace."""
    prefix = os.environ.get('COLCON_PREFIX_PATH', '').split(os.pathsep)[0] or 'install'
    exe = Path(prefix) / 'growspace_sim' / 'lib' / 'growspace_sim' / 'sim_node'
    return str(exe) if exe.exists() else (shutil.which('sim_node') or str(exe))


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process [s] (Linux /proc)."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')
