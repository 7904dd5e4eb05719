"""kOS over USB HID as a ByteStream (no ROS): reports, reassembly and the 4 s keep-alive.

The HID library is cython-hidapi (PyPI `hidapi`; rosdep key `python3-hidapi`, Debian/Ubuntu
`python3-hid`). It ships two modules with the same API: `hidraw` (Linux /dev/hidraw*, the
kernel's usbhid driver stays bound; the default) and `hid` (libusb on Linux, which detaches
the kernel driver and needs access to /dev/bus/usb; the native backend elsewhere). The module
is imported when a link is opened, so TCP users do not need it. Tests inject any object with
the methods of `hid.device` that this module uses (`open`, `open_path`, `read`, `write`,
`close`) through `device_factory`; the simulator offers one (`sim.SimHidDevice`).

`close()` waits for a read or write in progress (hidapi frees the device on close).
The keep-alive thread writes the document's six-byte keep-alive every `keepalive_period`
whatever else is sent ("must be sent every 4 seconds"). Writes from the client and from the
keep-alive thread are serialised so the reports of one message are never interleaved.
"""

from __future__ import annotations

import contextlib
import importlib
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from gimbal_driver_common.transport import ByteStream, LinkClosed, TransportError

from .protocol.usb import (
    REPORT_SIZE,
    USB_KEEPALIVE,
    USB_KEEPALIVE_PERIOD_S,
    ReportReassembler,
    encode_reports,
)


class HidDevice(Protocol):
    """The part of cython-hidapi's `hid.device` this link uses."""

    def open(self, vendor_id: int = 0, product_id: int = 0,
             serial_number: str | None = None) -> None: ...
    def open_path(self, path: bytes) -> None: ...
    def read(self, max_length: int, timeout_ms: int = 0) -> list[int]: ...
    def write(self, buff: Any) -> int: ...
    def close(self) -> None: ...


USB_BACKENDS = {'hidraw': 'hidraw', 'libusb': 'hid'}   # backend name -> cython-hidapi module


def hidapi_device(backend: str = 'hidraw') -> HidDevice:
    """A `device` of cython-hidapi's module for `backend` (not opened yet)."""
    module_name = USB_BACKENDS.get(backend)
    if module_name is None:
        raise TransportError(f'USB backend {backend!r} is not one of {sorted(USB_BACKENDS)}')
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:   # the wheel is in requirements.txt; a ROS install needs it too
        raise TransportError(f'USB backend {backend} needs the hidapi Python package (module '
                             f'"{module_name}"): {exc}') from exc
    return module.device()


@dataclass(frozen=True)
class UsbTarget:
    """Which HID device to open: a hidraw/HID path, or vendor/product id (+ serial)."""

    vendor_id: int = 0
    product_id: int = 0
    serial_number: str = ''
    path: str = ''                 # as hid.enumerate() lists it for the backend
    backend: str = 'hidraw'        # 'hidraw' or 'libusb' (see USB_BACKENDS)

    def describe(self) -> str:
        if self.path:
            return f'usb://{self.path}'
        serial = f'/{self.serial_number}' if self.serial_number else ''
        return f'usb://{self.vendor_id:04x}:{self.product_id:04x}{serial}'

    def check(self) -> None:
        if self.backend not in USB_BACKENDS:
            raise ValueError(f'backend {self.backend!r} is not one of {sorted(USB_BACKENDS)}')
        if self.path:
            return
        if not (0 < self.vendor_id <= 0xFFFF and 0 < self.product_id <= 0xFFFF):
            raise ValueError('USB needs a device path or both vendor and product id in '
                             f'1..0xFFFF, got {self.vendor_id:#x}:{self.product_id:#x}')


