"""The photo twin: a simulated chamber drawn as a webcam would photograph it.

Everything on the plant plane (a textured backdrop, the pots, the printed markers, the plant
with stems of varying width and colour, the white photo light and the grow lamp's cast) is
drawn on a millimetre canvas of the plane; one perspective warp (the pinhole pose of
``twin.pose``) puts it in the photo, which then gets vignetting, optical blur, shot and read
noise and JPEG compression. Every draw comes from one ``np.random.Generator`` in a fixed order,
so a seed gives the same bytes. A ``Variation`` (``twin.variation``) turns on factors in which
real rigs differ (hard lamp edges, backdrops, brown stems, leaves, lens distortion, ...); their
values come from a second generator of the same seed, so the default twin is unchanged. This
code shares nothing with the pipeline that measures the photos: a shared mistake would
otherwise pass unseen.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math

import cv2
import numpy as np

from growspace_camera.markers import MarkerLayout
from growspace_camera.twin import optics, surfaces
from growspace_camera.twin.surfaces import CANVAS_M
from growspace_camera.twin.pose import look_at_plane, Pose
from growspace_camera.twin.variation import draw_rig, jitter_for, RigDraw, Variation, VARY_SALT
from growspace_sim.core.chamber import Chamber

LIGHT_GRID_M = 0.01  # resolution of the illumination map [m]
POT_DEPTH_M, POT_TOP_M, POT_BOTTOM_M = 0.08, 0.10, 0.075
SHIFT = 4  # cv2 fixed-point bits for sub-pixel drawing
WHITE = 235.0  # the level a rig's exposure keeps the brightest backdrop under


@dataclass(frozen=True)
class TwinJitter:
    """Ranges the twin draws each photo's conditions from (uniform, low to high)."""

    hfov_deg: tuple[float, float] = (56.0, 64.0)  # horizontal field of view
    fill: tuple[float, float] = (1.05, 1.2)  # distance beyond a tight fit of the board
    tilt_deg: float = 4.0  # yaw and pitch at most this
    roll_deg: float = 2.0
    aim_m: float = 0.03  # aim point offset from the board centre at most this [m]
    # Exposure as a rig's operator sets it (docs/hardware.md): the brightest backdrop, under
    # the lamp, at this fraction of white (235 of 255), so nothing is clipped.
    exposure: tuple[float, float] = (0.75, 1.0)
    white_balance: float = 0.06  # per-channel gain within 1 +- this
    vignette: tuple[float, float] = (0.0, 0.3)  # brightness lost in the photo's corners
    lamp: tuple[float, float] = (0.0, 0.5)  # the grow lamp's cast, fraction of the photo light
    blur_px: tuple[float, float] = (0.3, 1.2)  # optical blur sigma [px]
    read_noise: tuple[float, float] = (1.0, 4.0)  # sigma [DN]
    shot_noise: tuple[float, float] = (0.02, 0.2)  # variance per DN of signal
    jpeg_quality: tuple[int, int] = (70, 95)
    stem_width: tuple[float, float] = (0.85, 1.2)  # per plant, times the simulator's thickness
    segment_width: float = 0.1  # per segment, within 1 +- this of its plant's width
    hue: tuple[float, float] = (36.0, 58.0)  # OpenCV hue (0-180): green to yellow-green
    saturation: tuple[float, float] = (110.0, 220.0)
    value: tuple[float, float] = (90.0, 190.0)


@dataclass
class TwinPhoto:
    """One twin photo and what was drawn in it.

    Attributes:
        jpeg: The JPEG bytes (what a UVC camera in MJPG mode delivers).
        bgr: The decoded photo, (H, W, 3) uint8 BGR.
        pose: The camera that took it.
        conditions: The drawn conditions (exposure, lamp, blur, noise, quality, ...).
    """

    jpeg: bytes
    bgr: np.ndarray = field(repr=False)
    pose: Pose
    conditions: dict[str, float]


