"""The gantry's side of the camera seam (``growspace_gantry.photo``): each lockstep step's photo.

First the ``Photographer`` and ``outputs`` alone over the in-process transport (a camera service
that answers, refuses, answers badly, is missing, never answers or answers too late), with a
stand-in for the controller's photo light; then ``gantry_node`` on the GRBL emulator, where the
photo light's ``M8``/``M9`` and the order of the step's outputs are read off the port and the
transport.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

from growspace_gantry.photo import outputs, Photographer
from growspace_sim.core.config import SimConfig
from growspace_sim.node.fake import FakeTransport
from growspace_sim.ros import convert, types
from growspace_sim.simulation import Simulation
from test_gantry_node import Rig, RIG as RIG_SETTINGS

STAMP = 1_700_000_000_000_000_123
CFG = SimConfig()  # control: one plant, 84 px


def response(ok: bool = True, reward: float = 0.25, stamp: int = 5, size: int = 84,
             code: str = '', error: str = '') -> Any:
    """A Capture answer as camera_node gives it (stamped ``stamp``)."""
    image = convert.image_msg(np.full((size, size, 3), 7, np.uint8), stamp, 'chamber_camera') \
        if ok else types.new(types.IMAGE, encoding='rgb8')
    return types.new(
        f'{types.CAPTURE}_Response', observation=image,
        plant=types.new(types.PLANT_STATE, header=convert.header(stamp, 'chamber'),
                        node_x=np.array([0.4, 0.4]), node_z=np.array([0.0, 0.1]),
                        parent=np.array([-1, 0], np.int32), plant=np.zeros(2, np.uint8),
                        tips=np.array([1], np.uint32)) if ok else
        types.new(types.PLANT_STATE),
        photo=types.new(types.COMPRESSED_IMAGE, header=convert.header(stamp, 'camera_optical'),
                        format='jpeg', data=np.frombuffer(b'\xff\xd8\xff\xe0fake', np.uint8)),
        measurement=types.new(types.CAMERA_MEASUREMENT, header=convert.header(stamp, 'chamber'),
                              ok=ok, error_code=code, error=error,
                              reward=reward if ok else 0.0,
                              plant_rewards=np.array([reward] if ok else [], np.float64),
                              success=False))


class PhotoLight:
    """Stands in for the controller: the photo light as asked, and as GRBL accepted it."""

    def __init__(self, wired: bool = True) -> None:
        self.has_photo_light = wired
        self.asked: list[bool] = []
        self.accepted = False

    def set_photo_light(self, on: bool) -> None:
        self.asked.append(on)

    def photo_light_on(self) -> bool:
        return self.accepted and bool(self.asked) and self.asked[-1]


class HeldClient:
    """A capture client whose answers the test gives (or never gives)."""

    def __init__(self) -> None:
        self.calls: list[tuple[Any, Any]] = []
        self.cancelled = 0

    def ready(self) -> bool:
        return True

    def call(self, request: Any, done: Any):
        self.calls.append((request, done))

        def cancel() -> None:
            self.cancelled += 1
        return cancel


class Camera:
    """A photographer on a fake transport, with what it answered."""

    def __init__(self, wired: bool = False, served: Any = None, held: bool = False,
                 timeout_s: float = 2.0, settle_s: float = 0.5) -> None:
        self.transport = FakeTransport('growspace_gantry', '/gs')
        self.held = HeldClient() if held else None
        if held:
            self.transport.client = lambda srv, name: self.held
        self.requests: list[Any] = []
        if served is not None:
            self.transport.serve(types.CAPTURE, 'camera/capture',
                                 lambda req: self.requests.append(req) or served)
        self.light = PhotoLight(wired)
        self.answers: list[tuple[Any, Any, str]] = []
        self.photographer = Photographer(self.transport, self.light, 'camera/capture',
                                         timeout_s, settle_s,
                                         lambda *answer: self.answers.append(answer))

    def start(self, now: float = 0.0) -> None:
        request = types.new(f'{types.CAPTURE}_Request', header=convert.header(STAMP, 'chamber'),
                            step_id=3, step=3)
        sim = Simulation(CFG)
        sim.reset(seed=1)
        light = convert.light_msg(sim.chamber.light, 3, STAMP, 'chamber')
        self.photographer.start(1, 3, STAMP, light, request, now)


# ----------------------------------------------------------------------------- Photographer


def test_an_answered_photo_gives_the_step_in_the_simulators_order_with_its_stamp() -> None:
    cam = Camera(served=response(reward=0.25, stamp=5))
    cam.start()
    assert len(cam.requests) == 1 and cam.requests[0].step_id == 3  # through the codec
    [(shot, answer, failure)] = cam.answers
    assert (shot.reset_id, shot.step_id, failure) == (1, 3, '')
    assert not cam.photographer.busy
    messages, outcome, failure = outputs(answer, shot.light, shot.stamp, CFG, failure)
    assert [key for key, _ in messages] == ['image', 'plant', 'light', 'photo', 'measurement']
    assert failure == '' and outcome.reward == 0.25 and list(outcome.plant_rewards) == [0.25]
    for key, msg in messages:  # the gantry owns the step: every output has its stamp
        assert convert.to_ns(msg.header.stamp) == STAMP, key


def test_without_a_photo_light_nothing_is_switched() -> None:
    cam = Camera(served=response())
    cam.start()
    assert True not in cam.light.asked and cam.answers[0][2] == ''


@pytest.mark.parametrize(('answer', 'code', 'why'), [
    (response(ok=False, code='markers', error='2 of 4 markers seen'), 'markers',
     '2 of 4 markers seen'),
    (response(ok=False), 'bad_answer', 'the camera refused the photo without a reason'),
    (response(size=28), 'bad_answer', 'the observation is 28 x 28'),
    (response(reward=float('nan')), 'bad_answer', 'do not fit 1 plant(s)'),
])
def test_a_photo_not_measured_gives_no_image_and_no_reward(answer, code, why) -> None:
    cam = Camera(served=answer)
    cam.start()
    [(shot, answer, failure)] = cam.answers
    messages, outcome, failure = outputs(answer, shot.light, shot.stamp, CFG, failure)
    assert outcome is None
    assert failure.startswith(f'{code}: ') and why in failure
    keys = [key for key, _ in messages]
    assert 'image' not in keys and 'plant' not in keys
    assert keys == ['light', 'photo', 'measurement']  # the photo is kept for the recording
    assert all(convert.to_ns(msg.header.stamp) == STAMP for _, msg in messages)


def test_no_service_fails_the_photo_as_unavailable_at_the_timeout() -> None:
    cam = Camera(timeout_s=2.0)  # nothing serves camera/capture
    cam.start(now=10.0)
    cam.photographer.poll(11.9)
    assert cam.answers == [] and cam.photographer.busy
    cam.photographer.poll(12.1)
    [(shot, answer, failure)] = cam.answers
    assert answer is None and failure.startswith('unavailable: no /gs/camera/capture service '
                                                 'within capture_timeout_s = 2 s')
    messages, outcome, _ = outputs(None, shot.light, shot.stamp, CFG, failure)
    assert [key for key, _ in messages] == ['light'] and outcome is None


def test_a_camera_that_never_answers_times_out_and_a_late_answer_is_ignored() -> None:
    cam = Camera(held=True, timeout_s=2.0)
    cam.start(now=0.0)
    [(request, done)] = cam.held.calls
    cam.photographer.poll(2.1)
    [(_, answer, failure)] = cam.answers
    assert answer is None and failure.startswith('timeout: no answer from /gs/camera/capture')
    assert cam.held.cancelled == 1
    done(response())  # the answer arrives after all
    assert len(cam.answers) == 1 and not cam.photographer.busy


def test_an_abandoned_photo_switches_the_light_off_and_ignores_its_answer() -> None:
    cam = Camera(wired=True, held=True, settle_s=0.0)
    cam.light.accepted = True
    cam.start()
    [(_, done)] = cam.held.calls
    shot = cam.photographer.abandon()
    assert shot.step_id == 3 and cam.held.cancelled == 1
    assert cam.light.asked == [True, False]
    done(response())
    assert cam.answers == [] and cam.photographer.abandon() is None


def test_the_photo_light_is_on_and_settled_before_the_call_and_off_after_it() -> None:
    cam = Camera(wired=True, held=True, settle_s=0.5, timeout_s=2.0)
    cam.start(now=0.0)
    assert cam.light.asked == [True] and cam.held.calls == []  # M8 not yet accepted
    cam.photographer.poll(1.0)
    assert cam.held.calls == []
    cam.light.accepted = True
    cam.photographer.poll(1.2)  # accepted: settling until 1.7
    cam.photographer.poll(1.6)
    assert cam.held.calls == []
    cam.photographer.poll(1.7)
    [(_, done)] = cam.held.calls
    done(response())
    assert cam.light.asked == [True, False] and cam.answers[0][2] == ''


def test_a_photo_light_the_controller_never_accepts_fails_the_photo() -> None:
    cam = Camera(wired=True, held=True, settle_s=0.5, timeout_s=2.0)
    cam.start(now=0.0)
    cam.photographer.poll(2.6)  # the deadline counts the settle time too
    [(_, answer, failure)] = cam.answers
    assert answer is None and 'did not accept the photo light (M8)' in failure
    assert cam.held.calls == [] and cam.light.asked == [True, False]


# --------------------------------------------------------------- gantry_node on the emulator


class CameraRig(Rig):
    """A gantry with a photo light on the flood output and a stand-in camera service."""

    def __init__(self, tmp_path, answer: Any = None, **params: Any) -> None:
        super().__init__(tmp_path, camera='camera/capture', **{'photo_light': True,
                                                                'photo_settle_s': 0.05,
                                                                'capture_timeout_s': 1.0,
                                                                **params})
        self.asked: list[tuple[Any, bool, str]] = []  # request, photo light on, state
        if answer is not None:
            self.transport.serve(types.CAPTURE, 'camera/capture', self._serve)
        self.answer = answer

    def _serve(self, request: Any) -> Any:
        self.asked.append((request, self.grbl.coolant, self.grbl.state))
        return self.answer


@pytest.fixture
def camera_rig(tmp_path):
    rig = CameraRig(tmp_path, answer=response(reward=0.5))
    yield rig
    rig.close()


@pytest.mark.slow
def test_each_step_is_photographed_under_the_photo_light_and_answered_with_the_measurement(
        camera_rig: CameraRig) -> None:
    rig = camera_rig
    rig.ready()
    assert rig.run_until(lambda: 'M9' in rig.grbl.lines)  # off at every connection
    rig.transport.time_s = 100.0
    rig.transport.inject('reset', types.new(types.RESET_REQUEST, reset_id=1, has_seed=True,
                                            seed=11))
    assert rig.run_until(lambda: rig.results() and rig.results()[-1].reset_id == 1)
    for step_id in (1, 2):
        rig.transport.time_s = 100.0 + step_id
        start = len(rig.transport.sequence)
        result = rig.command(step_id, mode=convert.MODE_DISCRETE, action=1)
        assert (result.info, result.reward, list(result.plant_rewards)) == ('', 0.5, [0.5])
        request, lit, state = rig.asked[-1]
        assert lit and state == 'Idle' and request.step_id == step_id
        # The episode's target as the camera is sent it is in the recorded chamber/config.
        config = json.loads(rig.transport.messages('chamber/config')[-1].data)
        assert config['reset_id'] == 1 and request.has_point_target
        assert config['target'] == {'x': request.target_x, 'z': request.target_z}
        assert json.loads(request.config)['target'] == config['target']
        assert convert.to_ns(request.header.stamp) == convert.to_ns(result.header.stamp)
        topics = [t.rsplit('/', 1)[-1] for t in rig.transport.sequence[start:]
                  if not t.endswith('gantry/status')]
        assert topics == ['image_raw', 'state', 'state', 'photo', 'measurement', 'step_result']
        for topic in ('camera/image_raw', 'plant/state', 'light/state', 'camera/photo',
                      'camera/measurement'):
            msg = rig.transport.messages(topic)[-1]
            assert msg.header.stamp == result.header.stamp, topic
    assert len(rig.asked) == 3  # the reset's photo and one per step
    # M8 before each photo and M9 after it, before the next move; G-code only while Idle, so
    # nothing was refused.
    assert rig.run_until(lambda: not rig.grbl.coolant)
    lights = [line[:2] for line in rig.grbl.lines if line in ('M8', 'M9') or
              line.startswith('$J')]
    assert lights == ['M9', '$J', 'M8', 'M9', '$J', 'M8', 'M9', '$J', 'M8', 'M9'], lights
    assert rig.grbl.coolant_history[-6:] == [True, False] * 3
    assert not any('refused: error' in w for w in rig.transport.warnings), \
        rig.transport.warnings

    def status() -> dict[str, str]:  # gantry/status says what is true of the photo light
        return {kv.key: kv.value for kv in
                rig.transport.messages('gantry/status')[-1].status[0].values}
    assert rig.run_until(lambda: (status()['photo'], status()['photo_light']) == ('idle', 'off'))

    # An unseeded reset: the camera is sent the episode's own chamber/config (seed None), not
    # the last seeded one's.
    rig.transport.inject('reset', types.new(types.RESET_REQUEST, reset_id=2, has_seed=False))
    assert rig.run_until(lambda: rig.results()[-1].reset_id == 2)
    config = rig.transport.messages('chamber/config')[-1].data
    assert rig.asked[-1][0].config == config and json.loads(config)['seed'] is None


@pytest.mark.slow
def test_no_camera_service_answers_unavailable_and_switches_the_light_off(tmp_path) -> None:
    rig = CameraRig(tmp_path, capture_timeout_s=0.3)
    try:
        rig.ready()
        rig.transport.inject('reset', types.new(types.RESET_REQUEST, reset_id=1, has_seed=True,
                                                seed=11))
        assert rig.run_until(lambda: rig.results() and rig.results()[-1].reset_id == 1)
        result = rig.results()[-1]
        assert result.info.startswith('error: camera: unavailable: no ')
        assert result.reward == 0.0 and not rig.transport.messages('camera/image_raw')
        assert rig.run_until(lambda: rig.grbl.lines[-1] == 'M9' and not rig.grbl.coolant)
    finally:
        rig.close()


def test_an_estop_during_the_photo_fails_the_step_and_leaves_the_light_off(tmp_path) -> None:
    rig = CameraRig(tmp_path, answer=response(), photo_settle_s=30.0, capture_timeout_s=30.0)
    try:
        rig.ready()
        rig.transport.inject('reset', types.new(types.RESET_REQUEST, reset_id=1, has_seed=True,
                                                seed=11))
        assert rig.run_until(lambda: rig.grbl.coolant)  # M8 accepted, settling
        sent = len(rig.grbl.lines)
        rig.node.estop('test')
        assert rig.results()[-1].info == 'error: emergency stop' and rig.asked == []
        # GRBL's reset switches the flood output off (the emulator reads the bytes in its own
        # thread), before the driver could send M9.
        assert rig.run_until(lambda: not rig.grbl.coolant)
        assert 'M9' not in rig.grbl.lines[sent:]
        assert rig.run_until(lambda: rig.controller.ready and rig.grbl.lines[-1] == 'M9')
    finally:
        rig.close()


def test_a_newer_command_abandons_the_photo_and_the_light_goes_off_before_the_move(
        tmp_path) -> None:
    rig = CameraRig(tmp_path, answer=response(), photo_settle_s=30.0, capture_timeout_s=30.0)
    try:
        rig.ready()
        rig.transport.inject('reset', types.new(types.RESET_REQUEST, reset_id=1, has_seed=True,
                                                seed=11))
        assert rig.run_until(lambda: rig.grbl.coolant)
        jogs_before = sum(line.startswith('$J') for line in rig.grbl.lines)
        rig.transport.inject('light/command', types.new(
            types.LIGHT_COMMAND, step_id=1, mode=convert.MODE_DISCRETE, action=1))
        assert rig.run_until(lambda: len(rig.results()) == 1)
        assert rig.results()[0].info.startswith('error: superseded by a newer command')
        assert rig.run_until(lambda: sum(line.startswith('$J') for line in rig.grbl.lines)
                             > jogs_before)
        after_m8 = rig.grbl.lines[rig.grbl.lines.index('M8') + 1:]
        assert after_m8.index('M9') < next(i for i, line in enumerate(after_m8)
                                           if line.startswith('$J'))
    finally:
        rig.close()


@pytest.mark.slow
def test_a_photo_in_progress_is_not_silence_for_the_watchdog(tmp_path) -> None:
    """The agent waits for the step's answer while the photo light settles: the watchdog
    (0.3 s here) must not take the lamp away from the photo."""
    rig = CameraRig(tmp_path, answer=response(reward=0.5), watchdog_s=0.3, photo_settle_s=0.8,
                    capture_timeout_s=5.0)
    try:
        rig.ready()
        rig.transport.inject('reset', types.new(types.RESET_REQUEST, reset_id=1, has_seed=True,
                                                seed=11))
        assert rig.run_until(lambda: rig.results())
        assert rig.results()[-1].info == '' and rig.results()[-1].reward == 0.5
        assert not any('watchdog' in w for w in rig.transport.warnings), rig.transport.warnings
        assert rig.asked and rig.asked[0][1]  # photographed under the photo light, lamp on
        assert rig.grbl.spindle[0] == 'M3'
    finally:
        rig.close()


@pytest.mark.parametrize('challenge', ['control', 'shape'])
def test_the_capture_request_carries_the_episodes_target(challenge) -> None:
    """A point for the point challenges, the digit's mask for shape (what the camera scores),
    and the chamber/config's ``target`` entry reads back as exactly that."""
    from growspace_gantry.photo import capture_request
    from growspace_sim.ros.interface import target_from_payload, target_payload

    sim = Simulation(SimConfig(challenge=challenge))
    sim.reset(seed=3)
    c, cfg = sim.chamber, sim.cfg
    light = convert.light_msg(c.light, 4, STAMP, 'chamber')
    request = capture_request(STAMP, 4, 2, '{"config": {}}', light, cfg, c.target,
                              c.target_mask, 'chamber')
    request = types.deserialize(types.serialize(request, f'{types.CAPTURE}_Request'),
                                f'{types.CAPTURE}_Request')
    assert (request.step_id, request.step, convert.to_ns(request.header.stamp)) == (4, 2, STAMP)
    assert request.light.x == c.light.x
    point, mask = target_from_payload(json.loads(json.dumps(target_payload(c.target,
                                                                           c.target_mask))))
    if challenge == 'shape':
        assert point is None and np.array_equal(mask.reshape(-1).astype(np.uint8),
                                                request.target_mask)
        assert not request.has_point_target
        assert np.array_equal(np.asarray(request.target_mask).reshape(c.target_mask.shape),
                              np.asarray(c.target_mask, np.uint8))
        assert request.target_mask.size == cfg.resolution ** 2 and request.target_mask.any()
    else:
        assert request.has_point_target and request.target_mask.size == 0
        assert complex(request.target_x, request.target_z) == c.target == point
        assert mask is None


