"""The four ArUco markers that tie a photo to the chamber frame: their layout, detection, sheet.

Each marker is printed at a known side and fixed with its centre at a known chamber-frame
position (x along the rail, z up, metres; docs/recording.md) on the plant's plane, outside the
chamber square so that no stem or pot hides one. OpenCV's ``cv2.aruco`` finds them (in
opencv-python-headless itself): the ``ArucoDetector`` class of OpenCV 4.7+ and the functional
API of OpenCV 4.6 (Ubuntu 24.04's ``python3-opencv``) are both supported.

Detection runs on a smaller copy of the photo (a 1080p photo takes about 100 ms at full size,
6 ms at half size, measured on OpenCV 4.12) and the corners are then refined on the full photo.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math

import cv2
import numpy as np

DICTIONARIES = ('DICT_4X4_50', 'DICT_5X5_50', 'DICT_6X6_50')
DETECT_LONG_SIDE_PX = 1000  # markers are looked for on a copy shrunk by an integer factor to this
SUBPIX_WINDOW_PX = 3  # half window of the corner refinement on the full photo
# Markers are first looked for with one adaptive threshold window of this side, about two of a
# marker's cells on the shrunk copy of a rig framed as docs/hardware.md says (half the time
# of OpenCV's three windows, and the same markers on 180 twin photos); only when that does
# not find each marker once are all three tried (worn, low-contrast prints need the 3 px one).
QUICK_WINDOW_PX = 13
# Default layout: 6 cm markers 6 cm outside each corner of the 0.84 m chamber square.
DEFAULT_IDS = (0, 1, 2, 3)
DEFAULT_CENTRES = ((-0.06, -0.06), (0.90, -0.06), (0.90, 0.90), (-0.06, 0.90))


@dataclass(frozen=True)
class MarkerLayout:
    """Where the markers are in the chamber frame, and how they are printed.

    Attributes:
        dictionary: The ArUco dictionary (one of ``DICTIONARIES``).
        ids: One id per marker, all different.
        centres: Per marker, its centre (x, z) in the chamber frame [m].
        side: The printed side of the black square (border included) [m].
    """

    dictionary: str = 'DICT_4X4_50'
    ids: tuple[int, ...] = DEFAULT_IDS
    centres: tuple[tuple[float, float], ...] = DEFAULT_CENTRES
    side: float = 0.06

    def __post_init__(self) -> None:
        if self.dictionary not in DICTIONARIES:
            raise ValueError(f'marker_dictionary must be one of {DICTIONARIES}, '
                             f'got {self.dictionary!r}.')
        size = int(self.dictionary.rsplit('_', 1)[1])
        if len(self.ids) != 4 or len(set(self.ids)) != 4 or not all(
                isinstance(i, int) and not isinstance(i, bool) and 0 <= i < size
                for i in self.ids):
            raise ValueError(f'marker_ids must be 4 different ids in 0..{size - 1}, '
                             f'got {list(self.ids)}.')
        if len(self.centres) != 4 or not all(
                len(c) == 2 and all(math.isfinite(v) and abs(v) < 100 for v in c)
                for c in self.centres):
            raise ValueError(f'marker_centres must be 4 (x, z) pairs of finite metres, got '
                             f'{self.centres!r}.')
        if not math.isfinite(self.side) or not 0.005 <= self.side <= 1.0:
            raise ValueError(f'marker_side must be in [0.005, 1.0] m, got {self.side!r}.')
        p = np.array(self.centres, np.float64)
        (ax, az), (bx, bz) = p[2] - p[0], p[3] - p[1]
        area = 0.5 * abs(ax * bz - az * bx)  # of the quadrilateral, from its diagonals
        if area < (2 * self.side) ** 2:
            raise ValueError(f'marker_centres must span a quadrilateral much larger than a '
                             f'marker (area {area:.4f} m^2 for {self.side} m markers).')

    def corners(self, index: int) -> np.ndarray:
        """(4, 2) chamber-frame corners (x, z) [m] of marker ``index`` in ArUco's order
        (top-left, top-right, bottom-right, bottom-left as printed, upright in the chamber)."""
        x, z = self.centres[index]
        h = 0.5 * self.side
        return np.array([(x - h, z + h), (x + h, z + h), (x + h, z - h), (x - h, z - h)])

    def bits(self, marker_id: int) -> np.ndarray:
        """The marker's cells (border included) as a bool array, True = black."""
        return marker_cells(self.dictionary, marker_id)


@dataclass(frozen=True)
class Detection:
    """One marker found in a photo.

    Attributes:
        marker_id: Its id.
        corners: (4, 2) float64 photo pixels (column, row) in ArUco's corner order.
    """

    marker_id: int
    corners: np.ndarray = field(repr=False)

    @property
    def centre(self) -> np.ndarray:
        return self.corners.mean(axis=0)


def dictionary(name: str):  # noqa: ANN201 - cv2.aruco.Dictionary
    """The predefined OpenCV ArUco dictionary of this name (e.g. ``DICT_4X4_50``)."""
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))


