#!/usr/bin/env python3
"""Micro-benchmark of the Cyclone DDS fallback transport over loopback.

Measures rosbags CDR encode/decode of an 84x84x3 rgb8 Image, then the publish -> take round trip
of a StepResult and of that Image between two processes (an echo child sends every sample back).

Usage (from the workspace root):
    PYTHONPATH=src/growspace_sim python scripts/bench_dds.py [--n 2000] [--domain 150]
Cyclone is confined to loopback (config/cyclonedds.xml) unless CYCLONEDDS_URI is already set.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import random
import statistics
import subprocess
import sys
import time

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
IMAGE = 'sensor_msgs/msg/Image'
# The echo child sends every sample back unchanged; an empty-frame ping with sec == -1 stops it.
ECHO = """
import sys
from growspace_sim.ros import dds, qos
keep_all = qos.QosProfile(history='keep_all')
with dds.DdsContext('bench_echo', '/bench') as ctx:
    sub = ctx.create_subscription(sys.argv[1], 'ping/' + sys.argv[2], keep_all)
    pub = ctx.create_publisher(sys.argv[1], 'pong/' + sys.argv[2], keep_all)
    print('READY', flush=True)
    while True:
        sub.wait(1.0)
        for data, _ in sub.take():
            if data[4:8] == b'\\xff\\xff\\xff\\xff':
                sys.exit(0)
            pub.publish_raw(data)
"""


def codec_us(n: int) -> tuple[float, float, bytes]:
    from growspace_sim.ros import types
    img = types.new(IMAGE, height=84, width=84, encoding='rgb8', step=252,
                    data=np.random.default_rng(0).integers(0, 256, 84 * 84 * 3, dtype=np.uint8))
    t0 = time.perf_counter()
    for _ in range(n):
        data = types.serialize(img, IMAGE)
    enc = (time.perf_counter() - t0) / n * 1e6
    t0 = time.perf_counter()
    for _ in range(n):
        types.deserialize(data, IMAGE)
    return enc, (time.perf_counter() - t0) / n * 1e6, data


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--n', type=int, default=2000, help='round trips per message type')
    parser.add_argument('--domain', type=int, default=random.randint(100, 200))
    args = parser.parse_args()
    os.environ.setdefault('CYCLONEDDS_URI', (ROOT / 'config' / 'cyclonedds.xml').as_uri())
    os.environ['ROS_DOMAIN_ID'] = str(args.domain)
    os.environ['PYTHONPATH'] = os.pathsep.join(
        filter(None, [str(ROOT / 'src' / 'growspace_sim'), os.environ.get('PYTHONPATH')]))
    sys.path.insert(0, str(ROOT / 'src' / 'growspace_sim'))
    from growspace_sim.ros import dds, qos, types

    enc, dec, image_cdr = codec_us(args.n)
    step_cdr = types.serialize(types.new(types.STEP_RESULT, reward=0.5, info='ok'),
                               types.STEP_RESULT)
    report = {'image_cdr_bytes': len(image_cdr), 'image_serialize_us': round(enc, 1),
              'image_deserialize_us': round(dec, 1)}
    keep_all = qos.QosProfile(history='keep_all')
    with dds.DdsContext('bench', '/bench') as ctx:
        for typename, cdr in ((types.STEP_RESULT, step_cdr), (IMAGE, image_cdr)):
            short = typename.rsplit('/', 1)[1]
            child = subprocess.Popen([sys.executable, '-c', ECHO, typename, short],
                                     stdout=subprocess.PIPE, text=True)
            try:
                assert child.stdout.readline().strip() == 'READY', 'echo child failed'
                ping = ctx.create_publisher(typename, 'ping/' + short, keep_all)
                pong = ctx.create_subscription(typename, 'pong/' + short, keep_all)
                assert ping.wait_for_subscribers(1, 10) and pong.wait_for_publishers(1, 10)
                rtts = []
                t_all = time.perf_counter()
                for _ in range(args.n):
                    t0 = time.perf_counter()
                    ping.publish_raw(cdr)
                    while not pong.take(1):
                        pong.wait(1.0)
                    rtts.append((time.perf_counter() - t0) * 1e6)
                total = time.perf_counter() - t_all
                ping.publish_raw(cdr[:4] + b'\xff\xff\xff\xff' + cdr[8:])  # stamp.sec = -1
                child.wait(timeout=5)
            finally:
                if child.poll() is None:
                    child.kill()
                    child.wait()
            rtts.sort()
            report[short] = {
                'rtt_us_p50': round(statistics.median(rtts), 1),
                'rtt_us_p99': round(rtts[int(len(rtts) * 0.99)], 1),
                'round_trips_per_s': round(args.n / total)}
    print(json.dumps(report, indent=2))


if __name__ == '__main__':
    main()