# ------------------------------------------------ the emulator's flood output, as GRBL documents


def test_the_emulators_flood_output_follows_grbl(tmp_path) -> None:
    """``M8``/``M9`` switch the flood output, ``A:`` reports it (``F``, after the spindle's
    ``S``) only beside ``Ov:``, at once after a change; ``M7`` needs a compile option; a soft
    reset and a limit alarm (GRBL's ``mc_reset``) switch it off."""
    from grbl_emulator import GrblEmulator
    from growspace_gantry.link import SerialLink
    from waiting import LinkLines

    with GrblEmulator(RIG_SETTINGS, speedup=40.0, link_dir=tmp_path) as grbl:
        link = SerialLink(grbl.port)
        lines = LinkLines(link)
        until, seen = lines.until, lines.seen

        def report_with_overrides(within: int = 12) -> str:
            for _ in range(within):
                line = until(lambda x: x.startswith('<'), b'?')
                if '|Ov:' in line:
                    return line
            raise AssertionError(seen[-within:])

        try:
            link.write(b'\x18')
            until(lambda x: x.startswith('Grbl '))
            assert until(lambda x: x in ('ok',) or x.startswith('error'), b'M8\n') == 'ok'
            assert grbl.coolant
            # the change at the next report, or the one after when that one carries WCO
            assert report_with_overrides(within=2).endswith('|A:F>')
            until(lambda x: x == 'ok', b'M3 S100\n')
            assert report_with_overrides().endswith('|A:SF>')
            assert until(lambda x: x == 'ok' or x.startswith('error'), b'M7\n') == 'error:20'
            assert until(lambda x: x == 'ok', b'M9\n') and not grbl.coolant
            assert report_with_overrides().endswith('|A:S>')
            until(lambda x: x == 'ok', b'M8\n')
            link.write(b'\x18')  # a soft reset: spindle and coolant off
            until(lambda x: x.startswith('Grbl '))
            assert not grbl.coolant and grbl.spindle[0] == 'M5'
            assert '|A:' not in report_with_overrides()
            until(lambda x: x == 'ok', b'M8\n')
            grbl.trigger_alarm(1)  # a hard limit: mc_reset, then the alarm
            until(lambda x: x == 'ALARM:1')
            assert not grbl.coolant
        finally:
            link.close()
