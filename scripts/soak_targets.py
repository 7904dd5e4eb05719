"""The drivers `make soak` runs: each simulator in-process (so faults are injected through its
own API), the node as a separate process, and the faults each simulator can inject.

A fault is a function that injects it and returns when the fault has *healed* (the link is
back, the device answers again); the soak times joint_states from that moment. ``link`` marks
faults that interrupt joint_states (link drop, silence, restart): their resume time is bounded
by ``reconnect_period + 1 s``. Faults a protocol cannot carry are listed in ``not_applicable``
with the reason, so the report says what was skipped and why.
"""

from __future__ import annotations

import math
import random
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

#: seconds a link stays down / silent; long enough for each driver's link watchdog to notice
LINK_DOWN_S = 2.0
SILENCE_S = 3.0


#: fault name (= the method that injects it) -> needs ~/reset_faults afterwards
OPTIONAL_FAULTS = {'lost_frames': False, 'malformed_frames': False, 'nack': False,
                   'fault_bits': True}


@dataclass
class Fault:
    name: str
    inject: Callable[[random.Random], None]  # returns once the fault has healed
    link: bool = False                       # interrupts joint_states (resume time measured)
    reset_faults: bool = False               # needs ~/reset_faults to clear


class SimHandle:
    """One in-process simulator; subclasses build it and know its faults."""

    package = ''
    node_executable = ''
    node_name = ''
    joints: tuple[str, ...] = ()
    #: a reachable goal for the final move (rad/m, per joint)
    final_goal: dict[str, float] = {}
    #: a valid joint_command target range (rad), inside every joint's limits
    safe_range = (-0.3, 0.3)
    #: extra services (name -> type name) the random traffic calls with absurd values
    extra_services: dict[str, str] = {}
    not_applicable: dict[str, str] = {}
    #: text that must never appear in the node log (a password)
    secrets: tuple[str, ...] = ()

    def __init__(self, workdir: Path) -> None:
        self.workdir = workdir
        self._hooks: list[Callable[[], None]] = []
        self._server = None
        self._running = None

    # lifecycle of the simulator
    def start(self) -> None:
        """Build and start the simulator: set ``_server`` (its TCP/pty server, where the
        receive hooks go) and ``_running`` (what :meth:`stop` stops)."""
        raise NotImplementedError

    def stop(self) -> None:
        self._running.stop()

    def restart(self, rng: random.Random) -> None:
        """Power-cycle: the old simulator goes away, a new one serves the same address."""
        self.stop()
        time.sleep(rng.uniform(0.2, 1.0))
        self.start()

    @property
    def server(self):  # TcpSimServer | PtySimServer
        return self._server

    def add_receive_hook(self, hook: Callable[[], None]) -> None:
        """A hook on this and every later (restarted) server."""
        self._hooks.append(hook)
        self.server.add_receive_hook(hook)

    def _started(self, server, running) -> None:
        """Record a (re)started simulator; the receive hooks move to its new server."""
        self._server, self._running = server, running
        for hook in self._hooks:
            server.add_receive_hook(hook)

    def node_parameters(self) -> dict[str, object]:
        raise NotImplementedError

    # faults every server has
    def drop_link(self, rng: random.Random) -> None:
        self.server.drop_link(LINK_DOWN_S)
        time.sleep(LINK_DOWN_S)

    def silence(self, rng: random.Random) -> None:
        self.server.set_silent(True)
        time.sleep(SILENCE_S)
        self.server.set_silent(False)

    def garbage(self, rng: random.Random) -> None:
        self.server.inject(bytes(rng.randrange(256) for _ in range(rng.randrange(16, 200))))

    def faults(self) -> list[Fault]:
        """The faults every server has, plus those the subclass implements (a method named
        in OPTIONAL_FAULTS)."""
        faults = [Fault('link_drop', self.drop_link, link=True),
                  Fault('silence', self.silence, link=True),
                  Fault('garbage', self.garbage),
                  Fault('sim_restart', self.restart, link=True)]
        for name, needs_reset in OPTIONAL_FAULTS.items():
            inject = getattr(self, name, None)
            if inject is not None:
                faults.append(Fault(name, inject, reset_faults=needs_reset))
        return faults


# ----------------------------------------------------------------------------- virtual gimbal
class VirtualGimbalSim(SimHandle):
    package = 'gimbal_driver_common'
    node_executable = 'virtual_gimbal_node'
    node_name = 'virtual_gimbal'
    joints = ('pan', 'tilt')
    final_goal = {'pan': 0.4, 'tilt': -0.2}
    not_applicable = {
        'nack': 'the line protocol answers ERR only to a request; an unsolicited ERR line '
                'would be a framing fault (covered by garbage/malformed)',
        'lost_frames': 'one reply per request over TCP; a lost reply is a silence (covered)',
    }

    def __init__(self, workdir: Path) -> None:
        super().__init__(workdir)
        self.port = 0
        self.device = None

    def start(self) -> None:
        from gimbal_driver_common.virtual_gimbal import make_server

        server, self.device = make_server(self.port)
        self.port = server.port
        self._started(server, server)



    def node_parameters(self) -> dict[str, object]:
        return {'host': '127.0.0.1', 'port': self.port}

    def malformed_frames(self, rng: random.Random) -> None:
        # a reply line that does not parse (no newline: it prefixes the next real reply)
        self.server.inject(b'POS nan x')

    def fault_bits(self, rng: random.Random) -> None:
        with self.device.lock:
            self.device.faults = 1  # FAULT_OVERTEMP



