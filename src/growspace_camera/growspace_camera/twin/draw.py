"""The photo twin: a simulated chamber drawn as a webcam would photograph it.

Everything on the plant plane (a textured backdrop, the pots, the printed markers, the plant
with stems of varying width and colour, the white photo light and the grow lamp's cast) is
drawn on a millimetre canvas of the plane; one perspective warp (the pinhole pose of
``twin.pose``) puts it in the photo, which then gets vignetting, optical blur, shot and read
noise and JPEG compression. Every draw comes from one ``np.random.Generator`` in a fixed order,
so a seed gives the same bytes. This code shares nothing with the pipeline that measures the
photos: a shared mistake would otherwise pass unseen.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import functools
import math

import cv2
import numpy as np

from growspace_camera.markers import MarkerLayout
from growspace_camera.twin.pose import look_at_plane, Pose
from growspace_sim.core.chamber import Chamber

CANVAS_M = 0.001  # canvas pixel [m]: about one photo pixel at the default distance
LIGHT_GRID_M = 0.01  # resolution of the illumination map [m]
LAMP_EDGE_M = 0.015  # soft edge of the grow lamp's light (sigma) [m]
LAMP_BGR = np.array([0.85, 0.3, 1.0], np.float32)  # red + blue LEDs: magenta
POT_DEPTH_M, POT_TOP_M, POT_BOTTOM_M = 0.08, 0.10, 0.075
SHIFT = 4  # cv2 fixed-point bits for sub-pixel drawing
BACKDROP_LEVEL = (190.0, 225.0)  # grey level of the backdrop under the photo light alone
WHITE = 235.0  # the level a rig's exposure keeps the brightest backdrop under
NOISE_SEED = 20_24  # the sensor noise bank's own seed (photos crop it at drawn offsets)


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
    """

    def __init__(self, layout: MarkerLayout, jitter: TwinJitter = TwinJitter(),
                 size: tuple[int, int] = (1920, 1080)) -> None:
        self.layout = layout
        self.jitter = jitter
        self.size = size

    def photo(self, chamber: Chamber, seed: int, hidden: tuple[int, ...] = (),
              plant: bool = True) -> TwinPhoto:
        """Photograph the chamber as it is now.

        Args:
            chamber: The simulated chamber (its plants and light are drawn).
            seed: Decides the conditions, the textures and the noise.
            hidden: Marker ids covered by something (a dark card).
            plant: False draws the empty pots (the plant is not drawn).
        """
        rng = np.random.default_rng(seed)
        j = self.jitter
        cfg = chamber.cfg
        x0, z0, x1, z1 = self._board(cfg.chamber_width, cfg.chamber_height)
        pose = self._pose(rng, (x0, z0, x1, z1))
        canvas = _backdrop(rng, x0, z0, x1, z1)
        to_canvas = _Canvas(x0, z1)
        roots = chamber.pos[:cfg.plant_count]
        for x in roots.real:
            _pot(canvas, to_canvas, rng, float(x))
        for index, marker_id in enumerate(self.layout.ids):
            _marker(canvas, to_canvas, self.layout, index, marker_id in hidden)
        if plant:
            _plant(canvas, to_canvas, rng, chamber, j)
        lit = _illumination(canvas.shape, to_canvas, rng, chamber, j)
        lamp = float(lit.max() - 1.0)
        brightest = BACKDROP_LEVEL[1] * float(lit.max())  # the backdrop where most light falls
        exposure = float(rng.uniform(*j.exposure)) * WHITE / brightest
        lit *= canvas
        photo = _room(rng, self.size)
        warp = pose.homography() @ to_canvas.to_plane
        cv2.warpPerspective(lit, warp, self.size, photo, cv2.INTER_LINEAR,
                            cv2.BORDER_TRANSPARENT)
        conditions = {'exposure': exposure, 'lamp': lamp}
        photo *= exposure * _vignette(self.size, float(rng.uniform(*j.vignette)))[..., None]
        blur = float(rng.uniform(*j.blur_px))
        cv2.GaussianBlur(photo, (0, 0), blur, dst=photo)
        read, shot = float(rng.uniform(*j.read_noise)), float(rng.uniform(*j.shot_noise))
        # Shot and read noise: variance shot x signal + read^2, per pixel and channel.
        sigma = np.maximum(photo, 0.0)
        sigma *= shot
        sigma += read * read
        np.sqrt(sigma, out=sigma)
        sigma *= _noise(rng, photo.shape)
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

    def _pose(self, rng: np.random.Generator, board: tuple[float, ...]) -> Pose:
        j = self.jitter
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


