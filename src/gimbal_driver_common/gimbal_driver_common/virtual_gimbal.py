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
"""

from __future__ import annotations

import argparse
import math
import sys
import threading
import time
from dataclasses import dataclass

from gimbal_driver_common.errors import DeviceRefused, DeviceTimeout
from gimbal_driver_common.sim_server import TcpSimServer
from gimbal_driver_common.transport import LinkClosed, TcpStream, TransportError

JOINTS = ('pan', 'tilt')
DEFAULT_SPEED = 0.8  # rad/s
FAULT_OVERTEMP = 0x1


@dataclass
class _Axis:
    position: float = 0.0
    velocity: float = 0.0
    target: float | None = None
    speed: float = DEFAULT_SPEED
    jog: float = 0.0


class VirtualGimbal:
    """Kinematics of two axes moving at constant speed toward targets or jogging."""

    def __init__(self) -> None:
        self.axes = {name: _Axis() for name in JOINTS}
        self.faults = 0
        self.lock = threading.Lock()
        self._last = time.monotonic()

    def step(self) -> None:
        now = time.monotonic()
        dt, self._last = now - self._last, now
        for axis in self.axes.values():
            if axis.target is not None:
                error = axis.target - axis.position
                move = math.copysign(min(abs(error), axis.speed * dt), error)
                axis.position += move
                axis.velocity = move / dt if dt > 0 else 0.0
                if abs(axis.target - axis.position) < 1e-9:
                    axis.target, axis.velocity = None, 0.0
            else:
                axis.position += axis.jog * dt
                axis.velocity = axis.jog

    def handle(self, line: str) -> str:
        with self.lock:
            self.step()
            words = line.split()
            if not words:
                return 'ERR empty request'
            command, args = words[0].upper(), words[1:]
            try:
                return self._dispatch(command, args)
            except (ValueError, KeyError, IndexError) as exc:
                return f'ERR {command}: {exc}'

    def _dispatch(self, command: str, args: list[str]) -> str:
        if command == 'ID':
            return 'ID virtual-gimbal VG-0001 1.0.0'
        if command == 'GET':
            pan, tilt = self.axes['pan'], self.axes['tilt']
            moving = sum(1 << i for i, a in enumerate(self.axes.values())
                         if a.target is not None or a.jog)
            return (f'POS {pan.position:.6f} {tilt.position:.6f} {pan.velocity:.6f} '
                    f'{tilt.velocity:.6f} {moving} {self.faults}')
        if command == 'MOVE':
            axis = self.axes[args[0]]
            speed = float(args[2])
            axis.target, axis.jog = float(args[1]), 0.0
            axis.speed = speed if speed > 0 else DEFAULT_SPEED
            return 'OK'
        if command == 'JOG':
            axis = self.axes[args[0]]
            axis.target, axis.jog = None, float(args[1])
            return 'OK'
        if command == 'STOP':
            for name in args or JOINTS:
                axis = self.axes[name]
                axis.target, axis.jog, axis.velocity = None, 0.0, 0.0
            return 'OK'
        if command == 'HOME':
            for axis in self.axes.values():
                axis.target, axis.jog, axis.speed = 0.0, 0.0, DEFAULT_SPEED
            return 'OK'
        if command == 'RESET':
            self.faults = 0
            return 'OK'
        if command == 'FAULT':  # simulator-only: set fault bits
            self.faults = int(args[0])
            return 'OK'
        return f'ERR unknown command {command}'


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
    args = parser.parse_args(argv)
    server, _ = make_server(args.port)
    print(f'virtual_gimbal_sim listening on 127.0.0.1:{server.port}', flush=True)
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        pass
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
