"""kOS device functions in SI (no ROS): calibration (begin and end marks, axis reset),
TakePicture, LEDStatus, SoftwareID and the aux inputs. A part of
:class:`~.device.KosDevice` (its ``functions`` attribute), kept apart so the adapter's core
(conversion, link, motion, refusals) reads in one sitting; the node's services call these
through ``controller.call``. It is handed the client, the joint table and the adapter's SI
conversion, idle check and calibration log (:class:`CalibrationSide`), and owns the device
settings it last read (LEDs, SoftwareID) for the diagnostics.
"""

from __future__ import annotations

import logging
from typing import Protocol

from gimbal_driver_common.errors import GimbalError, InvalidRequest

from .client import KosClient
from .moves import JointMapping
from .protocol import LedState

LED_NAMES = {int(state): state.name.lower() for state in LedState}

LOG = logging.getLogger('kessler_kos_driver.device')


class CalibrationSide(Protocol):
    """What the functions use of the adapter (:class:`~.device.KosDevice`)."""

    def to_si(self, joint: str, rotations: float) -> float:
        """A position in rotations as SI."""

    def require_idle(self) -> None:
        """Refuse while a move plays."""

    def note_calibration(self) -> None:
        """Log each change of a joint's end mark (the joint's units follow it)."""


class KosFunctions:
    """Calibration, camera, LED and SoftwareID requests of :class:`~.device.KosDevice`."""

    def __init__(self, client: KosClient, joints: dict[str, JointMapping],
                 adapter: CalibrationSide) -> None:
        self.client = client
        self.joints = joints  # the adapter's table (it changes units in place)
        self.adapter = adapter
        #: LEDStatus / SoftwareID as last read (connect, ~/command), for diagnostics
        self.device_settings: dict[str, str] = {}

    def read_device_settings(self) -> None:
        """LEDStatus and SoftwareID once per connection, for diagnostics."""
        self.device_settings.clear()
        try:
            self._remember_leds(*self.client.commands.led_status())
            self.software_id()
        except GimbalError as exc:
            LOG.warning('cannot read LEDStatus/SoftwareID: %s', exc)

    # ---------------------------------------------------- calibration, camera
    def mark_begin(self, joint: str) -> None:
        self.adapter.require_idle()
        self.client.commands.mark_begin(self._mapping(joint).address)

    def mark_end(self, joint: str) -> tuple[float, float]:
        """MarkEndPosition, then MotorInfo read again: the new end mark sets the joint's
        conversion (its span over the end); the calibrated (begin, end) in SI."""
        self.adapter.require_idle()
        client = self.client
        address = self._mapping(joint).address
        client.commands.mark_end(address)
        client.refresh_motors()
        self.adapter.note_calibration()
        motor = client.motor(address)
        to_si = self.adapter.to_si
        return to_si(joint, motor.begin_position), to_si(joint, motor.end_position)

    def reset_axis(self, joint: str) -> None:
        self.adapter.require_idle()
        self.client.commands.reset_axis(self._mapping(joint).address)

    def _mapping(self, joint: str) -> JointMapping:
        mapping = self.joints.get(joint)
        if mapping is None:
            raise InvalidRequest(f'unknown joint {joint!r}; this device has {list(self.joints)}')
        return mapping

    def take_picture(self, exposure: float) -> None:
        self.client.commands.take_picture(exposure)

    # --------------------------------------------------------- LEDs, SoftwareID
    def _remember_leds(self, master: int, slave: int) -> tuple[str, str]:
        names = LED_NAMES.get(master, str(master)), LED_NAMES.get(slave, str(slave))
        self.device_settings['led_master'], self.device_settings['led_slave'] = names
        return names

    def led_status(self) -> tuple[str, str]:
        """(master, slave) LED states by name."""
        return self._remember_leds(*self.client.commands.led_status())

    def set_led_status(self, master: int, slave: int) -> tuple[str, str]:
        return self._remember_leds(*self.client.commands.set_led_status(master, slave))

    def software_id(self) -> int:
        value = self.client.commands.software_id()
        self.device_settings['last_client_software_id'] = str(value)
        return value

    def set_software_id(self, platform: int) -> int:
        value = self.client.commands.set_software_id(platform)
        self.device_settings['last_client_software_id'] = str(value)
        return value

    @property
    def aux_inputs(self) -> int:
        return self.client.aux_inputs
