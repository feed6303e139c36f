"""One chamber with its renderer, targets and random stream: what every adapter drives.

The Gymnasium env, the ROS node and replay all advance a ``Simulation``, so the same seed and
the same actions give the same images, rewards and plants whichever way they arrive.
"""

from __future__ import annotations

from collections.abc import Sequence
import copy

import numpy as np

from growspace_sim import digits as digit_data
from growspace_sim.core import light as lights, task as tasks
from growspace_sim.core.chamber import Chamber, StepOutcome
from growspace_sim.core.config import SimConfig
from growspace_sim.render import Renderer


class Simulation:
    """A chamber, its renderer and its episode generator.

    The random stream is the simulation's own: ``reset(seed=...)`` restarts it, ``reset()``
    continues it, and ``with_config`` carries it over to another configuration.

    Args:
        cfg: the validated configuration.
        digit_source: where shape targets come from (``growspace_sim.digits.load_digits``).
    """

    def __init__(self, cfg: SimConfig, digit_source: str = 'auto') -> None:
        self.cfg = cfg
        self.digit_source = digit_source
        self.chamber = Chamber(cfg)
        self.renderer = Renderer(cfg)
        self.digit_set = None if cfg.task.digits is None else digit_data.load_digits(digit_source)
        self.target_digits = cfg.target_digits
        self.digit: int | None = None
        self._rng = np.random.default_rng()
        self._seed: int | None = None
        self._episode = 0

    @property
    def seed(self) -> int | None:
        """The latest seed the stream was restarted from (None: never seeded)."""
        return self._seed

    @property
    def episode(self) -> int:
        """Episodes begun so far (continued across ``with_config``)."""
        return self._episode

    def with_config(self, cfg: SimConfig) -> Simulation:
        """A simulation of ``cfg`` that continues this one's random stream, seed and episode
        count, so an unseeded reset after a change of challenge stays reproducible.

        Raises:
            ValueError, FileNotFoundError: as the constructor.
        """
        sim = Simulation(cfg, self.digit_source)
        sim._rng, sim._seed, sim._episode = self._rng, self._seed, self._episode
        return sim

    def fork(self, cfg: SimConfig) -> Simulation:
        """Like ``with_config``, on a copy of the random stream: a reset of the fork lays out
        what this simulation's next reset would, and leaves this one as it was (a reset that
        may still be refused is tried on a fork, and kept only once accepted)."""
        sim = self.with_config(cfg)
        sim._rng = copy.deepcopy(self._rng)
        if cfg == self.cfg:
            sim.target_digits = self.target_digits  # a curriculum's digits go on
        return sim

    def set_target_digits(self, digits: Sequence[int]) -> None:
        """Draw shape targets from these digits from the next reset on (curriculum learning).

        Raises:
            ValueError: if a digit is not in 0..9.
        """
        digits = tuple(int(d) for d in digits)
        self.cfg.replace(digits=digits)  # validates
        self.target_digits = digits

    def reset(self, seed: int | None = None,
              rng: np.random.Generator | None = None) -> StepOutcome:
        """Begin an episode; a seed restarts the random stream, as Gymnasium's ``reset`` does.

        Args:
            seed: restart the stream from this seed (``np.random.default_rng(seed)``, the same
                generator Gymnasium builds for ``reset(seed=seed)``); None continues it.
            rng: use this generator instead (the Gymnasium env passes its ``np_random``).
        """
        if rng is not None:
            self._rng = rng
        elif seed is not None:
            self._rng = np.random.default_rng(seed)
        self._seed = seed if seed is not None else self._seed
        image = None
        if self.digit_set is not None:
            image, self.digit = self.digit_set.sample(self._rng, self.target_digits)
        self.chamber.reset(self._rng, image)
        self.renderer.reset(self.chamber)
        self._episode += 1
        return self.chamber.current_reward()

    def apply_discrete(self, action: int) -> None:
        lights.apply_discrete(self.chamber.light, action, self.cfg)

    def apply_continuous(self, action: np.ndarray) -> None:
        lights.apply_continuous(self.chamber.light, action, self.cfg)

    def place_light(self, x: float, z: float, width: float, radius: float) -> None:
        lights.set_absolute(self.chamber.light, self.cfg, x, z, width, radius)

    def step(self) -> StepOutcome:
        """Grow one step under the light as it is now."""
        return self.chamber.step()

    def observe(self, features: bool = False) -> np.ndarray:
        """The observation image (RGB uint8), or binary feature maps."""
        if features:
            return self.renderer.features(self.chamber)
        return self.renderer.render(self.chamber)


def warm_up() -> None:
    """Compile every numba kernel a simulation calls, or load it from numba's on-disk cache.

    One short episode per light kind, with a draw of buds among too many (``max_branching``
    1), so each kernel meets the argument types it meets in use. ``./run.sh build`` calls it
    once after building, so that processes started together later (vector env workers, test
    subprocesses) load the cache instead of all compiling it at the same time.
    """
    digit = np.full((28, 28), 255, np.uint8)  # any target: no MNIST needed
    for spotlight, max_branching in ((False, 8), (True, 1)):
        task = next(t for t in tasks.all_tasks() if t.spotlight == spotlight)
        cfg = SimConfig(challenge=task.name, episode_length=8, max_branching=max_branching)
        chamber, renderer = Chamber(cfg), Renderer(cfg)
        chamber.reset(np.random.default_rng(0), None if cfg.task.digits is None else digit)
        renderer.reset(chamber)
        for action in (0, 1, 2, 3, 4, 5, 6, 2):
            lights.apply_discrete(chamber.light, action % (7 if cfg.uses_spotlight else 5), cfg)
            chamber.step()
            renderer.render(chamber)