def marker_cells(dictionary_name: str, marker_id: int) -> np.ndarray:
    """The cells of a marker, border included, True = black (1 px per cell)."""
    aruco = cv2.aruco
    dic = dictionary(dictionary_name)
    cells = int(dictionary_name.split('_')[1].split('X')[0]) + 2
    if hasattr(aruco, 'generateImageMarker'):  # OpenCV 4.7+
        image = aruco.generateImageMarker(dic, marker_id, cells)
    else:  # OpenCV 4.6
        image = aruco.drawMarker(dic, marker_id, cells)
    return image < 128


class MarkerDetector:
    """Finds the layout's markers in BGR or grey photos (OpenCV 4.6 and 4.7+ APIs).

    Args:
        layout: The markers to look for; other ids are ignored.
        aruco: The ``cv2.aruco`` module (tests pass a stand-in for the 4.6 API).
    """

    def __init__(self, layout: MarkerLayout, aruco=None) -> None:  # noqa: ANN001
        self.layout = layout
        self._aruco = aruco = aruco or cv2.aruco
        self._dictionary = aruco.getPredefinedDictionary(getattr(aruco, layout.dictionary))
        self._quick, self._detect = (self._detector(quick) for quick in (True, False))

    def _detector(self, quick: bool):  # noqa: ANN202 - image -> (corners, ids, rejected)
        aruco = self._aruco
        if hasattr(aruco, 'ArucoDetector'):  # OpenCV 4.7+
            detector = aruco.ArucoDetector(self._dictionary,
                                           _tune(aruco.DetectorParameters(), quick))
            return detector.detectMarkers
        params = _tune(aruco.DetectorParameters_create(), quick)  # 4.6: the functional API
        return lambda gray: aruco.detectMarkers(gray, self._dictionary, parameters=params)

    @staticmethod
    def shrink(gray: np.ndarray) -> np.ndarray:
        """The copy markers are looked for on: at most ``DETECT_LONG_SIDE_PX`` long."""
        # An integer factor: OpenCV's area shrink is then a plain block mean (fractional
        # factors cost 4 markers in 40 twin photos at 1000 px, none at 960 or 1100).
        factor = math.ceil(max(gray.shape) / DETECT_LONG_SIDE_PX)
        if factor == 1:
            return gray
        h, w = gray.shape
        return cv2.resize(gray, (w // factor, h // factor), interpolation=cv2.INTER_AREA)

    def detect(self, gray: np.ndarray, small: np.ndarray | None = None) -> list[Detection]:
        """The layout's markers in a grey photo, corners refined on the full photo.

        A marker id seen twice (a reflection, a second print) is left out: its position
        would be a guess.

        Args:
            gray: (H, W) uint8 photo.
            small: ``shrink(gray)``, if the caller has it already.

        Returns:
            One detection per layout marker found, in layout order.
        """
        small = self.shrink(gray) if small is None else small
        scale = small.shape[1] / gray.shape[1]
        found = _by_id(*self._quick(small)[:2], scale)
        if any(len(found.get(i, ())) != 1 for i in self.layout.ids):
            found = _by_id(*self._detect(small)[:2], scale)  # not each marker once: look harder
        wanted = [i for i in self.layout.ids if len(found.get(i, ())) == 1]
        if not wanted:
            return []
        points = np.concatenate([found[i][0] for i in wanted]).astype(np.float32)
        if scale < 1.0:
            criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 20, 0.01)
            side = min(np.linalg.norm(found[i][0][0] - found[i][0][2]) for i in wanted)
            half = max(1, min(SUBPIX_WINDOW_PX, int(side / 12)))
            cv2.cornerSubPix(gray, points, (half, half), (-1, -1), criteria)
        return [Detection(marker_id, points[4 * k:4 * k + 4].astype(np.float64))
                for k, marker_id in enumerate(wanted)]


def _by_id(corners, ids, scale: float) -> dict[int, list[np.ndarray]]:  # noqa: ANN001
    """OpenCV's detections as marker id -> the corners of each time it was seen, in photo
    pixels (the detection ran on a copy shrunk by ``scale``)."""
    found: dict[int, list[np.ndarray]] = {}
    for quad, marker_id in zip(corners, np.asarray(ids if ids is not None else []).reshape(-1)):
        # Pixel centres: (c + 0.5) / scale - 0.5 maps a small-image position to the photo.
        points = (np.asarray(quad, np.float64).reshape(4, 2) + 0.5) / scale - 0.5
        found.setdefault(int(marker_id), []).append(points)
    return found


def _tune(params, quick: bool = False):  # noqa: ANN001, ANN202 - aruco.DetectorParameters
    """Read each cell from 8 x 8 samples (OpenCV's default 4 misreads small markers). Quick:
    one thresholding window (``QUICK_WINDOW_PX``) instead of OpenCV's three (3, 13, 23 px)."""
    params.perspectiveRemovePixelPerCell = 8
    params.perspectiveRemoveIgnoredMarginPerCell = 0.2
    if quick:
        params.adaptiveThreshWinSizeMin = params.adaptiveThreshWinSizeMax = QUICK_WINDOW_PX
    return params


def to_gray(photo: np.ndarray) -> np.ndarray:
    """A grey copy of a BGR photo (a grey one is returned as it is)."""
    return photo if photo.ndim == 2 else cv2.cvtColor(photo, cv2.COLOR_BGR2GRAY)
