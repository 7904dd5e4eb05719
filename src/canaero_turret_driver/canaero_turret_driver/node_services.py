"""The turret's node services by name (no ROS): ``~/device_command`` (identify,
intervals, memory upload and download, node-id and flash writes behind their opt-ins) and
the node-ids in use. A part of :class:`~.device.TurretDevice` (its ``node_services``
attribute), handed the client, the data-download opt-in and the adapter's logger.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from gimbal_driver_common.errors import DeviceRefused

from .client import CommandError, TurretClient

#: node-id parameter name -> the ClientConfig field it sets
NODE_ID_FIELDS = ("turret_node_id", "cover_node_id", "rover_gnss_node_id",
                  "base_gnss_node_id", "zoom_node_id")
DEVICE_COMMANDS = ("identify", "set_interval", "upload", "download", "set_node_id",
                   "store_configuration")


class TurretNodeServices:
    """``~/device_command`` of :class:`~.device.TurretDevice`."""

    def __init__(self, client: TurretClient, allow_data_download: Callable[[], bool],
                 warn: Callable[[str], object]) -> None:
        self.client = client
        self._allow_data_download = allow_data_download  # a run-time setting: asked each time
        self._warn = warn

    def node_ids(self) -> dict[str, int]:
        """The node-ids in use (NIS through device_command changes them)."""
        return {name: getattr(self.client.config, name) for name in NODE_ID_FIELDS}

    def device_command(self, command: str, args: Sequence[str]) -> tuple[str, list[str]]:
        """`~/device_command`: the node services by name; returns (message, results).

        identify [node-id] | set_interval <key> <ms> | upload <memid> <length> |
        download <memid> <hex> | set_node_id <new> [node-id] |
        store_configuration <security code> [node-id]. NIS and FPS need their opt-in in
        the client config, DDS (download) `allow_data_download`.
        """
        client = self.client
        args = list(args)
        command = command.strip()

        def number(text: str) -> int:
            try:
                return int(text, 0)
            except ValueError as exc:
                raise CommandError(f"{text!r} is not an integer") from exc

        if command == "identify":
            info = client.services.identify(number(args[0]) if args else None)
            return "IDS answered", [
                f"hardware_revision={info.hardware_revision}",
                f"software_revision={info.software_revision}",
                f"identifier_distribution={info.identifier_distribution}",
                f"header_type={info.header_type}"]
        if command == "set_interval":
            if len(args) != 2:
                raise CommandError("set_interval needs <data key> <ms>")
            client.services.set_transmission_interval(args[0], number(args[1]))
            return f"{args[0]} every {number(args[1])} ms", []
        if command == "set_node_id":
            if not args:
                raise CommandError("set_node_id needs <new node-id> [node-id]")
            node = number(args[1]) if len(args) > 1 else client.config.turret_node_id
            new_id = number(args[0])
            client.services.set_node_id(new_id, node)
            self._warn(
                f"node {node} now has node-id {new_id}; put it in the parameter file, and "
                "store it with store_configuration (FPS) to keep it after a power cycle")
            return f"node-id {node} changed to {new_id}", []
        if command == "upload":
            if len(args) != 2:
                raise CommandError("upload needs <memory id> <length in bytes>")
            data = client.services.upload(number(args[0]), number(args[1]))
            return f"{len(data)} bytes read from memory {number(args[0])} (DUS)", [data.hex()]
        if command == "download":
            if not self._allow_data_download():
                raise DeviceRefused("data download (DDS) writes device memory and is "
                                    "disabled; set allow_data_download to use it")
            if len(args) != 2:
                raise CommandError("download needs <memory id> <hex bytes>")
            try:
                data = bytes.fromhex(args[1])
            except ValueError as exc:
                raise CommandError(f"{args[1]!r} is not hex bytes") from exc
            checksum = client.services.download(number(args[0]), data)
            return (f"{len(data)} bytes written to memory {number(args[0])} (DDS)",
                    [f"checksum={checksum}"])
        if command == "store_configuration":
            if not args:
                raise CommandError("store_configuration needs <security code>")
            client.services.store_configuration(number(args[0]),
                                                number(args[1]) if len(args) > 1 else None)
            return "configuration stored in flash", []
        raise CommandError(f"unknown command {command!r}; commands: "
                           + ", ".join(DEVICE_COMMANDS))
