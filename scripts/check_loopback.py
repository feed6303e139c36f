"""Does a chamber reach beyond loopback? A fake LAN beside loopback, its packets counted.

Fixed method (root only: it makes network namespaces). In a new network namespace A holding
loopback and one end of a veth pair (the "LAN", 10.231.0.1/24, IPv6 off so the kernel sends
nothing on its own), whose other end sits in a second new namespace B (10.231.0.2/24), for each
configuration and repeat: start ``sim_node`` (lockstep), attach a bridge env to it, play a
reset and 20 steps, stop both. Counted: packets sent on A's LAN end while that ran (the
kernel's own count, ``/proc/net/dev``), the node's UDP sockets
by bound address, how many of its ports a datagram sent from B to A's LAN address reaches (a
socket on 0.0.0.0 takes it; the others count in A's UDP NoPorts), and the
time from starting the node to the env's first reset answered (discovery included). Nothing
is sent anywhere but inside the two namespaces this script creates.

    sudo .venv/bin/python scripts/check_loopback.py --repeats 5   # with the workspace sourced
"""

from __future__ import annotations

import argparse
import collections
import os
from pathlib import Path
import re
import signal
import statistics
import subprocess
import sys
import time

ROOT = Path(__file__).resolve().parents[1]
PROFILE = ROOT / 'config' / 'fastdds_loopback.xml'
INSIDE = 'GROWSPACE_LOOPBACK_CHECK_INSIDE'
LAN = ('lan0', '10.231.0.1/24', 'lan1', '10.231.0.2/24')
CONFIGS = {  # name -> (ROS_AUTOMATIC_DISCOVERY_RANGE, Fast DDS profile); '' unsets the range
    'LOCALHOST + loopback profile (run.sh until now)': ('LOCALHOST', str(PROFILE)),
    'LOCALHOST alone': ('LOCALHOST', None),
    'ROS defaults (control)': ('', None),
}
CLIENT = """
import sys, time
from growspace_gym_bridge.envs import GrowSpaceBridgeEnv
start = float(sys.argv[2])
env = GrowSpaceBridgeEnv(namespace=sys.argv[1], connect_timeout_s=60.0)
env.reset(seed=1)
print(f'{time.monotonic() - start:.3f}', flush=True)
for k in range(20):
    env.step(k % 5)
env.close()
"""


def run(*cmd: str) -> str:
    return subprocess.run(cmd, check=True, capture_output=True, text=True).stdout


def make_lan() -> subprocess.Popen:
    """Namespace B (a sleeping process) and the veth pair between this namespace and it."""
    peer = subprocess.Popen(['unshare', '-n', 'sleep', '3600'])
    time.sleep(0.2)
    a, a_ip, b, b_ip = LAN
    run('ip', 'link', 'set', 'lo', 'up')
    run('ip', 'link', 'add', a, 'type', 'veth', 'peer', 'name', b, 'netns', str(peer.pid))
    run('sysctl', '-qw', f'net.ipv6.conf.{a}.disable_ipv6=1')
    run('ip', 'addr', 'add', a_ip, 'dev', a)
    run('ip', 'link', 'set', a, 'up')
    for cmd in (('sysctl', '-qw', f'net.ipv6.conf.{b}.disable_ipv6=1'),
                ('ip', 'addr', 'add', b_ip, 'dev', b), ('ip', 'link', 'set', b, 'up')):
        run('nsenter', '-t', str(peer.pid), '-n', *cmd)
    time.sleep(1.0)  # the link settles
    return peer


def sent_on_lan() -> int:
    """Packets sent on A's LAN end (/proc/net/dev is this namespace's view; /sys is not)."""
    for line in Path('/proc/self/net/dev').read_text().splitlines():
        name, _, counters = line.partition(':')
        if name.strip() == LAN[0]:
            return int(counters.split()[9])  # transmit: bytes, packets, ...
    raise RuntimeError(f'{LAN[0]} is missing')


def udp_sockets(pid: int) -> list[tuple[str, int]]:
    """The (address, port) of every UDP socket of a process, as bound."""
    found = []
    for line in run('ss', '-uapnH').splitlines():
        if f'pid={pid},' in line:
            address, _, port = line.split()[3].rpartition(':')
            found.append((address, int(port)))
    return found


def udp_counter(name: str) -> int:
    """A counter of this namespace's UDP statistics (/proc/net/snmp), e.g. NoPorts."""
    header, values = [line.split() for line in Path('/proc/self/net/snmp').read_text()
                      .splitlines() if line.startswith('Udp:')]
    return int(values[header.index(name)])


