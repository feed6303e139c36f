#!/usr/bin/env python3
"""Rebuild the real plant photos of the test suite (tests/data/real_photos) from their sources.

Each photo in ``tests/data/real_photos/MANIFEST.yaml`` comes from a public phenotyping
repository whose licence allows redistributing it (PlantCV's test and tutorial images, MPL-2.0:
the licence text is stored beside the photos). This script takes each source file at the
manifest's commit, checks its sha256, places it on the chamber plane (the manifest says which
source pixel is the stem's foot on the soil line and how many metres a source pixel spans),
draws the project's ArUco marker layout (``config/markers.yaml``, through ``MarkerLayout``) at
the margins, as printed sheets fixed on the plane, and writes a small JPEG (at most
``MAX_BYTES``), whose sha256 it records in the manifest (``built_sha256``). The camera then
sees a real plant in a chamber it can calibrate.

The view is a camera square to the plane: 1000 x 750 px, ``PX_PER_M`` pixels per metre, the
chamber's centre in the middle. Where the source photo does not reach, its edge pixels are
repeated (a plain backdrop; never plant: every source's edge is backdrop or rig).

Usage (workspace sourced):
    python scripts/real_photos.py --source PLANTCV_CLONE [--overlays /tmp/real]
    python scripts/real_photos.py            # downloads each source from raw.githubusercontent
``--source`` is a local clone (a work tree or a bare git directory) of the manifest's
repository; the files are read at the manifest's commit with ``git show``. ``--overlays DIR``
also measures each built photo with the default pipeline and writes the segmentation overlay
(mask green, tips red, markers magenta) to DIR for people to look at.
"""

from __future__ import annotations

import argparse
import hashlib
from pathlib import Path
import subprocess
import sys
import urllib.request

import cv2
import numpy as np
import yaml

from growspace_camera.markers import MarkerLayout
from growspace_camera.settings import load_layout

HERE = Path(__file__).resolve().parent.parent / 'tests' / 'data' / 'real_photos'
MANIFEST = HERE / 'MANIFEST.yaml'
SIZE = (1000, 750)  # photo (width, height) [px]: markers found without shrinking it
PX_PER_M = 640.0  # photo pixels per metre of the plant plane
CENTRE_M = (0.42, 0.42)  # chamber point at the photo's centre (the 0.84 m chamber's middle)
MAX_BYTES = 150_000  # largest JPEG stored
PAPER, INK = (245, 245, 245), (18, 18, 18)  # printed marker sheet: white paper, black cells
SHIFT = 4  # cv2 fixed-point bits for sub-pixel drawing


def plane_to_photo(points_m: np.ndarray) -> np.ndarray:
    """(N, 2) chamber (x, z) [m] -> (N, 2) photo (column, row) [px] of the square view."""
    p = np.asarray(points_m, np.float64).reshape(-1, 2)
    return np.column_stack((0.5 * SIZE[0] - 0.5 + (p[:, 0] - CENTRE_M[0]) * PX_PER_M,
                            0.5 * SIZE[1] - 0.5 - (p[:, 1] - CENTRE_M[1]) * PX_PER_M))


def place(source: np.ndarray, foot_px: tuple[float, float], foot_m: tuple[float, float],
          m_per_px: float) -> np.ndarray:
    """The source photo on the plane, seen by the square view.

    Args:
        source: (H, W, 3) uint8 BGR source photo.
        foot_px: Source pixel (column, row) that lands on ``foot_m``.
        foot_m: Chamber point (x, z) [m] of that pixel (the stem's foot: z = 0 is the soil).
        m_per_px: Metres of plane per source pixel.

    Returns:
        (SIZE[1], SIZE[0], 3) uint8 BGR.
    """
    scale = m_per_px * PX_PER_M
    h, w = source.shape[:2]
    size = (max(1, round(w * scale)), max(1, round(h * scale)))
    shrinking = scale < 1.0
    resized = cv2.resize(source, size, interpolation=cv2.INTER_AREA if shrinking
                         else cv2.INTER_CUBIC)
    sx, sy = size[0] / w, size[1] / h
    # resized pixel centre c <-> source (c + 0.5) / s - 0.5; then source -> plane -> photo
    (col, row), = plane_to_photo(np.array([foot_m]))
    src_col, src_row = (foot_px[0] + 0.5) * sx - 0.5, (foot_px[1] + 0.5) * sy - 0.5
    shift = np.array([[1.0, 0.0, col - src_col], [0.0, 1.0, row - src_row]])
    return cv2.warpAffine(resized, shift, SIZE, flags=cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_REPLICATE)


def draw_markers(photo: np.ndarray, layout: MarkerLayout) -> None:
    """Draw the layout's markers where it says they are: a white sheet with a quiet zone of
    1.5 cells, then the black cells (``MarkerLayout.bits``: OpenCV's own ArUco pattern)."""
    for index, marker_id in enumerate(layout.ids):
        cells = layout.bits(marker_id)
        n = cells.shape[0]
        unit = layout.side / n
        x, z = layout.centres[index]
        left, top = x - 0.5 * layout.side, z + 0.5 * layout.side
        quiet = 1.5 * unit
        paper = [(left - quiet, top + quiet), (left + layout.side + quiet, top + quiet),
                 (left + layout.side + quiet, top - layout.side - quiet),
                 (left - quiet, top - layout.side - quiet)]
        _fill(photo, paper, PAPER)
        for r, c in zip(*np.nonzero(cells)):
            a = (left + c * unit, top - r * unit)
            _fill(photo, [a, (a[0] + unit, a[1]), (a[0] + unit, a[1] - unit),
                          (a[0], a[1] - unit)], INK)


