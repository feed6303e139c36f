"""The photo twin as a capture source: a simulated plant that grows under the reached light.

Each photo request says which step of which episode it is for and where the light is; the
source grows its own ``Simulation`` to that step under that light (resetting it with the
episode's seed at a new episode) and photographs it. So camera_node, fed by a gantry on the
GRBL emulator, closes the whole loop without hardware: the "real plant" is the simulator.
"""

from __future__ import annotations

import time

from growspace_camera.capture import CaptureError, Frame, Shot
from growspace_camera.markers import MarkerLayout
from growspace_camera.twin.draw import PhotoTwin, TwinJitter
from growspace_sim.simulation import Simulation


class TwinSource:
    """Photos of a simulated chamber (``source: twin``).

    Args:
        layout: The markers drawn on the plane.
        seed: Seed of the photos' conditions (pose, light, noise), mixed with episode and step.
        jitter: The twin's ranges.
        digit_source: Where the simulated shape targets come from.
    """

    name = 'twin'

    def __init__(self, layout: MarkerLayout, seed: int = 0, jitter: TwinJitter | None = None,
                 digit_source: str = 'auto') -> None:
        self.twin = PhotoTwin(layout, jitter or TwinJitter())
        self.seed = seed
        self.digit_source = digit_source
        self.sim: Simulation | None = None
        self._episode: int | None = None

    def open(self) -> dict[str, str]:
        w, h = self.twin.size
        return {'width': str(w), 'height': str(h), 'seed': str(self.seed)}

    def read(self, shot: Shot) -> Frame:
        sim = self.sim
        if sim is None or sim.cfg != shot.cfg or self._episode != shot.episode \
                or sim.chamber.steps > shot.step:
            try:
                sim = self.sim = Simulation(shot.cfg, self.digit_source)
            except (ValueError, FileNotFoundError) as e:
                raise CaptureError(f'twin: cannot simulate {shot.cfg.challenge}: {e}') from None
            sim.reset(seed=shot.seed if shot.seed is not None else self.seed)
            self._episode = shot.episode
        light = shot.light
        while sim.chamber.steps < min(shot.step, shot.cfg.episode_length):
            sim.place_light(light.x, light.z, light.width, light.radius)
            sim.step()
        photo_seed = hash((self.seed, shot.episode, shot.step)) & 0x7FFF_FFFF
        photo = self.twin.photo(sim.chamber, photo_seed)
        return Frame(photo.bgr, photo.jpeg, time.time_ns())

    def close(self) -> None:
        self.sim = None
