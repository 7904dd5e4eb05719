"""Every driver's simulator in the test process, with what its device received.

The cross-driver process tests (``test_ros_properties.py``, ``test_crash_safety.py``) run one
node process per driver against a simulator served from the test process, so they can see the
device's receive side: every request its model handled, classified as

* *changing*: anything that moves, stops or changes the device (the property tests: a refused
  request must send none of these), and
* *motion*: what moves or stops an axis (the takeover test: a new node must not redirect or
  stop a move the device is running on its own, where the protocol lets it stay silent).

``DRIVERS`` names, per driver, the node, how to start its simulator, and the slow far move and
follow-up goal the takeover test uses (the same slow moves as each package's conformance test).
"""

from __future__ import annotations

import enum
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path


class SimDevice:
    """A simulator served from this process; subclasses start it and classify requests."""

    #: ``-p`` parameters (``name:=value``) that point the node at this simulator
    node_parameters: list[str]

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._requests: list[str] = []
        self.receptions = 0

    def _watch(self, server) -> None:
        """Count what the server receives (a byte-level hook: the node's polls show here)."""
        def received() -> None:
            with self._lock:
                self.receptions += 1

        server.add_receive_hook(received)

    def record(self, request: str) -> None:
        with self._lock:
            self._requests.append(request)

    def requests(self) -> list[str]:
        with self._lock:
            return list(self._requests)

    def mark(self) -> int:
        return len(self.requests())

    def changes_since(self, mark: int) -> list[str]:
        return [r for r in self.requests()[mark:] if self.changing(r)]

    def motions_since(self, mark: int) -> list[str]:
        return [r for r in self.requests()[mark:] if self.motion(r)]

    def changing(self, request: str) -> bool:
        raise NotImplementedError

    def motion(self, request: str) -> bool:
        raise NotImplementedError

    def moving(self, joint: str) -> bool:
        raise NotImplementedError

    def stop(self) -> None:
        raise NotImplementedError


# ----------------------------------------------------------------------------- virtual gimbal
class VirtualGimbalDevice(SimDevice):
    """Request lines; ``ID`` and ``GET`` only read."""

    READS = ('ID', 'GET')
    MOTION = ('MOVE', 'JOG', 'STOP', 'HOME')

    def __init__(self, workdir: Path) -> None:
        super().__init__()
        from gimbal_driver_common.virtual_gimbal import make_server

        self.server, self.device = make_server(0)
        self._watch(self.server)
        handle = self.device.handle

        def recorded(line: str) -> str:
            self.record(line.strip())
            return handle(line)

        self.device.handle = recorded
        self.node_parameters = [f'port:={self.server.port}']

    @staticmethod
    def _verb(line: str) -> str:
        return line.split()[0].upper() if line.split() else ''

    def changing(self, request: str) -> bool:
        return self._verb(request) not in self.READS

    def motion(self, request: str) -> bool:
        return self._verb(request) in self.MOTION

    def moving(self, joint: str) -> bool:
        with self.device.lock:
            axis = self.device.axes[joint]
            return axis.target is not None or axis.jog != 0.0

    def stop(self) -> None:
        self.server.stop()


# ----------------------------------------------------------------------------- Capture
#: commands that move or stop a Capture axis (the conformance suite's list plus the stops)
CAPTURE_MOTION = ('MOT_SendPosition', 'MOT_Update', 'MOT_SetSpeed', 'MOT_SetSpeedMode',
                  'PRST_GoToPreset', 'PRST_StopPresetLooping', 'SCN_StartScanZigZag',
                  'SCN_StartScanSnake', 'SCN_StopScan', 'DG_GoToCamera', 'MOT_Home',
                  'GPS_StopTargetLooping')
CAPTURE_AXES = {'pan': 1, 'tilt': 2}


class CaptureDevice(SimDevice):
    """Command names; a query (no argument, a returned value) and the COM_Connect handshake
    only read."""

    def __init__(self, workdir: Path) -> None:
        super().__init__()
        from capture_driver.protocol import BY_OPCODE
        from capture_driver.sim import CaptureSimulator, PedestalModel

        self.sim = CaptureSimulator(PedestalModel(), tcp_port=0).start()
        self._watch(self.sim.tcp)
        handle = self.sim.model.handle

        def recorded(frame, session):
            known = BY_OPCODE.get(frame.opcode)
            self.record(known.name if known is not None else f'0x{frame.opcode:04X}')
            return handle(frame, session)

        self.sim.model.handle = recorded
        self.node_parameters = ['transport:=tcp', 'host:=127.0.0.1',
                                f'port:={self.sim.tcp.port}', 'status_period:=0.5']

    def changing(self, request: str) -> bool:
        from capture_driver.protocol import COMMANDS, DataType

        command = COMMANDS.get(request)
        reads = command is not None and command.arg is DataType.NONE \
            and command.ret is not DataType.NONE
        return not (request == 'COM_Connect' or reads)

    def motion(self, request: str) -> bool:
        return request in CAPTURE_MOTION

    def moving(self, joint: str) -> bool:
        model = self.sim.model
        with model.lock:
            return model.axes[CAPTURE_AXES[joint]].velocity != 0.0

    def stop(self) -> None:
        self.sim.stop()


