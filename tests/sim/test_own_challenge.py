"""A challenge in a module of its own, outside the package, runs by name everywhere.

``SimConfig(challenge='my_tall_task:TALL')`` imports the module and registers its ``Task`` the
first time (as Gymnasium loads ``module:EnvId``), so ``sim_node -p challenge:=my_tall_task:TALL``
and a bridged env run it; a message from the network never makes the node import a module.
"""

from __future__ import annotations

from collections.abc import Iterator
import os
from pathlib import Path
import textwrap

import numpy as np
import pytest

from bridge_helpers import loopback_domain
from growspace_sim.core import task as tasks
from growspace_sim.core.config import SimConfig
from growspace_sim.envs.env import GrowSpaceEnv

MODULE = textwrap.dedent('''
    """A user's own challenge: grow as tall as you can."""
    import numpy as np
    from growspace_sim.core.task import Layout, Task


    def layout(cfg, rng):
        stem = float(rng.uniform(0.2, 0.8)) * cfg.chamber_width
        return Layout((stem,), complex(stem, 0.95 * cfg.chamber_height), light_x=stem)


    def score(state, cfg):
        height = float(state.pos[:state.n_nodes].imag.max()) / cfg.chamber_height
        return height, np.array([height]), height >= 0.9


    TALL = Task(name='my_tall', env_name='MyTall', layout=layout, score=score, resolution=32,
                settings=('easy',))
    NOT_A_TASK = 42
''')
CHALLENGE = 'my_tall_task:TALL'


@pytest.fixture
def own_module(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    """The module on sys.path here and on PYTHONPATH for the nodes we start."""
    (tmp_path / 'my_tall_task.py').write_text(MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv('PYTHONPATH', os.pathsep.join(filter(None, (
        str(tmp_path), os.environ.get('PYTHONPATH')))))
    yield CHALLENGE
    tasks.unregister('my_tall')


def test_module_attribute_loads_and_registers_the_task(own_module: str) -> None:
    cfg = SimConfig(challenge=own_module)
    assert cfg.task.name == 'my_tall' and cfg.resolution == 32 and cfg.challenge == own_module
    assert SimConfig(challenge='my_tall').task is cfg.task  # registered under its own name too
    env = GrowSpaceEnv(own_module)
    obs, _ = env.reset(seed=3)
    assert obs.shape == (32, 32, 3)
    assert 0 < env.step(2)[1] <= 1


@pytest.mark.parametrize('name, message', [
    ('no_such_module_xyz:TALL', "cannot import 'no_such_module_xyz'"),
    ('my_tall_task:NOT_A_TASK', 'my_tall_task.NOT_A_TASK is int, not a growspace_sim'),
    ('my_tall_task:MISSING', 'my_tall_task.MISSING is NoneType'),
])
def test_a_bad_module_attribute_is_one_clear_error(own_module: str, name: str,
                                                   message: str) -> None:
    with pytest.raises(ValueError, match=message):
        SimConfig(challenge=name)


def test_a_network_reset_may_not_import_a_module() -> None:
    from growspace_sim.core.errors import CommandError
    from growspace_sim.ros import convert, types

    msg = types.new(types.RESET_REQUEST, challenge='os:path')
    with pytest.raises(CommandError, match='challenge'):
        convert.reset_args(msg)


@pytest.mark.slow
def test_own_challenge_runs_in_sim_node_through_the_bridge(own_module: str) -> None:
    from growspace_gym_bridge.envs import GrowSpaceBridgeEnv

    local = GrowSpaceEnv(own_module)
    for _ in loopback_domain():
        env = GrowSpaceBridgeEnv(own_module)  # starts its own sim_node with that challenge
        try:
            assert env.cfg.challenge == own_module
            assert env.observation_space == local.observation_space
            bridged, ref = env.reset(seed=5)[0], local.reset(seed=5)[0]
            np.testing.assert_array_equal(bridged, ref)
            for action in (2, 0, 1, 2):
                b, l_ = env.step(action), local.step(action)
                np.testing.assert_array_equal(b[0], l_[0])
                assert b[1] == l_[1]
        finally:
            env.close()
