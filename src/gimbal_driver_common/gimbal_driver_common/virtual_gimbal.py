"""A minimal virtual pan-tilt device: the reference driver for the shared base node.

It speaks a small line protocol over TCP so that the base node's behaviour
(lifecycle, reconnect, jog watchdog, moves, presets, scans, diagnostics) is
tested through a real transport without any vendor protocol, and so that a new
driver has a short, complete example to copy the shape of. Protocol, one
request line -> one reply line (ASCII, ``\\n``-terminated, SI units)::

    ID                     -> ID <model> <serial> <firmware>
    GET                    -> POS <pan> <tilt> <pan_vel> <tilt_vel> <moving_bits> <fault_bits>
    MOVE <joint> <pos> <v> -> OK          (v = 0: default speed)
    JOG <joint> <vel>      -> OK
    STOP [<joint>]         -> OK
    HOME                   -> OK          (both axes to 0 at default speed)
    RESET                  -> OK          (clears fault bits)
    anything else          -> ERR <reason>

Motion runs on the shared trapezoidal axis model (``sim_motion.AxisMotion``); the
simulator is driven by the shared control verbs (``sim_control``: drop, silence,
garbage, ``nack`` = ERR replies, ``fault overtemp|BITS``, clear, state, quit).
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from collections.abc import Callable

from gimbal_driver_common.errors import DeviceRefused, DeviceTimeout
from gimbal_driver_common.sim_control import ControlError, SimControl, run_simulator
from gimbal_driver_common.sim_motion import AxisMotion
from gimbal_driver_common.sim_server import TcpSimServer
from gimbal_driver_common.transport import LinkClosed, TcpStream, TransportError

JOINTS = ('pan', 'tilt')
DEFAULT_SPEED = 0.8  # rad/s
#: rad/s^2, accelerating and braking: DEFAULT_SPEED in 0.1 s, so moves keep nearly the
#: timing of the earlier constant-speed model (an invented device: no spec to follow)
DEFAULT_ACCELERATION = 8.0
FAULT_OVERTEMP = 0x1
FAULT_NAMES = {'overtemp': FAULT_OVERTEMP}


class VirtualGimbal:
    """Two axes on the shared trapezoidal model, integrated lazily at each request."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self.axes = {name: AxisMotion(acceleration=DEFAULT_ACCELERATION)
                     for name in JOINTS}
        self.faults = 0
        self.nack_all = False  # sim: answer every request with ERR (the console's nack)
        self.nack_pending: list[str | None] = []  # next requests to refuse (None: any)
        self.lock = threading.Lock()
        self._clock = clock
        self._last = clock()

    def step(self) -> None:
        now = self._clock()
        dt, self._last = now - self._last, now
        for axis in self.axes.values():
            axis.step(dt)

    def handle(self, line: str) -> str:
        with self.lock:
            self.step()
            words = line.split()
            if not words:
                return 'ERR empty request'
            command, args = words[0].upper(), words[1:]
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
            pan, tilt = self.axes['pan'], self.axes['tilt']
            moving = sum(1 << i for i, a in enumerate(self.axes.values()) if a.moving)
            return (f'POS {pan.position:.6f} {tilt.position:.6f} {pan.velocity:.6f} '
                    f'{tilt.velocity:.6f} {moving} {self.faults}')
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
    def __init__(self, device: VirtualGimbal) -> None:
        self.device = device
        self.buffer = b''

    def on_bytes(self, data: bytes) -> bytes:
        self.buffer += data
        out = []
        while b'\n' in self.buffer:
            line, self.buffer = self.buffer.split(b'\n', 1)
            out.append(self.device.handle(line.decode('ascii', 'replace')) + '\n')
        if len(self.buffer) > 4096:
            self.buffer = b''
        return ''.join(out).encode()


def make_server(port: int = 0) -> tuple[TcpSimServer, VirtualGimbal]:
    device = VirtualGimbal()
    return TcpSimServer(lambda: _LineSession(device), port=port).start(), device


def make_control(server: TcpSimServer, device: VirtualGimbal) -> SimControl:
    """The shared control verbs for a running virtual gimbal."""
    return SimControl('virtual_gimbal_sim', device.state, links=[server],
                      nack=device.control_nack, fault=device.control_fault,
                      fault_names=tuple(FAULT_NAMES), clear_device=device.control_clear)


class VirtualGimbalClient:
    """Request/reply client with one request in flight (thread-safe)."""

    def __init__(self, host: str, port: int, timeout: float = 1.0) -> None:
        self.stream = TcpStream(host, port)
        self.timeout = timeout
        self._lock = threading.Lock()
        self._buffer = b''

    def open(self) -> None:
        self.stream.open()
        self._buffer = b''

    def close(self) -> None:
        self.stream.close()

    def request(self, line: str) -> str:
        with self._lock:
            self.stream.write(line.encode() + b'\n')
            deadline = time.monotonic() + self.timeout
            while b'\n' not in self._buffer:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise DeviceTimeout(f'no reply to {line.split()[0]} within {self.timeout} s')
                self._buffer += self.stream.read(4096, remaining)
            reply, self._buffer = self._buffer.split(b'\n', 1)
        text = reply.decode('ascii', 'replace')
        if text.startswith('ERR'):
            raise DeviceRefused(f'device refused {line!r}: {text[4:]}')
        return text


def sim_main(argv: list[str] | None = None) -> int:
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


def node_main(argv: list[str] | None = None) -> int:
    """``virtual_gimbal_node``: the reference driver node (imports ROS only here)."""
    from gimbal_driver_common.virtual_gimbal_node import main

    return main(argv)


if __name__ == '__main__':
    sys.exit(sim_main())


__all__ = ['LinkClosed', 'TransportError', 'VirtualGimbal', 'VirtualGimbalClient', 'make_server']
