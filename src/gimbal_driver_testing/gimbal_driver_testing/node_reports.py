"""pytest plugin: a failed test shows what each process it left running was doing.

Why: a node under test that stops publishing or answering fails the test with a timeout
("no matching message on joint_states", "no reply of ~/set_emergency_stop"), and the
cause (a hung thread, a lost peer, a crash) is then in that node, not in the test. At a
failure, every :class:`~gimbal_driver_testing.ManagedProcess` of this test process
that still runs is asked for a thread dump (the driver processes register faulthandler on
:data:`~gimbal_driver_testing.THREAD_DUMP_SIGNAL`, ``ros.run.run_driver``), and its
log's tail and path are added to the report as a section of their own. Processes a ``with``
block or ``driver_rig`` stopped on the error attach theirs to the exception instead.

Load it with ``-p gimbal_driver_testing.node_reports`` (every package's pytest.ini).
"""

from __future__ import annotations

from collections.abc import Generator

import pytest

from gimbal_driver_testing import ManagedProcess


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]
                              ) -> Generator[None, pytest.TestReport, pytest.TestReport]:
    """On a failed set-up or test: each live process' thread dump and log, as sections."""
    report = yield
    if report.failed and call.when in ('setup', 'call'):
        for process in list(ManagedProcess.live.values()):
            if not process.running:
                continue
            dumped = process.thread_dump()
            title = f'{"thread dump and " if dumped else ""}log of {process.name}'
            report.sections.append((title, process.report()))
    return report