class PhotoTwin:
    """Draws twin photos of a simulated chamber.

    Args:
        layout: The markers on the plane (what ``growspace-camera markers`` printed).
        jitter: The ranges of the drawn conditions.
        size: Photo (width, height) [px].
        variation: The factors in which rigs differ that photos draw (default: none, the
            twin the pipeline was built with).
    """

    def __init__(self, layout: MarkerLayout, jitter: TwinJitter = TwinJitter(),
                 size: tuple[int, int] = (1920, 1080),
                 variation: Variation | None = None) -> None:
        self.layout = layout
        self.jitter = jitter
        self.size = size
        self.variation = variation or Variation()

    def photo(self, chamber: Chamber, seed: int, hidden: tuple[int, ...] = (),
              plant: bool = True, variation: Variation | None = None,
              rig_seed: int | None = None) -> TwinPhoto:
        """Photograph the chamber as it is now.

        Args:
            chamber: The simulated chamber (its plants and light are drawn).
            seed: Decides the conditions, the textures and the noise.
            hidden: Marker ids covered by something (a dark card).
            plant: False draws the empty pots (the plant is not drawn).
            variation: This photo's factors (default: the twin's own).
            rig_seed: With a variation, draws what belongs to the rig rather than to the
                photo (the camera's pose, the factors' values: backdrop, lamp, lens, the
                markers' wear) from this seed: a rig's camera stays put for an episode, so
                the pipeline's held plane fit meets the photos it is made for. None: all
                from ``seed`` (the default twin always: each photo its own pose).
        """
        rng = np.random.default_rng(seed)
        variation = self.variation if variation is None else variation
        j = jitter_for(self.jitter, variation)
        cfg = chamber.cfg
        fixed = rig_seed is not None and bool(variation.factors)
        rig = draw_rig(rig_seed if fixed else seed, variation, cfg.plant_count, seed)
        x0, z0, x1, z1 = self._board(cfg.chamber_width, cfg.chamber_height)
        pose = self._pose(rng, (x0, z0, x1, z1), j)
        if fixed:  # the photo's own draw is made all the same, so the rest stay aligned
            pose = self._pose(np.random.default_rng([rig_seed, VARY_SALT, 3]),
                              (x0, z0, x1, z1), j)
        canvas = surfaces.board(rng, x0, z0, x1, z1)
        level = surfaces.BACKDROP_LEVEL[1]
        if rig.backdrop != 'grey':
            canvas, level = surfaces.rig_backdrop(np.random.default_rng([seed, VARY_SALT, 1]),
                                          canvas.shape, rig.backdrop)
        to_canvas = _Canvas(x0, z1)
        roots = chamber.pos[:cfg.plant_count]
        for x in roots.real:
            _pot(canvas, to_canvas, rng, float(x), rig)
        for index, marker_id in enumerate(self.layout.ids):
            _marker(canvas, to_canvas, self.layout, index, marker_id in hidden, rig)
        if plant:
            _plant(canvas, to_canvas, rng, chamber, j, rig)
            if rig.leaves:
                _leaves(canvas, to_canvas, np.random.default_rng([seed, VARY_SALT, 2]),
                        chamber, rig)
        lit = _illumination(canvas.shape, to_canvas, rng, chamber, j, rig)
        lamp = float(lit.max() - 1.0)
        brightest = level * float(lit.max())  # the backdrop where most light falls
        exposure = float(rng.uniform(*j.exposure)) * WHITE / brightest
        lit *= canvas
        photo = surfaces.room(rng, self.size)
        warp = pose.homography() @ to_canvas.to_plane
        cv2.warpPerspective(lit, warp, self.size, photo, cv2.INTER_LINEAR,
                            cv2.BORDER_TRANSPARENT)
        if rig.distortion_k1:
            photo = optics.distort(photo, rig.distortion_k1)
        conditions = {'exposure': exposure, 'lamp': lamp}
        photo *= exposure * optics.vignette(self.size, float(rng.uniform(*j.vignette)))[..., None]
        blur = float(rng.uniform(*j.blur_px))
        cv2.GaussianBlur(photo, (0, 0), blur, dst=photo)
        read, shot = float(rng.uniform(*j.read_noise)), float(rng.uniform(*j.shot_noise))
        # Shot and read noise: variance shot x signal + read^2, per pixel and channel.
        sigma = np.maximum(photo, 0.0)
        sigma *= shot
        sigma += read * read
        np.sqrt(sigma, out=sigma)
        sigma *= optics.noise(rng, photo.shape)
        photo += sigma
        quality = int(rng.integers(j.jpeg_quality[0], j.jpeg_quality[1] + 1))
        ok, jpeg = cv2.imencode('.jpg', np.clip(photo, 0, 255).astype(np.uint8),
                                (cv2.IMWRITE_JPEG_QUALITY, quality))
        assert ok, 'OpenCV could not encode a JPEG'
        conditions.update(blur_px=blur, read_noise=read, shot_noise=shot, jpeg_quality=quality,
                          distance_m=float(-pose.centre[1]), focal_px=pose.focal_px)
        bgr = cv2.imdecode(jpeg, cv2.IMREAD_COLOR)
        return TwinPhoto(jpeg.tobytes(), bgr, pose, conditions)

    def _board(self, width: float, height: float) -> tuple[float, float, float, float]:
        """The backdrop's extent (x0, z0, x1, z1) [m]: the chamber and the markers, with room."""
        corners = np.concatenate([self.layout.corners(i) for i in range(len(self.layout.ids))])
        pad = 0.5 * self.layout.side + 0.03
        return (min(0.0, corners[:, 0].min()) - pad, min(-POT_DEPTH_M, corners[:, 1].min()) - pad,
                max(width, corners[:, 0].max()) + pad, max(height, corners[:, 1].max()) + pad)

    def _pose(self, rng: np.random.Generator, board: tuple[float, ...],
              j: TwinJitter) -> Pose:
        x0, z0, x1, z1 = board
        hfov = float(rng.uniform(*j.hfov_deg))
        w, h = self.size
        half_h = math.tan(math.radians(0.5 * hfov))
        half_v = half_h * h / w
        fill = float(rng.uniform(*j.fill))
        distance = fill * max(0.5 * (x1 - x0) / half_h, 0.5 * (z1 - z0) / half_v)
        aim = (0.5 * (x0 + x1) + float(rng.uniform(-j.aim_m, j.aim_m)),
               0.5 * (z0 + z1) + float(rng.uniform(-j.aim_m, j.aim_m)))
        turns = rng.uniform(-1.0, 1.0, 3) * (j.tilt_deg, j.tilt_deg, j.roll_deg)
        # Aim back at the board centre after turning, so the tilt shows as perspective.
        yaw, pitch, roll = (float(t) for t in turns)
        aim = (aim[0] - distance * math.tan(math.radians(yaw)),
               aim[1] + distance * math.tan(math.radians(pitch)))
        return look_at_plane(self.size, hfov, aim, distance, yaw, pitch, roll)


