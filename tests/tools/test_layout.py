"""The layout shows the architecture: imports point down the layers, modules stay readable.

Every import of our packages is read from the source (module level, inside functions and under
``TYPE_CHECKING`` alike) and checked against the layer table below, so an arrow drawn back up
the house fails here before it confuses a reader.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[2] / 'src'
SIM = SRC / 'growspace_sim' / 'growspace_sim'
# Bottom to top; a module may import its own layer and the layers below. Inside growspace_sim
# a layer is a subpackage or top-level module; the other packages sit above the simulator's
# node, and its console programs (``tools``) above everything.
LAYERS = (
    ('core',),
    ('digits', 'render'),
    ('simulation',),
    ('envs', 'agents', 'ros', 'arguments'),
    ('recording', 'view'),
    ('node',),
    ('replay', 'learn', 'sweep', 'growspace_gym_bridge', 'growspace_gantry',
     'growspace_camera'),
    ('tools', 'rig'),
)
# Inside the core, bottom to top (tasks/ is the challenges, above everything they use).
CORE = ('errors', 'photoperiod', 'kernels', 'schema', 'task', 'config', 'light', 'state',
        'chamber', 'tasks')
MAX_LINES = 450
# An entry point that composes an upper layer, and why.
COMPOSES = {('growspace_sim.node.main', 'growspace_sim.replay'):
            "sim_node's resume_path reads a recording to start from (replay.resume_point)"}


def _layer(module: str) -> int | None:
    parts = module.split('.')
    key = parts[1] if parts[0] == 'growspace_sim' and len(parts) > 1 else parts[0]
    for level, names in enumerate(LAYERS):
        if key in names:
            return level
    return None


def _imports(path: Path, module: str) -> set[str]:
    """The modules of ours that a file imports (relative imports resolved)."""
    package = module if path.name == '__init__.py' else module.rpartition('.')[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:
                anchor = package.split('.')[:len(package.split('.')) - node.level + 1]
                base = '.'.join(anchor + ([base] if base else []))
            # `from pkg import mod` imports pkg.mod when mod is a module of ours.
            for alias in node.names:
                sub = f'{base}.{alias.name}'
                found.add(sub if _is_ours(sub) else base)
    return {m for m in found if m.split('.')[0].startswith('growspace_')}


def _is_ours(module: str) -> bool:
    path = SRC / module.split('.')[0] / module.replace('.', '/')
    return path.with_suffix('.py').exists() or (path / '__init__.py').exists()


def _modules() -> list[tuple[str, Path]]:
    out = []
    for package in sorted(SRC.glob('growspace_*/growspace_*')):
        for path in sorted(package.rglob('*.py')):
            parts = path.relative_to(package.parent).with_suffix('').parts
            name = '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)
            out.append((name, path))
    return out


def test_no_import_runs_up_the_layers():
    wrong = []
    for module, path in _modules():
        if module == 'growspace_sim':
            continue  # the package's face: its version, and it registers the Gymnasium ids
        level = _layer(module)
        assert level is not None, f'{module} is in no layer of tests/tools/test_layout.py'
        for imported in _imports(path, module):
            if imported == 'growspace_sim':
                continue  # only __version__ lives there
            target = _layer(imported)
            if (module, imported) in COMPOSES:
                continue
            if target is not None and target > level:
                wrong.append(f'{module} imports {imported} (layer {target} > {level})')
    assert not wrong, '\n'.join(wrong)


def test_the_core_imports_down_its_own_order():
    wrong = []
    for module, path in _modules():
        if not module.startswith('growspace_sim.core.'):
            continue
        level = CORE.index(module.split('.')[2])
        for imported in _imports(path, module):
            if imported.startswith('growspace_sim.') and _layer(imported) != 0:
                wrong.append(f'{module} imports {imported}, outside the core')
            elif imported.startswith('growspace_sim.core.'):
                target = CORE.index(imported.split('.')[2])
                if target > level:
                    wrong.append(f'{module} imports {imported}')
    assert not wrong, '\n'.join(wrong)


def test_the_simulators_top_level_holds_packages_and_at_most_three_modules():
    modules = sorted(p.name for p in SIM.glob('*.py') if p.name != '__init__.py')
    assert len(modules) <= 3, modules


@pytest.mark.parametrize('package', sorted(p.name for p in SRC.iterdir() if p.is_dir()))
def test_no_module_is_over_450_lines(package):
    long = [f'{p.relative_to(SRC)} ({n} lines)' for p in (SRC / package).rglob('*.py')
            if (n := len(p.read_text().splitlines())) > MAX_LINES]
    assert not long, long


def test_the_checker_sees_an_upward_import(tmp_path):
    # The test above must be able to fail: a core module importing the node is caught.
    path = tmp_path / 'chamber.py'
    path.write_text('from growspace_sim.node import chamber_node\n'
                    'def f():\n    from growspace_sim.tools import demo\n')
    found = _imports(path, 'growspace_sim.core.chamber')
    assert found == {'growspace_sim.node.chamber_node', 'growspace_sim.tools.demo'}
    assert all(_layer(m) > _layer('growspace_sim.core.chamber') for m in found)


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import circles of ``graph`` (module -> modules it imports): each strongly connected
    set of two or more modules, or a module importing itself, sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found = []

    def visit(module: str) -> None:  # Tarjan's algorithm
        index[module] = low[module] = len(index)
        stack.append(module)
        for target in sorted(graph.get(module, ())):
            if target not in index:
                visit(target)
                low[module] = min(low[module], low[target])
            elif target in stack:
                low[module] = min(low[module], index[target])
        if low[module] == index[module]:
            members = []
            while not members or members[-1] != module:
                members.append(stack.pop())
            if len(members) > 1 or module in graph.get(module, ()):
                found.append(sorted(members))

    for module in sorted(graph):
        if module not in index:
            visit(module)
    return sorted(found)


def test_no_modules_import_each_other():
    """Not even inside functions (issue 33: ros/plain.py and ros/types.py did): a circle means
    neither module can be read, or loaded, without the other."""
    # A module's own packages are loaded before it in any case (the sweep's cli reads its
    # package's docstring): importing them closes no circle.
    graph = {module: {m for m in _imports(path, module) if not module.startswith(m + '.')}
             for module, path in _modules()}
    assert _circles(graph) == []


def test_the_circle_check_sees_a_circle_through_a_function(tmp_path):
    # What plain.py and types.py were: one imports the other at the top, the other imports
    # it back inside a function.
    (tmp_path / 'types.py').write_text('from growspace_sim.ros import plain\n')
    (tmp_path / 'plain.py').write_text('def check():\n    from growspace_sim.ros import types\n')
    graph = {f'growspace_sim.ros.{name}': _imports(tmp_path / f'{name}.py',
                                                   f'growspace_sim.ros.{name}')
             for name in ('plain', 'types')}
    assert _circles(graph) == [['growspace_sim.ros.plain', 'growspace_sim.ros.types']]
    assert _circles({'a': {'b'}, 'b': set()}) == []
