"""Where photos come from: a V4L2 webcam, a video file, a folder of photos, the photo twin.

A source only yields frames and reports loss (``CaptureError``); everything after it is pure.
``Camera`` wraps a source with what a lost USB cable needs: it reopens the source with back-off
and never raises, so a node callback gets a frame or a reason. Devices go through
``cv2.VideoCapture`` with the V4L2 backend: size, frame rate, MJPG, manual exposure and white
balance are asked for, then read back, because drivers ignore what they do not support (the
log and ``settings`` say what the camera really accepted).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
import bisect
import glob
import os
from pathlib import Path
import time
from typing import Any, Protocol

import cv2
import numpy as np

from growspace_sim.core.config import SimConfig
from growspace_sim.core.light import Light

BACKOFF_S = (0.5, 1.0, 2.0, 5.0, 10.0)  # waits between tries to reopen a lost source
PHOTO_SUFFIXES = ('.jpg', '.jpeg', '.png', '.bmp', '.tif', '.tiff', '.webp')
V4L2_MANUAL_EXPOSURE = 1  # V4L2 auto-exposure menu: 1 = manual, 3 = aperture priority


class CaptureError(Exception):
    """The source gave no frame: missing, unplugged, at its end, or unreadable."""


class SourceEnded(CaptureError):
    """A file source reached its end and does not loop: nothing to retry."""


@dataclass(frozen=True)
class Shot:
    """What a photo is for: the twin source grows its plant to it; real sources ignore it.

    Attributes:
        cfg: The episode's configuration.
        light: The light as reached.
        step: Steps taken in the episode (0: just reset).
        seed: The episode's seed (the twin's layout), None if unknown.
        episode: Counts resets, so the twin knows a new episode from a repeated step 0.
    """

    cfg: SimConfig
    light: Light
    step: int
    seed: int | None = None
    episode: int = 0


@dataclass
class Frame:
    """One photo.

    Attributes:
        bgr: (H, W, 3) uint8 BGR, as OpenCV decodes.
        jpeg: The JPEG bytes as delivered, when the source had them (else None).
        taken_ns: Wall-clock time of the capture [ns].
    """

    bgr: np.ndarray = field(repr=False)
    jpeg: bytes | None = field(default=None, repr=False)
    taken_ns: int = 0


class Source(Protocol):
    """A place photos come from."""

    name: str

    def open(self) -> dict[str, str]:
        """Open it; returns what it accepted (for the log and camera/status).

        Raises:
            CaptureError: it cannot be opened.
        """

    def read(self, shot: Shot) -> Frame:
        """The next photo.

        Raises:
            CaptureError: no photo (lost, at its end, unreadable).
        """

    def close(self) -> None:
        """Release it. Idempotent."""


@dataclass(frozen=True)
class DeviceSettings:
    """What is asked of a webcam (camera_node's parameters of the same names)."""

    width: int = 1920
    height: int = 1080
    fps: float = 30.0
    exposure: float = -1.0  # -1: leave automatic
    white_balance_k: int = 0  # 0: leave automatic
    flush_frames: int = 2


class DeviceSource:
    """A V4L2 webcam, by index or ``/dev/videoN`` path."""

    def __init__(self, device: int | str, settings: DeviceSettings) -> None:
        self.device, self.settings = device, settings
        self.name = f'/dev/video{device}' if isinstance(device, int) else str(device)
        self._cap: Any = None

    def open(self) -> dict[str, str]:
        if isinstance(self.device, str) and not os.path.exists(self.device):
            raise CaptureError(f'{self.device} does not exist (camera unplugged, or another '
                               f'/dev/videoN: list them with v4l2-ctl --list-devices)')
        cap = cv2.VideoCapture(self.device, cv2.CAP_V4L2)
        if not cap.isOpened():
            cap.release()
            raise CaptureError(f'{self.name} cannot be opened by OpenCV (V4L2): in use by '
                               f'another program, or no permission (group video)')
        s = self.settings
        cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter_fourcc(*'MJPG'))  # 1080p30 on USB 2
        cap.set(cv2.CAP_PROP_FRAME_WIDTH, s.width)
        cap.set(cv2.CAP_PROP_FRAME_HEIGHT, s.height)
        cap.set(cv2.CAP_PROP_FPS, s.fps)
        cap.set(cv2.CAP_PROP_BUFFERSIZE, 1)
        if s.exposure > 0:
            cap.set(cv2.CAP_PROP_AUTO_EXPOSURE, V4L2_MANUAL_EXPOSURE)
            cap.set(cv2.CAP_PROP_EXPOSURE, s.exposure)
        if s.white_balance_k > 0:
            cap.set(cv2.CAP_PROP_AUTO_WB, 0)
            cap.set(cv2.CAP_PROP_WB_TEMPERATURE, s.white_balance_k)
        self._cap = cap
        fourcc = int(cap.get(cv2.CAP_PROP_FOURCC))
        return {  # read back: what the driver really took
            'width': f'{cap.get(cv2.CAP_PROP_FRAME_WIDTH):.0f}',
            'height': f'{cap.get(cv2.CAP_PROP_FRAME_HEIGHT):.0f}',
            'fps': f'{cap.get(cv2.CAP_PROP_FPS):g}',
            'fourcc': ''.join(chr((fourcc >> 8 * i) & 0xFF) for i in range(4)),
            'auto_exposure': f'{cap.get(cv2.CAP_PROP_AUTO_EXPOSURE):g}',
            'exposure': f'{cap.get(cv2.CAP_PROP_EXPOSURE):g}',
            'auto_wb': f'{cap.get(cv2.CAP_PROP_AUTO_WB):g}',
            'wb_temperature': f'{cap.get(cv2.CAP_PROP_WB_TEMPERATURE):g}',
        }

    def read(self, shot: Shot) -> Frame:
        cap = self._cap
        if cap is None:
            raise CaptureError(f'{self.name} is not open')
        for _ in range(self.settings.flush_frames):  # frames queued before the light moved
            cap.grab()
        ok, bgr = cap.read()
        if not ok or bgr is None:
            raise CaptureError(f'{self.name} gave no frame (unplugged?)')
        return Frame(bgr, None, time.time_ns())

    def close(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None


class VideoSource:
    """A video file (or an image-sequence pattern such as ``shots/img_%04d.png``)."""

    def __init__(self, path: str, loop: bool) -> None:
        self.name, self.loop = path, loop
        self._cap: Any = None

    def open(self) -> dict[str, str]:
        if '%' not in self.name and not os.path.isfile(self.name):
            raise CaptureError(f'{self.name} does not exist')
        cap = cv2.VideoCapture(self.name)
        if not cap.isOpened():
            cap.release()
            raise CaptureError(f'{self.name} cannot be read by OpenCV (codec, format)')
        self._cap = cap
        return {'frames': f'{cap.get(cv2.CAP_PROP_FRAME_COUNT):.0f}',
                'width': f'{cap.get(cv2.CAP_PROP_FRAME_WIDTH):.0f}',
                'height': f'{cap.get(cv2.CAP_PROP_FRAME_HEIGHT):.0f}'}

    def read(self, shot: Shot) -> Frame:
        if self._cap is None:
            raise CaptureError(f'{self.name} is not open')
        ok, bgr = self._cap.read()
        if not ok and self.loop:
            self._cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
            ok, bgr = self._cap.read()
        if not ok or bgr is None:
            raise SourceEnded(f'{self.name}: no more frames')
        return Frame(bgr, None, time.time_ns())

    def close(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None


class PhotoSource:
    """A folder of photos, or a glob, in name order (JPEG bytes kept as they are).

    A file that cannot be read as a photo is skipped with one line to ``warn`` and left out of
    later rounds: one bad file neither ends nor restarts the run. Reopened (after a lost
    source), it goes on after the last photo it gave.

    Args:
        pattern: A folder, a glob such as ``shots/*.jpg``, or one photo's path.
        loop: Start again at the first photo after the last.
        warn: Writes a warning line (a skipped file); None: silent.
    """

    def __init__(self, pattern: str, loop: bool,
                 warn: Callable[[str], Any] | None = None) -> None:
        self.name, self.loop = pattern, loop
        self.warn = warn or (lambda line: None)
        self._files: list[str] = []
        self._next = 0
        self._last = ''  # the last photo given, so a reopen goes on after it
        self._bad: set[str] = set()  # files found unreadable (skipped, said once)

    def open(self) -> dict[str, str]:
        files = [f for f in self._list() if f not in self._bad]
        if not files:
            raise CaptureError(f'{self.name}: none of its files is a photo OpenCV can read')
        self._files = files
        self._next = bisect.bisect_right(files, self._last) if self._last else 0
        return {'photos': str(len(files)), 'first': files[0]}

    def _list(self) -> list[str]:
        """The photos the pattern names, in name order (raises for a missing path or none)."""
        if os.path.isdir(self.name):
            files = [str(p) for p in sorted(Path(self.name).iterdir())
                     if p.suffix.lower() in PHOTO_SUFFIXES]
            if not files:
                raise CaptureError(f'folder {self.name} holds no photos '
                                   f'({", ".join(PHOTO_SUFFIXES)})')
            return files
        if not any(c in self.name for c in '*?['):
            if not os.path.isfile(self.name):  # (an existing folder was listed above)
                what = 'photo' if Path(self.name).suffix.lower() in PHOTO_SUFFIXES \
                    and not self.name.endswith(('/', os.sep)) else 'folder'
                raise CaptureError(f'{what} {self.name} does not exist')
            return [self.name]
        folder = os.path.dirname(self.name)
        if folder and not any(c in folder for c in '*?[') and not os.path.isdir(folder):
            raise CaptureError(f'folder {folder} (of {self.name}) does not exist')
        files = sorted(f for f in glob.glob(self.name) if os.path.isfile(f))
        if not files:
            raise CaptureError(f'{self.name}: no file matches')
        return files

    def read(self, shot: Shot) -> Frame:
        while self._files:
            if self._next >= len(self._files):
                if not self.loop:
                    break
                self._next = 0
            path = self._files[self._next]
            try:
                bgr, data = read_photo(path)
            except CaptureError as e:
                self.warn(f'camera: skipped {e}')
                self._bad.add(path)
                del self._files[self._next]
                continue
            self._next += 1
            self._last = path
            jpeg = data if data[:3] == b'\xff\xd8\xff' else None
            return Frame(bgr, jpeg, time.time_ns())
        if not self._files:
            raise SourceEnded(f'{self.name}: none of its files is a photo OpenCV can read')
        raise SourceEnded(f'{self.name}: no more photos')

    def close(self) -> None:
        self._files = []


def read_photo(path: str) -> tuple[np.ndarray, bytes]:
    """A photo file's (H, W, 3) uint8 BGR pixels and its bytes.

    Raises:
        CaptureError: naming the path and what is wrong: it does not exist, it is a folder, it
            cannot be read (permissions), it is empty, or OpenCV cannot decode it.
    """
    if os.path.isdir(path):
        raise CaptureError(f'{path} is a folder, not a photo')
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        raise CaptureError(f'{path} does not exist') from None
    except OSError as e:
        raise CaptureError(f'{path} cannot be read: {e.strerror or e}') from None
    if not data:
        raise CaptureError(f'{path} is not a photo OpenCV can read: the file is empty')
    try:  # (OpenCV raises for some broken headers and returns None for others)
        bgr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    except cv2.error:
        bgr = None
    if bgr is None:
        raise CaptureError(f'{path} is not a photo OpenCV can read ({len(data)} bytes, '
                           f'starting {data[:8]!r})')
    return bgr, data


def open_source(spec: str, device: DeviceSettings, loop: bool,
                twin: Callable[[], Source] | None = None,
                warn: Callable[[str], Any] | None = None) -> Source:
    """The source a ``source`` parameter names (not opened yet).

    Args:
        spec: 'twin', a device index ('0') or ``/dev/videoN``, a video file, a folder of
            photos, or a glob of photos.
        device: What to ask of a webcam.
        loop: Files start again at their end.
        twin: Builds the twin source (the node passes one that knows the marker layout).
        warn: Writes a warning line (a photo file skipped as unreadable).
    """
    spec = spec.strip()
    if spec == 'twin':
        if twin is None:
            raise ValueError("source 'twin' needs a twin factory")
        return twin()
    if spec.isdigit():
        return DeviceSource(int(spec), device)
    if spec.startswith('/dev/'):
        return DeviceSource(spec, device)
    if os.path.isdir(spec) or spec.endswith(('/', os.sep)) or any(c in spec for c in '*?['):
        return PhotoSource(spec, loop, warn)
    if Path(spec).suffix.lower() in PHOTO_SUFFIXES and '%' not in spec:
        return PhotoSource(spec, loop, warn)
    return VideoSource(spec, loop)


class Camera:
    """A source kept open: reopened with back-off when lost; ``read`` never raises.

    Args:
        source: The source (not yet opened).
        warn: Writes a warning line (the source is lost, once per reason).
        info: Writes an informational line (the source is open, and what it accepted).
        clock: Monotonic time [s].
        retry_max_s: Longest wait between two tries.
    """

    def __init__(self, source: Source, warn: Callable[[str], Any], info: Callable[[str], Any],
                 clock: Callable[[], float] = time.monotonic, retry_max_s: float = 10.0) -> None:
        self.source, self.warn, self.info, self.clock = source, warn, info, clock
        self.backoff = tuple(min(s, retry_max_s) for s in BACKOFF_S)
        self.online = False
        self.ended = False  # a file source that does not loop is done
        self.accepted: dict[str, str] = {}
        self.failure = ''  # why the source is offline (a sentence naming the source)
        self.frames = 0
        self._tries = 0
        self._next_try = 0.0

    def poll(self) -> None:
        """Open the source if it is due (a timer calls this; so does ``read``)."""
        if self.online or self.ended or self.clock() < self._next_try:
            return
        try:
            self.accepted = self.source.open()
        except CaptureError as e:
            self._lost(str(e))
            return
        except Exception as e:  # noqa: BLE001 - a driver's surprise must not end the node
            self._lost(f'{self.source.name}: {type(e).__name__}: {e}')
            return
        self.online, self._tries, self.failure = True, 0, ''
        self.info(f'camera: {self.source.name} open: '
                 + ', '.join(f'{k} {v}' for k, v in self.accepted.items()))

    def read(self, shot: Shot) -> Frame | None:
        """A photo, or None (``failure`` says why)."""
        self.poll()
        if not self.online:
            return None
        try:
            frame = self.source.read(shot)
        except SourceEnded as e:
            self.online, self.ended, self.failure = False, True, str(e)
            return None
        except CaptureError as e:
            self._drop(str(e))
            return None
        except Exception as e:  # noqa: BLE001 - same as in poll
            self._drop(f'{self.source.name}: {type(e).__name__}: {e}')
            return None
        self.frames += 1
        return frame

    @property
    def retry_in_s(self) -> float:
        return max(0.0, self._next_try - self.clock())

    def close(self) -> None:
        try:
            self.source.close()
        finally:
            self.online = False

    def _drop(self, reason: str) -> None:
        try:
            self.source.close()
        except Exception:  # noqa: BLE001 - it is already lost
            pass
        self.online = False
        self._tries = 0
        self._lost(reason)

    def _lost(self, reason: str) -> None:
        wait = self.backoff[min(self._tries, len(self.backoff) - 1)]
        self._tries += 1
        self._next_try = self.clock() + wait
        if reason != self.failure:  # one line per new reason, not one per retry
            self.warn(f'camera: {reason}; retrying every '
                     f'{wait:g}-{self.backoff[-1]:g} s')
        self.failure = reason
