"""The virtual gimbal as a device (gimbal_driver_common.device.Device): no ROS.

Copy its shape for a new driver: the adapter turns the client's protocol into the device
contract in SI units and REP-103 signs (this invented device already speaks both).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence

from gimbal_driver_common.device import (
    Device,
    DeviceInfo,
    Homing,
    JointSample,
    Moves,
    PostedWrite,
    StatusReport,
)
from gimbal_driver_common.diagnostics import Level, RegisterFlag, StatusPart, decode_register
from gimbal_driver_common.errors import DeviceTimeout, GimbalError
from gimbal_driver_common.unanswered import ConnectReads

from .client import Posted, Reply, VirtualGimbalClient
from .protocol import (
    FAULT_OVERTEMP,
    JOINTS,
    jog_request,
    move_request,
    parse_identity,
    parse_position,
    stop_request,
)

LOG = logging.getLogger(__name__)
#: GET polls unanswered in a row that make the link lost (:meth:`VirtualGimbalDevice.read`)
MISSED_POLLS_LOST = 2
FAULT_FLAGS = [RegisterFlag(0, 'overtemperature', Level.ERROR, 'motor over temperature')]
assert 1 << FAULT_FLAGS[0].bit == FAULT_OVERTEMP


class VirtualGimbalDevice(Device, Homing, StatusReport):
    """The virtual gimbal's line protocol as a device (it already speaks SI units)."""

    def __init__(self, host: str, port: int, home_timeout: float = 60.0,
                 request_timeout: float = 1.0) -> None:
        super().__init__()
        self.client = VirtualGimbalClient(host, port, timeout=request_timeout)
        #: best-effort connect requests the device left unanswered
        self.unanswered = ConnectReads(LOG.warning)
        self.home_timeout = home_timeout
        self._faults = 0
        self._latest: JointSample | None = None
        self._missed_polls = 0
        #: the joint poll in flight (:meth:`request_read`): its tag and when it was written,
        #: what takes its sample, and a failed reply the next request raises
        self._poll_lock = threading.Lock()
        self._poll: tuple[int, float] | None = None
        self._deliver: Callable[[JointSample], object] = lambda sample: None
        self._poll_error: GimbalError | None = None
        self.capabilities.homing = self
        self.capabilities.status = self

    def open(self) -> DeviceInfo:
        """Connect; only the joint data (GET) is required, its failure names it. The
        identity (ID) is best effort: unanswered, a WARN and a diagnostics key, and
        connecting goes on."""
        self.client.open()
        self.unanswered.clear()
        reply = self.unanswered.read('ID', lambda: self.client.request('ID'))
        if reply is None:
            info = DeviceInfo('virtual gimbal (ID unanswered)')
        else:
            identity = parse_identity(reply)
            info = DeviceInfo(identity.model, identity.serial_number,
                              identity.firmware_version)
        with self._poll_lock:
            self._missed_polls, self._poll, self._poll_error = 0, None, None
        self._read_joints()  # the joint data: required
        return info

    def close(self) -> None:
        self.client.close()

    def description(self) -> str:
        return f'tcp://{self.client.host}:{self.client.port}'

    def read(self) -> JointSample | None:
        """The joint poll. One GET left unanswered skips a sample (WARN) and the next poll
        asks again; :data:`MISSED_POLLS_LOST` in a row lose the link. One late reply (a
        host that stalled for a moment) is not a lost link; a device gone silent is."""
        try:
            sample = self._read_joints()
        except DeviceTimeout as exc:
            self._missed_polls += 1
            if self._missed_polls >= MISSED_POLLS_LOST:
                raise DeviceTimeout(f'{exc} ({self._missed_polls} polls in a row)') from None
            LOG.warning('poll skipped: %s (the link counts as lost after %d in a row)', exc,
                        MISSED_POLLS_LOST)
            return None
        self._missed_polls = 0
        return sample

    def request_read(self, deliver: Callable[[JointSample], object]) -> bool:
        """The joint poll without waiting (the controller's device thread): GET written
        now, its sample handed to ``deliver`` by the reader thread (:meth:`_poll_answered`).
        A GET still unanswered is not asked again before its ``request_timeout``; then it
        counts as :meth:`read` counts one (skipped, WARN; :data:`MISSED_POLLS_LOST` in a row
        lose the link), and a reply that failed (ERR, not a POS line) is raised here."""
        with self._poll_lock:
            self._deliver = deliver
            failed, self._poll_error = self._poll_error, None
            if failed is not None:
                raise failed
            if self._poll is not None:
                tag, written_at = self._poll
                timeout = self.client.timeout
                if time.monotonic() - written_at < timeout:
                    return True  # the GET in flight may still be answered
                self.client.forget(tag)
                self._poll = None
                self._missed_polls += 1
                exc = DeviceTimeout(f'no reply to GET within {timeout:g} s')
                if self._missed_polls >= MISSED_POLLS_LOST:
                    raise DeviceTimeout(f'{exc} ({self._missed_polls} polls in a row)')
                LOG.warning('poll skipped: %s (the link counts as lost after %d in a row)',
                            exc, MISSED_POLLS_LOST)
            written_at = time.monotonic()
            self._poll = (self.client.ask('GET', self._poll_answered), written_at)
        return True

    def _poll_answered(self, reply: Reply) -> None:
        """The reply to :meth:`request_read`'s GET, on the reader thread."""
        try:
            sample = self._joints(VirtualGimbalClient.checked('GET', reply.text))
        except GimbalError as exc:
            sample, error = None, exc
        with self._poll_lock:
            if self._poll is not None and self._poll[0] == reply.tag:
                self._poll = None
            if sample is None:
                self._poll_error = error
                return
            self._missed_polls = 0
            deliver = self._deliver
        deliver(sample)

    def _read_joints(self) -> JointSample:
        return self._joints(self.client.request('GET'))

    def _joints(self, text: str) -> JointSample:
        reply = parse_position(text)
        self._faults = reply.faults
        self._latest = JointSample(positions=reply.positions, velocities=reply.velocities,
                                   moving=reply.moving)
        return self._latest

    def move(self, moves: Moves) -> None:
        for joint, (position, speed) in moves.items():
            self.client.request(move_request(joint, position, speed))

    def post(self, moves: Moves, jogs: dict[str, float]) -> PostedWrite | None:
        """A stream move's MOVE lines written at once, one OK each, taken by :meth:`settle`
        (the command thread, or the next send that holds the link lock): the joint_command
        callback never waits for a reply."""
        lines = [move_request(joint, position, speed)
                 for joint, (position, speed) in moves.items()]
        if jogs or not lines:
            return None
        posted = self.client.post(lines)
        return PostedWrite(dict(moves), {}, replies=len(lines), expected=posted)

    def settle(self, posted: PostedWrite) -> bool:
        """False when an OK never came (the command path sends the moves again)."""
        assert isinstance(posted.expected, Posted)  # what post() wrote
        try:
            self.client.settle(posted.expected)
        except DeviceTimeout:
            return False
        return True

    def jog(self, velocities: dict[str, float]) -> None:
        for joint, velocity in velocities.items():
            self.client.request(jog_request(joint, velocity))

    def stop(self, joints: Sequence[str] | None = None) -> None:
        self.client.request(stop_request(joints))

    def reset_faults(self) -> str:
        self.client.request('RESET')
        return 'faults cleared'

    def home(
        self, joints: Sequence[str], report: Callable[[str], None], cancelled: threading.Event
    ) -> str:
        self.client.request('HOME')
        deadline = time.monotonic() + self.home_timeout
        while time.monotonic() < deadline and not cancelled.is_set():
            report('moving to index')
            sample = self._latest
            if sample and all(abs(sample.positions[j]) < 1e-3 for j in JOINTS):
                return 'homed at 0'
            time.sleep(0.05)
        raise DeviceTimeout('homing did not finish')

    def parts(self) -> list[StatusPart]:
        active = decode_register(self._faults, FAULT_FLAGS, 'faults')
        part = StatusPart.from_flags('device', active, [
            ('fault_bits', hex(self._faults)), *self.unanswered.diagnostics()])
        missing = self.unanswered.summary()
        if missing:  # best effort at connect: the node works without it
            part.level = max(part.level, Level.WARN)
            part.message += f' | {missing}'
        return [part]

    def errors(self) -> list[str]:
        return [a.flag.name for a in decode_register(self._faults, FAULT_FLAGS)]
