"""Republish a recording over rclpy: message by message (``play``, ``ros2 bag play`` without
rosbag2), or step by step onto a lockstep node that may be a machine (``play_steps``)."""

from __future__ import annotations

from collections.abc import Callable, Iterable
import dataclasses
import datetime
import os
import secrets
import time
from typing import Any

from growspace_sim.recording.scan import Damage
from growspace_sim.replay.bag import Bag, ReplayError
from growspace_sim.replay.episodes import Episode, read_episodes
from growspace_sim.ros import qos as ros_qos, types
from growspace_sim.ros.interface import COMMAND_QOS, OBSERVATION_QOS

WAITING_NOTE_S = 60.0  # while a step takes longer than this, say so this often [s]
NODE_GONE_S = 5.0  # no publisher of step_result for this long: the node left [s]
MATCH_SETTLE_S = 0.5  # after the node's endpoints match ours, before the first request [s]
# How long ``play`` waits for its readers by default: discovering a running view_node took
# more than 1 s on this loaded 2-core VM, and whatever is published before is lost to it [s].
PLAY_WAIT_S = 10.0


def play(path: str | os.PathLike, *, rate: float | None = 1.0, topics: Iterable[str] | None = None,
         domain_id: int | None = None, wait_for_subscribers_s: float = PLAY_WAIT_S,
         log: Callable[[str], None] | None = None) -> int:
    """Republish a recording on its topics over rclpy (``ros2 bag play`` without rosbag2).

    On a machine with ROS 2, ``ros2 bag play BAG`` does the same through rmw. To drive a
    lockstep node (the LED gantry above all) use ``play_steps``: it waits for each step.

    Args:
        path: The recording.
        rate: Speed factor on the recorded log times (1.0 = original timing); None = as fast
            as possible.
        topics: Only these recorded topic names; None = all.
        domain_id: ROS domain; None = ROS_DOMAIN_ID.
        wait_for_subscribers_s: Before playing, wait up to this long until a reader matched
            and every reader the ROS graph shows on the played topics matched (topics nobody
            reads are not waited for); then play, matched or not. 0 = play at once.
        log: Where progress lines go (None = quiet).

    Returns:
        The number of messages published (an empty one, which DDS cannot send, is skipped
        with a warning).

    Raises:
        ReplayError: The file cannot be read or the rate is not positive.
    """
    if rate is not None and not rate > 0:
        raise ReplayError(f'rate must be > 0, got {rate}.')
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
            _wait_for_readers(transport, sorted(publishers), wait_for_subscribers_s, log)
            start_wall = time.monotonic()
            first_log: int | None = None
            for msg in bag.messages(wanted):
                if rate is not None:
                    first_log = msg.log_time if first_log is None else first_log
                    delay = (start_wall + (msg.log_time - first_log) / 1e9 / rate
                             - time.monotonic())
                    if delay > 0:
                        time.sleep(delay)
                if not msg.data:  # no CDR header; DDS would hold back the rest of the topic
                    if log is not None:
                        log(f'warning: skipped an empty message on {msg.topic} at log time '
                            f'{msg.log_time} ns')
                    continue
                publishers[msg.topic](msg.data)
                count += 1
                if log is not None and count % 500 == 0:
                    log(f'published {count} messages')
            transport.flush(2.0)
        finally:
            transport.close()
    return count


def _wait_for_readers(transport: Any, topics: list[str], timeout_s: float,
                      log: Callable[[str], None] | None) -> None:
    """Until a reader matched and every reader the graph shows on ``topics`` matched, then
    ``MATCH_SETTLE_S`` more (each side sees a match on its own: a reader that does not know our
    writer yet drops what it sends); at most ``timeout_s``, then on regardless."""
    deadline = time.monotonic() + timeout_s
    while timeout_s > 0:
        counts = [transport.readers(t) for t in topics]
        if any(matched for _, matched in counts) and all(
                matched >= on_graph for on_graph, matched in counts):
            settle = time.monotonic() + MATCH_SETTLE_S
            while time.monotonic() < settle:
                transport.spin_once(0.05)
            return
        if time.monotonic() > deadline:
            unmatched = [t for t, (on_graph, matched) in zip(topics, counts)
                         if matched < on_graph]
            if log is not None:
                log(f'warning: within {timeout_s:g} s (--wait) ' + (
                    f'readers of {", ".join(unmatched)} did not match' if unmatched
                    else 'no reader matched') + '; playing anyway')
            return
        transport.spin_once(0.05)


@dataclasses.dataclass
class StepReplay:
    """What ``play_steps`` did."""

    requests: int = 0  # resets and commands published
    answered: int = 0  # of them answered without an error
    failures: list[str] = dataclasses.field(default_factory=list)  # 'episode E, step_id S: why'
    stopped: str = ''  # why the replay stopped before the end ('' = it played everything)


@dataclasses.dataclass
class _Request:
    what: str  # for the log: 'reset', 'step 3/50 (step_id 3)', ...
    topic: str  # 'reset' or 'command'
    msg: Any
    reset_id: int
    step_id: int


