"""The README's main job: agents run chambers, the runs are recorded and re-simulate."""

from __future__ import annotations

import pytest

from growspace_sim import replay


from growspace_sim.tools import demo
from bridge_helpers import loopback_domain

# Most tests here take seconds (processes, ROS graphs, Ray): none in the quick tier.
pytestmark = pytest.mark.slow

domain = pytest.fixture(scope='module')(loopback_domain)


def test_demo_records_reproducible_runs(tmp_path, domain, capsys):
    assert demo.main(['--out', str(tmp_path), '--seed', '3']) == 0
    (run,) = tmp_path.iterdir()
    oracle, bridge = run / 'oracle.mcap', run / 'bridge.mcap'
    episodes = replay.summary(oracle)['episodes']
    assert [e['challenge'] for e in episodes] == ['control', 'find_plant', 'fairness', 'shape']
    with replay.Bag(bridge) as bag:
        steps = [e.n_steps for e in replay.read_episodes(bag)]
    assert 50 in steps  # the bridged episode, recorded by the sim_node process itself
    assert len(list(run.glob('*.gif'))) == 5
    out = capsys.readouterr().out
    assert out.count('reproduced bit for bit') == 2


def test_demo_never_overwrites(tmp_path, monkeypatch):
    monkeypatch.setattr(demo.time, 'strftime', lambda fmt: 'fixed')
    assert demo.main(['--out', str(tmp_path), '--no-ros']) == 0
    with pytest.raises(FileExistsError):
        demo.main(['--out', str(tmp_path), '--no-ros'])
