"""Republish a recording on its topics over rclpy (``ros2 bag play`` without rosbag2)."""

from __future__ import annotations

from collections.abc import Callable, Iterable
import os
import time

from growspace_sim.recording.scan import Damage
from growspace_sim.replay.bag import Bag, ReplayError
from growspace_sim.ros import types

REQUESTS = (types.LIGHT_COMMAND, types.RESET_REQUEST)  # what --step-period paces


def play(path: str | os.PathLike, *, rate: float | None = 1.0, topics: Iterable[str] | None = None,
         domain_id: int | None = None, wait_for_subscribers_s: float = 0.0,
         log: Callable[[str], None] | None = None, step_period_s: float | None = None) -> int:
    """Republish a recording on its topics over rclpy (``ros2 bag play`` without rosbag2).

    On a machine with ROS 2, ``ros2 bag play BAG`` does the same through rmw.

    Args:
        path: The recording.
        rate: Speed factor on the recorded log times (1.0 = original timing); None = as fast
            as possible.
        topics: Only these recorded topic names; None = all.
        domain_id: ROS domain; None = ROS_DOMAIN_ID.
        wait_for_subscribers_s: Before playing, wait up to this long for every publisher to
            match a subscriber.
        log: Where progress lines go (None = quiet).
        step_period_s: Pace by steps instead of recorded times: each request (a LightCommand
            or a ResetRequest) after the first is published this many seconds after the
            previous one, what else came between them right after it. A real plant grows in
            hours: 3600 gives a hardware replay one recorded step per hour.

    Returns:
        The number of messages published.

    Raises:
        ReplayError: The file cannot be read or the rate is not positive.
    """
    if rate is not None and not rate > 0:
        raise ReplayError(f'rate must be > 0, got {rate}.')
    if step_period_s is not None and not step_period_s > 0:
        raise ReplayError(f'step period must be > 0 s, got {step_period_s}.')
    from growspace_sim.node.rclpy_transport import RclpyTransport

    count = 0

    def skipped(part: Damage) -> None:
        if log is not None:
            log(f'warning: skipped unreadable {part}')

    with Bag(path, on_damage=skipped) as bag:
        transport = RclpyTransport(f'growspace_replay_{os.getpid()}', domain_id=domain_id)
        try:
            wanted = set(bag.topics) if topics is None else set(topics) & set(bag.topics)
            publishers = {t: transport.raw_publisher(bag.topics[t].typename, t,
                                                     bag.topics[t].qos)
                          for t in sorted(wanted)}
            deadline = time.monotonic() + wait_for_subscribers_s
            while time.monotonic() < deadline and not all(map(transport.matched, publishers)):
                transport.spin_once(0.02)
            start_wall = time.monotonic()
            first_log: int | None = None
            next_request = time.monotonic()
            for msg in bag.messages(wanted):
                if step_period_s is not None:
                    if msg.typename in REQUESTS:
                        time.sleep(max(0.0, next_request - time.monotonic()))
                        next_request = time.monotonic() + step_period_s
                elif rate is not None:
                    first_log = msg.log_time if first_log is None else first_log
                    delay = (start_wall + (msg.log_time - first_log) / 1e9 / rate
                             - time.monotonic())
                    if delay > 0:
                        time.sleep(delay)
                publishers[msg.topic](msg.data)
                count += 1
                if log is not None and count % 500 == 0:
                    log(f'published {count} messages')
            transport.flush(2.0)
        finally:
            transport.close()
    return count
