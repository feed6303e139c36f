"""Faults injected into running chambers, counted: what README "Reliability" reports.

Fixed method; run with the workspace sourced, inside a loopback-only namespace
(``unshare -n`` then ``ip link set lo up``), as ``./run.sh test`` does::

    python scripts/fault_injection.py vector --rounds 5   # Gymnasium AsyncVectorEnv, 2 bridged
    python scripts/fault_injection.py stops --rounds 25   # SIGINT to sim_node beside view_node

``vector``: per round and fault, a fresh ``AsyncVectorEnv`` of two bridged envs (spawned
workers, step timeout 1 s); the fault hits the first env's node or process: ``killed``
(SIGKILL to the node, then a step), ``stalled`` (SIGSTOP to the node, then a step),
``trainer`` (SIGKILL to a child process holding the vector env while one node is stopped),
``worker`` (SIGKILL to the first worker process; Gymnasium's ``close()`` then fails on the
dead worker's pipe, and ``close(terminate=True)`` follows). Counted: the error the parent got
(type, and whether its text is the one the worker raised), seconds to it, seconds ``close()``
took, seconds until no node or worker of the round was left (limit 15 s).

``stops``: ``view_node`` with a Foxglove server and a WebSocket client subscribed to its view
image, beside ``sim_node`` in realtime at ``--rate-hz`` with that view drawing every step;
per round a fresh ``sim_node`` runs 1.5 s, then gets SIGINT. Counted: seconds to exit, exit
status, rounds whose output has "context is invalid" or a traceback, rounds still running
after 15 s (then SIGKILLed). ``--src DIR`` runs ``sim_node`` from another checkout's
``src/`` (e.g. ``git archive COMMIT src | tar -x -C DIR``) for a before/after comparison.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
from pathlib import Path
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time

BRIDGED = 'growspace_gym_bridge:GrowSpaceROS/Control-Easy-v0'
GONE_LIMIT_S = 15.0


def running(pid: int) -> bool:
    try:
        return Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0] not in 'ZX'
    except FileNotFoundError:
        return False


def gone_after(pids: list[int], since: float) -> float:
    """Seconds from ``since`` until none of ``pids`` runs (inf past the limit)."""
    while any(running(p) for p in pids):
        if time.monotonic() - since > GONE_LIMIT_S:
            for pid in pids:  # ours: leave nothing behind
                if running(pid):
                    os.kill(pid, signal.SIGCONT)
                    os.kill(pid, signal.SIGKILL)
            return float('inf')
        time.sleep(0.05)
    return time.monotonic() - since


TRAINER = f"""
import functools, json, os, signal, time
import gymnasium as gym
if __name__ == '__main__':
    make = functools.partial(gym.make, {BRIDGED!r})
    vec = gym.vector.AsyncVectorEnv([make, make], context='spawn')
    vec.reset(seed=[1, 2])
    pids = list(vec.get_attr('node_pid')) + [p.pid for p in vec.processes]
    os.kill(pids[0], signal.SIGSTOP)
    print(json.dumps(pids), flush=True)
    time.sleep(600)
