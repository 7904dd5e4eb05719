"""KosClient against the simulator over TCP loopback (real sockets, real framing).

The simulator runs time-scaled so that moves of a few simulated seconds finish quickly; tests
wait *up to* a timeout for conditions and never assert on timings.
"""

import math
import socket
import time
from dataclasses import dataclass
from typing import ClassVar

import pytest

from kessler_kos_driver.client import (
    CommandRejected,
    DeviceTimeout,
    KosClient,
    MessageUnsupported,
    NotConnected,
    PasswordRejected,
)
from kessler_kos_driver.moves import (
    AxisRange,
    JointMapping,
    Keyframe,
    PlaybackSettings,
    from_keyframes,
    from_segments,
)
from kessler_kos_driver.protocol import (
    ErrorCode,
    ErrorStatus,
    FrameParser,
    GetDeviceInfo,
    GetTrajectoryData,
    Message,
    MessageType,
    MotorCalibrated,
    PlaybackMode,
    PlaybackState,
    ResetAxis,
    TrajectoryData,
    UserPassword,
    decode,
    encode_frame,
)
from kessler_kos_driver.sim import KosSimulator, SimSettings
from kessler_kos_driver.units import JointUnits

PASSWORD = 'hunter2'
TWO_PI = 2 * math.pi
JOINTS = {n: JointMapping(n, a, JointUnits(scale=TWO_PI))
          for n, a in (('slider', 1), ('pan', 2), ('tilt', 3))}
S = PlaybackState


