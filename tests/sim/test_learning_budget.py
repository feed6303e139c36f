"""scripts/learning_budget.py without torch: the runs a call trains, issue 32's summary line."""

from __future__ import annotations

import argparse
import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location('learning_budget',
                                              ROOT / 'scripts' / 'learning_budget.py')
budget = importlib.util.module_from_spec(spec)
spec.loader.exec_module(budget)

HEADER = 'case,env,agent,runs,episodes,steps,mean,se\n'


def _args(**kw) -> argparse.Namespace:
    base = dict(out='runs/b', cases='Control-Hard,Shape-Curriculum', seeds=2, first_seed=0,
                steps=1_000_000, minutes=60.0, device='cuda', n_envs=8, vec='native',
                rollout_buffer='device', checkpoint_every=250_000)
    return argparse.Namespace(**{**base, **kw})


def test_every_run_resumes_with_the_case_studies_rollout_and_a_whole_budget_curriculum():
    runs = dict(budget.run_specs(_args()))
    assert sorted(Path(r).name for r in runs) == [
        'ppo-control-hard-s0', 'ppo-control-hard-s1', 'ppo-shape-curriculum-s0',
        'ppo-shape-curriculum-s1']
    argv = runs['runs/b/ppo-control-hard-s1']
    assert '--resume' in argv and argv[argv.index('--seed') + 1] == '1'
    assert 'n_steps=256' in argv and 'batch_size=64' in argv  # 8 x 256 = 2,048 per update
    assert argv[argv.index('--rollout-buffer') + 1] == 'device'
    curriculum = runs['runs/b/ppo-shape-curriculum-s0']
    # 1M steps / 8 envs / 50 steps = 2,500 episodes per chamber over 12 stages
    assert json.loads(curriculum[curriculum.index('--env-kwargs') + 1]) == {
        'episodes_per_stage': 208}
    argv = dict(budget.run_specs(_args(n_envs=32, cases='Shape-Easy', seeds=1)))
    assert 'n_steps=64' in next(iter(argv.values()))


def test_report_line_counts_cases_pools_camera_halves_and_overlapping_calls_once(tmp_path):
    results = tmp_path / 'results.csv'
    results.write_text(HEADER + ''.join([
        'a/easy,A,random,0,60,0,10.0,1.0\n', 'a/easy,A,oracle,0,60,0,20.0,1.0\n',
        'a/easy,A,ppo,2,60,100,18.5,1.0\n',   # beats random, within 10 % of the oracle
        'b/hard,B,random,0,60,0,10.0,1.0\n', 'b/hard,B,oracle,0,60,0,20.0,1.0\n',
        'b/hard,B,ppo,2,60,300,11.5,1.0\n',   # 10.5 > 11 is false: the intervals touch
        'c/easy,C,random,0,60,0,1.0,0.1\n', 'c/easy,C,oracle,0,60,0,2.0,0.1\n']))
    halves = []
    for i, (sim, cam) in enumerate([([4.0, 4.0], [2.0, 4.0]), ([4.0, 4.0], [4.0, 4.0])]):
        halves.append(tmp_path / f'cam_{i}.json')
        halves[-1].write_text(json.dumps({
            'fair': {'sim_returns': sim, 'camera_returns': cam},
            'ctrl': {'sim_returns': [2.0], 'camera_returns': [2.0]}}))
    calls = []
    for name, wall in [('call_6000_cuda_1', 360.0), ('call_6030_cpu_2', 720.0),
                       ('call_9000_cuda_3', 1800.0)]:
        calls.append(tmp_path / f'{name}.json')
        calls[-1].write_text(json.dumps({'wall_s': wall}))
    line = budget.report_line(results, halves, calls)
    assert line == ('learning: runs=4 steps_per_run=200 ppo_beats_random=1/2 '
                    'ppo_within_oracle_10pct=1/2 camera_ratio_min=0.875 hours_total=0.70')


@pytest.mark.parametrize('n_envs', [3, 48])
def test_train_refuses_envs_that_do_not_divide_the_rollout(n_envs, capsys):
    with pytest.raises(SystemExit):
        budget.main(['train', '--out', 'x', '--minutes', '1', '--n-envs', str(n_envs)])
    assert f'--n-envs must divide 2048, got {n_envs}' in capsys.readouterr().err