def _fill(photo: np.ndarray, quad_m: list[tuple[float, float]], colour: tuple) -> None:
    corners = np.rint(plane_to_photo(np.array(quad_m)) * (1 << SHIFT)).astype(np.int32)
    cv2.fillConvexPoly(photo, corners, colour, cv2.LINE_AA, SHIFT)


def compose(source: np.ndarray, entry: dict, layout: MarkerLayout) -> bytes:
    """A manifest entry's test photo: JPEG bytes of at most ``MAX_BYTES``."""
    p = entry['place']
    gain = float(p.get('gain', 1.0))
    if gain != 1.0:  # the exposure a rig's operator would set: the backdrop below white
        source = cv2.convertScaleAbs(source, alpha=gain)
    foot = tuple(p['foot_px'])
    if 'top_cut' in p:  # the source's top edge cuts the plant there: backdrop above, not plant
        c0, c1 = p['top_cut']
        if not 1 <= c0 < c1 <= source.shape[1]:
            raise SystemExit(f'{entry["name"]}: top_cut {p["top_cut"]} is not allowed; '
                             f'[c0, c1) with 1 <= c0 < c1 <= {source.shape[1]}')
        edge = source[:1].copy()
        edge[0, c0:c1] = source[0, c0 - 1]
        source, foot = np.vstack((edge, source)), (foot[0], foot[1] + 1)
    photo = place(source, foot, tuple(p['foot_m']), float(p['m_per_px']))
    draw_markers(photo, layout)
    for quality in range(92, 40, -4):
        ok, jpeg = cv2.imencode('.jpg', photo, (cv2.IMWRITE_JPEG_QUALITY, quality))
        if ok and jpeg.size <= MAX_BYTES:
            return jpeg.tobytes()
    raise SystemExit(f'{entry["name"]}: no JPEG quality gives {MAX_BYTES} bytes or less')


def read_source(manifest: dict, entry: dict, clone: Path | None) -> bytes:
    """The source file's bytes at the manifest's commit, its sha256 checked."""
    repo, commit = manifest['source']['repository'], manifest['source']['commit']
    if clone is not None:
        git = ['git', '-C', str(clone)]
        if (clone / 'HEAD').is_file() and not (clone / '.git').exists():
            git = ['git', f'--git-dir={clone}']
        data = subprocess.run([*git, 'show', f'{commit}:{entry["path"]}'], check=True,
                              capture_output=True).stdout
    else:
        url = f'https://raw.githubusercontent.com/{repo}/{commit}/{entry["path"]}'
        with urllib.request.urlopen(url, timeout=60) as response:  # noqa: S310 - https only
            data = response.read()
    digest = hashlib.sha256(data).hexdigest()
    if digest != entry['sha256']:
        raise SystemExit(f'{entry["name"]}: {repo}@{commit[:10]}:{entry["path"]} has sha256 '
                         f'{digest}, the manifest says {entry["sha256"]}')
    return data


def measure_overlay(jpeg: bytes, out: Path) -> str:
    """Measure a built photo with the default pipeline; write its overlay; say what it gave."""
    from growspace_camera.measure import Target
    from growspace_camera.pipeline import overlay, Pipeline
    from growspace_sim.core.config import SimConfig
    from growspace_sim.core.light import Light

    cfg = SimConfig(challenge='control')
    light = Light(False, 0.42, 0.84, 0.2, 0.1)  # a beam over the plant
    photo = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    m = Pipeline().measure(photo, cfg, light, Target(0.42 + 0.6j))
    cv2.imwrite(str(out), overlay(photo, m, scale=1.0))
    if not m.ok:
        return f'refused: {m.error}'
    tips = ' '.join(f'({x:.3f}, {z:.3f})' for x, z in m.tree.nodes[m.tree.tips])
    return f'ok reward={m.reward:.3f} plants={m.tree.plants} tips: {tips}'


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--source', type=Path, help="a local clone of the manifest's "
                        'repository (else each file is downloaded)')
    parser.add_argument('--overlays', type=Path, help='write segmentation overlays here')
    args = parser.parse_args(argv)
    manifest = yaml.safe_load(MANIFEST.read_text(encoding='utf-8'))
    layout = load_layout()
    text = MANIFEST.read_text(encoding='utf-8')
    if args.overlays:
        args.overlays.mkdir(parents=True, exist_ok=True)
    for entry in manifest['photos']:
        source = cv2.imdecode(np.frombuffer(read_source(manifest, entry, args.source),
                                            np.uint8), cv2.IMREAD_COLOR)
        jpeg = compose(source, entry, layout)
        (HERE / entry['file']).write_bytes(jpeg)
        digest = hashlib.sha256(jpeg).hexdigest()
        text = _set_built_sha256(text, entry['name'], digest)
        line = f'{entry["file"]}: {len(jpeg)} bytes sha256 {digest}'
        if args.overlays:
            line += '\n  ' + measure_overlay(jpeg, args.overlays / f'{entry["name"]}.png')
        print(line)
    MANIFEST.write_text(text, encoding='utf-8')
    return 0


def _set_built_sha256(text: str, name: str, digest: str) -> str:
    """The manifest's text with entry ``name``'s built_sha256 set (comments kept)."""
    start = text.index(f'- name: {name}\n')
    key = text.index('built_sha256: ', start)
    end = text.index('\n', key)
    return f'{text[:key]}built_sha256: {digest}{text[end:]}'


if __name__ == '__main__':
    sys.exit(main())
