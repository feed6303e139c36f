"""Photo -> chamber plane: a homography fitted to the markers of every photo.

The plant grows in the chamber's x-z plane and the markers lie on that plane, so a pinhole
camera sees the plane through a homography (with a calibrated ``Lens``, between the plane and
the photo as a distortion-free lens would have taken it). All four markers give 16 corners
with known chamber positions; ``cv2.findHomography`` fits them by least squares, and the
residual says how well the markers agree with the layout.

When some markers are hidden (a leaf, the lamp, a hand), the last good fit is held if the
markers still seen sit where it puts them: the camera has not moved. Otherwise, or with no fit
yet, the photo is refused: nothing is guessed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from growspace_camera.errors import CameraError, FIT, MARKERS
from growspace_camera.lens import Lens
from growspace_camera.markers import Detection, MarkerLayout


@dataclass(frozen=True)
class PlaneFit:
    """A homography between photo pixels and chamber-plane metres.

    Attributes:
        to_plane: (3, 3) photo (column, row, 1) -> chamber (x, z, 1) [m], homogeneous (the
            photo's pixels as a distortion-free lens would have put them, with a ``lens``).
        to_photo: (3, 3) its inverse.
        markers: The marker ids it was fitted on.
        rms_error_m: RMS distance between the markers' fitted and laid-out corners [m].
        lens: The calibrated lens the photo's pixels are undistorted with; None: none.
    """

    to_plane: np.ndarray = field(repr=False)
    to_photo: np.ndarray = field(repr=False)
    markers: tuple[int, ...]
    rms_error_m: float
    lens: Lens | None = None

    def plane_points(self, pixels: np.ndarray) -> np.ndarray:
        """(N, 2) photo pixels -> (N, 2) chamber (x, z) [m]."""
        return _apply(self.to_plane, pixels if self.lens is None else self.lens.ideal(pixels))

    def photo_points(self, points: np.ndarray) -> np.ndarray:
        """(N, 2) chamber (x, z) [m] -> (N, 2) photo pixels (column, row)."""
        ideal = _apply(self.to_photo, points)
        return ideal if self.lens is None else self.lens.distorted(ideal)

    def px_per_m(self, at: tuple[float, float]) -> float:
        """Photo pixels per metre on the plane near ``at`` (x, z) [m] (geometric mean)."""
        step = 0.01
        x, z = at
        p = self.photo_points(np.array([(x, z), (x + step, z), (x, z + step)]))
        return float(np.sqrt(np.linalg.norm(p[1] - p[0]) * np.linalg.norm(p[2] - p[0]))
                     / step)


@dataclass(frozen=True)
class FitReport:
    """Which fit a photo is measured with, and how sure that is.

    Attributes:
        fit: The homography used.
        seen: The marker ids found in this photo.
        held: True when the fit is an earlier photo's (some markers hidden here).
        age: Photos since ``fit`` was made (0: made on this photo).
        check_error_m: RMS distance of the seen markers from where ``fit`` puts them [m]
            (for a fresh fit, its own residual).
    """

    fit: PlaneFit
    seen: tuple[int, ...]
    held: bool
    age: int
    check_error_m: float


class Calibrator:
    """Fits the plane on every photo and holds the last good fit when markers are hidden.

    Args:
        layout: Where the markers are.
        max_error_m: Largest RMS corner error a fit or a hold check may have [m].
        lens: The camera's calibrated lens; None: a distortion-free one.
    """

    def __init__(self, layout: MarkerLayout, max_error_m: float = 0.005,
                 lens: Lens | None = None) -> None:
        self.layout = layout
        self.max_error_m = max_error_m
        self.lens = lens
        self.last: PlaneFit | None = None
        self._age = 0

    def reset(self) -> None:
        """Forget the last fit (the camera was moved on purpose)."""
        self.last, self._age = None, 0

    def update(self, detections: Sequence[Detection]) -> FitReport:
        """The fit for a photo with these marker detections.

        Raises:
            CameraError: ``MARKERS`` when fewer than four markers are seen and there is no fit
                to hold (or none is seen at all); ``FIT`` when the markers disagree with the
                layout or with the held fit by more than ``max_error_m``.
        """
        seen = tuple(d.marker_id for d in detections)
        expected = list(self.layout.ids)
        if len(seen) == len(expected):
            fit = fit_plane(self.layout, detections, self.lens)
            if fit.rms_error_m > self.max_error_m:
                raise CameraError(FIT, f'the markers do not sit where the layout says: RMS '
                                  f'corner error {fit.rms_error_m * 1000:.1f} mm > '
                                  f'{self.max_error_m * 1000:.1f} mm (moved markers, a wrong '
                                  f'marker_centres or marker_side, or a misprint)')
            self.last, self._age = fit, 0
            return FitReport(fit, seen, False, 0, fit.rms_error_m)
        hidden = [i for i in expected if i not in seen]
        if self.last is None or not seen:
            why = 'no fit to hold yet: a first fit needs all four' if self.last is None else \
                'none is seen, so the held fit cannot be checked'
            raise CameraError(MARKERS, f'markers {list(seen)} of {expected} found ({why}); '
                              f'hidden: {hidden}')
        error = corner_error(self.last, self.layout, detections)
        if error > self.max_error_m:
            raise CameraError(FIT, f'markers {hidden} are hidden and the ones seen moved by '
                              f'{error * 1000:.1f} mm (RMS) from the held fit: the camera has '
                              f'moved; uncover all four markers for a new fit')
        self._age += 1
        return FitReport(self.last, seen, True, self._age, error)


def fit_plane(layout: MarkerLayout, detections: Sequence[Detection],
              lens: Lens | None = None) -> PlaneFit:
    """Least-squares homography of the detected markers' corners (at least one marker),
    undistorted first with a ``lens``.

    Raises:
        CameraError: ``FIT`` if OpenCV finds no homography (degenerate corners).
    """
    photo, plane = _pairs(layout, detections)
    if lens is not None:
        photo = lens.ideal(photo)
    to_plane, _ = cv2.findHomography(photo, plane, 0)
    if to_plane is None or not np.all(np.isfinite(to_plane)) \
            or abs(np.linalg.det(to_plane)) < 1e-300:
        raise CameraError(FIT, f'no homography fits markers {[d.marker_id for d in detections]} '
                          f'(degenerate corners)')
    to_photo = np.linalg.inv(to_plane)
    residual = np.linalg.norm(_apply(to_plane, photo) - plane, axis=1)
    return PlaneFit(to_plane, to_photo, tuple(d.marker_id for d in detections),
                    float(np.sqrt(np.mean(residual ** 2))), lens)


def corner_error(fit: PlaneFit, layout: MarkerLayout, detections: Sequence[Detection]) -> float:
    """RMS distance [m] on the plane between detected corners and the layout's corners."""
    photo, plane = _pairs(layout, detections)
    return float(np.sqrt(np.mean(np.sum((fit.plane_points(photo) - plane) ** 2, axis=1))))


def _pairs(layout: MarkerLayout, detections: Sequence[Detection]) -> tuple[np.ndarray, ...]:
    index = {marker_id: k for k, marker_id in enumerate(layout.ids)}
    photo = np.concatenate([d.corners for d in detections])
    plane = np.concatenate([layout.corners(index[d.marker_id]) for d in detections])
    return photo.astype(np.float64), plane


def _apply(h: np.ndarray, points: np.ndarray) -> np.ndarray:
    points = np.asarray(points, np.float64).reshape(-1, 2)
    out = np.c_[points, np.ones(len(points))] @ h.T
    return out[:, :2] / out[:, 2:3]