# ----------------------------------------------------------------------------- CANaerospace
class TurretDevice(SimDevice):
    """The turret's CANaerospace command messages (every one acts: set-points, stops, modes,
    controls) and node-service requests; identification (IDS) and data upload (DUS, a read
    of node memory) only read."""

    MOTION_SUFFIXES = ('_position_setpoint', '_velocity_setpoint', '_relative_setpoint',
                       '_actuator_mode')
    MOTION_KEYS = ('stop_actuators', 'restore_position')
    READ_SERVICES = ('service IDS', 'service DUS')

    def __init__(self, workdir: Path) -> None:
        super().__init__()
        from canaero_turret_driver.protocol import nodeservice
        from canaero_turret_driver.protocol.message import CanAerospaceMessage
        from canaero_turret_driver.sim import SimConfig, SlcanSession, TurretSimulator
        from gimbal_driver_common.sim_server import PtySimServer

        # the turret's set-points have no speed field (it moves at its own profile): a slow
        # yaw drive makes the takeover test's far move last
        simulator = self.simulator = TurretSimulator(SimConfig(yaw_max_velocity=11.5))
        handle = simulator.handle

        def recorded(frame):
            commands = len(simulator.received_commands)
            replies = handle(frame)
            for key, value in simulator.received_commands[commands:]:
                self.record(f'{key} {value}')
            service = nodeservice.service_channel_of(frame.arbitration_id)
            if service is not None and service[1]:  # a request
                try:
                    code = CanAerospaceMessage.from_frame(frame.arbitration_id,
                                                          frame.data).service_code
                    self.record(f'service {nodeservice.ServiceCode(code).name}')
                except ValueError:
                    self.record(f'service {frame.data.hex()}')
            return replies

        simulator.handle = recorded
        link = str(workdir / 'turret_tty')
        self.server = PtySimServer(lambda: SlcanSession(simulator), link_path=link).start()
        self._watch(self.server)
        # actuator_mode stays at its default (unset): a node that sets it at activate
        # re-initialises the drives, which stops a move in progress (see the README)
        self.node_parameters = [
            'can_interface:=slcan', f'can_channel:={link}',
            "can_options:=['sleep_after_open=0']", 'service_timeout:=0.3',
            'node_timeout:=0.6', 'stale_timeout:=0.6']

    def changing(self, request: str) -> bool:
        return request not in self.READ_SERVICES

    def motion(self, request: str) -> bool:
        key = request.split()[0]
        return key.endswith(self.MOTION_SUFFIXES) or key in self.MOTION_KEYS

    def moving(self, joint: str) -> bool:
        return self.simulator.state()['axes'][joint]['velocity'] != 0.0

    def stop(self) -> None:
        self.server.stop()


# ----------------------------------------------------------------------------- Kessler
KOS_PASSWORD = 'Zq8-kos-property'


class KesslerDevice(SimDevice):
    """kOS message types; Get* requests and the password handshake only read, every Action
    (moves, stops, playback, resets) is motion."""

    READS = ('UserPassword', 'DevicePassword')

    def __init__(self, workdir: Path) -> None:
        super().__init__()
        from kessler_kos_driver.protocol import messages
        from kessler_kos_driver.sim import KosSimulator, SimSettings

        self.actions = {name for name, value in vars(messages).items()
                        if isinstance(value, type) and issubclass(value, messages.Action)}
        self.sim = KosSimulator(SimSettings(password=KOS_PASSWORD, precalibrated=True,
                                            time_scale=2.0), port=0, discovery_port=0)
        handle = self.sim.device.handle

        def recorded(message, frame, session):
            self.record(type(message).__name__)
            return handle(message, frame, session)

        self.sim.device.handle = recorded
        self.sim.start()
        self._watch(self.sim.server)
        self.node_parameters = ['host:=127.0.0.1', f'port:={self.sim.port}',
                                f'password:={KOS_PASSWORD}']

    def changing(self, request: str) -> bool:
        return not (request.startswith('Get') or request in self.READS)

    def motion(self, request: str) -> bool:
        return request in self.actions

    def moving(self, joint: str) -> bool:
        device = self.sim.device
        with device.lock:
            motor = next(m for m in device.motors.values() if m.role == joint)
            return motor.moving or abs(motor.velocity) > 1e-9

    def stop(self) -> None:
        self.sim.stop()


