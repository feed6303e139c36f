"""The network rule, measured: a chamber under our loopback settings talks on loopback only.

Issue 24 item 13. Run inside ``./run.sh test``'s private network namespace, where a veth
pair stands for a LAN (both ends stay in that namespace; the counters of the addressed end
count what was handed to it): the node, with the settings everything we start gets
(``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and ``config/fastdds_loopback.xml``), hands the
LAN no packet, and a datagram addressed to the LAN address reaches none of its receiving
ports. Its one socket bound to 0.0.0.0 (and one on the LAN address) belong to the UDP transport
rmw_fastrtps adds for LOCALHOST (no interface whitelist): Fast DDS only sends from them.
Skipped outside a namespace of our own: no interface is ever added to a real network stack.
"""

from __future__ import annotations

import errno
import os
from pathlib import Path
import socket
import subprocess

import pytest

from ros_helpers import Client, NodeProcess

# Most tests here take seconds (processes, ROS graphs, Ray): none in the quick tier.
pytestmark = pytest.mark.slow

LAN, PEER = 'gs_lan0', 'gs_lan1'
LAN_ADDRESS = '10.231.0.1'


def _interfaces() -> list[str]:
    lines = Path('/proc/self/net/dev').read_text().splitlines()[2:]
    return [line.split(':')[0].strip() for line in lines]


def _sent(interface: str) -> int:
    for line in Path('/proc/self/net/dev').read_text().splitlines()[2:]:
        name, _, counters = line.partition(':')
        if name.strip() == interface:
            return int(counters.split()[9])
    raise AssertionError(f'{interface} is missing')


@pytest.fixture
def lan():
    """A 'LAN' interface (one end of a veth pair) in this private namespace; removed after."""
    if _interfaces() != ['lo']:
        pytest.skip('not in a private network namespace holding only loopback (./run.sh test)')
    try:
        subprocess.run(['ip', 'link', 'add', LAN, 'type', 'veth', 'peer', 'name', PEER],
                       check=True, capture_output=True)
    except (OSError, subprocess.CalledProcessError) as e:
        pytest.skip(f'cannot add a veth pair here: {e}')
    try:
        for end in (LAN, PEER):
            ipv6 = Path(f'/proc/sys/net/ipv6/conf/{end}/disable_ipv6')
            if ipv6.exists():
                ipv6.write_text('1')  # no router solicitations of the kernel's own
        subprocess.run(['ip', 'addr', 'add', f'{LAN_ADDRESS}/24', 'dev', LAN], check=True)
        for end in (PEER, LAN):
            subprocess.run(['ip', 'link', 'set', end, 'up'], check=True)
        yield LAN
    finally:
        subprocess.run(['ip', 'link', 'del', LAN], check=False)


def _udp_sockets(pid: int) -> list[tuple[str, int]]:
    out = subprocess.run(['ss', '-uapnH'], capture_output=True, text=True, check=True).stdout
    found = []
    for line in out.splitlines():
        if f'pid={pid},' in line:
            address, _, port = line.split()[3].rpartition(':')
            found.append((address, int(port)))
    return found


def _reaches(port: int) -> bool:
    """Whether a datagram from the LAN address to the LAN address finds a socket on ``port``
    (else the kernel answers port unreachable, which a connected socket reports)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind((LAN_ADDRESS, 0))
        probe.connect((LAN_ADDRESS, port))
        probe.settimeout(0.3)
        probe.send(b'not RTPS')
        try:
            probe.recv(16)
        except ConnectionRefusedError:
            return False
        except TimeoutError:
            return True
        except OSError as e:  # pragma: no cover - anything else is a finding
            raise AssertionError(f'port {port}: {errno.errorcode.get(e.errno, e)}') from e
    return True


def test_a_confined_chamber_sends_nothing_to_the_lan_and_receives_nothing_from_it(lan):
    assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'  # conftest: confine()
    assert os.environ['FASTRTPS_DEFAULT_PROFILES_FILE'].endswith('fastdds_loopback.xml')
    before = _sent(lan)
    node = NodeProcess(namespace='/gs_lan')
    client = Client('/gs_lan')
    try:
        client.connect()
        client.reset(1, has_seed=True, seed=3)
        for step_id in range(1, 11):
            client.step(step_id, step_id % 5)
        sockets = _udp_sockets(node.proc.pid)
        reached = sorted(port for port in {p for _, p in sockets} if _reaches(port))
    finally:
        client.close()
        node.stop()
    assert _sent(lan) - before == 0  # not one packet handed to the LAN
    receiving = {p for a, p in sockets if a == '127.0.0.1'}
    assert receiving and not receiving & set(reached), (sockets, reached)
    # What a LAN datagram can reach: only the send sockets of rmw's LOCALHOST transport, on
    # ports the kernel picked (Fast DDS never reads them).
    low = int(Path('/proc/sys/net/ipv4/ip_local_port_range').read_text().split()[0])
    assert all(port >= low for port in reached), (sockets, reached)