def play_steps(path: str | os.PathLike, *, episode: int | None = None, start_step: int = 1,
               stop_step: int | None = None, step_period_s: float = 0.0,
               keep_going: bool = False, step_timeout_s: float = 600.0,
               namespace: str | None = None, domain_id: int | None = None,
               wait_for_subscribers_s: float = 10.0,
               log: Callable[[str], None] | None = None) -> StepReplay:
    """Replay a lockstep recording onto a running node, one step at a time, waiting for it.

    For each episode: its reset first (the recorded seed, challenge and setting, so the light
    starts where it started), then each recorded command, each only after the node answered the
    previous request with its ``step_result`` and at least ``step_period_s`` after it. Onto the
    LED gantry a step may take minutes; with 3600 a real plant gets one step an hour.

    Args:
        path: The recording (lockstep: every command has a step_id).
        episode: Only this episode (0-based, -1 = last); None = all, in order.
        start_step: The first step_id to play. Steps before it are skipped: after the reset one
            absolute command (step_id ``start_step - 1``) places the light where the recording
            had it after that step, so the actions that follow move it as they did.
        stop_step: The last step_id to play; None = to the end of the episode.
        step_period_s: The least time between two requests [s] (a minimum: a slow machine
            takes longer).
        keep_going: Go on after a step that fails on the node (default: stop, with its reason).
        step_timeout_s: Give up when a request has no answer for this long [s].
        namespace: The chamber namespace in the recording (None = its only one); the node must
            listen there.
        domain_id: ROS domain; None = ROS_DOMAIN_ID.
        wait_for_subscribers_s: How long to wait for the node to appear [s].
        log: Where progress lines go: each step's outcome and when the next one is due.

    Returns:
        What was sent and answered, the failures, and why it stopped early, if it did.

    Raises:
        ReplayError: The file cannot be read, is not a lockstep recording, has no such episode
            or steps, or no node answers on its topics.
    """
    if not step_period_s >= 0:
        raise ReplayError(f'step period must be >= 0 s, got {step_period_s}.')
    if start_step < 1 or (stop_step is not None and stop_step < start_step):
        raise ReplayError(f'steps {start_step}..{stop_step}: need 1 <= start <= stop.')
    say = log or (lambda line: None)
    with Bag(path) as bag:
        topics = bag.chamber_topics(namespace)
        episodes = read_episodes(bag, namespace)
    prefix = topics['step_result'][:-len('step_result')]
    if episode is not None:
        if not -len(episodes) <= episode < len(episodes):
            raise ReplayError(f'--episode {episode}: the recording has {len(episodes)} '
                              f'episode(s)')
        episodes = [episodes[episode]]
    plans = [_plan(ep, start_step, stop_step, say) for ep in episodes]
    from growspace_sim.node.rclpy_transport import RclpyTransport

    out = StepReplay()
    transport = RclpyTransport(f'growspace_replay_{os.getpid()}', domain_id=domain_id)
    try:
        publish = {'reset': transport.publisher(types.RESET_REQUEST, f'{prefix}reset',
                                                COMMAND_QOS),
                   'command': transport.publisher(types.LIGHT_COMMAND, f'{prefix}light/command',
                                                  COMMAND_QOS)}
        results: list[Any] = []
        transport.subscribe(types.STEP_RESULT, f'{prefix}step_result', OBSERVATION_QOS,
                            lambda msg, cdr: results.append(msg))
        # Each side sees a match on its own: the node's step_result writer may not know our
        # reader yet when ours knows it, and would drop its answer to our first request. Its
        # latched chamber/config arriving shows its writers have matched ours (as the bridge
        # connects), and a short settle covers the rest.
        configs: list[Any] = []
        transport.subscribe(types.STRING, f'{prefix}chamber/config', ros_qos.LATCHED,
                            lambda msg, cdr: configs.append(msg))
        names = (f'{prefix}reset', f'{prefix}light/command', f'{prefix}step_result')
        deadline = time.monotonic() + wait_for_subscribers_s
        while not (all(map(transport.matched, names)) and configs):
            if time.monotonic() > deadline:
                raise ReplayError(f'no node answers on {prefix}step_result within '
                                  f'{wait_for_subscribers_s:g} s (is it running, in lockstep '
                                  f'mode, in namespace {prefix.rstrip("/") or "/"}?)')
            transport.spin_once(0.05)
        settle = time.monotonic() + MATCH_SETTLE_S
        while time.monotonic() < settle:
            transport.spin_once(0.05)
        next_at = time.monotonic()
        for ep, plan in zip(episodes, plans):
            count = sum(1 for r in plan if r.topic == 'command')
            say(f'episode {ep.index} (recorded reset_id {ep.reset_id}, seed {ep.seed}): reset '
                f'as reset_id {plan[0].reset_id}, then {count} request(s)')
            for request in plan:
                _wait_until(transport, next_at, request.what, say)
                results.clear()
                publish[request.topic](request.msg)
                out.requests += 1
                sent = time.monotonic()
                next_at = sent + step_period_s
                answer = _answer(transport, results, request, sent, step_timeout_s, say,
                                 names[-1])
                where = f'episode {ep.index}, {request.what}'
                if not isinstance(answer, Answer):
                    out.stopped = f'{where}: {answer}'
                    say(out.stopped)
                    return out
                answer = answer.result
                took = time.monotonic() - sent
                if not answer.info:
                    out.answered += 1
                    say(f'{where}: done in {took:.2f} s')
                    continue
                out.failures.append(f'{where}: {answer.info}')
                say(f'{where}: FAILED after {took:.2f} s: {answer.info}')
                if not keep_going:
                    out.stopped = f'{where} failed on the node: {answer.info} (--keep-going ' \
                                  f'plays on)'
                    return out
                if request.topic == 'reset':
                    break  # its steps would land in another episode
        transport.flush(2.0)
    finally:
        transport.close()
    return out


