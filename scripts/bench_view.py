#!/usr/bin/env python3
"""CPU per frame of view_node's work: the view scene, the MarkerArray and the view image.

Method: per challenge (easy setting, seed 0, the challenge's oracle steering so the plant
grows as in a real run), the messages of one 50-step episode are built first
(``view.sample.episode_messages``: config, then per tick plant/state, light/state,
step_result, as sim_node publishes them). Timed, with ``time.process_time`` on one CPU
(``sched_setaffinity``): for each of the 51 ticks what ``ViewNode`` does when both outputs are
subscribed — feed the ``Scene`` (the re-simulation steps along), build the MarkerArray and
serialise it to CDR, draw the view image (``--size`` px) and serialise its ``sensor_msgs/Image``.
Not timed: the DDS publish itself (rmw), which bench_node.py measures at 40-110 us per message.
A figure is the best of ``--repeats`` episodes, as ms per frame and as the share of one core
that 50 frames per second take (a 50 Hz chamber).

``--live SECONDS`` also measures the real thing: the installed ``view_node`` beside a
``sim_node`` in realtime mode at 50 Hz (control, seed 0, the light left alone, episodes
restarting), an rclpy client subscribed to ``plant/markers`` and ``camera/image_view``; the view
process's CPU (/proc, user + system, rmw and executor included) over the frames the client
received in that time. Needs the workspace sourced and the network rule (``./run.sh`` style).

Usage (the workspace's venv): python scripts/bench_view.py [--size 512] [--repeats 5]
    [--live 20]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'src', 'growspace_sim'))

from growspace_sim.core.config import SimConfig  # noqa: E402
from growspace_sim.ros import convert  # noqa: E402
from growspace_sim.ros import types  # noqa: E402
from growspace_sim.view import markers, Scene  # noqa: E402
from growspace_sim.view.image import ViewRenderer  # noqa: E402
from growspace_sim.view.sample import episode_messages, feed  # noqa: E402

RATE_HZ = 50.0


def live(seconds: float) -> None:
    """The installed view_node next to a realtime sim_node at 50 Hz: CPU per frame."""
    sys.path.insert(0, os.path.join(ROOT, 'tests'))
    sys.path.insert(0, os.path.join(ROOT, 'scripts'))
    from bench_common import cpu_seconds
    from ros_helpers import Client, NodeProcess
    from sensor_msgs.msg import Image
    from visualization_msgs.msg import MarkerArray

    from growspace_sim.node.view_node import NODE_NAME  # noqa: F401 - the package is there
    from ament_index_python.packages import get_package_prefix

    exe = os.path.join(get_package_prefix('growspace_sim'), 'lib', 'growspace_sim', 'view_node')
    ns = f'/bench_view_{os.getpid()}'
    sim = NodeProcess('-p', 'mode:=realtime', '-p', f'rate_hz:={RATE_HZ}', '-p', 'seed:=0',
                      namespace=ns)
    view = NodeProcess(namespace=ns, executable=exe)
    client = Client(ns, name='bench_view_client')
    try:
        got = {'markers': 0, 'images': 0}

        def count(key: str) -> object:
            return lambda _msg: got.__setitem__(key, got[key] + 1)
        client.node.create_subscription(MarkerArray, 'plant/markers', count('markers'), 10)
        client.node.create_subscription(Image, 'camera/image_view', count('images'), 10)
        assert client.spin_until(lambda: got['markers'] > 10, 30.0), 'no markers'
        start_cpu, start = cpu_seconds(view.proc.pid), dict(got)
        client.drain(seconds)
        cpu = cpu_seconds(view.proc.pid) - start_cpu
        frames = got['markers'] - start['markers']
        print(f'\nlive, {seconds:.0f} s: {frames} marker arrays and '
              f'{got["images"] - start["images"]} images received ({frames / seconds:.1f} Hz); '
              f'view_node CPU {cpu / frames * 1e3:.2f} ms per frame, '
              f'{cpu / seconds:.0%} of one core')
    finally:
        client.close()
        view.stop()
        sim.stop()


def one_episode(messages: list, size: int) -> tuple[float, int, int]:
    """Process CPU seconds for one episode's frames, the frame count and the CDR bytes."""
    scene, renderer = Scene(), ViewRenderer(size)
    frames = size_bytes = 0
    start = time.process_time()
    for topic, msg in messages:
        frame = feed(scene, topic, msg)
        if frame is None:
            continue
        array = markers.marker_array(frame)
        size_bytes += len(types.serialize(array, markers.MARKER_ARRAY))
        image = convert.image_msg(renderer.render(frame), frame.stamp_ns, 'chamber_camera')
        size_bytes += len(types.serialize(image, types.IMAGE))
        frames += 1
    return time.process_time() - start, frames, size_bytes


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--size', type=int, default=512, help='view image width [px]')
    parser.add_argument('--repeats', type=int, default=5, help='episodes timed; best counts')
    parser.add_argument('--live', type=float, default=0.0,
                        help='seconds of the live measurement; 0 = skip it')
    args = parser.parse_args()
    if args.live:
        live(args.live)  # before pinning: three processes share the machine's cores
    if hasattr(os, 'sched_setaffinity'):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    print(f'view frames, {args.size} px, best of {args.repeats} episodes, one CPU')
    print('| challenge | ms per frame | share of one core at 50 Hz | markers kB | segments |')
    print('|---|---|---|---|---|')
    for challenge in ('control', 'fairness', 'shape'):
        cfg = SimConfig(challenge=challenge)
        messages = list(episode_messages(cfg, seed=0))
        one_episode(messages, args.size)  # warm-up: caches, the digit set
        best = min(one_episode(messages, args.size) for _ in range(args.repeats))
        seconds, frames, _ = best
        last = messages[-3][1]  # the last plant/state
        scene = Scene()
        frame = [feed(scene, t, m) for t, m in messages][-1]
        kb = len(types.serialize(markers.marker_array(frame), markers.MARKER_ARRAY)) / 1e3
        per_frame = seconds / frames
        print(f'| {challenge} | {per_frame * 1e3:.2f} | {per_frame * RATE_HZ:.0%} | '
              f'{kb:.1f} | {int((last.parent >= 0).sum())} |')
    return 0


if __name__ == '__main__':
    sys.exit(main())
