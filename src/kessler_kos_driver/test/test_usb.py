"""kOS over USB HID ("USB Notes"): report framing, the 4 s keep-alive and reassembly.

There is no USB device on the test machines. The transport is tested at the library
boundary: `HidStream` is given objects with the methods of cython-hidapi's `hid.device`
(a scripted fake here, and the simulator's `SimHidDevice`, which carries the full device
model), so every byte the client would hand to hidapi is checked.
"""

from __future__ import annotations

import logging
import math
import threading
import time

import pytest

from gimbal_driver_common.controller import ControllerConfig, GimbalController
from gimbal_driver_common.joint_command import JointLimits
from gimbal_driver_common.transport import LinkClosed, TransportError
from gimbal_driver_testing import wait_for
from kessler_kos_driver.client import CommandRejected, KosClient, NotConnected
from kessler_kos_driver.device import KosDevice as KosAdapter
from kessler_kos_driver.device import joint_mappings
from kessler_kos_driver.moves import (
    AxisRange,
    JointMapping,
    Keyframe,
    PlaybackSettings,
    from_keyframes,
)
from kessler_kos_driver.protocol import (
    REPORT_SIZE,
    USB_KEEPALIVE,
    AuxInputStatus,
    FrameParser,
    GetDeviceInfo,
    MessageId,
    PlaybackState,
    ReportReassembler,
    decode,
    encode_reports,
)
from kessler_kos_driver.sim import SimHidDevice, SimSettings, SimulatedRig
from kessler_kos_driver.units import JointUnits
from kessler_kos_driver.usb_link import HidStream, UsbTarget

TWO_PI = 2 * math.pi
TARGET = UsbTarget(vendor_id=0x1234, product_id=0x5678)


def wait_until(predicate, what='condition'):
    """True once predicate() holds (generous timeout for a loaded machine)."""
    return bool(wait_for(predicate, 20.0, what))


# ------------------------------------------------------------------------- framing (pure)
def test_keepalive_is_one_padded_report():
    (report,) = encode_reports(USB_KEEPALIVE)
    assert len(report) == REPORT_SIZE == 64
    assert report[:7] == bytes.fromhex('01 04 00 06 00 00 00')
    assert report[7:] == bytes(57)


def test_long_message_is_split_into_reports_and_reassembled():
    message = bytes((4,)) + (150).to_bytes(2, 'big') + bytes((0, 0x12, 0)) + bytes(range(144))
    reports = encode_reports(message)
    assert [len(r) for r in reports] == [64, 64, 64]
    assert all(r[0] == 0x01 for r in reports)
    assert b''.join(r[1:] for r in reports)[:150] == message
    assert reports[-1][1 + 150 - 126:] == bytes(63 - 24)   # the last report is zero padded
    reassembler = ReportReassembler()
    assert b''.join(reassembler.feed(r) for r in reports) == message
    assert reassembler.pending == 0


def test_reassembler_cuts_by_header_size_and_drops_foreign_reports():
    reassembler = ReportReassembler()
    frame = GetDeviceInfo().encode()
    (report,) = encode_reports(frame)
    assert reassembler.feed(report) == frame                      # padding removed
    assert reassembler.feed(b'\x02' + report[1:]) == b''          # other report ID
    assert reassembler.feed(bytes((1,)) + bytes(63)) == b''        # padding only
    assert reassembler.feed(b'') == b''
    assert reassembler.dropped_reports == 2
    assert reassembler.feed(report) == frame                      # still in step


def test_report_size_is_checked():
    with pytest.raises(ValueError, match='report_size'):
        encode_reports(b'\x04\x00\x06\x00\x00\x00', 4)
    assert len(encode_reports(USB_KEEPALIVE, 65)[0]) == 65       # 64 data bytes after the ID


# ------------------------------------------------------- HidStream against a fake hid.device
class FakeHid:
    """Scripted stand-in for `hid.device`: records writes, replays queued input reports."""

    def __init__(self, open_error: Exception | None = None) -> None:
        self.opened_with: tuple | None = None
        self.written: list[bytes] = []
        self.inbox: list[list[int]] = []
        self.closed = False
        self.open_error = open_error
        self.read_error: Exception | None = None
        self.write_result: int | None = None
        self.lock = threading.Lock()

    def open(self, vendor_id=0, product_id=0, serial_number=None):
        if self.open_error:
            raise self.open_error
        self.opened_with = (vendor_id, product_id, serial_number)

    def open_path(self, path):
        self.opened_with = (path,)

    def write(self, buff):
        with self.lock:
            self.written.append(bytes(buff))
        return len(buff) if self.write_result is None else self.write_result

    def read(self, max_length, timeout_ms=0):
        if self.read_error:
            raise self.read_error
        with self.lock:
            if self.inbox:
                return self.inbox.pop(0)[:max_length]
        time.sleep(min(timeout_ms, 5) / 1000)
        return []

    def close(self):
        self.closed = True


