"""The main job (``./run.sh demo``): chambers run by agents, recorded to ``bags/``.

1. The oracle plays one episode of each challenge on the chamber node, in process; the node
   records every message to ``bags/demo-<time>/oracle.mcap``.
2. A real ROS 2 ``sim_node`` process (rclpy, Fast DDS, confined to loopback) records itself to
   ``bags/demo-<time>/bridge.mcap`` while a random agent plays one control episode through the
   Gymnasium bridge, over its topics.
3. Both recordings are re-simulated from their seeds and commands and must match bit for bit;
   every episode is exported as a GIF next to them.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from growspace_sim import arguments, replay
from growspace_sim.agents import OracleAgent, play_episodes, RandomAgent
from growspace_sim.core import task as tasks
from growspace_sim.core.config import SimConfig
from growspace_sim.node.episode_runner import EpisodeRunner
from growspace_sim.recording import McapRecorder
from growspace_sim.ros import loopback


def record_oracle(path: Path, setting: str, seed: int) -> None:
    """One oracle episode per challenge (with an oracle and this setting) on an in-process
    chamber node, recorded to ``path``."""
    with McapRecorder(path) as recorder:
        challenges = [t.name for t in tasks.all_tasks() if setting in t.settings and t.oracle]
        runner = EpisodeRunner(SimConfig(challenge=challenges[0], setting=setting), recorder)
        oracle = OracleAgent()
        for challenge in challenges:
            played = play_episodes(runner, oracle, [seed], options={'challenge': challenge})
            print(f'  oracle  {challenge:10s} {setting}: return {played.returns[0]:6.2f} over '
                  f'{played.steps} steps')
        runner.close()


def record_bridged(path: Path, setting: str, seed: int) -> None:
    """A random agent plays control through the ROS bridge; the node records to ``path``."""
    from growspace_gym_bridge.envs import GrowSpaceBridgeEnv  # ROS 2 only for this part

    env = GrowSpaceBridgeEnv('control', setting, node_params={'record_path': str(path)})
    try:
        played = play_episodes(env, RandomAgent(env.action_space, seed), [seed])
        print(f'  random  control    {setting}: return {played.returns[0]:6.2f} through sim_node '
              f'({env.namespace})')
    finally:
        env.close()  # stops the node, which finishes its recording


def check_and_export(path: Path) -> bool:
    """Re-simulate a recording and export each of its episodes as a GIF; True if it matched."""
    report = replay.resimulate(path)
    verdict = 'reproduced bit for bit' if report.ok else f'MISMATCH: {report.mismatch}'
    print(f'  {path}: {report.episodes} episodes, {report.steps} steps, {verdict}')
    with replay.Bag(path) as bag:
        episodes = replay.read_episodes(bag)
    for index, episode in enumerate(episodes):
        if episode.n_steps:  # the node's start-up episode before a client's reset has none
            gif = path.with_name(f'{path.stem}-episode{index}.gif')
            replay.export_episode(path, gif, episode=index, progress=False)
    return report.ok


def main(argv: list[str] | None = None) -> int:
    parser = arguments.Parser(prog='growspace-demo', description=__doc__.splitlines()[0])
    parser.add_argument('--out', type=arguments.folder, default='bags',
                        help='parent directory (default: bags/)')
    parser.add_argument('--seed', type=arguments.SEED, default=0)
    parser.add_argument('--setting', default='hard',
                        choices=sorted({s for task in tasks.all_tasks() for s in task.settings}))
    parser.add_argument('--no-ros', action='store_true',
                        help='skip the sim_node + bridge part (no ROS 2)')
    args = parser.parse_args(argv)
    loopback.confine()  # the network rule, for the node we start and our own side
    out = Path(args.out) / f'demo-{time.strftime("%Y%m%d-%H%M%S")}'
    out.mkdir(parents=True, exist_ok=False)  # a new directory: nothing is ever overwritten
    print(f'Recording to {out}/')
    record_oracle(out / 'oracle.mcap', args.setting, args.seed)
    recordings = [out / 'oracle.mcap']
    if not args.no_ros:
        record_bridged(out / 'bridge.mcap', args.setting, args.seed)
        recordings.append(out / 'bridge.mcap')
    print('Re-simulating and exporting GIFs:')
    ok = all([check_and_export(path) for path in recordings])
    print(f'Done: {out}/ (open the .mcap files in Foxglove, or: growspace-replay info FILE)')
    return 0 if ok else 1


if __name__ == '__main__':
    np.seterr(all='raise')  # a silent NaN would be a bug worth stopping for
    sys.exit(main())