# ----------------------------------------------------------------------------- Capture
class CaptureSim(SimHandle):
    package = 'capture_driver'
    node_executable = 'capture_driver_node'
    node_name = 'capture_driver'
    joints = ('pan', 'tilt')
    final_goal = {'pan': 0.4, 'tilt': -0.2}
    extra_services = {'set_stabilization': 'std_srvs/srv/SetBool',
                      'command': 'gimbal_msgs/srv/DeviceCommand'}

    def __init__(self, workdir: Path) -> None:
        super().__init__(workdir)
        self.port = 0
        self.sim = None

    def start(self) -> None:
        from capture_driver.sim import CaptureSimulator, PedestalModel

        self.sim = CaptureSimulator(PedestalModel(), tcp_port=self.port).start()
        self.port = self.sim.tcp.port
        self._started(self.sim.tcp, self.sim)



    def node_parameters(self) -> dict[str, object]:
        return {'transport': 'tcp', 'host': '127.0.0.1', 'port': self.port,
                'status_period': 0.2, 'default_speed': 1.0, 'acceleration': 6.0}

    def lost_frames(self, rng: random.Random) -> None:
        self.sim.model.lose_replies(rng.randrange(1, 4))

    def malformed_frames(self, rng: random.Random) -> None:
        from capture_driver.protocol import COMMANDS, DataType, Frame, encode_value

        opcode = COMMANDS['MOT_GetLoadPosition'].opcode
        frame = bytearray(Frame(0, 1, opcode, encode_value(DataType.F32, 12.5)).encode())
        frame[-1] ^= 0x5A  # checksum no longer matches
        self.server.inject(bytes(frame))

    def nack(self, rng: random.Random) -> None:
        self.sim.model.nack_next(count=rng.randrange(1, 4))

    def fault_bits(self, rng: random.Random) -> None:
        self.sim.model.inject_fault(rng.choice((1, 2)), 'over_current')



# ----------------------------------------------------------------------------- CANaerospace
class CanaeroSim(SimHandle):
    package = 'canaero_turret_driver'
    node_executable = 'canaero_turret_driver_node'
    node_name = 'canaero_turret_driver'
    joints = ('yaw', 'pitch')
    final_goal = {'yaw': 0.4, 'pitch': 0.2}
    safe_range = (-0.2, 0.3)
    extra_services = {'set_actuator_mode': 'gimbal_msgs/srv/SetMode',
                      'set_fan': 'std_srvs/srv/SetBool',
                      'device_command': 'gimbal_msgs/srv/DeviceCommand'}
    not_applicable = {'nack': 'CANaerospace services have no negative acknowledge the turret '
                              'sends; its error path is the EED event, injected as fault_bits'}

    def __init__(self, workdir: Path) -> None:
        super().__init__(workdir)
        self.link = str(workdir / 'canaero_tty')
        self.simulator = None

    def start(self) -> None:
        from canaero_turret_driver.sim import SimConfig, SlcanSession, TurretSimulator
        from gimbal_driver_common.sim_server import PtySimServer

        self.simulator = TurretSimulator(SimConfig())
        simulator = self.simulator
        server = PtySimServer(lambda: SlcanSession(simulator), link_path=self.link).start()
        self._started(server, server)



    def node_parameters(self) -> dict[str, object]:
        return {'can_interface': 'slcan', 'can_channel': self.link,
                'can_options': ['sleep_after_open=0'], 'service_timeout': 0.3,
                'transmission_intervals': ['yaw_position=20', 'pitch_position=20'],
                'actuator_mode': 'auto_brake'}

    def silence(self, rng: random.Random) -> None:
        self.simulator.silence_all(SILENCE_S)
        time.sleep(SILENCE_S)

    def lost_frames(self, rng: random.Random) -> None:
        self.simulator.lose_frames(rng.choice(('yaw_position', 'pitch_position')),
                                   rng.randrange(1, 6))

    def malformed_frames(self, rng: random.Random) -> None:
        self.simulator.send_malformed(rng.randrange(1, 5))

    def fault_bits(self, rng: random.Random) -> None:
        axis = rng.choice(tuple(self.simulator.axes))
        self.simulator.set_axis_fault(axis, True)
        time.sleep(0.5)
        self.simulator.set_axis_fault(axis, False)  # the cause goes away; reset_faults follows