class _Canvas:
    """The plane canvas: pixel (column, row) <-> chamber (x, z); row 0 is the top."""

    def __init__(self, x0: float, z1: float) -> None:
        self.x0, self.z1 = x0, z1
        s = CANVAS_M
        # canvas pixel centre c maps to x0 + (c + 0.5) s: OpenCV warps address pixel centres.
        self.to_plane = np.array([[s, 0.0, x0 + 0.5 * s], [0.0, -s, z1 - 0.5 * s],
                                  [0.0, 0.0, 1.0]])

    def px(self, points: np.ndarray) -> np.ndarray:
        """(N, 2) plane (x, z) [m] -> (N, 2) canvas pixels (float)."""
        points = np.asarray(points, np.float64).reshape(-1, 2)
        return np.column_stack(((points[:, 0] - self.x0) / CANVAS_M - 0.5,
                                (self.z1 - points[:, 1]) / CANVAS_M - 0.5))

    def fixed(self, points: np.ndarray) -> np.ndarray:
        """Canvas pixels in OpenCV's fixed point (``SHIFT`` fractional bits), int32."""
        return np.rint(self.px(points) * (1 << SHIFT)).astype(np.int32)


def _pot(canvas: np.ndarray, to: _Canvas, rng: np.random.Generator, x: float,
         rig: RigDraw) -> None:
    """A pot below the floor line (terracotta unless the rig's), its soil up to z = 0."""
    top, bottom = 0.5 * POT_TOP_M, 0.5 * POT_BOTTOM_M
    body = np.array([(x - top, 0.0), (x + top, 0.0), (x + bottom, -POT_DEPTH_M),
                     (x - bottom, -POT_DEPTH_M)])
    colour = (np.array([60.0, 95.0, 175.0]) * rng.uniform(0.85, 1.1)).tolist()
    if rig.pot_bgr is not None:
        colour = list(rig.pot_bgr)
    cv2.fillConvexPoly(canvas, to.fixed(body), colour, cv2.LINE_AA, SHIFT)
    soil = np.array([(x - top, 0.0), (x + top, 0.0), (x + top, -0.012), (x - top, -0.012)])
    cv2.fillConvexPoly(canvas, to.fixed(soil), tuple(rig.soil_bgr), cv2.LINE_AA, SHIFT)