def _backdrop(rng: np.random.Generator, x0: float, z0: float, x1: float,
              z1: float) -> np.ndarray:
    """A matte, slightly tinted board with low-frequency blotches and fine grain."""
    w = int(math.ceil((x1 - x0) / CANVAS_M))
    h = int(math.ceil((z1 - z0) / CANVAS_M))
    base = rng.uniform(*BACKDROP_LEVEL) * (1.0 + rng.uniform(-0.04, 0.04, 3))
    coarse = rng.standard_normal((h // 40 + 2, w // 40 + 2, 3)).astype(np.float32)
    coarse = base.astype(np.float32) * (1.0 + 0.05 * cv2.GaussianBlur(coarse, (0, 0), 1.0))
    board = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC)
    grain = rng.standard_normal((h // 2 + 1, w // 2 + 1), dtype=np.float32) * 4.0
    board += cv2.resize(grain, (w, h), interpolation=cv2.INTER_LINEAR)[..., None]
    return np.clip(board, 0, 255, out=board).astype(np.uint8)


def _room(rng: np.random.Generator, size: tuple[int, int]) -> np.ndarray:
    """What the photo shows around the backdrop: a dim, uneven room (float32 BGR)."""
    w, h = size
    grey = rng.uniform(30.0, 110.0, (6, 10, 1))
    coarse = (grey * rng.uniform(0.85, 1.15, (6, 10, 3))).astype(np.float32)  # dull colours
    return cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC)


def _pot(canvas: np.ndarray, to: _Canvas, rng: np.random.Generator, x: float) -> None:
    """A terracotta pot below the floor line, its soil up to z = 0."""
    top, bottom = 0.5 * POT_TOP_M, 0.5 * POT_BOTTOM_M
    body = np.array([(x - top, 0.0), (x + top, 0.0), (x + bottom, -POT_DEPTH_M),
                     (x - bottom, -POT_DEPTH_M)])
    colour = (np.array([60.0, 95.0, 175.0]) * rng.uniform(0.85, 1.1)).tolist()
    cv2.fillConvexPoly(canvas, to.fixed(body), colour, cv2.LINE_AA, SHIFT)
    soil = np.array([(x - top, 0.0), (x + top, 0.0), (x + top, -0.012), (x - top, -0.012)])
    cv2.fillConvexPoly(canvas, to.fixed(soil), (35, 45, 60), cv2.LINE_AA, SHIFT)


def _marker(canvas: np.ndarray, to: _Canvas, layout: MarkerLayout, index: int,
            hidden: bool) -> None:
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
    cv2.fillConvexPoly(canvas, to.fixed(paper), (245, 245, 245), cv2.LINE_AA, SHIFT)
    for r, c in zip(*np.nonzero(cells)):
        a = (left + c * unit, top - r * unit)
        quad = np.array([a, (a[0] + unit, a[1]), (a[0] + unit, a[1] - unit),
                         (a[0], a[1] - unit)])
        cv2.fillConvexPoly(canvas, to.fixed(quad), (18, 18, 18), cv2.LINE_AA, SHIFT)
    if hidden:
        card = paper + np.array([0.2 * unit, -0.3 * unit])
        cv2.fillConvexPoly(canvas, to.fixed(card), (70, 75, 80), cv2.LINE_AA, SHIFT)


def _plant(canvas: np.ndarray, to: _Canvas, rng: np.random.Generator, chamber: Chamber,
           j: TwinJitter) -> None:
    """Each segment a tapered quad between its nodes, each node a disc closing the joint."""
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
    for node in range(plants, n):
        p = plant[node]
        half = 0.5 * thickness[node] * widths[p] * jitter[node]
        end = 0.35 * half if tips[node] else half
        a, b = pos[parent[node]], pos[node]
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


def _bgr(hsv: tuple[float, float, float]) -> tuple[int, int, int]:
    h, s, v = hsv
    pixel = np.uint8([[[int(np.clip(h, 0, 179)), int(np.clip(s, 0, 255)),
                        int(np.clip(v, 0, 255))]]])
    b, g, r = cv2.cvtColor(pixel, cv2.COLOR_HSV2BGR)[0, 0]
    return int(b), int(g), int(r)


def _illumination(shape: tuple[int, ...], to: _Canvas, rng: np.random.Generator,
                  chamber: Chamber, j: TwinJitter) -> np.ndarray:
    """Per canvas pixel and channel, the light falling there: the white photo light (with a
    white-balance error and a gentle gradient) plus the grow lamp's magenta cast."""
    h, w = shape[:2]
    gh, gw = int(h * CANVAS_M / LIGHT_GRID_M) + 2, int(w * CANVAS_M / LIGHT_GRID_M) + 2
    xs = to.x0 + (np.arange(gw) + 0.5) * LIGHT_GRID_M
    zs = to.z1 - (np.arange(gh) + 0.5) * LIGHT_GRID_M
    x, z = np.meshgrid(xs, zs)
    balance = 1.0 + rng.uniform(-j.white_balance, j.white_balance, 3)
    tilt = rng.uniform(-0.1, 0.1, 2)
    white = 1.0 + tilt[0] * (x - x.mean()) + tilt[1] * (z - z.mean())
    light = chamber.light
    strength = float(rng.uniform(*j.lamp))
    if light.spot:
        inside = (light.radius - np.hypot(x - light.x, z - light.z)) / LAMP_EDGE_M
    else:
        inside = (0.5 * light.width - np.abs(x - light.x)) / LAMP_EDGE_M
        inside = np.minimum(inside, (chamber.cfg.chamber_height + 0.02 - z) / LAMP_EDGE_M)
    lamp = strength / (1.0 + np.exp(-inside))
    grid = white[..., None] * balance + lamp[..., None] * LAMP_BGR
    return cv2.resize(grid.astype(np.float32), (w, h), interpolation=cv2.INTER_LINEAR)


@functools.cache
def _noise_bank(shape: tuple[int, ...]) -> np.ndarray:
    """Standard normal noise a little larger than a photo, drawn once per photo size (drawing
    6 million normals for every photo would cost more than everything else the twin does)."""
    h, w, c = shape
    bank = np.random.default_rng(NOISE_SEED).standard_normal((h + 64, w + 64, c), np.float32)
    bank.flags.writeable = False
    return bank


def _noise(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """A photo's noise: a crop of the bank at a drawn offset, drawn flips and sign."""
    h, w = shape[:2]
    dy, dx = (int(v) for v in rng.integers(0, 65, 2))
    crop = _noise_bank(tuple(shape))[dy:dy + h, dx:dx + w]
    flip_rows, flip_cols, sign = (bool(v) for v in rng.integers(0, 2, 3))
    crop = crop[::-1] if flip_rows else crop
    crop = crop[:, ::-1] if flip_cols else crop
    return -crop if sign else crop


def _vignette(size: tuple[int, int], strength: float) -> np.ndarray:
    w, h = size
    x = (np.arange(w, dtype=np.float32) - 0.5 * w) / (0.5 * w)
    y = (np.arange(h, dtype=np.float32) - 0.5 * h) / (0.5 * w)
    r2 = x[None, :] ** 2 + y[:, None] ** 2
    return 1.0 - strength * r2 / r2.max()
