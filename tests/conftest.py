"""Make the packages importable from a source checkout (./run.sh installs them as well)."""

import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
for package in ('growspace_sim', 'growspace_gym_bridge'):
    path = os.path.join(ROOT, 'src', package)
    if path not in sys.path:
        sys.path.insert(0, path)


def child_env() -> dict:
    """Environment for a child Python process that must import the packages like we do."""
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(
        [os.path.join(ROOT, 'src', p) for p in ('growspace_sim', 'growspace_gym_bridge')]
        + [os.path.join(ROOT, 'tests')] + ([env['PYTHONPATH']] if env.get('PYTHONPATH') else []))
    return env


def pytest_configure(config):
    config.addinivalue_line(
        'markers', 'slow: long runs (minutes, e.g. learning checks); skipped unless '
                   'GROWSPACE_RUN_SLOW=1 or selected with -m slow')


def pytest_collection_modifyitems(config, items):
    import pytest  # noqa: PLC0415

    if os.environ.get('GROWSPACE_RUN_SLOW') == '1' or 'slow' in (config.getoption('-m') or ''):
        return
    skip = pytest.mark.skip(reason='slow: set GROWSPACE_RUN_SLOW=1 or use -m slow')
    for item in items:
        if 'slow' in item.keywords:
            item.add_marker(skip)