def test_stream_writes_padded_reports_and_opens_by_id_or_path():
    fake = FakeHid()
    stream = HidStream(UsbTarget(0x1234, 0x5678, 'SN1'), keepalive_period=0,
                       device_factory=lambda: fake)
    stream.open()
    assert fake.opened_with == (0x1234, 0x5678, 'SN1')
    stream.write(GetDeviceInfo().encode())
    assert fake.written == [bytes.fromhex('01 04 00 06 00 0f 01') + bytes(57)]
    stream.close()
    assert fake.closed and not stream.is_open
    by_path = FakeHid()
    stream = HidStream(UsbTarget(path='/dev/hidraw3'), keepalive_period=0,
                       device_factory=lambda: by_path)
    stream.open()
    assert by_path.opened_with == (b'/dev/hidraw3',)
    assert stream.description == 'usb:///dev/hidraw3'
    stream.close()


def test_stream_sends_the_keepalive_every_period_alongside_traffic():
    fake = FakeHid()
    stream = HidStream(TARGET, keepalive_period=0.05, device_factory=lambda: fake)
    stream.open()
    try:
        keepalive = encode_reports(USB_KEEPALIVE)[0]
        assert wait_until(lambda: fake.written.count(keepalive) >= 3)
        stream.write(GetDeviceInfo().encode())
        # every write is a whole report: a keep-alive never splits another message's reports
        assert all(len(r) == 64 and r[0] == 1 for r in fake.written)
    finally:
        stream.close()
    sent = len(fake.written)
    time.sleep(0.15)
    assert len(fake.written) == sent        # the keep-alive stops with the link


def test_stream_reassembles_responses_spanning_reports():
    fake = FakeHid()
    stream = HidStream(TARGET, keepalive_period=0, device_factory=lambda: fake)
    stream.open()
    long_message = bytes((4,)) + (100).to_bytes(2, 'big') + bytes((0, 0x0F, 2)) + bytes(94)
    short = GetDeviceInfo().encode()
    fake.inbox = [list(r) for r in encode_reports(long_message) + encode_reports(short)]
    fake.inbox.insert(1, [])                       # a read timeout between the reports
    data = b''
    for _ in range(6):
        data += stream.read(4096, 0.01)
    assert FrameParser().feed(data) == [long_message, short]
    stream.close()


def test_stream_failures_are_transport_errors():
    with pytest.raises(TransportError, match='cannot open usb://1234:5678'):
        HidStream(TARGET, device_factory=lambda: FakeHid(OSError('open failed'))).open()
    fake = FakeHid()
    stream = HidStream(TARGET, keepalive_period=0, device_factory=lambda: fake)
    stream.open()
    fake.write_result = -1
    with pytest.raises(LinkClosed, match='hidapi returned -1'):
        stream.write(USB_KEEPALIVE)
    fake.read_error = OSError('read error')
    with pytest.raises(LinkClosed, match='read error'):
        stream.read(64, 0.01)
    stream.close()
    with pytest.raises(ValueError, match='vendor and product id'):
        HidStream(UsbTarget())


# ------------------------------------------------ client over USB against the device model
@pytest.fixture
def usb_rig():
    device = SimulatedRig(SimSettings(password='not-used-on-usb', precalibrated=True,
                                   time_scale=20.0))
    hid_device = SimHidDevice(device)
    client = KosClient(usb=TARGET, usb_keepalive_period=0.1, poll_period=0.05,
                       usb_device_factory=lambda: hid_device)
    yield device, hid_device, client
    client.close()


def frames_written(hid_device):
    reassembler, parser = ReportReassembler(), FrameParser()
    return parser.feed(b''.join(reassembler.feed(r) for r in list(hid_device.reports_written)))


def test_client_over_usb_initialises_without_password(usb_rig):
    _device, hid_device, client = usb_rig
    client.connect()
    assert client.connected and client.description == 'usb://1234:5678'
    assert sorted(client.motors) == [1, 2, 3] and client.guid
    sent_ids = {decode(f).MESSAGE_ID for f in frames_written(hid_device)
                if f != USB_KEEPALIVE}
    assert MessageId.USER_PASSWORD not in sent_ids       # "not required or supported"
    assert all(len(r) == 64 and r[0] == 0x01 for r in hid_device.reports_written)
    assert all(len(r) == 64 and r[0] == 0x01 for r in hid_device.reports_read)
    assert wait_until(lambda: hid_device.session.usb_keepalives >= 2)


