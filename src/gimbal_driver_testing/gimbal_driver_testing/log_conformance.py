"""The logging part of the conformance suite: a warning the driver's *library* code logs
through Python :mod:`logging` (client, adapter, the core's session; not the node) reaches
/rosout at WARN under the node's name, its logger's name in the text.

Each driver's simulator handle says how to make its library warn on a real path and what
it then logs (:meth:`~gimbal_driver_common.sim_handle.SimHandle.provoke_library_warning`):
a link drop, bytes that do not frame, an emergency event. The bridge that carries the line
is ``gimbal_driver_common.ros.log_bridge``.
"""

from __future__ import annotations

import pytest
from rcl_interfaces.msg import Log

from gimbal_driver_common.sim_handle import LibraryWarning
from gimbal_driver_testing import wait_for
from gimbal_driver_testing.conformance_rig import OK, ConformanceHelpers, ConformanceRig

#: injections tried before the test gives up (one can race the driver's own exchange)
ATTEMPTS = 5
#: seconds each waits for its line on /rosout
WAIT_S = 10.0


def forwarded(lines: list[Log], wanted: LibraryWarning) -> Log | None:
    """The first /rosout line that is ``wanted``: its logger's name, then its text."""
    prefix = f'{wanted.logger}: '
    return next((m for m in list(lines) if m.msg.startswith(prefix) and wanted.text in m.msg),
                None)


class LogConformance(ConformanceHelpers):
    """Mixed into :class:`~gimbal_driver_testing.conformance.DriverConformance`."""

    @pytest.mark.ros
    def test_a_library_warning_reaches_rosout_under_the_node_name(
            self, rig: ConformanceRig) -> None:
        assert rig.ros is not None and rig.sim is not None
        received = rig.ros.subscribe('/rosout', Log)
        start = len(received)
        found: Log | None = None
        for _attempt in range(ATTEMPTS):
            expected = rig.sim.provoke_library_warning()
            try:
                found = wait_for(lambda wanted=expected: forwarded(received[start:], wanted),
                                 WAIT_S, f'{expected} on /rosout')
                break
            except TimeoutError:
                continue
        assert found is not None, (
            f'no {expected} on /rosout after {ATTEMPTS} tries; lines from the node: '
            f'{[m.msg for m in received[start:] if m.name == self.node_name][-10:]}')
        assert found.level == Log.WARN, found
        assert found.name == self.node_name, found
        # the device link is back (a drop) before the next test uses the shared node
        self.wait_connection(rig.ros, OK)
