"""Where a chamber step's time goes, without Gymnasium (runs on a bare numpy + numba + OpenCV box).

    python scripts/perf_core.py [--profile]
"""
import argparse
import cProfile
import pstats
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'src' / 'growspace_sim'))

import numpy as np  # noqa: E402

from growspace_sim.core import light as lights  # noqa: E402
from growspace_sim.core.config import SimConfig  # noqa: E402
from growspace_sim.simulation import Simulation  # noqa: E402


def run(challenge: str, episodes: int, observe: bool) -> float:
    sim = Simulation(SimConfig(challenge=challenge))
    n = len(lights.SPOT_ACTIONS if sim.cfg.uses_spotlight else lights.BEAM_ACTIONS)
    actions = np.random.default_rng(0).integers(n, size=50 * episodes).tolist()
    k = 0
    start = time.process_time()
    for episode in range(episodes):
        sim.reset(seed=episode)
        for _ in range(50):
            sim.apply_discrete(actions[k])
            sim.step()
            if observe:
                sim.observe()
            k += 1
    return k / (time.process_time() - start)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument('--profile', action='store_true')
    parser.add_argument('--episodes', type=int, default=300)
    parser.add_argument('--challenges', default='control,fairness,shape')
    args = parser.parse_args()
    for challenge in args.challenges.split(','):
        core = max(run(challenge, args.episodes, False) for _ in range(3))
        full = max(run(challenge, args.episodes, True) for _ in range(3))
        print(f'{challenge:9s} core {core:8.0f}/s ({1e6 / core:5.1f} us)  '
              f'core+render {full:8.0f}/s ({1e6 / full:5.1f} us)')
    if args.profile:
        cProfile.run('run("control", 200, True)', '/tmp/perf.prof')
        pstats.Stats('/tmp/perf.prof').sort_stats('tottime').print_stats(25)


if __name__ == '__main__':
    main()