def _marker(canvas: np.ndarray, to: _Canvas, layout: MarkerLayout, index: int,
            hidden: bool, rig: RigDraw) -> None:
    """The printed marker: a white quiet zone, then its black cells; or a card over it."""
    cells = layout.bits(layout.ids[index])
    n = cells.shape[0]
    unit = layout.side / n
    x, z = layout.centres[index]
    left, top = x - 0.5 * layout.side, z + 0.5 * layout.side
    quiet = 1.5 * unit
    paper = np.array([(left - quiet, top + quiet), (left + layout.side + quiet, top + quiet),
                      (left + layout.side + quiet, top - layout.side - quiet),
                      (left - quiet, top - layout.side - quiet)])
    cv2.fillConvexPoly(canvas, to.fixed(paper), (rig.marker_paper,) * 3, cv2.LINE_AA, SHIFT)
    for r, c in zip(*np.nonzero(cells)):
        a = (left + c * unit, top - r * unit)
        quad = np.array([a, (a[0] + unit, a[1]), (a[0] + unit, a[1] - unit),
                         (a[0], a[1] - unit)])
        cv2.fillConvexPoly(canvas, to.fixed(quad), (rig.marker_black,) * 3, cv2.LINE_AA, SHIFT)
    if rig.marker_covered == index:  # a strip of brown tape over the marker's left edge
        reach = left - quiet + rig.marker_cover * layout.side
        low = top - layout.side - quiet
        tape = np.array([(left - quiet, top + quiet), (reach, top + quiet), (reach, low),
                         (left - quiet, low)])
        cv2.fillConvexPoly(canvas, to.fixed(tape), (80, 130, 165), cv2.LINE_AA, SHIFT)
    if hidden:
        card = paper + np.array([0.2 * unit, -0.3 * unit])
        cv2.fillConvexPoly(canvas, to.fixed(card), (70, 75, 80), cv2.LINE_AA, SHIFT)