# ----------------------------------------------------------------------------- U-Camera
class UCameraDevice(SimDevice):
    """UCSP packets. The driver re-sends mode and angles/rates at ``refresh_rate``, so a packet
    counts as changing when it changed what the gimbal was told (mode, angle target, rates,
    zoom, settings, a non-volatile save): a refresh of the same values changes nothing."""

    MOTION = ('SetMode', 'SetAngles', 'SetRates')

    def __init__(self, workdir: Path) -> None:
        super().__init__()
        from ucamera_driver.sim import SimConfig, UCameraSim

        link = str(workdir / 'ucamera_tty')
        self.sim = UCameraSim(SimConfig(init_time=0.1, max_rate=math.radians(180.0),
                                        acceleration=math.radians(1800.0)), link_path=link)
        model = self.sim.model
        handle = model.handle

        def commanded() -> tuple:
            return (model.mode, model.angles_target, model.commanded_angles,
                    model.commanded_rates, model.zoom_target, model.telemetry_rate,
                    model.gps_feed, model.antenna, model.ir_palette, model.nv_saves,
                    model.ffc_saves)

        def recorded(packet):
            with model.lock:
                before = commanded()
                answers = handle(packet)
                changed = commanded() != before
            self.record(f'{type(packet).__name__} {"changed" if changed else "same"}')
            return answers

        model.handle = recorded
        self.sim.start()
        self._watch(self.sim.server)
        self.node_parameters = [f'serial_port:={link}', 'silence_timeout:=0.5']

    def changing(self, request: str) -> bool:
        return request.endswith(' changed')

    def motion(self, request: str) -> bool:
        return self.changing(request) and request.split()[0] in self.MOTION

    def moving(self, joint: str) -> bool:
        model = self.sim.model
        with model.lock:
            return abs(getattr(model, joint).velocity) > 1e-6

    def stop(self) -> None:
        self.sim.stop()


# ----------------------------------------------------------------------------- the drivers
class Takeover(enum.Enum):
    """What happens to a slow move when its node is SIGKILLed and a new node starts."""

    #: the device runs the move on; the new node sends no motion command of its own
    RUNS_ON = 'runs on'
    #: the device runs the move on until the new node connects: the protocol's connect
    #: handshake itself stops the axes (Capture COM_Connect, spec 4.6.2: "position mode,
    #: relative with speed set to 0")
    STOPS_ON_CONNECT = 'stops on connect'
    #: the slow move is the driver's own ramp of set-points (U-Camera has no speed input):
    #: the device stops at the last set-point the killed node sent
    STOPS_WITH_NODE = 'stops with the node'


@dataclass(frozen=True)
class Driver:
    """One driver as the cross-driver process tests run it."""

    package: str
    executable: str
    node_name: str
    start_device: Callable[[Path], SimDevice]
    #: (joint, target, speed) of a slow far move the device runs for tens of seconds (the
    #: speed is the device's: the turret's own profile runs at 11.5 deg/s = 0.2 rad/s)
    far_move: tuple[str, float, float]
    #: a reachable MoveTo goal (joint -> rad) after a takeover
    goal: dict[str, float]
    takeover: Takeover = Takeover.RUNS_ON
    #: preset calls that are valid with nothing stored: (service, index; None = any index),
    #: for presets the device keeps itself (clearing an empty Capture slot is a no-op; turret
    #: preset 0 is its remembered position, recalled as it is)
    valid_preset_calls: tuple[tuple[str, int | None], ...] = ()

    def preset_call_valid(self, service: str, index: int) -> bool:
        return any(name == service and slot in (None, index)
                   for name, slot in self.valid_preset_calls)


DRIVERS: dict[str, Driver] = {
    'virtual_gimbal': Driver('gimbal_driver_common', 'virtual_gimbal_node', 'virtual_gimbal',
                             VirtualGimbalDevice, ('pan', 2.5, 0.25),
                             {'pan': 0.2, 'tilt': -0.1}),
    'capture': Driver('capture_driver', 'capture_driver_node', 'capture_driver', CaptureDevice,
                      ('pan', 2.5, 0.1), {'pan': 0.2, 'tilt': -0.1}, Takeover.STOPS_ON_CONNECT,
                      valid_preset_calls=(('clear_preset', None),)),
    'canaero_turret': Driver('canaero_turret_driver', 'canaero_turret_driver_node',
                             'canaero_turret_driver', TurretDevice, ('yaw', 2.5, 0.2),
                             {'yaw': 0.2, 'pitch': 0.1},
                             valid_preset_calls=(('clear_preset', 0), ('goto_preset', 0))),
    'kessler_kos': Driver('kessler_kos_driver', 'kessler_kos_driver_node', 'kessler_kos_driver',
                          KesslerDevice, ('pan', 600.0, 5.0), {'pan': 20.0, 'tilt': -20.0}),
    'ucamera': Driver('ucamera_driver', 'ucamera_driver_node', 'ucamera_driver', UCameraDevice,
                      ('pan', 2.5, 0.2), {'pan': 0.2, 'tilt': -0.1}, Takeover.STOPS_WITH_NODE),
}