# ----------------------------------------------------------------------------- Kessler
class KesslerSim(SimHandle):
    package = 'kessler_kos_driver'
    node_executable = 'kessler_kos_driver_node'
    node_name = 'kessler_kos_driver'
    joints = ('pan', 'tilt', 'slider')
    final_goal = {'pan': 3.0, 'tilt': -2.0}
    password = 'soak-kos-secret'
    secrets = (password,)
    extra_services = {'take_picture': 'std_srvs/srv/Trigger',
                      'stop_playback': 'std_srvs/srv/Trigger',
                      'load_trajectory': 'gimbal_msgs/srv/LoadTrajectory'}
    not_applicable = {'nack': 'kOS answers a bad request with ErrorStatus, injected as '
                              'fault_bits (device error broadcast)'}
    #: joint -> (low, high) rad inside the simulator's --precalibrated ranges
    joint_ranges = {'pan': (1.0, 20.0), 'tilt': (-20.0, -1.0), 'slider': (1.0, 20.0)}

    def __init__(self, workdir: Path) -> None:
        super().__init__(workdir)
        self.port = 0
        self.sim = None

    def start(self) -> None:
        from kessler_kos_driver.sim import KosSimulator, SimSettings

        self.sim = KosSimulator(SimSettings(password=self.password, precalibrated=True),
                                port=self.port, discovery_port=0).start()
        self.port = self.sim.port
        self._started(self.sim.server, self.sim)



    def node_parameters(self) -> dict[str, object]:
        password_file = self.workdir / 'kessler_password'
        password_file.write_text(self.password + '\n', encoding='utf-8')
        password_file.chmod(0o600)
        scale = 2 * math.pi
        return {'host': '127.0.0.1', 'port': self.port, 'password_file': str(password_file),
                'discovery_bind': '127.0.0.1', 'joint_names': list(self.joints),
                'motor_addresses': [2, 3, 1], 'joint_scales': [scale, scale, scale],
                'poll_period': 0.05}

    def malformed_frames(self, rng: random.Random) -> None:
        from kessler_kos_driver.protocol import MotorInfo, MotorInfoEntry

        frame = bytearray(MotorInfo([MotorInfoEntry(2, 1.0, 0.0, 100.0, 5.0, 5.0, 10.0)],
                                    more_follows=True).encode())
        frame[len(frame) // 2] ^= 0xFF
        self.server.inject(bytes(frame))

    def lost_frames(self, rng: random.Random) -> None:
        # replies lost for a moment, shorter than the driver's link watchdog
        self.server.set_silent(True)
        time.sleep(0.3)
        self.server.set_silent(False)

    def fault_bits(self, rng: random.Random) -> None:
        from kessler_kos_driver.protocol import ErrorStatus

        with self.sim.device.lock:
            self.sim.device.broadcast(ErrorStatus(16, 1))  # axis fault reported on the slider



# ----------------------------------------------------------------------------- U-Camera
class UCameraSoakSim(SimHandle):
    package = 'ucamera_driver'
    node_executable = 'ucamera_driver_node'
    node_name = 'ucamera_driver'
    joints = ('pan', 'tilt')
    final_goal = {'pan': 0.4, 'tilt': -0.3}
    extra_services = {'set_mode': 'gimbal_msgs/srv/SetMode',
                      'save_configuration': 'std_srvs/srv/Trigger',
                      'save_ffc': 'std_srvs/srv/Trigger'}
    not_applicable = {
        'nack': 'UCSP has no acknowledge/negative acknowledge',
        'fault_bits': 'UCSP reports no fault register (and has no fault reset)',
    }

    def __init__(self, workdir: Path) -> None:
        super().__init__(workdir)
        self.link = str(workdir / 'ucamera_tty')
        self.sim = None

    def start(self) -> None:
        from ucamera_driver.sim import SimConfig, UCameraSim

        self.sim = UCameraSim(SimConfig(), link_path=self.link).start()
        self._started(self.sim.server, self.sim)



    def node_parameters(self) -> dict[str, object]:
        return {'serial_port': self.link, 'telemetry_rate': 50, 'gps_feed': 'external'}

    def garbage(self, rng: random.Random) -> None:
        self.sim.inject_noise(rng.randrange(16, 200))

    def lost_frames(self, rng: random.Random) -> None:
        self.sim.drop_frames(0.3)
        time.sleep(1.0)
        self.sim.drop_frames(0.0)

    def malformed_frames(self, rng: random.Random) -> None:
        self.sim.corrupt(next_frames=rng.randrange(1, 8))



TARGETS: dict[str, type[SimHandle]] = {
    'virtual_gimbal': VirtualGimbalSim,
    'capture': CaptureSim,
    'canaero_turret': CanaeroSim,
    'kessler_kos': KesslerSim,
    'ucamera': UCameraSoakSim,
}


def joint_range(handle: SimHandle, joint: str) -> tuple[float, float]:
    ranges = getattr(handle, 'joint_ranges', None)
    if ranges and joint in ranges:
        return ranges[joint]
    return handle.safe_range
