"""A MarkerArray drawn as RViz would show it from the front: for the README and its test.

An orthographic view along +y (x to the right, z up) of the marker types ``view.markers``
sends: LINE_STRIP, TRIANGLE_LIST, CUBE, CYLINDER (a disc facing the viewer), SPHERE, POINTS,
CUBE_LIST and TEXT_VIEW_FACING, with their colours and alpha. It reads only the message, so a
picture made with it shows what a subscriber of ``plant/markers`` gets.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from growspace_sim.view import markers as m

BACKGROUND = (48, 48, 48)  # RViz's default background, RGB


def draw(array: Any, width_px: int = 512) -> np.ndarray:
    """The (H, W, 3) uint8 RGB front view of a MarkerArray with a ``chamber`` outline marker.

    Raises:
        ValueError: the array has no ``chamber`` marker (nothing gives the extent).
    """
    shown = [k for k in array.markers if k.action == m.ADD]
    walls = next((k for k in shown if k.ns == 'chamber'), None)
    if walls is None:
        raise ValueError('the MarkerArray has no "chamber" marker to size the picture by.')
    extent = np.array([(p.x, p.z) for p in walls.points])
    width_m, height_m = extent.max(axis=0)
    margin = 0.05 * width_m
    top = 0.15 * width_m  # room for the status text above the chamber
    scale = width_px / (width_m + 2 * margin)
    height_px = round((height_m + margin + top) * scale)
    image = np.empty((height_px, width_px, 3), np.uint8)
    image[:] = BACKGROUND

    def px(x: float, z: float) -> tuple[int, int]:
        return (round((x + margin) * scale), round((height_m + top - z) * scale))

    for k in shown:
        rgb = tuple(round(255 * c) for c in (k.color.r, k.color.g, k.color.b))
        layer = image.copy() if k.color.a < 1.0 else image
        pos = k.pose.position
        if k.type == m.LINE_STRIP:
            pts = np.array([px(p.x, p.z) for p in k.points], np.int32)
            cv2.polylines(layer, [pts], False, rgb, max(1, round(k.scale.x * scale)),
                          cv2.LINE_AA)
        elif k.type == m.TRIANGLE_LIST:
            pts = np.array([px(p.x, p.z) for p in k.points], np.int32).reshape(-1, 3, 2)
            cv2.fillPoly(layer, list(pts), rgb, cv2.LINE_AA)
        elif k.type == m.CUBE:
            cv2.rectangle(layer, px(pos.x - k.scale.x / 2, pos.z + k.scale.z / 2),
                          px(pos.x + k.scale.x / 2, pos.z - k.scale.z / 2), rgb, -1)
        elif k.type in (m.CYLINDER, m.SPHERE):  # the cylinder is a disc facing the viewer
            cv2.circle(layer, px(pos.x, pos.z), round(k.scale.x / 2 * scale), rgb, -1,
                       cv2.LINE_AA)
        elif k.type == m.POINTS:
            r = max(1, round(k.scale.x / 2 * scale))
            for p in k.points:
                cv2.circle(layer, px(p.x, p.z), r, rgb, -1, cv2.LINE_AA)
        elif k.type == m.CUBE_LIST:
            for p in k.points:
                cv2.rectangle(layer, px(p.x - k.scale.x / 2, p.z + k.scale.z / 2),
                              px(p.x + k.scale.x / 2, p.z - k.scale.z / 2), rgb, -1)
        elif k.type == m.TEXT_VIEW_FACING:
            font = k.scale.z * scale / 22  # Hershey simplex capitals are ~22 px at scale 1
            (w, _), _ = cv2.getTextSize(k.text, cv2.FONT_HERSHEY_SIMPLEX, font, 1)
            x, z = px(pos.x, pos.z)
            cv2.putText(layer, k.text, (x - w // 2, z), cv2.FONT_HERSHEY_SIMPLEX, font, rgb,
                        1, cv2.LINE_AA)
        if layer is not image:
            cv2.addWeighted(layer, k.color.a, image, 1.0 - k.color.a, 0.0, dst=image)
    return image
