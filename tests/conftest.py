"""Test session set-up: ROS 2 stays on this host, in a domain of its own.

The packages are installed by the colcon build that ``./run.sh`` sources, so only the test
folders themselves are added to ``sys.path`` here. ``./run.sh test`` already runs the session in
a loopback-only network namespace where the OS allows one; the loopback defaults and random
ROS domains (one per test module) keep a session started any other way off the network and
apart from other sessions on the same host.
"""

from collections.abc import Iterator
import itertools
import os
import random
import sys

import pytest

from growspace_sim.ros import loopback

# tests/ mirrors the packages (sim, node, bridge, recording, rig, gantry, camera, tools); a few
# test modules reuse another's rig or fixture by import (test_gantry_node's Rig, ...), so every
# folder is importable whatever order pytest collects them in (file names stay unique).
_HERE = os.path.dirname(os.path.abspath(__file__))
_FOLDERS = sorted(entry.path for entry in os.scandir(_HERE)
                  if entry.is_dir() and not entry.name.startswith(('_', '.', 'data')))
sys.path[1:1] = _FOLDERS

loopback.confine()
_FIXED_DOMAIN = os.environ.get('GROWSPACE_TEST_DOMAIN')
# 1..101: domain ids whose ports fit with Fast DDS's defaults, in turn from a random first one.
_FIRST = random.SystemRandom().randint(1, 101)
_DOMAINS = itertools.cycle([(_FIRST + k - 1) % 101 + 1 for k in range(101)])
os.environ['ROS_DOMAIN_ID'] = _FIXED_DOMAIN or str(next(_DOMAINS))


def next_domain() -> int:
    """The next test domain id (the fixed one of GROWSPACE_TEST_DOMAIN if set)."""
    return int(_FIXED_DOMAIN) if _FIXED_DOMAIN else next(_DOMAINS)


@pytest.fixture(scope='module', autouse=True)
def module_domain() -> Iterator[int]:
    """Each test module in a ROS domain of its own.

    A process killed by a test (SIGKILL) leaves its DDS participant in the graph of everyone in
    its domain until its lease runs out (Fast DDS: 20 s), and every other participant then
    handles its removal. A participant torn down at that moment can hang for good: Fast DDS
    2.14 deletes a participant only after its listener's callbacks end, and busy-waits for
    them while holding the lock they need to end (eProsima/Fast-DDS#6513). A module of its own
    keeps another module's leftovers out of its tests' graphs; ``own_domain`` does the same for
    a test that kills something.
    """
    with pytest.MonkeyPatch.context() as patch:
        domain = next_domain()
        patch.setenv('ROS_DOMAIN_ID', str(domain))
        yield domain


@pytest.fixture
def own_domain(monkeypatch: pytest.MonkeyPatch) -> int:
    """A ROS domain for this test alone (see ``module_domain``)."""
    domain = next_domain()
    monkeypatch.setenv('ROS_DOMAIN_ID', str(domain))
    return domain


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
    chosen = config.getoption('-m') or ''
    if os.environ.get('GROWSPACE_RUN_LEARNING') == '1' or (
            'learning' in chosen and 'not learning' not in chosen):
        return
    skip = pytest.mark.skip(reason='learning: set GROWSPACE_RUN_LEARNING=1 or use -m learning')
    for item in items:
        if item.get_closest_marker('learning') is not None:
            item.add_marker(skip)
