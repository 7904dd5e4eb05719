"""A :class:`GimbalController` running with its threads, for the core's in-process tests.

Open, activate, wait for the first sample; on the way out shut it down and stop the
housekeeping and sensor threads (``shutdown`` leaves them to the node, which stops them
when it is destroyed). Written once here: the tests of the controller, its watches and its
sample paths each had a copy.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator
from typing import Any

from gimbal_driver_common.controller import ControllerConfig, GimbalController
from gimbal_driver_common.device import Device
from gimbal_driver_testing import wait_for

#: how long the first sample may take (a generous outer deadline, not a timing bound)
FIRST_SAMPLE_S = 5.0


@contextlib.contextmanager
def running_controller(device: Device, config: ControllerConfig,
                       log: logging.Logger | None = None, *, first_sample: bool = True,
                       **options: Any) -> Iterator[GimbalController]:
    """The controller of ``device``, opened and active (``options`` go to its
    constructor: ``on_sample``, ``clock``...); with ``first_sample``, once it has read one."""
    ctl = GimbalController(device, config, log or logging.getLogger('test'), **options)
    try:
        ctl.open()
        ctl.activate()
        if first_sample:
            wait_for(lambda: ctl.latest is not None, FIRST_SAMPLE_S, 'a first sample')
        yield ctl
    finally:
        ctl.shutdown()
        ctl.periodic.stop()
        ctl.sensors.stop()
