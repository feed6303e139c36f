"""Where the twin's camera stands: a pinhole camera in front of the chamber's plant plane.

World frame = the chamber frame in 3-D: x along the rail, y into the chamber (away from the
camera), z up; the plant plane is y = 0. The camera's optical frame has z forward, x right and
y down (REP-103's ``_optical``). Points of the plane map to pixels through
``K [r1 r3 t]``: the twin draws with this projection, which it builds from a pose, never from
the pipeline's marker fit.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

# Chamber axes -> optical axes before any tilt: x_opt = x, y_opt = -z, z_opt = y.
_LOOK_INTO_PLANE = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


@dataclass(frozen=True)
class Pose:
    """A pinhole camera looking at the plant plane.

    Attributes:
        size: (width, height) of the photo [px].
        focal_px: Focal length [px] (square pixels, principal point at the centre).
        rotation: (3, 3) chamber axes -> optical axes.
        centre: (3,) camera centre in the chamber frame [m] (y < 0: in front of the plane).
    """

    size: tuple[int, int]
    focal_px: float
    rotation: np.ndarray
    centre: np.ndarray

    @property
    def intrinsics(self) -> np.ndarray:
        w, h = self.size
        return np.array([[self.focal_px, 0.0, 0.5 * w - 0.5],
                         [0.0, self.focal_px, 0.5 * h - 0.5], [0.0, 0.0, 1.0]])

    def homography(self) -> np.ndarray:
        """(3, 3) chamber plane (x, z, 1) [m] -> photo (column, row, 1), homogeneous."""
        r = self.rotation
        columns = np.column_stack((r[:, 0], r[:, 2], -r @ self.centre))
        return self.intrinsics @ columns

    def project(self, points: np.ndarray) -> np.ndarray:
        """(N, 2) plane points (x, z) [m] -> (N, 2) photo pixels (column, row)."""
        points = np.asarray(points, np.float64).reshape(-1, 2)
        out = np.c_[points, np.ones(len(points))] @ self.homography().T
        return out[:, :2] / out[:, 2:3]

    def px_per_m(self, points: np.ndarray) -> np.ndarray:
        """(N,) photo pixels per metre on the plane at these points (focal / depth)."""
        points = np.asarray(points, np.float64).reshape(-1, 2)
        world = np.column_stack((points[:, 0], np.zeros(len(points)), points[:, 1]))
        depth = (world - self.centre) @ self.rotation[2]
        return self.focal_px / depth


def look_at_plane(size: tuple[int, int], hfov_deg: float, aim: tuple[float, float],
                  distance_m: float, yaw_deg: float = 0.0, pitch_deg: float = 0.0,
                  roll_deg: float = 0.0) -> Pose:
    """A camera ``distance_m`` in front of the plane, aimed at ``aim`` (x, z), then turned.

    Args:
        size: Photo (width, height) [px].
        hfov_deg: Horizontal field of view [deg].
        aim: The plane point the optical axis meets before turning (x, z) [m].
        distance_m: Distance from the camera to the plane [m].
        yaw_deg, pitch_deg, roll_deg: Turns about the optical y, x and z axes [deg]: a
            camera not quite square to the plane.
    """
    focal = 0.5 * size[0] / math.tan(math.radians(0.5 * hfov_deg))
    turn = _rot_z(roll_deg) @ _rot_x(pitch_deg) @ _rot_y(yaw_deg)
    rotation = turn @ _LOOK_INTO_PLANE
    centre = np.array([aim[0], -distance_m, aim[1]])
    return Pose(size, focal, rotation, centre)


def _rot_x(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_y(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rot_z(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