def probe_from_lan(peer: int, ports: list[int]) -> int:
    """Send one datagram from namespace B to each port at A's LAN address; how many found a
    socket (the others count in A's NoPorts). Inside our own two namespaces only."""
    refused = udp_counter('NoPorts')
    code = ('import socket, sys\ns = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)\n'
            'for p in sys.argv[2:]:\n    s.sendto(b"not RTPS", (sys.argv[1], int(p)))\n')
    run('nsenter', '-t', str(peer), '-n', sys.executable, '-c', code,
        LAN[1].split('/')[0], *map(str, ports))
    time.sleep(0.2)
    return len(ports) - (udp_counter('NoPorts') - refused)


def one_run(config: str, domain: int, peer: int) -> dict:
    discovery_range, profile = CONFIGS[config]
    env = {k: v for k, v in os.environ.items()
           if k not in ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'FASTRTPS_DEFAULT_PROFILES_FILE')}
    env['ROS_DOMAIN_ID'] = str(domain)
    if discovery_range:
        env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = discovery_range
    if profile:
        env['FASTRTPS_DEFAULT_PROFILES_FILE'] = profile
    namespace = f'/lan_probe_{domain}'
    before = sent_on_lan()
    start = time.monotonic()
    node = subprocess.Popen(['sim_node', '--ros-args', '-r', f'__ns:={namespace}'], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        client = subprocess.Popen([sys.executable, '-c', CLIENT, namespace, str(start)],
                                  env=env, stdout=subprocess.PIPE, text=True)
        first = float('nan')
        for line in client.stdout:  # Fast DDS may print first
            if re.fullmatch(r'[0-9.]+', line.strip()):
                first = float(line)
                break
        sockets = udp_sockets(node.pid)
        reachable = probe_from_lan(peer, sorted({port for _, port in sockets}))
        client.wait(timeout=120)
    finally:
        node.send_signal(signal.SIGINT)
        node.wait(timeout=30)
    time.sleep(0.5)  # anything sent at shutdown
    kinds = collections.Counter('loopback' if a == '127.0.0.1' else 'any address'
                                if a in ('0.0.0.0', '*') else a for a, _ in sockets)
    return {'sent': sent_on_lan() - before, 'sockets': kinds, 'reachable': reachable,
            'ports': len({port for _, port in sockets}), 'first_reset_s': first}


def inside(repeats: int) -> int:
    peer = make_lan()
    idle = sent_on_lan()
    time.sleep(2.0)
    print(f'LAN idle for 2 s: {sent_on_lan() - idle} packets sent by the kernel itself\n')
    results: dict[str, list[dict]] = {name: [] for name in CONFIGS}
    try:
        for i in range(repeats):  # configurations interleaved, so load hits all alike
            for j, name in enumerate(CONFIGS):
                results[name].append(one_run(name, 60 + 3 * i + j, peer.pid))
    finally:
        peer.kill()
    print('| configuration | packets sent on the LAN (per run) | node UDP sockets | node ports '
          'a LAN datagram reaches | start to first reset s (median, range) |')
    print('|---|---|---|---|---|')
    for name, runs in results.items():
        times = [r['first_reset_s'] for r in runs]
        sockets = ', '.join(f'{n} on {kind}' for kind, n in sorted(runs[0]['sockets'].items()))
        reached = ', '.join(f'{r["reachable"]} of {r["ports"]}' for r in runs)
        print(f'| {name} | {", ".join(str(r["sent"]) for r in runs)} | {sockets} | {reached} | '
              f'{statistics.median(times):.2f} ({min(times):.2f}-{max(times):.2f}) |')
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n', 1)[0])
    parser.add_argument('--repeats', type=int, default=3)
    args = parser.parse_args()
    if os.environ.get(INSIDE):
        return inside(args.repeats)
    if os.geteuid() != 0:
        print('check_loopback: needs root (it creates network namespaces).', file=sys.stderr)
        return 2
    if not re.search(r'growspace_sim', os.environ.get('AMENT_PREFIX_PATH', '') +
                     os.environ.get('PATH', '')):
        print('check_loopback: source the workspace first (install/setup.bash).',
              file=sys.stderr)
        return 2
    return subprocess.run(['unshare', '-n', sys.executable, __file__, '--repeats',
                           str(args.repeats)], env={**os.environ, INSIDE: '1'}).returncode


if __name__ == '__main__':
    sys.exit(main())
