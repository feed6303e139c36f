"""Test session set-up: ROS 2 stays on this host, in a domain of its own.

The packages are installed by the colcon build that ``./run.sh`` sources, so nothing is added to
``sys.path`` here. ``./run.sh test`` already runs the session in a loopback-only network
namespace where the OS allows one; the loopback defaults and a random ROS domain keep a session
started any other way off the network and apart from other sessions on the same host.
"""

import os
import random

from growspace_sim.ros import loopback

loopback.confine()
if 'GROWSPACE_TEST_DOMAIN' in os.environ:
    os.environ['ROS_DOMAIN_ID'] = os.environ['GROWSPACE_TEST_DOMAIN']
else:  # 1..101: domain ids whose ports fit with Fast DDS's defaults
    os.environ['ROS_DOMAIN_ID'] = str(random.SystemRandom().randint(1, 101))


def child_env() -> dict:
    """Environment for a child Python process: ours (workspace sourced, loopback, domain), and
    the tests directory importable, as it is here."""
    env = dict(os.environ)
    tests = os.path.dirname(os.path.abspath(__file__))
    env['PYTHONPATH'] = os.pathsep.join([tests] + ([env['PYTHONPATH']] if env.get('PYTHONPATH')
                                                   else []))
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
