"""``virtual_gimbal_sim``: the virtual gimbal's simulator on TCP 127.0.0.1 (no ROS).

It answers the line protocol of :mod:`virtual_gimbal_driver.protocol`. Motion runs on the
shared trapezoidal axis model (``sim_motion.AxisMotion``); the simulator is driven by the
shared control verbs (``sim_control``: drop, silence, garbage, ``nack`` = ERR replies,
``fault overtemp|BITS``, ignore_motion, ``mute VERB``, ``delay VERB SECONDS``, ``ignore VERB
SECONDS``, clear, state, quit); ``mute``/``delay``/``ignore`` take the request verbs of
:data:`REQUESTS` (an ignored MOVE, JOG, STOP, HOME or RESET is answered OK, not acted on).
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from collections.abc import Callable

from gimbal_driver_common.sim_control import ControlError, SimControl, run_simulator
from gimbal_driver_common.sim_motion import AxisMotion
from gimbal_driver_common.sim_requests import LateReplies, RequestFaults
from gimbal_driver_common.sim_server import TcpSimServer

from .protocol import FAULT_NAMES, JOINTS, READS, format_position, split_tag, tagged, verb

DEFAULT_SPEED = 0.8  # rad/s
#: rad/s^2, accelerating and braking: DEFAULT_SPEED in 0.1 s, so moves keep nearly the
#: timing of the earlier constant-speed model (an invented device: no spec to follow)
DEFAULT_ACCELERATION = 8.0
#: the request verbs of the line protocol (``mute``/``delay``/``ignore`` take them)
REQUESTS = ('ID', 'GET', 'MOVE', 'JOG', 'STOP', 'HOME', 'RESET')


class VirtualGimbal:
    """Two axes on the shared trapezoidal model, integrated lazily at each request."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self.axes = {name: AxisMotion(acceleration=DEFAULT_ACCELERATION)
                     for name in JOINTS}
        self.faults = 0
        self.nack_all = False  # sim: answer every request with ERR (the console's nack)
        self.nack_pending: list[str | None] = []  # next requests to refuse (None: any)
        #: the requests never answered (mute) or answered late (delay, by the session)
        self.request_faults = RequestFaults()
        self.lock = threading.Lock()
        self._clock = clock
        self._last = clock()

    def step(self) -> None:
        now = self._clock()
        dt, self._last = now - self._last, now
        for axis in self.axes.values():
            axis.step(dt)

    def handle(self, line: str) -> str | None:
        """The reply line to one request line; None for a muted request (received and
        dropped: not acted on, never answered)."""
        with self.lock:
            self.step()
            command, args = verb(line), line.split()[1:]
            if not command:
                return 'ERR empty request'
            if self.request_faults.muted(command):
                return None
            if command not in READS and self.request_faults.ignored(command):
                return 'OK'  # ignore: answered as always, not acted on
            refused = self._injected_nack(command)
            if refused:
                return refused
            try:
                return self._dispatch(command, args)
            except (ValueError, KeyError, IndexError) as exc:
                return f'ERR {command}: {exc}'

    def _injected_nack(self, command: str) -> str:
        if self.nack_all:
            return f'ERR {command}: injected NACK'
        for index, wanted in enumerate(self.nack_pending):
            if wanted in (None, command):
                del self.nack_pending[index]
                return f'ERR {command}: injected NACK'
        return ''

    def _dispatch(self, command: str, args: list[str]) -> str:
        if command == 'ID':
            return 'ID virtual-gimbal VG-0001 1.0.0'
        if command == 'GET':
            axes = [self.axes[name] for name in JOINTS]
            return format_position([a.position for a in axes], [a.velocity for a in axes],
                                   [a.moving for a in axes], self.faults)
        if command == 'MOVE':
            axis = self.axes[args[0]]
            speed = float(args[2])
            axis.move_to(float(args[1]), speed if speed > 0 else DEFAULT_SPEED)
            return 'OK'
        if command == 'JOG':
            self.axes[args[0]].jog(float(args[1]))
            return 'OK'
        if command == 'STOP':
            for name in args or JOINTS:
                self.axes[name].stop()
            return 'OK'
        if command == 'HOME':
            for axis in self.axes.values():
                axis.move_to(0.0, DEFAULT_SPEED)
            return 'OK'
        if command == 'RESET':
            self.faults = 0
            return 'OK'
        if command == 'FAULT':  # simulator-only: set fault bits
            self.faults = int(args[0])
            return 'OK'
        return f'ERR unknown command {command}'

    # ----------------------------------------------------------- control verbs
    def control_nack(self, args: list[str]) -> str | None:
        """``nack on|off`` (every request) or ``nack COMMAND|* [COUNT]`` (the next ones)."""
        word = args[0].lower()
        with self.lock:
            if word in ('on', 'off'):
                self.nack_all = word == 'on'
                if word == 'off':
                    self.nack_pending.clear()
                return None
            count = int(args[1]) if len(args) > 1 else 1
            self.nack_pending += [None if word == '*' else word.upper()] * count
        return None

    def control_fault(self, args: list[str]) -> str | None:
        name = args[0].lower()
        bits = FAULT_NAMES[name] if name in FAULT_NAMES else int(name, 0)
        if bits < 0:
            raise ControlError(f'fault bits {bits} < 0')
        with self.lock:
            self.faults |= bits
        return None

    def control_clear(self) -> None:
        with self.lock:
            self.faults = 0
            self.nack_all = False
            self.nack_pending.clear()

    def state(self) -> dict:
        with self.lock:
            self.step()
            return {'axes': {name: axis.snapshot() for name, axis in self.axes.items()},
                    'faults': self.faults, 'nack_all': self.nack_all}


