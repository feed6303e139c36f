"""How rigs differ: the twin's factors, each a named range, drawn per photo from a seed.

The default twin (no factor on) is the one the pipeline was built with: a grey board, soft
magenta lamp edges, green stems. Each factor below widens one way real rigs differ (issue 30),
drawn from its own generator (the photo seed and ``VARY_SALT``), so that turning a factor on
leaves every other draw of the photo as it was: one factor's effect is the difference it makes.
``Variation.combination(id)`` turns on a seeded subset of the factors: combinations 0-999 are
for tuning, from ``HELD_OUT_FIRST`` on they are held out (the bench's headline figures).
The ranges are documented in docs/hardware.md ("The photo twin's variations"); keep both true.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import math

import numpy as np

VARY_SALT = 0x5A17  # mixed with a photo's seed for the factors' own generator
HELD_OUT_FIRST = 1_000_000  # combination ids from here on are held out: never used in tuning
COMBINATION_P = 0.5  # each factor is on in a combination with this probability
MARKER_COVERED_P = 0.3  # with 'markers', the share of photos with one marker partly covered

# The factors, in drawing order, and what each varies (docs/hardware.md has the ranges).
FACTORS = {
    'lamp_edge': 'the grow lamp beam from soft (15 mm) to hard-edged (0.3 mm, an LED bar cut-off)',
    'lamp_bands': 'the beam as 2-4 separate LED bars with dark gaps',
    'lamp_colour': 'the lamp cast: magenta, red, blue, warm or cool white, up to 0.8 of the '
                   'photo light',
    'backdrop': 'grey or white board, wood, fabric, unevenly painted board',
    'pots': 'pot and soil colours (terracotta, black, green, white; dark to sandy soil)',
    'woody': 'stems from green to brown and woody (older, thicker parts browner)',
    'taper': 'stem widths that taper along each segment and from base to top',
    'leaves': 'blades on petioles at nodes, some drooping across the soil line, some over stems',
    'uneven_light': 'a hot spot and a strong gradient of the photo light, vignetting to 0.6',
    'lens': 'barrel or pincushion distortion (k1 -0.06 to 0.03), calibrated once per rig',
    'optics': 'blur to 2.5 px, read noise to 8 DN, shot noise to 0.4, JPEG quality 40-95',
    'camera': 'camera distance (fill 1.08-1.5), tilt to 8 degrees, roll to 6 degrees',
    'markers': 'worn markers (grey black, dull paper); in 3 photos of 10 one partly covered',
}

LAMP_CASTS = {  # BGR per unit of lamp strength
    'magenta': (0.85, 0.3, 1.0), 'red': (0.15, 0.1, 1.0), 'blue': (1.0, 0.35, 0.25),
    'warm_white': (0.55, 0.8, 1.0), 'cool_white': (1.0, 0.95, 0.85)}
POTS_BGR = {'terracotta': (60, 95, 175), 'black': (30, 30, 32), 'green': (50, 110, 45),
            'white': (215, 220, 220)}
SOILS_BGR = {'dark': (25, 32, 45), 'peat': (35, 50, 70), 'sandy': (95, 135, 165),
             'grey': (80, 85, 90)}
BACKDROPS = ('grey', 'white', 'wood', 'fabric', 'paint')


@dataclass(frozen=True)
class Variation:
    """Which factors vary (a subset of ``FACTORS``); empty = the default twin.

    Attributes:
        factors: Names of the factors on.
        label: What the bench calls it.
    """

    factors: frozenset[str] = field(default_factory=frozenset)
    label: str = 'default'

    def __post_init__(self) -> None:
        unknown = sorted(set(self.factors) - set(FACTORS))
        if unknown:
            raise ValueError(f'Variation: unknown factor(s) {unknown}; '
                             f'known: {sorted(FACTORS)}')

    @classmethod
    def only(cls, name: str) -> Variation:
        """One factor on."""
        return cls(frozenset((name,)), name)

    @classmethod
    def every(cls) -> Variation:
        """All factors on."""
        return cls(frozenset(FACTORS), 'all')

    @classmethod
    def combination(cls, combination_id: int) -> Variation:
        """A seeded subset of the factors (each on with ``COMBINATION_P``), at least one."""
        rng = np.random.default_rng([combination_id, VARY_SALT])
        on = [name for name in FACTORS if rng.random() < COMBINATION_P]
        if not on:
            on = [list(FACTORS)[int(rng.integers(len(FACTORS)))]]
        return cls(frozenset(on), f'combination {combination_id}')

    def __contains__(self, name: str) -> bool:
        return name in self.factors


@dataclass
class RigDraw:
    """One photo's drawn rig (the default twin's values where a factor is off)."""

    lamp_edge_m: float = 0.015  # the logistic edge's width (soft by default) [m]
    lamp_bands: int = 1
    lamp_gap: float = 0.0  # fraction of each band's pitch that is dark
    lamp_bgr: tuple[float, float, float] = LAMP_CASTS['magenta']  # red + blue LEDs
    backdrop: str = 'grey'
    pot_bgr: tuple[float, float, float] | None = None  # None: the default terracotta draw
    soil_bgr: tuple[float, float, float] = (35, 45, 60)
    woody: np.ndarray | None = None  # per plant, 0 green .. 1 brown
    brown_hsv: np.ndarray | None = None  # per plant, the bark's colour
    taper: float = 0.0  # 0: the default widths; else how much wider the base than the top
    leaves: bool = False
    hot_spot: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)  # gain, x, z, radius
    gradient: float = 0.1
    distortion_k1: float = 0.0
    marker_black: float = 18.0
    marker_paper: float = 245.0
    marker_cover: float = 0.0  # tape over one marker, from its paper's edge [marker sides]
    marker_covered: int = -1


def jitter_for(jitter, variation: Variation):  # noqa: ANN001, ANN201
    """The default ranges widened by the factors that widen ranges (same draw count: turning
    one of these factors on changes its own draws only)."""
    if 'optics' in variation:
        jitter = replace(jitter, blur_px=(0.3, 2.5), read_noise=(1.0, 8.0),
                         shot_noise=(0.02, 0.4), jpeg_quality=(40, 95))
    if 'camera' in variation:
        jitter = replace(jitter, fill=(1.08, 1.5), tilt_deg=8.0, roll_deg=6.0, aim_m=0.04)
    if 'uneven_light' in variation:
        jitter = replace(jitter, vignette=(0.0, 0.6))
    if 'lamp_colour' in variation:
        jitter = replace(jitter, lamp=(0.0, 0.8))
    return jitter


def draw_rig(seed: int, variation: Variation, plants: int,
             photo_seed: int | None = None) -> RigDraw:
    """The factors' values for one photo (their own generator: see the module docstring):
    the rig's from ``seed``; what changes from photo to photo on a rig (tape or a leaf over
    a marker) from ``photo_seed`` (default: ``seed``)."""
    rig = RigDraw()
    if not variation.factors:
        return rig
    rng = np.random.default_rng([seed, VARY_SALT])
    # Every factor draws whether it is on or not, so one factor's draws never shift another's.
    edge = math.exp(rng.uniform(math.log(0.0003), math.log(0.015)))
    bands, gap = int(rng.integers(2, 5)), float(rng.uniform(0.15, 0.5))
    cast = list(LAMP_CASTS)[int(rng.integers(len(LAMP_CASTS)))]
    backdrop = BACKDROPS[int(rng.integers(len(BACKDROPS)))]
    pot = list(POTS_BGR)[int(rng.integers(len(POTS_BGR)))]
    soil = list(SOILS_BGR)[int(rng.integers(len(SOILS_BGR)))]
    pot_shade, soil_shade = rng.uniform(0.85, 1.1, 2)
    woody = rng.uniform(0.3, 1.0, plants)
    brown = np.column_stack((rng.uniform(8.0, 22.0, plants), rng.uniform(80.0, 170.0, plants),
                             rng.uniform(55.0, 140.0, plants)))
    taper = float(rng.uniform(0.3, 1.2))
    hot = (float(rng.uniform(0.2, 0.6)), float(rng.uniform(0.1, 0.9)),
           float(rng.uniform(0.1, 0.9)), float(rng.uniform(0.2, 0.5)))
    gradient = float(rng.uniform(0.2, 0.5))
    k1 = float(rng.uniform(-0.06, 0.03))
    black, paper = float(rng.uniform(40.0, 95.0)), float(rng.uniform(185.0, 235.0))
    shot = np.random.default_rng([seed if photo_seed is None else photo_seed, VARY_SALT, 4])
    cover, covered = float(shot.uniform(0.1, 0.35)), int(shot.integers(4))
    covered = covered if shot.random() < MARKER_COVERED_P else -1
    v = variation
    if 'lamp_edge' in v:
        rig.lamp_edge_m = edge
    if 'lamp_bands' in v:
        rig.lamp_bands, rig.lamp_gap = bands, gap
    if 'lamp_colour' in v:
        rig.lamp_bgr = LAMP_CASTS[cast]
    if 'backdrop' in v:
        rig.backdrop = backdrop
    if 'pots' in v:
        rig.pot_bgr = tuple(c * pot_shade for c in POTS_BGR[pot])
        rig.soil_bgr = tuple(c * soil_shade for c in SOILS_BGR[soil])
    if 'woody' in v:
        rig.woody, rig.brown_hsv = woody, brown
    if 'taper' in v:
        rig.taper = taper
    rig.leaves = 'leaves' in v
    if 'uneven_light' in v:
        rig.hot_spot, rig.gradient = hot, gradient
    if 'lens' in v:
        rig.distortion_k1 = k1
    if 'markers' in v:
        rig.marker_black, rig.marker_paper = black, paper
        rig.marker_cover, rig.marker_covered = cover, covered
    return rig
