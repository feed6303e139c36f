"""Test session set-up: ROS 2 stays on this host, in a domain of its own.

The packages are installed by the colcon build that ``./run.sh`` sources, so only the test
folders themselves are added to ``sys.path`` here. ``./run.sh test`` already runs the session in
a loopback-only network namespace where the OS allows one; the loopback defaults and a random
ROS domain keep a session started any other way off the network and apart from other sessions
on the same host.
"""

import os
import random
import sys

from growspace_sim.ros import loopback

# tests/ mirrors the packages (sim, node, bridge, recording, rig, gantry, camera, tools); a few
# test modules reuse another's rig or fixture by import (test_gantry_node's Rig, ...), so every
# folder is importable whatever order pytest collects them in (file names stay unique).
_HERE = os.path.dirname(os.path.abspath(__file__))
_FOLDERS = sorted(entry.path for entry in os.scandir(_HERE)
                  if entry.is_dir() and not entry.name.startswith(('_', '.', 'data')))
sys.path[1:1] = _FOLDERS

loopback.confine()
if 'GROWSPACE_TEST_DOMAIN' in os.environ:
    os.environ['ROS_DOMAIN_ID'] = os.environ['GROWSPACE_TEST_DOMAIN']
else:  # 1..101: domain ids whose ports fit with Fast DDS's defaults
    os.environ['ROS_DOMAIN_ID'] = str(random.SystemRandom().randint(1, 101))


def child_env() -> dict:
    """Environment for a child Python process: ours (workspace sourced, loopback, domain), and
    the tests directories importable, as they are here."""
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join([_HERE, *_FOLDERS] + ([env['PYTHONPATH']]
                                                              if env.get('PYTHONPATH') else []))
    return env


def pytest_configure(config):
    config.addinivalue_line(
        'markers', 'slow: takes a second or more (ROS processes, sweeps, README runs); run by '
                   'default and in CI, left out of the quick tier: -m "not slow"')
    config.addinivalue_line(
        'markers', 'learning: learning checks (minutes each); skipped unless '
                   'GROWSPACE_RUN_LEARNING=1 or selected with -m learning')


def pytest_collection_modifyitems(config, items):
    import pytest  # noqa: PLC0415

    chosen = config.getoption('-m') or ''
    if os.environ.get('GROWSPACE_RUN_LEARNING') == '1' or (
            'learning' in chosen and 'not learning' not in chosen):
        return
    skip = pytest.mark.skip(reason='learning: set GROWSPACE_RUN_LEARNING=1 or use -m learning')
    for item in items:
        if item.get_closest_marker('learning') is not None:
            item.add_marker(skip)
