"""The network rule: ROS processes we start talk only on this host unless the user chose otherwise.

Two settings together, each applied only where the user set nothing:
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (rcl, Jazzy) and a Fast DDS profile
(``FASTRTPS_DEFAULT_PROFILES_FILE``) whose only transports are UDP on 127.0.0.1 and shared memory.
Either alone was measured to send no packet to a LAN interface beside loopback; the profile
also keeps the receiving ports on 127.0.0.1 (with ``LOCALHOST`` alone they listen on every
interface). README "Networks" has the figures (``scripts/check_loopback.py``).
Both are read when the first ROS context of a process starts, so call ``confine`` before
``rclpy.init`` and pass ``confined_env`` to child processes.
"""

from __future__ import annotations

from collections.abc import MutableMapping
import os
from pathlib import Path

from growspace_sim.ros.share import share_file

RANGE_VAR = 'ROS_AUTOMATIC_DISCOVERY_RANGE'
PROFILE_VAR = 'FASTRTPS_DEFAULT_PROFILES_FILE'
PROFILE_NAME = 'fastdds_loopback.xml'


def profile_path() -> Path:
    """The shipped Fast DDS loopback profile."""
    return share_file('growspace_sim', 'config', PROFILE_NAME)


def confine(env: MutableMapping[str, str] | None = None) -> MutableMapping[str, str]:
    """Set the loopback defaults in ``env`` (``os.environ`` by default) where they are unset.

    Returns:
        ``env``, for chaining into a child process's environment.
    """
    env = os.environ if env is None else env
    if not env.get(RANGE_VAR):
        env[RANGE_VAR] = 'LOCALHOST'
    if not env.get(PROFILE_VAR) and not env.get('FASTDDS_DEFAULT_PROFILES_FILE'):
        env[PROFILE_VAR] = str(profile_path())
    return env


def confined_env() -> dict[str, str]:
    """A copy of this process's environment with the loopback defaults, for a child process."""
    env = dict(os.environ)
    confine(env)
    return env
