"""The turret client's errors, configuration, samples and counters (no ROS)."""

from __future__ import annotations

from dataclasses import dataclass, field

from gimbal_driver_common import errors

from .protocol import nodeservice as ns
from .protocol.identifiers import (
    BASE_GNSS_NODE_ID,
    COVER_NODE_ID,
    DEFAULT_ZOOM_POSITION_ID,
    MASTER_NODE_ID,
    ROVER_GNSS_NODE_ID,
    TURRET_NODE_ID,
    ZOOM_NODE_ID,
)


class TurretError(errors.GimbalError):
    """Base of the client's errors; the message is meant for a person."""


class LinkError(TurretError, errors.LinkError):
    """The CAN interface is not open or failed while sending."""


class CommandError(TurretError, errors.InvalidRequest):
    """A command was refused before anything was sent."""


class ServiceError(TurretError):
    """A node-service request failed (no response, or a negative status)."""


class ServiceRefused(ServiceError, errors.DeviceRefused):
    """A node answered a node-service request with a negative status."""


class ServiceTimeout(ServiceError, errors.DeviceTimeout):
    """A node did not answer a node-service request (or stopped answering mid-transfer)."""


class NotAllowedError(TurretError, errors.DeviceRefused):
    """A persistent or identity-changing service was not enabled by configuration."""


@dataclass
class ClientConfig:
    interface: str = "socketcan"
    channel: str = "can0"
    bitrate: int | None = None
    bus_options: dict[str, object] = field(default_factory=dict)
    client_node_id: int = MASTER_NODE_ID
    turret_node_id: int = TURRET_NODE_ID
    cover_node_id: int = COVER_NODE_ID
    rover_gnss_node_id: int = ROVER_GNSS_NODE_ID
    base_gnss_node_id: int = BASE_GNSS_NODE_ID
    zoom_node_id: int = ZOOM_NODE_ID
    zoom_position_id: int = DEFAULT_ZOOM_POSITION_ID
    service_channel: int = 0
    service_timeout: float = ns.SERVICE_RESPONSE_TIMEOUT_S
    service_attempts: int = 3
    stale_timeout: float = 1.0
    node_timeout: float = 1.0
    # Drop the interface (connected -> False, the supervisor reopens it) when no frame at
    # all arrived for this long (0 = never). Some transports (a socketcand TCP link that
    # the peer closed, a wedged USB adapter) go quiet instead of raising; a CAN bus with a
    # broadcasting turret is never quiet.
    reopen_after_silence: float = 0.0
    pad_frames: bool = False
    allow_node_id_change: bool = False
    allow_flash_programming: bool = False
    # DDS/DUS data messages count from 0 or from 1 (the ICD does not say, see nodeservice)
    transfer_first_number: int = ns.DEFAULT_FIRST_NUMBER


@dataclass(frozen=True)
class Sample:
    """The latest value of one data identifier."""

    key: str
    value: object  # as decoded: the ICD's units (the adapter converts, readings.si)
    stamp: float  # wall-clock time of arrival (for ROS headers)
    received: float  # monotonic time of arrival (for staleness)
    message_code: int
    node_id: int

    @property
    def integer(self) -> int:
        """The value of an integer identifier (a status byte, a mode, flags). The client
        caches a value only when its data type is the identifier's in the ICD, so anything
        else here is a wrong key, not a device fault."""
        value = self.value
        if isinstance(value, bool) or not isinstance(value, int):
            raise TypeError(f"{self.key} carries {type(value).__name__}, not an integer")
        return value


@dataclass
class Counters:
    frames: int = 0
    malformed: int = 0
    unknown: int = 0
    foreign_node: int = 0
    type_mismatch: int = 0
    eed: int = 0
    bus_errors: int = 0
    reconnects: int = 0
    last_malformed: str = ""