def test_client_moves_and_plays_a_multi_report_trajectory_over_usb(usb_rig):
    device, hid_device, client = usb_rig
    client.connect()
    client.commands.move_to(2, 20.0, 50.0)
    assert wait_until(lambda: abs(client.motors[2].position - 20.0) < 1e-3)
    ranges = {a: AxisRange(m.begin_position, m.end_position) for a, m in client.motors.items()}
    joints = {n: JointMapping(n, a, JointUnits(scale=TWO_PI))
              for n, a in (('slider', 1), ('pan', 2), ('tilt', 3))}
    keyframes = [Keyframe(0.0, {'slider': 0.0, 'pan': 10.0, 'tilt': -10.0}),
                 Keyframe(2.0, {'slider': 60.0, 'pan': 150.0, 'tilt': -100.0})]
    trajectory = from_keyframes(keyframes, joints, ranges, PlaybackSettings(duration=2.0))
    assert len(trajectory.to_message().encode()) > 63     # spans several reports both ways
    client.commands.load_trajectory(trajectory)                    # confirmed by GetTrajectoryData
    assert device.playback.trajectory is not None
    client.commands.setup_playback()
    assert client.commands.wait_playback(PlaybackState.SETUP_COMPLETED, 20)
    client.commands.start_playback()
    assert client.commands.wait_playback(PlaybackState.FULL_STOP, 20)
    assert hid_device.session.malformed == 0 and client.malformed_frames == 0
    hid_device.inject_report(b'\x02' + bytes(63))                # another report ID
    assert wait_until(lambda: client.usb_dropped_reports == 1)


def test_aux_inputs_leds_and_software_id_over_usb(usb_rig):
    device, _hid, client = usb_rig
    seen = []
    client.notifications.on_aux_inputs = seen.append
    client.connect()
    with device.lock:
        device.aux_input = 0b10001
        device.broadcast(AuxInputStatus(0b10001))
    assert wait_until(lambda: seen == [0b10001]) and client.aux_inputs == 0b10001
    assert client.commands.set_led_status(2, 3) == (2, 3) and device.led == (2, 3)
    with pytest.raises(CommandRejected, match='master LED status 7'):
        client.commands.set_led_status(7, 0)
    assert device.led == (2, 3)                            # nothing sent
    assert client.commands.set_software_id(42) == 42 and device.software_id == 42


def test_unplugged_usb_device_is_a_lost_link_and_reconnects(usb_rig):
    """The client sees the lost link; the controller's supervisor (the only reconnect loop)
    opens the adapter again once the device is back."""
    _device, hid_device, client = usb_rig
    joints = ['slider', 'pan', 'tilt']
    config = ControllerConfig(joints, {n: JointLimits() for n in joints}, reconnect_period=0.05)
    errors = []
    controller = GimbalController(
        KosAdapter(client, joint_mappings(joints, [1, 2, 3], [JointUnits(scale=TWO_PI)] * 3),
                   config), config,
        logging.getLogger('test_usb'), on_link_change=lambda: errors.append(controller.link_error))
    controller.open()
    try:
        assert wait_until(lambda: controller.connected)
        hid_device.unplug()
        assert wait_until(lambda: not controller.connected)
        assert wait_until(lambda: errors)
        assert 'read error' in errors[0] or 'not open' in errors[0]
        hid_device.plug_in()
        assert wait_until(lambda: controller.connected and controller.reconnects == 1)
        assert client.connected and client.description == 'usb://1234:5678'
    finally:
        controller.close()


def test_usb_client_without_device_fails_clearly():
    client = KosClient(usb=TARGET, usb_device_factory=lambda: FakeHid(OSError('open failed')))
    with pytest.raises(NotConnected, match='cannot open usb://1234:5678: open failed'):
        client.connect()


@pytest.mark.parametrize('backend', ['hidraw', 'libusb'])
def test_real_hidapi_backends_report_a_missing_device(backend):
    """The installed cython-hidapi is used as is; no kOS device is plugged in here."""
    pytest.importorskip('hid', reason='the hidapi wheel (requirements.txt) is not installed')
    stream = HidStream(UsbTarget(0x1234, 0x5678, backend=backend), keepalive_period=0)
    with pytest.raises(TransportError, match='cannot open usb://1234:5678'):
        stream.open()
    assert not stream.is_open
    with pytest.raises(ValueError, match='backend'):
        UsbTarget(0x1234, 0x5678, backend='serial').check()


def test_close_waits_for_a_read_in_progress():
    """hidapi frees the device on close: a concurrent read must have returned first."""
    class SlowHid(FakeHid):
        def __init__(self):
            super().__init__()
            self.reading = threading.Event()
            self.closed_during_read = False

        def read(self, max_length, timeout_ms=0):
            self.reading.set()
            time.sleep(timeout_ms / 1000)
            self.closed_during_read = self.closed
            return []

    fake = SlowHid()
    stream = HidStream(TARGET, keepalive_period=0, device_factory=lambda: fake)
    stream.open()
    reader = threading.Thread(target=stream.read, args=(64, 0.3))
    reader.start()
    assert fake.reading.wait(10)
    stream.close()
    reader.join(10)
    assert fake.closed and not fake.closed_during_read
