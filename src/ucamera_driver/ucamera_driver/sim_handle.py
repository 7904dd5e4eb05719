"""The U-Camera simulator on a pty in the caller's process: its faults (soak) and its
receive side (the cross-driver process tests)."""

from __future__ import annotations

import math
import random
import time
from pathlib import Path
from typing import Any

from gimbal_driver_common.registry import DriverSpec
from gimbal_driver_common.sim_control import SimControl
from gimbal_driver_common.sim_handle import LibraryWarning, SimHandle, Takeover


class UCameraSimHandle(SimHandle):
    """The receive side logs UCSP packets. The driver re-sends mode and angles/rates at
    ``refresh_rate``, so a packet counts as changing when it changed what the gimbal was
    told (mode, angle target, rates, zoom, settings, a non-volatile save): a refresh of the
    same values changes nothing."""

    not_applicable = {
        'nack': 'UCSP has no acknowledge/negative acknowledge',
        'fault_bits': 'UCSP reports no fault register (and has no fault reset)',
    }
    far_move = ('pan', 2.5, 0.2)
    takeover = Takeover.STOPS_WITH_NODE
    stop_requests = ('SetRates', 'SetAngles')
    stop_request = 'SetRates'  # zero rates: a jog's stop
    # silence_timeout stays the driver's 1.5 s in the process tests: at 0.5 s a one-core
    # run (make test-one-core) starved the simulator or the reader for that long, the node
    # dropped the link mid-test and refused the conformance case's joint_command
    # (docs/testing.md, "On one core")
    MOTION = ('SetMode', 'SetAngles', 'SetRates')

    def __init__(self, spec: DriverSpec, workdir: Path, process_tests: bool = False) -> None:
        super().__init__(spec, workdir, process_tests)
        self.sim: Any = None   # the simulator, once start() made it

    def start(self) -> None:
        from ucamera_driver.sim import SimConfig, UCameraSim

        # process tests: a fast-settling gimbal follows the driver's own slow ramp closely,
        # and the start-up, alignment, FFC and save pauses are short
        config = SimConfig(init_time=0.1, max_rate=math.radians(180.0),
                           acceleration=math.radians(1800.0), autoalign_time=0.3,
                           ffc_time=0.3, save_pause=0.5) if self.process_tests else SimConfig()
        self.sim = UCameraSim(config, link_path=self.link)
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
        self._started(self.sim.server, self.sim)

    def changing(self, request: str) -> bool:
        return request.endswith(' changed')

    def motion(self, request: str) -> bool:
        return self.changing(request) and request.split()[0] in self.MOTION

    def moving(self, joint: str) -> bool:
        model = self.sim.model
        with model.lock:
            return abs(getattr(model, joint).velocity) > 1e-6

    def device_target(self, joint: str) -> float | None:
        """The last commanded angle (rad) of ``joint``, as the gimbal model holds it."""
        return self.sim.model.commanded_angles[self.spec.joints.index(joint)]

    def set_gnss(self, latitude: float, longitude: float, altitude: float) -> None:
        """The on-board GPS position (deg, deg, m) the System Position Report gives."""
        self.control(f'gnss {latitude!r} {longitude!r} {altitude!r}')

    def vehicle_angles(self) -> tuple[float, float, float] | None:
        """(yaw, pitch, roll) rad, NED/FRD, the last Send Vehicle Angles the gimbal got."""
        with self.sim.model.lock:
            return self.sim.model.vehicle_angles

    def axis_limits(self, joint: str) -> tuple[float, float]:
        model = self.sim.model
        with model.lock:  # rad; the gimbal has no speed input: its own rate and acceleration
            axis = getattr(model, joint)
            return axis.move_speed, axis.acceleration

    def controls(self) -> SimControl:
        return self.sim.controls

    def garbage(self, rng: random.Random) -> None:
        # noise with false 0xCC syncs (a random run rarely looks like a frame start)
        self.control(f'noise {rng.randrange(16, 200)}')

    def lost_frames(self, rng: random.Random) -> None:
        self.sim.drop_frames(0.3)
        time.sleep(1.0)
        self.sim.drop_frames(0.0)

    def malformed_frames(self, rng: random.Random) -> None:
        self.sim.corrupt(next_frames=rng.randrange(1, 8))

    def provoke_library_warning(self) -> LibraryWarning:
        # the pty goes away under the reader: the core's session reports the loss
        self.drop_link(0.5)
        return LibraryWarning('gimbal_driver_common.session', str(self.link))