class HidStream(ByteStream):
    """A kOS device on USB HID, seen as the byte stream of kOS messages it carries."""

    def __init__(
        self,
        target: UsbTarget,
        keepalive_period: float = USB_KEEPALIVE_PERIOD_S,
        report_size: int = REPORT_SIZE,
        device_factory: Callable[[], HidDevice] | None = None,
    ) -> None:
        target.check()
        encode_reports(b'', report_size)   # validates report_size
        self.target = target
        self.keepalive_period = keepalive_period
        self.report_size = report_size
        self._device_factory = device_factory or (lambda: hidapi_device(target.backend))
        self._device: HidDevice | None = None
        self._write_lock = threading.Lock()
        # hidapi frees the device in close(): a read or write still running in another
        # thread must finish first (reads are bounded by their timeout).
        self._read_lock = threading.Lock()
        self._reassembler = ReportReassembler()
        self._pending = b''
        self._keepalive_stop = threading.Event()
        self._keepalive_thread: threading.Thread | None = None
        self._failure = ''
        self.keepalives_sent = 0

    @property
    def description(self) -> str:
        return self.target.describe()

    @property
    def is_open(self) -> bool:
        return self._device is not None

    @property
    def dropped_reports(self) -> int:
        return self._reassembler.dropped_reports

    def open(self) -> None:
        self.close()
        device = self._device_factory()   # may raise TransportError (library missing)
        try:
            if self.target.path:
                device.open_path(self.target.path.encode())
            else:
                device.open(self.target.vendor_id, self.target.product_id,
                            self.target.serial_number or None)
        except (OSError, ValueError) as exc:
            raise TransportError(f'cannot open {self.description}: {exc} (device plugged in? '
                                 'permission on /dev/hidraw*?)') from exc
        self._device = device
        self._reassembler.reset()
        self._pending = b''
        self._failure = ''
        self._keepalive_stop = threading.Event()
        if self.keepalive_period > 0:
            self._keepalive_thread = threading.Thread(
                target=self._keepalive_loop, args=(self._keepalive_stop,),
                name='kos-usb-keepalive', daemon=True)
            self._keepalive_thread.start()

    def close(self) -> None:
        self._keepalive_stop.set()
        thread, self._keepalive_thread = self._keepalive_thread, None
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=2.0)
        with self._read_lock, self._write_lock:
            device, self._device = self._device, None
        if device is not None:
            with contextlib.suppress(OSError, ValueError):
                device.close()

    def _require(self) -> HidDevice:
        device = self._device
        if device is None:
            raise LinkClosed(f'{self.description} is not open'
                             + (f' ({self._failure})' if self._failure else ''))
        if self._failure:
            raise LinkClosed(f'{self.description}: {self._failure}')
        return device

    def _write_message(self, data: bytes) -> None:
        with self._write_lock:
            device = self._require()
            for report in encode_reports(data, self.report_size):
                try:
                    written = device.write(report)
                except (OSError, ValueError) as exc:
                    raise LinkClosed(f'write to {self.description} failed: {exc}') from exc
                if written is not None and written < 0:
                    raise LinkClosed(f'write to {self.description} failed (hidapi returned '
                                     f'{written})')

    def write(self, data: bytes) -> None:
        self._write_message(bytes(data))

    def send_keepalive(self) -> None:
        self._write_message(USB_KEEPALIVE)
        self.keepalives_sent += 1

    def _keepalive_loop(self, stop: threading.Event) -> None:
        while not stop.wait(self.keepalive_period):
            try:
                self.send_keepalive()
            except TransportError as exc:
                self._failure = f'keep-alive failed: {exc}'
                return

    def read(self, max_bytes: int, timeout: float) -> bytes:
        if not self._pending:
            with self._read_lock:
                device = self._require()
                try:
                    report = device.read(self.report_size, max(int(timeout * 1000), 1))
                except (OSError, ValueError) as exc:
                    raise LinkClosed(f'read from {self.description} failed: {exc}') from exc
            if not report:
                return b''
            self._pending = self._reassembler.feed(bytes(report))
        data, self._pending = self._pending[:max_bytes], self._pending[max_bytes:]
        return data
