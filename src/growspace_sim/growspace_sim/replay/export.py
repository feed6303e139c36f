"""Export one recorded episode's camera images as a GIF or MP4."""

from __future__ import annotations

from collections.abc import Callable
import os
from pathlib import Path

import numpy as np
from tqdm import tqdm

from growspace_sim.recording import METADATA_NAME
from growspace_sim.recording.scan import Damage
from growspace_sim.replay.bag import Bag, ReplayError
from growspace_sim.replay.episodes import read_episodes
from growspace_sim.ros import convert

# GIF stores a frame's delay in hundredths of a second (16 bits): 100 fps is its finest step.
FPS_RANGE = (0.1, 100.0)  # frames per second
SCALE_RANGE = (1, 16)  # upscaling factor: an 84 px frame becomes at most 1,344 px wide


def export_episode(path: str | os.PathLike, out: str | os.PathLike, *, episode: int = 0,
                   fps: float | None = None, scale: int = 4, namespace: str | None = None,
                   progress: bool = True, overwrite: bool = False,
                   warn: Callable[[str], None] | None = None) -> int:
    """Write one episode's camera images as an animated GIF or an MP4 video.

    Args:
        path: The recording.
        out: ``.gif`` (Pillow) or ``.mp4`` (OpenCV's bundled FFmpeg, codec mp4v).
        episode: 0-based episode index (negative counts from the end).
        fps: Frames per second in ``FPS_RANGE``; None = the recorded rate (default 10),
            brought into that range with a warning.
        scale: Integer upscaling (nearest neighbour) so 84 px frames are visible, in
            ``SCALE_RANGE``.
        namespace: The chamber namespace; None = the only one.
        progress: Show a progress bar on stderr.
        overwrite: Replace ``out`` if it exists.
        warn: Told of each unreadable part of the file and of a chosen episode with steps
            missing (the frames that could be read are exported).

    Returns:
        The number of frames written.

    Raises:
        ReplayError: Unreadable recording, no such episode, an existing output or a missing
            folder for it, an unknown extension, ``fps`` or ``scale`` out of range, or no MP4
            encoder.
    """
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in ('.gif', '.mp4'):
        raise ReplayError(f'Cannot export to {out}: use a .gif or .mp4 file name.')
    if out.exists() and not overwrite:
        raise ReplayError(f'{out} exists already, not overwriting.')
    if not out.parent.is_dir():  # found out now, not after rendering every frame
        raise ReplayError(f'Cannot export to {out}: the folder {out.parent} does not exist.')
    if fps is not None and not FPS_RANGE[0] <= fps <= FPS_RANGE[1]:
        raise ReplayError(f'fps = {fps!r} is not allowed; expected frames per second in '
                          f'[{FPS_RANGE[0]}, {FPS_RANGE[1]}].')
    if isinstance(scale, bool) or not isinstance(scale, int) or \
            not SCALE_RANGE[0] <= scale <= SCALE_RANGE[1]:
        raise ReplayError(f'scale = {scale!r} is not allowed; expected an integer in '
                          f'[{SCALE_RANGE[0]}, {SCALE_RANGE[1]}].')

    def skipped(part: Damage) -> None:
        if warn is not None:
            warn(f'skipped unreadable {part}')

    with Bag(path, on_damage=skipped) as bag:
        episodes = read_episodes(bag, namespace)
        if not -len(episodes) <= episode < len(episodes):
            raise ReplayError(f'{bag.path} has {len(episodes)} episode(s); episode {episode} '
                              f'does not exist.')
        chosen = episodes[episode]
        if chosen.damaged and warn is not None:
            warn(f'episode {chosen.index} is incomplete ({"; ".join(chosen.damaged)}); '
                 f'exporting the frames that could be read.')
        if fps is None:
            rate = float(bag.metadata.get(METADATA_NAME, {}).get('rate_hz') or 10.0)
            fps = min(max(rate, FPS_RANGE[0]), FPS_RANGE[1])
            if fps != rate and warn is not None:  # e.g. a real plant on the gantry, 1 step/h
                warn(f'the recorded rate of {rate:g} Hz is outside [{FPS_RANGE[0]}, '
                     f'{FPS_RANGE[1]}] frames per second; exporting at {fps:g}.')
        frames = []
        for record in chosen.steps:
            image = record.outputs.get('camera/image_raw')
            if image is not None:
                frame = convert.image_from_msg(image.decode())
                frames.append(np.repeat(np.repeat(frame, scale, axis=0), scale, axis=1))
    if not frames:
        raise ReplayError(f'Episode {episode} of {path} has no camera images.')
    bar = tqdm(total=len(frames), desc=f'export {out.name}', unit='frame', disable=not progress)
    if suffix == '.gif':
        from PIL import Image

        images = []
        for frame in frames:
            images.append(Image.fromarray(frame))
            bar.update()
        bar.close()
        images[0].save(out, save_all=True, append_images=images[1:],
                       duration=round(1000 / fps), loop=0)
    else:
        import cv2

        h, w = frames[0].shape[:2]
        writer = cv2.VideoWriter(str(out), cv2.VideoWriter_fourcc(*'mp4v'), fps, (w, h))
        if not writer.isOpened():
            raise ReplayError(f'No MP4 encoder available to OpenCV for {out}; export a .gif.')
        try:
            for frame in frames:
                writer.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))  # OpenCV writes BGR
                bar.update()
        finally:
            bar.close()
            writer.release()
    return len(frames)