"""


def vector_round(fault: str) -> dict:
    import gymnasium as gym
    import numpy as np

    if fault == 'trainer':
        child = subprocess.Popen([sys.executable, '-c', TRAINER], stdout=subprocess.PIPE,
                                 text=True)
        pids = json.loads(child.stdout.readline())
        start = time.monotonic()
        child.kill()
        child.wait()
        return {'gone_s': gone_after(pids, start)}
    make = functools.partial(gym.make, BRIDGED, timeout_s=1.0)
    vec = gym.vector.AsyncVectorEnv([make, make], context='spawn')
    nodes = list(vec.get_attr('node_pid'))
    workers = [p.pid for p in vec.processes]
    vec.reset(seed=[1, 2])
    out: dict = {}
    if fault == 'worker':
        start = time.monotonic()
        os.kill(workers[0], signal.SIGKILL)
        out['node_gone_s'] = gone_after(nodes[:1], start)
    else:
        os.kill(nodes[0], signal.SIGKILL if fault == 'killed' else signal.SIGSTOP)
        start = time.monotonic()
        try:
            vec.step(np.array([0, 1]))
            out['error'] = 'none'
        except Exception as e:  # noqa: BLE001 - what the parent got is the measurement
            out['error'] = type(e).__name__
            out['error_s'] = time.monotonic() - start
            out['same_text'] = 'sim node' in str(e) or 'step_result' in str(e)
    start = time.monotonic()
    try:
        vec.close()
    except Exception as e:  # noqa: BLE001 - Gymnasium's close() with a dead worker
        out['close_error'] = type(e).__name__
        vec.close(terminate=True)  # what is left to a user then
    out['close_s'] = time.monotonic() - start
    out['gone_s'] = max(out.get('gone_s', 0.0), gone_after(nodes + workers, start))
    return out


def vector(rounds: int, faults: list[str]) -> None:
    results: dict[str, list[dict]] = {f: [] for f in faults}
    for _ in range(rounds):
        for fault in results:
            results[fault].append(vector_round(fault))
    print('| fault | rounds | error in the parent | s to the error | close() s | '
          "the fault's node gone s (max) | all gone s (max) |")
    print('|---|---|---|---|---|---|---|')
    for fault, rows in results.items():
        errors = sorted({r.get('error', '-') + ('' if r.get('same_text', True) else ' (text?)')
                         + (f', close: {r["close_error"]}' if 'close_error' in r else '')
                         for r in rows})
        node = max(r.get('node_gone_s', 0.0) for r in rows)
        print(f'| {fault} | {len(rows)} | {", ".join(errors)} | {_median(rows, "error_s")} | '
              f'{_median(rows, "close_s")} | {f"{node:.2f}" if node else "-"} | '
              f'{max(r["gone_s"] for r in rows):.2f} |')


def _median(rows: list[dict], key: str) -> str:
    return f'{statistics.median(r[key] for r in rows):.2f}' if all(key in r for r in rows) \
        else '-'


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def _foxglove_client(port: int, stop: threading.Event) -> None:
    """Subscribe to every channel of the Foxglove server and read until ``stop``."""
    from websockets.sync.client import connect

    deadline = time.monotonic() + 30
    while not stop.is_set() and time.monotonic() < deadline:
        try:
            ws = connect(f'ws://127.0.0.1:{port}', subprotocols=['foxglove.sdk.v1'],
                         open_timeout=5)
            break
        except OSError:
            time.sleep(0.2)
    else:
        return
    with ws:
        subscribed: set[int] = set()
        while not stop.is_set():
            try:
                raw = ws.recv(timeout=0.2)
            except TimeoutError:
                continue
            except Exception:  # noqa: BLE001 - server gone
                return
            if isinstance(raw, str):
                msg = json.loads(raw)
                if msg['op'] == 'advertise':
                    new = [c['id'] for c in msg['channels'] if c['id'] not in subscribed]
                    subscribed.update(new)
                    ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [
                        {'id': 1000 + c, 'channelId': c} for c in new]}))


def stops(rounds: int, rate_hz: float, src: str | None) -> None:
    env = dict(os.environ, ROS_DOMAIN_ID=os.environ.get('ROS_DOMAIN_ID', '77'))
    node_cmd = ['sim_node']
    if src:  # another checkout: its package sources first on the path
        env['PYTHONPATH'] = os.pathsep.join([str(Path(src) / 'src' / 'growspace_sim'),
                                             env.get('PYTHONPATH', '')])
        node_cmd = [sys.executable, '-c', 'import sys; from growspace_sim.node.main import '
                    'main; sys.exit(main())']
    port = _free_port()
    view = subprocess.Popen(['view_node', '--ros-args', '-r', '__ns:=/stops', '-p',
                             f'foxglove_port:={port}'], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    stop = threading.Event()
    client = threading.Thread(target=_foxglove_client, args=(port, stop), daemon=True)
    client.start()
    times, codes, noisy, hung, odd = [], [], 0, 0, []
    try:
        for _ in range(rounds):
            with tempfile.TemporaryFile('w+') as log:
                node = subprocess.Popen([*node_cmd, '--ros-args', '-r', '__ns:=/stops', '-p',
                                         'mode:=realtime', '-p', f'rate_hz:={rate_hz}'],
                                        env=env, stdout=log, stderr=subprocess.STDOUT)
                time.sleep(1.5)
                node.send_signal(signal.SIGINT)
                start = time.monotonic()
                try:
                    node.wait(timeout=GONE_LIMIT_S)
                    times.append(time.monotonic() - start)
                except subprocess.TimeoutExpired:
                    hung += 1
                    node.kill()
                    node.wait()
                codes.append(node.returncode)
                log.seek(0)
                text = log.read()
                if 'context is invalid' in text or 'Traceback' in text or node.returncode:
                    noisy += 'context is invalid' in text or 'Traceback' in text
                    odd.append(f'exit {node.returncode}:\n{text[-3000:]}')
    finally:
        stop.set()
        view.send_signal(signal.SIGINT)
        view.wait(timeout=30)
    print(f'{rounds} stops of sim_node (realtime {rate_hz:g} Hz, view_node + Foxglove client '
          f'beside it{", sources " + src if src else ""}): exit in '
          f'{statistics.median(times):.2f} s median, {max(times):.2f} s max; exit codes '
          f'{sorted(set(codes))}; "context is invalid" or a traceback in {noisy}; still '
          f'running after {GONE_LIMIT_S:g} s: {hung}')
    if odd and os.environ.get('GROWSPACE_SHOW_ODD'):
        print('\n---\n'.join(odd))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n', 1)[0])
    parser.add_argument('what', choices=('vector', 'stops'))
    parser.add_argument('--rounds', type=int, default=5)
    parser.add_argument('--faults', default='killed,stalled,trainer,worker',
                        help='vector: which faults, comma-separated')
    parser.add_argument('--rate-hz', type=float, default=100.0)
    parser.add_argument('--src', help='a checkout whose src/ sim_node runs from (stops)')
    args = parser.parse_args()
    if args.what == 'vector':
        vector(args.rounds, args.faults.split(','))
    else:
        stops(args.rounds, args.rate_hz, args.src)
    return 0


if __name__ == '__main__':
    sys.exit(main())
