#!/usr/bin/env python3
"""The README's pictures of the view: docs/view_image.png and docs/view_markers.png.

Both show the same frame: control easy, seed 0, the oracle steering, after ``--step`` steps,
built in process from the messages sim_node publishes (``view.sample``). ``view_image.png`` is
``camera/image_view`` (512 px); ``view_markers.png`` is ``plant/markers`` drawn from the
MarkerArray itself, seen from the front (``view.marker_png``), the picture RViz or Foxglove's
3D panel shows from that side. tests/node/test_view.py checks that the markers picture still
matches what this script draws.

Usage (the workspace's venv): python scripts/make_view_screenshot.py [--step 30]
"""

from __future__ import annotations

import argparse
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'src', 'growspace_sim'))

import cv2  # noqa: E402

from growspace_sim.view import marker_png, markers, Scene  # noqa: E402
from growspace_sim.view.image import ViewRenderer  # noqa: E402
from growspace_sim.view.sample import readme_frame  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--step', type=int, default=30, help='steps into the episode')
    parser.add_argument('--out', default=os.path.join(ROOT, 'docs'), help='directory')
    args = parser.parse_args()
    frame = readme_frame(Scene(), args.step)
    image = ViewRenderer(512).render(frame)
    drawn = marker_png.draw(markers.marker_array(frame), 512)
    for name, rgb in (('view_image.png', image), ('view_markers.png', drawn)):
        path = os.path.join(args.out, name)
        cv2.imwrite(path, cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, 9])
        print(f'{path}: {os.path.getsize(path) / 1e3:.0f} kB')
    return 0


if __name__ == '__main__':
    sys.exit(main())
