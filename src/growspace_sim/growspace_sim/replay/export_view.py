"""A copy of a recording with the view added: ``plant/markers`` and ``camera/image_view``.

``growspace-replay export BAG OUT.mcap --view``: every recorded message is copied unchanged
(same channels, QoS metadata, bytes, times, order, metadata records), and after each
``step_result`` of the chamber the frame ``view_node`` would have published for it is added,
with the step_result's log and publish times. The frames come from the same ``view`` modules
as the node's, fed the recorded messages in file order, so Foxglove opens the file with the 3D
plant and the view image and no ROS install.
"""

from __future__ import annotations

from collections.abc import Callable
import os
from typing import Any

from tqdm import tqdm

from growspace_sim.recording import McapRecorder
from growspace_sim.replay.bag import Bag, ReplayError
from growspace_sim.ros import convert
from growspace_sim.ros import types
from growspace_sim.ros.interface import OBSERVATION_QOS
from growspace_sim.view import markers, Scene, ViewInputError
from growspace_sim.view.image import DEFAULT_SIZE, ViewRenderer


def export_with_view(path: str | os.PathLike, out: str | os.PathLike, *,
                     namespace: str | None = None, view_size: int = DEFAULT_SIZE,
                     overwrite: bool = False, progress: bool = True,
                     warn: Callable[[str], Any] | None = None) -> int:
    """Copy a recording and add the view's markers and images.

    Args:
        path: The recording.
        out: The new ``.mcap`` file.
        namespace: The chamber namespace; None = the only one.
        view_size: Width of the view images [px].
        overwrite: Replace ``out`` if it exists.
        progress: Show a progress bar on stderr.
        warn: Where a line about an unusable recorded message goes (None: dropped silently).

    Returns:
        The number of frames added.

    Raises:
        ReplayError: unreadable recording, no chamber, an existing output, a bad size.
        RecordingError: the output cannot be written.
    """
    if not str(out).endswith('.mcap'):
        raise ReplayError(f'Cannot export the view to {out}: use a .mcap file name.')
    try:
        renderer = ViewRenderer(view_size)
    except ValueError as e:
        raise ReplayError(str(e)) from None
    frames = 0
    with Bag(path) as bag:
        names = bag.chamber_topics(namespace)
        if 'step_result' not in names:
            raise ReplayError(f'{bag.path} has no step_result topic to draw frames for.')
        prefix = names['step_result'][:-len('step_result')]
        scene = Scene()
        handlers = {names.get('chamber/config'): lambda msg: scene.on_config(msg.data),
                    names.get('plant/state'): scene.on_plant,
                    names.get('light/state'): scene.on_light}
        handlers.pop(None, None)
        with McapRecorder(out, overwrite=overwrite) as recorder:
            for name, data in bag.metadata.items():
                recorder.add_metadata(name, data)
            channels = {t: recorder.add_channel(t, i.typename, i.qos)
                        for t, i in bag.topics.items()}
            marker_channel = recorder.add_channel(f'{prefix}plant/markers',
                                                  markers.MARKER_ARRAY, OBSERVATION_QOS)
            image_channel = recorder.add_channel(f'{prefix}camera/image_view', types.IMAGE,
                                                 OBSERVATION_QOS)
            total = sum(i.count for i in bag.topics.values())
            with tqdm(total=total, desc='export', unit='msg', disable=not progress) as bar:
                for msg in bag.messages():
                    recorder.write(channels[msg.topic], msg.data, msg.log_time,
                                   msg.publish_time)
                    bar.update()
                    handle = handlers.get(msg.topic)
                    try:
                        if handle is not None:
                            handle(msg.decode())
                            continue
                        if msg.topic != names['step_result']:
                            continue
                        frame = scene.on_result(msg.decode())
                    except ViewInputError as e:
                        if warn is not None:
                            warn(str(e))
                        continue
                    times = (msg.log_time, msg.publish_time)
                    array = markers.marker_array(frame, scene.frame_id)
                    recorder.write(marker_channel,
                                   types.serialize(array, markers.MARKER_ARRAY), *times)
                    image = convert.image_msg(renderer.render(frame), frame.stamp_ns,
                                              scene.image_frame_id)
                    recorder.write(image_channel, types.serialize(image, types.IMAGE), *times)
                    frames += 1
    return frames