def _plant(canvas: np.ndarray, to: _Canvas, rng: np.random.Generator, chamber: Chamber,
           j: TwinJitter, rig: RigDraw) -> None:
    """Each segment a tapered quad between its nodes, each node a disc closing the joint.

    With the rig's ``woody`` the older, thicker parts turn to its bark's brown; with its
    ``taper`` each segment narrows from its parent's width to its own, and a plant's widths
    from its base (wider) to its top."""
    cfg, n = chamber.cfg, chamber.n_nodes
    pos, parent, plant = chamber.pos[:n], chamber.parent[:n], chamber.plant[:n]
    thickness = chamber.thickness()
    plants = cfg.plant_count
    widths = rng.uniform(*j.stem_width, plants)
    hsv = np.column_stack((rng.uniform(*j.hue, plants), rng.uniform(*j.saturation, plants),
                           rng.uniform(*j.value, plants)))
    jitter = rng.uniform(1.0 - j.segment_width, 1.0 + j.segment_width, n)
    shade = rng.uniform(-0.12, 0.12, n)
    tips = ~chamber.state.has_child[:n]
    top = max(float(pos.imag.max()), 0.01)
    for node in range(plants, n):
        p = plant[node]
        half = 0.5 * thickness[node] * widths[p] * jitter[node]
        end = 0.35 * half if tips[node] else half
        a, b = pos[parent[node]], pos[node]
        if rig.taper:  # from the parent's width at a to this one's at b, wider low down
            lift = 1.0 + rig.taper * (0.5 - np.array([a.imag, b.imag]) / top)
            start = 0.5 * thickness[parent[node]] * widths[p] if parent[node] >= plants \
                else 1.3 * half
            half, end = start * lift[0], (0.35 * half if tips[node] else half) * lift[1]
            half, end = max(half, end), max(end, 0.0003)
        d = b - a
        if abs(d) == 0.0:
            continue
        normal = 1j * d / abs(d)
        quad = np.array([a + half * normal, b + end * normal, b - end * normal,
                         a - half * normal])
        h, s, v = hsv[p]
        # Older, thicker stems turn a little yellow-brown, as real ones do.
        woody = min(0.25, 0.05 * (thickness[node] / thickness.min() - 1.0))
        colour = _bgr((h - 12.0 * woody, s * (1.0 - 0.3 * woody), v * (1.0 + shade[node])))
        if rig.woody is not None:  # bark: the thicker (older) the segment, the browner
            age = min(1.0, (thickness[node] / thickness.min() - 1.0) / 1.5)
            mix = float(np.clip(rig.woody[p] * (0.5 + age), 0.0, 1.0))
            bark = rig.brown_hsv[p]
            colour = _bgr(((1 - mix) * h + mix * bark[0], (1 - mix) * s + mix * bark[1],
                           ((1 - mix) * v + mix * bark[2]) * (1.0 + shade[node])))
        corners = to.fixed(np.column_stack((quad.real, quad.imag)))
        cv2.fillConvexPoly(canvas, corners, colour, cv2.LINE_AA, SHIFT)
        centre = to.fixed(np.array([(b.real, b.imag), (a.real, a.imag)]))
        radius = int(round(end / CANVAS_M * (1 << SHIFT)))
        cv2.circle(canvas, tuple(int(v) for v in centre[0]), radius, colour, -1, cv2.LINE_AA,
                   SHIFT)
        if parent[node] >= plants:  # close the joint at the parent with this width too
            cv2.circle(canvas, tuple(int(v) for v in centre[1]),
                       int(round(half / CANVAS_M * (1 << SHIFT))), colour, -1, cv2.LINE_AA,
                       SHIFT)


def _leaves(canvas: np.ndarray, to: _Canvas, rng: np.random.Generator, chamber: Chamber,
            rig: RigDraw) -> None:
    """Leaves: at some nodes a petiole and an elliptic blade, some drooping (the lower ones
    across the soil line), drawn after the stems so that some cover them."""
    cfg, n = chamber.cfg, chamber.n_nodes
    pos = chamber.pos[:n]
    for node in range(cfg.plant_count, n):
        if rng.random() > 0.5:
            continue
        b = pos[node]
        side = 1.0 if rng.random() < 0.5 else -1.0
        droop = rng.random() < 0.35
        angle = math.radians(rng.uniform(-85.0, -30.0) if droop else rng.uniform(-20.0, 60.0))
        direction = complex(side * math.cos(angle), math.sin(angle))
        petiole = rng.uniform(0.008, 0.025)
        length = rng.uniform(0.03, 0.08) * (1.5 if droop and b.imag < 0.12 else 1.0)
        width = length * rng.uniform(0.25, 0.5)
        base = b + petiole * direction
        green = _bgr((rng.uniform(38.0, 62.0), rng.uniform(120.0, 230.0),
                      rng.uniform(80.0, 180.0)))
        line = to.fixed(np.array([(b.real, b.imag), (base.real, base.imag)]))
        thick = max(1, int(round(rng.uniform(0.0012, 0.003) / CANVAS_M)))
        cv2.line(canvas, tuple(int(v) for v in line[0]), tuple(int(v) for v in line[1]), green,
                 thick, cv2.LINE_AA, SHIFT)
        t = np.linspace(0.0, math.pi, 24)  # a blade: pointed ends, widest in the middle
        along = 0.5 * length * (1.0 - np.cos(t))
        across = 0.5 * width * np.sin(t) ** 1.3
        outline = np.concatenate((along + 1j * across, (along - 1j * across)[::-1]))
        blade = base + outline * direction
        cv2.fillPoly(canvas, [to.fixed(np.column_stack((blade.real, blade.imag)))], green,
                     cv2.LINE_AA, SHIFT)


