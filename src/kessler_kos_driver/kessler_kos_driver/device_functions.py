"""kOS device functions in SI (no ROS): calibration (begin and end marks, axis reset),
TakePicture, LEDStatus, SoftwareID and the aux inputs. A mixin of
:class:`~.device.KosDevice`, kept apart so the adapter's core (conversion, link, motion,
refusals) reads in one sitting; the node's services call these through
``controller.call``.
"""

from __future__ import annotations

from gimbal_driver_common.errors import InvalidRequest

from .client import KosClient
from .moves import JointMapping
from .protocol import LedState

LED_NAMES = {int(state): state.name.lower() for state in LedState}


class KosFunctions:
    """Calibration, camera, LED and SoftwareID requests of :class:`~.device.KosDevice` (a
    mixin: the device provides ``client``, ``joints``, ``device_settings``, the SI
    conversion and ``require_idle``)."""

    client: KosClient
    joints: dict[str, JointMapping]
    device_settings: dict[str, str]

    # ---------------------------------------------------- calibration, camera
    def mark_begin(self, joint: str) -> None:
        self.require_idle()
        self.client.mark_begin(self._mapping(joint).address)

    def mark_end(self, joint: str) -> tuple[float, float]:
        """MarkEndPosition, then MotorInfo read again: the new end mark sets the joint's
        conversion (its span over the end); the calibrated (begin, end) in SI."""
        self.require_idle()
        client = self.client
        address = self._mapping(joint).address
        client.mark_end(address)
        client.refresh_motors()
        self._note_calibration()
        motor = client.motor(address)
        return self.to_si(joint, motor.begin_position), self.to_si(joint, motor.end_position)

    def reset_axis(self, joint: str) -> None:
        self.require_idle()
        self.client.reset_axis(self._mapping(joint).address)

    def _mapping(self, joint: str) -> JointMapping:
        mapping = self.joints.get(joint)
        if mapping is None:
            raise InvalidRequest(f'unknown joint {joint!r}; this device has {list(self.joints)}')
        return mapping

    def take_picture(self, exposure: float) -> None:
        self.client.take_picture(exposure)

    # --------------------------------------------------------- LEDs, SoftwareID
    def _remember_leds(self, master: int, slave: int) -> tuple[str, str]:
        names = LED_NAMES.get(master, str(master)), LED_NAMES.get(slave, str(slave))
        self.device_settings['led_master'], self.device_settings['led_slave'] = names
        return names

    def led_status(self) -> tuple[str, str]:
        """(master, slave) LED states by name."""
        return self._remember_leds(*self.client.led_status())

    def set_led_status(self, master: int, slave: int) -> tuple[str, str]:
        return self._remember_leds(*self.client.set_led_status(master, slave))

    def software_id(self) -> int:
        value = self.client.software_id()
        self.device_settings['last_client_software_id'] = str(value)
        return value

    def set_software_id(self, platform: int) -> int:
        value = self.client.set_software_id(platform)
        self.device_settings['last_client_software_id'] = str(value)
        return value

    @property
    def aux_inputs(self) -> int:
        return self.client.aux_inputs