def _plan(ep: Episode, start: int, stop: int | None, say: Callable[[str], None]) -> list[
        _Request]:
    """The reset, maybe a placement, and the commands of one episode's chosen steps."""
    stepped = ep.stepped
    if any(int(r.result.step_id) == 0 for r in stepped):
        raise ReplayError(f'episode {ep.index} was recorded in realtime mode (step_id 0): a '
                          f'step by step replay needs a lockstep recording; use --rate.')
    if ep.config is None:
        raise ReplayError(f'episode {ep.index}: its challenge and setting are not recorded')
    if ep.seed is None:
        say(f'warning: episode {ep.index} continued the random stream of the one before it '
            f'(no seed of its own): its reset may place the light elsewhere than recorded')
    # A fresh reset_id: the answers of this episode cannot be taken for a node's own (its
    # start-up episode is reset_id 0, as the recording's first episode often is).
    reset_id = secrets.randbits(63) | 1
    reset = types.new(types.RESET_REQUEST, reset_id=reset_id, has_seed=ep.seed is not None,
                      seed=ep.seed or 0, challenge=ep.config.challenge,
                      setting=ep.config.setting)
    plan = [_Request('reset', 'reset', reset, reset_id, 0)]
    chosen = [r for r in stepped if start <= r.result.step_id <= (stop or r.result.step_id)]
    if not chosen:
        raise ReplayError(f'episode {ep.index} has no step_id in {start}..{stop or "end"} '
                          f'(it has {len(stepped)} steps)')
    before = [r for r in stepped if r.result.step_id < chosen[0].result.step_id]
    if start > 1 and before and 'light/state' in before[-1].outputs:
        light = before[-1].outputs['light/state'].decode()
        place = types.new(types.LIGHT_COMMAND, step_id=before[-1].result.step_id,
                          mode=light.mode, x=light.x, z=light.z, width=light.width,
                          radius=light.radius)
        plan.append(_Request(f'placement (the light after step_id {place.step_id})', 'command',
                             place, reset_id, int(place.step_id)))
    for n, record in enumerate(chosen, 1):
        step_id = int(record.result.step_id)
        command = next((c for c in record.commands if c.step_id == step_id), None)
        if command is None:
            raise ReplayError(f'episode {ep.index}, step_id {step_id}: its light/command is not '
                              f'in the recording')
        plan.append(_Request(f'step {n}/{len(chosen)} (step_id {step_id})', 'command',
                             command, reset_id, step_id))
    return plan


def _wait_until(transport: Any, at: float, what: str, say: Callable[[str], None]) -> None:
    """Spin until ``at`` (monotonic), saying when the next request goes if that is a while."""
    wait = at - time.monotonic()
    if wait > 1.0:
        when = datetime.datetime.now() + datetime.timedelta(seconds=wait)
        say(f'next: {what} at {when:%H:%M:%S} (in {wait:.0f} s)')
    while time.monotonic() < at:
        transport.spin_once(min(0.1, max(0.0, at - time.monotonic())))


@dataclasses.dataclass(frozen=True)
class Answer:
    result: Any  # the step_result of a request


def _answer(transport: Any, results: list[Any], request: _Request, sent: float,
            timeout_s: float, say: Callable[[str], None], result_topic: str) -> Answer | str:
    """The node's step_result for ``request``, or why there is none: no answer after
    ``timeout_s``, or the node gone (no one publishes ``result_topic`` any more for
    ``NODE_GONE_S``: a node that died mid-step will not answer, however long we wait)."""
    note = sent + WAITING_NOTE_S
    seen = sent
    while time.monotonic() - sent < timeout_s:
        for result in results:
            if int(result.step_id) == request.step_id and int(result.reset_id) == \
                    request.reset_id:
                return Answer(result)
        now = time.monotonic()
        if transport.matched(result_topic):
            seen = now
        elif now - seen > NODE_GONE_S:
            return f'the node left ({result_topic} has no publisher for {NODE_GONE_S:g} s)'
        if now > note:
            say(f'{request.what}: still waiting for its step_result '
                f'({now - sent:.0f} s)')
            note += WAITING_NOTE_S
        transport.spin_once(0.05)
    return f'no step_result within {timeout_s:g} s'