def _bgr(hsv: tuple[float, float, float]) -> tuple[int, int, int]:
    h, s, v = hsv
    pixel = np.uint8([[[int(np.clip(h, 0, 179)), int(np.clip(s, 0, 255)),
                        int(np.clip(v, 0, 255))]]])
    b, g, r = cv2.cvtColor(pixel, cv2.COLOR_HSV2BGR)[0, 0]
    return int(b), int(g), int(r)


def _illumination(shape: tuple[int, ...], to: _Canvas, rng: np.random.Generator,
                  chamber: Chamber, j: TwinJitter, rig: RigDraw) -> np.ndarray:
    """Per canvas pixel and channel, the light falling there: the white photo light (with a
    white-balance error, a gradient and the rig's hot spot) plus the grow lamp's cast (the
    rig's colour, edge and bands; magenta and soft by default).

    A hard edge (sharper than the light grid) is computed on the canvas itself, so that the
    beam's cut-off is as sharp in the photo as the lens leaves it."""
    h, w = shape[:2]
    gh, gw = int(h * CANVAS_M / LIGHT_GRID_M) + 2, int(w * CANVAS_M / LIGHT_GRID_M) + 2
    xs = to.x0 + (np.arange(gw) + 0.5) * LIGHT_GRID_M
    zs = to.z1 - (np.arange(gh) + 0.5) * LIGHT_GRID_M
    x, z = np.meshgrid(xs, zs)
    balance = 1.0 + rng.uniform(-j.white_balance, j.white_balance, 3)
    tilt = rng.uniform(-0.1, 0.1, 2) * (rig.gradient / 0.1)
    white = 1.0 + tilt[0] * (x - x.mean()) + tilt[1] * (z - z.mean())
    gain, hx, hz, radius = rig.hot_spot
    if gain:
        white += gain * np.exp(-0.5 * ((x - to.x0 - hx * (x.max() - x.min())) ** 2
                                       + (z - to.z1 + hz * (z.max() - z.min())) ** 2)
                               / radius ** 2)
    strength = float(rng.uniform(*j.lamp))
    cast = np.asarray(rig.lamp_bgr, np.float32)
    if rig.lamp_edge_m >= LIGHT_GRID_M and rig.lamp_bands == 1:  # soft: on the light grid
        lamp = strength / (1.0 + np.exp(-_beam(x, z, chamber, rig)))
        grid = white[..., None] * balance + lamp[..., None] * cast
        return cv2.resize(grid.astype(np.float32), (w, h), interpolation=cv2.INTER_LINEAR)
    grid = cv2.resize((white[..., None] * balance).astype(np.float32), (w, h),
                      interpolation=cv2.INTER_LINEAR)
    xs = to.x0 + (np.arange(w, dtype=np.float32) + 0.5) * CANVAS_M
    zs = to.z1 - (np.arange(h, dtype=np.float32) + 0.5) * CANVAS_M
    inside = np.clip(_beam(xs[None, :], zs[:, None], chamber, rig), -60.0, 60.0)
    lamp = (strength / (1.0 + np.exp(-inside))).astype(np.float32)
    grid += lamp[..., None] * cast
    return grid


def _beam(x: np.ndarray, z: np.ndarray, chamber: Chamber, rig: RigDraw) -> np.ndarray:
    """How far (x, z) is inside the grow lamp's light, in edge widths (the argument of a
    logistic edge): one beam, or bands (LED bars with dark gaps between them across it)."""
    light, edge = chamber.light, rig.lamp_edge_m
    if light.spot:
        inside = (light.radius - np.hypot(x - light.x, z - light.z)) / edge
        across, span = x - (light.x - light.radius), 2.0 * light.radius
    else:
        inside = (0.5 * light.width - np.abs(x - light.x)) / edge
        inside = np.minimum(inside, (chamber.cfg.chamber_height + 0.02 - z) / edge)
        across, span = x - (light.x - 0.5 * light.width), light.width
    if rig.lamp_bands > 1:  # each bar lit over (1 - gap) of its pitch, dark between bars
        pitch = span / rig.lamp_bands
        offset = np.mod(across, pitch) - 0.5 * pitch
        bar = (0.5 * (1.0 - rig.lamp_gap) * pitch - np.abs(offset)) / edge
        inside = np.minimum(inside, bar)
    return inside