def wait_until(predicate, timeout=5.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()


@pytest.fixture
def make_sim():
    sims = []

    def factory(**kwargs):
        settings = SimSettings(password=PASSWORD, time_scale=kwargs.pop('time_scale', 20.0),
                               **kwargs)
        sim = KosSimulator(settings, discovery_port=0).start()
        sims.append(sim)
        return sim

    yield factory
    for sim in sims:
        sim.stop()


@pytest.fixture
def make_client():
    clients = []

    def factory(sim, **kwargs):
        kwargs.setdefault('password', PASSWORD)
        kwargs.setdefault('poll_period', 0.05)
        kwargs.setdefault('reply_timeout', 2.0)
        client = KosClient('127.0.0.1', sim.port, **kwargs)
        clients.append(client)
        return client

    yield factory
    for client in clients:
        client.close()


@pytest.fixture
def calibrated(make_sim, make_client):
    sim = make_sim(precalibrated=True)
    client = make_client(sim)
    client.connect()
    return sim, client


def ranges(client):
    return {a: AxisRange(m.begin_position, m.end_position) for a, m in client.motors.items()}


def three_axis_keyframes():
    # slider range 0..200 rot, pan 0..100 rot, tilt 0..-40 rot (simulator defaults), in rad
    return [
        Keyframe(0.0, {'slider': 0.0, 'pan': 10.0, 'tilt': -10.0}),
        Keyframe(2.0, {'slider': 60.0, 'pan': 150.0, 'tilt': -100.0}),
        Keyframe(4.0, {'slider': 20.0, 'pan': 300.0, 'tilt': -200.0}),
    ]


def test_initialisation_sequence(make_sim, make_client):
    sim = make_sim()
    client = make_client(sim)
    client.connect()
    assert client.connected
    assert client.device_info.device_type == 11   # CineShooter
    assert client.guid == sim.device.settings.guid.hex()
    assert sorted(client.motors) == [1, 2, 3]
    assert not any(m.calibrated for m in client.motors.values())
    assert client.motors[3].max_move_speed == 65.0        # tilt maxima from the document
    assert PASSWORD not in repr(client.device_info)


def test_an_unanswered_guid_never_keeps_the_device_from_connecting(make_sim, make_client):
    """GetDeviceGuid is an identity detail: unanswered, the client connects without it and
    says so; the motors are polled and a move runs."""
    sim = make_sim(precalibrated=True)
    sim.device.request_faults.mute('GetDeviceGuid')
    client = make_client(sim, reply_timeout=0.5)
    client.connect()
    assert client.connected and client.guid == ''
    assert 'GetDeviceGuid' in client.unanswered
    assert sorted(client.motors) == [1, 2, 3]
    sim.device.request_faults.clear()
    client.connect()   # answered on the next connection: nothing left on record
    assert client.guid == sim.device.settings.guid.hex() and not client.unanswered


@pytest.mark.parametrize('required', ['GetDeviceInfo', 'GetMotorInfo'])
def test_an_unanswered_required_request_names_itself(make_sim, make_client, required):
    sim = make_sim(precalibrated=True)
    sim.device.request_faults.mute(required)
    client = make_client(sim, reply_timeout=0.5)
    with pytest.raises(DeviceTimeout, match=required):
        client.connect()
    assert not client.connected


def test_wrong_password_is_refused_without_sending_it(make_sim, make_client):
    sim = make_sim()
    client = make_client(sim, password='wrong')
    with pytest.raises(PasswordRejected) as info:
        client.connect()
    assert 'wrong' not in str(info.value) and PASSWORD not in str(info.value)
    assert not client.connected


def test_locked_device_ignores_commands_and_reports_error_15(make_sim):
    sim = make_sim()
    with socket.create_connection(('127.0.0.1', sim.port), 2) as sock:
        sock.settimeout(2)
        sock.sendall(UserPassword('nope').encode() + encode_frame(0x0B, 1) +
                     GetDeviceInfo().encode())
        parser, messages = FrameParser(), []
        while not any(type(m).__name__ == 'DeviceInfo' for m in messages):
            messages += [decode(f) for f in parser.feed(sock.recv(4096))]
    kinds = [type(m).__name__ for m in messages]
    assert 'MotorInfo' not in kinds                           # ignored while locked
    assert ErrorStatus(ErrorCode.LOCKED_OUT, 0) in messages   # wrong password reported


def test_keepalive_keeps_an_idle_connection(make_sim, make_client):
    sim = make_sim(keepalive_timeout=1.5)
    client = make_client(sim, poll_period=0.0, keepalive_period=0.2)
    client.connect()
    time.sleep(3.0)     # twice the device's keep-alive window without any other traffic
    assert client.connected and sim.server.connections == 1
    client.refresh_motors()


def test_silent_client_is_dropped_by_the_device(make_sim, make_client):
    sim = make_sim(keepalive_timeout=0.4)
    client = make_client(sim, poll_period=0.0, keepalive_period=0.0)
    client.connect()
    assert wait_until(lambda: not client.connected, 5.0)
    with pytest.raises(NotConnected):
        client.refresh_motors()


def test_uncalibrated_jog_stop_and_calibration(make_sim, make_client):
    sim = make_sim()
    client = make_client(sim)
    client.connect()
    client.commands.jog(2, 20.0)
    assert wait_until(lambda: client.motors[2].position > 5.0)
    client.commands.stop_motor(2)
    assert wait_until(lambda: not sim.device.motors[2].moving)
    client.commands.move_to(2, 5.0, 50.0)
    assert wait_until(lambda: abs(client.motors[2].position - 5.0) < 1e-3)
    client.commands.mark_begin(2)
    client.commands.move_to(2, 25.0, 50.0)
    assert wait_until(lambda: abs(client.motors[2].position - 25.0) < 1e-3)
    begin, end = client.commands.mark_end(2)
    assert (begin, end) == (0.0, pytest.approx(20.0, abs=1e-3))
    assert client.motors[2].calibrated
    # the calibrated range and MaxMaxSetupSpeed are the adapter's checks, in SI
    # (test_device.py::test_refusal_reasons_in_si_and_nothing_sent); the client sends as given
    assert client.motors[2].travel() == (0.0, pytest.approx(20.0, abs=1e-3))
    client.commands.move_to(2, 10.0, 50.0)
    assert wait_until(lambda: abs(client.motors[2].position - 10.0) < 1e-3)
    client.commands.bump(2, 2.5, 50.0)
    assert wait_until(lambda: abs(client.motors[2].position - 12.5) < 1e-3)
    with pytest.raises(CommandRejected, match='outside'):
        client.commands.bump(2, 50.0, 50.0)
    client.commands.reset_axis(2)
    assert not client.motors[2].calibrated and client.motors[2].position == 0.0


def test_calibration_error_when_end_equals_begin(make_sim, make_client):
    sim = make_sim()
    client = make_client(sim)
    client.connect()
    client.commands.mark_begin(1)
    with pytest.raises(CommandRejected, match='calibration failed'):
        client.commands.mark_end(1)


def test_live_motion_full_sequence(calibrated):
    _sim, client = calibrated
    traj = from_keyframes(three_axis_keyframes(), JOINTS, ranges(client),
                          PlaybackSettings(duration=4.0))
    client.commands.load_trajectory(traj)
    client.commands.setup_playback()
    assert client.commands.wait_playback(S.SETUP_COMPLETED, 10)
    assert client.playback.history == [S.MOTORS_HOME, S.SETUP_COMPLETED]
    # at the first key frame after the setup
    assert client.motors[2].position == pytest.approx(10.0 / TWO_PI, abs=1e-3)
    client.commands.start_playback()
    assert client.commands.wait_playback(S.FULL_STOP, 10)
    assert client.playback.history == [S.MOTORS_HOME, S.SETUP_COMPLETED, S.START_FORWARD,
                                       S.END_OF_MOVE, S.FULL_STOP]
    assert not client.playback.loaded      # FullStop consumes the move
    last = three_axis_keyframes()[-1].positions
    for name, mapping in JOINTS.items():
        assert client.playback.positions[mapping.address] * TWO_PI == pytest.approx(
            last[name], abs=1e-3)
    with pytest.raises(CommandRejected, match='no trajectory loaded'):
        client.commands.start_playback()


def test_live_motion_with_delay_and_reverse_loop(calibrated):
    _sim, client = calibrated
    settings = PlaybackSettings(loop_count=1, start_delay=0.5)
    client.commands.load_trajectory(from_keyframes(three_axis_keyframes(), JOINTS, ranges(client),
                                          settings))
    client.commands.start_playback()      # no SetupPlayback: no SetupCompleted
    assert client.commands.wait_playback(S.FULL_STOP, 10)
    assert client.playback.history == [
        S.MOTORS_HOME, S.DELAY_TIMER_STARTED, S.START_FORWARD, S.END_OF_MOVE,
        S.START_REVERSE, S.END_OF_MOVE, S.START_FORWARD, S.END_OF_MOVE, S.FULL_STOP]


def test_delay_until_date_and_delay_return(calibrated):
    """DelayMode 2 waits for a wall-clock date (not scaled time); DelayReturn sets up in place."""
    _sim, client = calibrated
    start_at = math.ceil(time.time()) + 2
    settings = PlaybackSettings(start_time=start_at)
    client.commands.load_trajectory(from_keyframes(three_axis_keyframes(), JOINTS, ranges(client),
                                          settings))
    before = client.motors[2].position
    client.commands.setup_playback(delay_return=True)
    assert client.commands.wait_playback(S.SETUP_COMPLETED, 10)
    assert client.playback.history == [S.SETUP_COMPLETED]     # no MotorsHome: no return yet
    assert client.motors[2].position == before
    client.commands.start_playback()
    assert client.commands.wait_playback(S.DELAY_TIMER_STARTED, 10)
    assert client.commands.wait_playback(S.START_FORWARD, 20)
    assert time.time() >= start_at              # 20x time scale does not shorten a date
    assert client.commands.wait_playback(S.FULL_STOP, 20)
    assert client.playback.history[:3] == [S.SETUP_COMPLETED, S.MOTORS_HOME,
                                           S.DELAY_TIMER_STARTED]


def test_rapid_reverse_loop_forever_until_stop(calibrated):
    sim, client = calibrated
    settings = PlaybackSettings(loop_count=255, rapid_reverse=True)
    client.commands.load_trajectory(from_keyframes(three_axis_keyframes(), JOINTS, ranges(client),
                                          settings))
    client.commands.setup_playback(delay_return=True)
    assert client.commands.wait_playback(S.SETUP_COMPLETED, 10)
    assert S.MOTORS_HOME not in client.playback.history    # DelayReturn
    client.commands.start_playback()
    assert client.wait_for(lambda: client.playback.history.count(S.START_REVERSE) >= 2, 10)
    client.commands.stop_playback()
    assert client.commands.wait_playback(S.FULL_STOP, 5)
    assert wait_until(lambda: not any(m.moving for m in sim.device.motors.values()))


def test_time_lapse_continuous_sequence_and_photo_count(calibrated):
    _sim, client = calibrated
    settings = PlaybackSettings(mode=PlaybackMode.TIMELAPSE_CONTINUOUS, interval=0.5,
                                exposure=0.1, move_photos=10, pre_move_photos=2,
                                post_move_photos=3)
    client.commands.load_trajectory(from_keyframes(three_axis_keyframes(), JOINTS, ranges(client),
                                          settings))
    client.commands.setup_playback()
    assert client.commands.wait_playback(S.SETUP_COMPLETED, 10)
    client.commands.start_playback()
    assert client.commands.wait_playback(S.FULL_STOP, 10)
    assert client.playback.history == [
        S.MOTORS_HOME, S.SETUP_COMPLETED, S.PRE_MOVE_PHOTOS_STARTED, S.START_FORWARD,
        S.END_OF_MOVE, S.POST_MOVE_PHOTOS_COMPLETED, S.FULL_STOP]
    assert client.playback.photo_count == 15


def test_time_lapse_sms_sequence(calibrated):
    _sim, client = calibrated
    settings = PlaybackSettings(mode=PlaybackMode.TIMELAPSE_SMS, interval=0.05, exposure=0.02,
                                move_photos=3)
    client.commands.load_trajectory(from_keyframes(three_axis_keyframes(), JOINTS, ranges(client),
                                          settings))
    client.commands.setup_playback()
    assert client.commands.wait_playback(S.SETUP_COMPLETED, 10)
    client.commands.start_playback()
    assert client.commands.wait_playback(S.FULL_STOP, 20)
    frames = [S.START_FRAME, S.SMS_MOTORS_STOPPED] * 3
    assert client.playback.history == [
        S.MOTORS_HOME, S.SETUP_COMPLETED, S.PRE_MOVE_PHOTOS_STARTED, S.START_FORWARD, *frames,
        S.END_OF_MOVE, S.POST_MOVE_PHOTOS_COMPLETED, S.FULL_STOP]
    assert client.playback.photo_count == 3


def test_time_lapse_refuses_loops_before_sending(calibrated):
    sim, client = calibrated
    settings = PlaybackSettings(mode=PlaybackMode.TIMELAPSE_SMS, interval=0.1, move_photos=3,
                                loop_count=2)
    traj = from_keyframes(three_axis_keyframes(), JOINTS, ranges(client), settings)
    frames_before = sim.device.frames_received
    with pytest.raises(CommandRejected, match='time lapse'):
        client.commands.load_trajectory(traj)
    client.barrier()
    # only the MotorInfo refresh and the barrier reached the device, no TrajectoryData
    assert sim.device.playback.trajectory is None
    assert sim.device.frames_received > frames_before


def test_too_fast_move_is_refused(calibrated):
    _sim, client = calibrated
    keyframes = [Keyframe(0.0, {'tilt': 0.0}), Keyframe(0.1, {'tilt': -250.0})]
    traj = from_keyframes(keyframes, JOINTS, ranges(client), PlaybackSettings())
    with pytest.raises(CommandRejected, match='MaxMaxMoveSpeed'):
        client.commands.load_trajectory(traj)


def test_explicit_segments(calibrated):
    _sim, client = calibrated
    segments = {'pan': [(0, 0, 1 / 3, 0, 2 / 3, 1, 1, 1)]}
    client.commands.load_trajectory(
        from_segments(segments, JOINTS, PlaybackSettings(duration=10.0)))
    client.commands.start_playback()
    assert client.commands.wait_playback(S.FULL_STOP, 10)
    assert client.motors[2].position == pytest.approx(100.0, abs=1e-3)


def test_device_rejects_bad_trajectory_with_error_3(calibrated):
    _sim, client = calibrated
    traj = from_keyframes(three_axis_keyframes(), JOINTS, ranges(client),
                          PlaybackSettings(duration=4.0))
    message = traj.to_message()
    message.blocks[0].camera_roll_enabled = True      # bypass the client's validation
    marker = client.error_total
    client.send(message)
    client.barrier()
    assert [e.code for e in client.state.errors_since(marker)] == [ErrorCode.TRAJECTORY_DATA]
    echo = client.request(GetTrajectoryData())     # must answer even with no move stored
    assert isinstance(echo, TrajectoryData) and echo.blocks == []


def test_unsupported_message_is_reported(make_sim, make_client):
    sim = make_sim()
    client = make_client(sim)
    client.connect()
    client._stream.write(encode_frame(0x10, 1))          # (Get)UserPassword: not supported
    client._stream.write(encode_frame(0x80, 0, b'\x30'))  # undefined action id
    assert wait_until(lambda: client.unsupported_replies >= 2)


@dataclass
class GetUndefined(Message):
    """A Get of a MessageID the document does not define (the device does not support it)."""

    MESSAGE_ID: ClassVar[int] = 0x55
    message_type: ClassVar[int] = MessageType.GET


def test_a_request_answered_with_unsupported_message_is_named_not_timed_out(
        make_sim, make_client):
    """The device answers, with UnsupportedMessage: the request says so (issue 26), it is
    not "no reply", and the link stays up."""
    sim = make_sim()
    client = make_client(sim, reply_timeout=10.0)
    client.connect()
    with pytest.raises(MessageUnsupported, match='answered GetUndefined with '
                                                 'UnsupportedMessage'):
        client.request(GetUndefined())
    assert client.connected
    assert client.request(GetDeviceInfo()) is not None


def test_take_picture(make_sim, make_client):
    sim = make_sim()
    client = make_client(sim)
    client.connect()
    client.commands.take_picture(0.1)
    assert sim.device.photos_taken == 1
    with pytest.raises(CommandRejected):
        client.commands.take_picture(-1.0)


def test_garbage_is_skipped(calibrated):
    sim, client = calibrated
    assert sim.command('garbage hex 00ff04ffff1234') == 'ok 7 bytes'
    assert sim.command('garbage hex 0400') == 'ok 2 bytes'
    assert wait_until(lambda: client.malformed_frames > 0)
    client.refresh_motors()
    client.barrier()
    assert client.connected


def test_motor_offline_and_online(calibrated):
    sim, client = calibrated
    assert sim.command('offline 2') == 'ok'
    assert wait_until(lambda: not client.motors[2].online)
    with pytest.raises(CommandRejected, match='offline'):
        client.commands.move_to(2, 1.0, 10.0)
    traj = from_keyframes(three_axis_keyframes(), JOINTS, ranges(client), PlaybackSettings())
    with pytest.raises(CommandRejected, match='not connected'):
        client.commands.load_trajectory(traj)
    sim.command('online 2')
    assert wait_until(lambda: client.motors[2].online)
    client.commands.move_to(2, 1.0, 10.0)


def test_axis_fault_during_playback(calibrated):
    sim, client = calibrated
    traj = from_keyframes(three_axis_keyframes(), JOINTS, ranges(client),
                          PlaybackSettings(duration=30.0))
    client.commands.load_trajectory(traj)
    client.commands.start_playback()
    assert client.commands.wait_playback(S.START_FORWARD, 10)
    assert sim.command('fault axis 3') == 'ok'
    assert client.commands.wait_playback(S.FULL_STOP, 5)
    assert wait_until(lambda: any(e.code == ErrorCode.AXIS_FAULT and e.motor_address == 3
                                  for e in client.errors))
    assert wait_until(lambda: not client.motors[3].calibrated)


# Reconnecting is the controller's job: test_device.py::test_link_drop_then_reconnect.


def test_connect_failure_is_clear():
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        port = probe.getsockname()[1]
    client = KosClient('127.0.0.1', port, connect_timeout=0.5)
    with pytest.raises(NotConnected, match='cannot connect'):
        client.connect()


def test_discovery_by_network_info_datagrams(make_client):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(('127.0.0.1', 0))
        udp_port = probe.getsockname()[1]
    settings = SimSettings(password=PASSWORD, time_scale=20.0)
    sim = KosSimulator(settings, discovery_port=udp_port).start()
    try:
        client = KosClient('', sim.port, password=PASSWORD, discovery_port=udp_port,
                           discovery_timeout=5.0, discovery_bind='127.0.0.1', poll_period=0)
        client.connect()
        assert client.description == f'tcp://127.0.0.1:{sim.port}'
        client.close()
    finally:
        sim.stop()


def test_motor_calibrated_notification_updates_state(calibrated):
    sim, client = calibrated
    # Only the notification may update the state here: stop the MotorInfo polls, which would
    # (rightly) overwrite the notified value with the simulator's own calibration.
    client.poll_period = 0.0
    time.sleep(0.1)  # let a poll already in flight be answered
    with sim.device.lock:
        sim.device.broadcast(MotorCalibrated(1, 0.0, 42.0))
    assert wait_until(lambda: client.motors[1].end_position == 42.0)


# The silent device, detected by the client and recovered by the controller's supervisor:
# test_device.py::test_silent_device_is_detected_and_recovered.


def test_rapid_to_first_key_frame(calibrated):
    _sim, client = calibrated
    client.commands.load_trajectory(from_keyframes(three_axis_keyframes(), JOINTS, ranges(client),
                                          PlaybackSettings()))
    client.commands.rapid_to_first_key_frame()
    assert client.commands.wait_playback(S.MOTORS_HOME, 10)
    assert client.motors[3].position == pytest.approx(-10.0 / TWO_PI, abs=1e-3)


def test_device_refuses_to_play_on_an_axis_that_lost_calibration(calibrated):
    _sim, client = calibrated
    client.commands.load_trajectory(from_keyframes(three_axis_keyframes(), JOINTS, ranges(client),
                                          PlaybackSettings()))
    client.send(ResetAxis(1))           # behind the client's back: slider uncalibrated
    assert wait_until(lambda: not client.motors[1].calibrated)
    with pytest.raises(CommandRejected, match='error 2'):
        client.commands.start_playback()
