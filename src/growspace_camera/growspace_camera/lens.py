"""The camera's lens: intrinsics and distortion from a calibration, in OpenCV's model.

A pinhole camera sees the chamber's plane through a homography, but a real lens bends straight
lines (barrel or pincushion distortion), most at the photo's edges, where the markers are. With
a calibration (``settings.load_lens``: the YAML that ROS's camera_calibration writes and
camera_info_manager reads), the markers' corners are undistorted before the plane is fitted,
and the rectified view is sampled through the distortion: ``cv2.initUndistortRectifyMap``
with the grid's homography as its rectification, so no undistorted copy of the photo is made.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from growspace_camera.errors import BAD_INPUT, CameraError

COEFFICIENTS = (4, 5, 8, 12, 14)  # the distortion vector lengths OpenCV takes
# Undistorting is iterative: OpenCV's default 5 steps leave 0.02 px at a strong barrel's corner.
UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-9)


@dataclass(frozen=True)
class Lens:
    """A calibrated camera (OpenCV's pinhole model with distortion).

    Attributes:
        camera_matrix: (3, 3) fx, fy, cx, cy [px].
        distortion: OpenCV's coefficients (k1, k2, p1, p2[, k3[, k4, k5, k6[, ...]]]).
        size: (width, height) [px] of the photos it was calibrated on.
    """

    camera_matrix: np.ndarray = field(repr=False)
    distortion: np.ndarray = field(repr=False)
    size: tuple[int, int]

    def __post_init__(self) -> None:
        k = np.asarray(self.camera_matrix, np.float64)
        d = np.asarray(self.distortion, np.float64).reshape(-1)
        if k.shape != (3, 3) or not np.all(np.isfinite(k)) or k[0, 0] <= 0 or k[1, 1] <= 0 \
                or not np.array_equal(k[2], (0.0, 0.0, 1.0)):
            raise ValueError(f'camera_matrix must be 3 x 3 [[fx, 0, cx], [0, fy, cy], '
                             f'[0, 0, 1]] with fx, fy > 0, got {k.tolist()}')
        if d.size not in COEFFICIENTS or not np.all(np.isfinite(d)):
            raise ValueError(f'distortion must hold {", ".join(map(str, COEFFICIENTS))} finite '
                             f'coefficients (OpenCV), got {d.tolist()}')
        if len(self.size) != 2 or min(self.size) < 1:
            raise ValueError(f'size must be (width, height) in pixels, got {self.size}')
        object.__setattr__(self, 'camera_matrix', k)
        object.__setattr__(self, 'distortion', d)
        object.__setattr__(self, 'size', (int(self.size[0]), int(self.size[1])))

    def check(self, shape: tuple[int, ...]) -> None:
        """Raises CameraError ``BAD_INPUT`` for a photo of another size than calibrated."""
        if (shape[1], shape[0]) != self.size:
            raise CameraError(BAD_INPUT, f'the photo is {shape[1]} x {shape[0]} px, the lens '
                              f'calibration is for {self.size[0]} x {self.size[1]} px')

    def ideal(self, pixels: np.ndarray) -> np.ndarray:
        """(N, 2) photo pixels -> where a distortion-free lens would have put them."""
        points = np.asarray(pixels, np.float64).reshape(-1, 1, 2)
        return cv2.undistortPointsIter(points, self.camera_matrix, self.distortion, None,
                                       self.camera_matrix, UNDISTORT_CRITERIA).reshape(-1, 2)

    def distorted(self, pixels: np.ndarray) -> np.ndarray:
        """(N, 2) distortion-free pixels -> where this lens puts them in the photo."""
        points = np.asarray(pixels, np.float64).reshape(-1, 2)
        rays = np.c_[points, np.ones(len(points))] @ np.linalg.inv(self.camera_matrix).T
        out, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), self.camera_matrix,
                                   self.distortion)
        return out.reshape(-1, 2)

    def sample_maps(self, to_ideal: np.ndarray, size: tuple[int, int],
                    to_sampled: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``cv2.remap`` maps of an image ``size`` (width, height) whose pixel (column, row)
        shows the distortion-free photo pixel ``to_ideal`` @ (column, row, 1).

        Args:
            to_ideal: (3, 3) output pixel -> distortion-free photo pixel (a homography).
            size: The output's (width, height) [px].
            to_sampled: (3, 3) affine from photo pixels to the image remap reads (a crop,
                shrunk).
        """
        # initUndistortRectifyMap takes output pixels to rays by inv(new @ R): with R = I
        # and new = inv(to_ideal) @ K, that is inv(K) @ to_ideal; it distorts the rays and
        # puts them through its first matrix, here the photo's K followed by ``to_sampled``.
        new = np.linalg.inv(to_ideal) @ self.camera_matrix
        return cv2.initUndistortRectifyMap(to_sampled @ self.camera_matrix, self.distortion,
                                           np.eye(3), new, size, cv2.CV_32FC1)