class _LineSession:
    """One TCP connection: request lines in, reply lines out; a delayed request's reply
    line waits in :attr:`late` for the server's poll, which writes it between other replies
    (never inside one)."""

    def __init__(self, device: VirtualGimbal) -> None:
        self.device = device
        self.buffer = b''
        self.late: LateReplies[bytes] = LateReplies()

    def on_bytes(self, data: bytes) -> bytes:
        self.buffer += data
        out = []
        while b'\n' in self.buffer:
            line, self.buffer = self.buffer.split(b'\n', 1)
            text, tag = split_tag(line.decode('ascii', 'replace'))
            reply = self.device.handle(text)
            if reply is None:
                continue
            encoded = ((reply if tag is None else tagged(reply, tag)) + '\n').encode()
            seconds = self.device.request_faults.delay_of(verb(text))
            if seconds:
                self.late.hold([encoded], seconds)
            else:
                out.append(encoded)
        if len(self.buffer) > 4096:
            self.buffer = b''
        return b''.join(out)

    def poll(self) -> bytes:
        return b''.join(self.late.due())


def make_server(port: int = 0) -> tuple[TcpSimServer, VirtualGimbal]:
    device = VirtualGimbal()
    return TcpSimServer(lambda: _LineSession(device), port=port).start(), device


def make_control(server: TcpSimServer, device: VirtualGimbal) -> SimControl:
    """The shared control verbs for a running virtual gimbal."""
    return SimControl('virtual_gimbal_sim', device.state, links=[server],
                      nack=device.control_nack, fault=device.control_fault,
                      fault_names=tuple(FAULT_NAMES), clear_device=device.control_clear,
                      axes=lambda: device.axes.values(), request_names=lambda: REQUESTS,
                      request_faults=device.request_faults)


def main(argv: list[str] | None = None) -> int:
    """``virtual_gimbal_sim --port N``: serve the virtual gimbal on 127.0.0.1."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--port', type=int, default=4950)
    parser.add_argument('--control-port', type=int, default=0,
                        help='control console on 127.0.0.1 (0 = any free port, -1 = none)')
    args = parser.parse_args(argv)
    server, device = make_server(args.port)
    try:
        run_simulator(make_control(server, device), {'port': server.port}, args.control_port)
    finally:
        server.stop()
    return 0


if __name__ == '__main__':
    sys.exit(main())
