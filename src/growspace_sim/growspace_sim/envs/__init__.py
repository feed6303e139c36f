"""The Gymnasium face: ``GrowSpaceEnv`` (``env``), the native vector env ``GrowSpaceVectorEnv``
(``vector``) and the ids (``registration``, run on ``import growspace_sim``).

The env classes load on first use (PEP 562), so importing the ids does not load OpenCV.
"""

import importlib

from growspace_sim.envs.registration import env_id, register_envs

_LAZY = {'GrowSpaceEnv': 'env', 'make_curriculum': 'env', 'GrowSpaceVectorEnv': 'vector'}

__all__ = ['GrowSpaceEnv', 'GrowSpaceVectorEnv', 'env_id', 'make_curriculum', 'register_envs']


def __getattr__(name: str):
    if name not in _LAZY:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    return getattr(importlib.import_module(f'{__name__}.{_LAZY[name]}'), name)
