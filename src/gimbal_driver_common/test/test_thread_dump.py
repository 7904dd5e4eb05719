"""A failure shows where a node's threads are: ManagedProcess.thread_dump asks a process
that registered faulthandler (as run_driver does) for its stacks, never signals one that
did not (the signal would end it), and attach_report puts the dump and log on an error."""

from __future__ import annotations

import signal
import sys
from pathlib import Path

import pytest

from gimbal_driver_testing import (
    THREAD_DUMP_SIGNAL,
    ManagedProcess,
    attach_report,
    wait_for,
)

HANGS = '''
import faulthandler, signal, sys, threading
# Ctrl-C ends it, as it does a node, even if started with SIGINT ignored (a background job)
signal.signal(signal.SIGINT, signal.default_int_handler)
if sys.argv[1] == 'dumps':
    faulthandler.register(signal.SIGUSR2, file=sys.stderr, all_threads=True)
def stuck_in_a_wait_for_the_device():
    threading.Event().wait()
threading.Thread(target=stuck_in_a_wait_for_the_device, daemon=True).start()
print('up', flush=True)
try:
    threading.Event().wait(600)  # hung until the test ends it
except KeyboardInterrupt:
    pass
'''


def test_the_signal_is_the_one_run_driver_registers() -> None:
    pytest.importorskip('rclpy')
    from gimbal_driver_common.ros import run

    assert run.THREAD_DUMP_SIGNAL == THREAD_DUMP_SIGNAL == signal.SIGUSR2


def test_a_process_with_the_handler_dumps_every_thread_into_its_log() -> None:
    with ManagedProcess([sys.executable, '-c', HANGS, 'dumps'], name='hangs') as process:
        process.wait_for_output('up')
        wait_for(lambda: process.catches(THREAD_DUMP_SIGNAL), 10.0, 'the handler')
        assert process.thread_dump()
        assert 'stuck_in_a_wait_for_the_device' in process.output()
        assert process.running
        error = AssertionError('no joint_states')
        attach_report(error, process)
        (note,) = error.__notes__
        assert 'thread dump and log of hangs' in note and process.log_path in note
        assert 'stuck_in_a_wait_for_the_device' in note
        assert ManagedProcess.live[id(process)] is process
    assert id(process) not in ManagedProcess.live
    assert Path(process.log_path).exists(), 'a log a report named went at the stop'


def test_a_stopped_process_keeps_its_output_and_leaves_no_log_file() -> None:
    with ManagedProcess([sys.executable, '-c', HANGS, 'plain'], name='plain') as process:
        process.wait_for_output('up')
    assert not Path(process.log_path).exists()
    assert process.output() == 'up\n'
    assert 'removed at its stop' in process.report()


def test_a_process_without_the_handler_is_not_signalled() -> None:
    with ManagedProcess([sys.executable, '-c', HANGS, 'plain'], name='plain') as process:
        process.wait_for_output('up')
        assert not process.catches(THREAD_DUMP_SIGNAL)
        assert not process.thread_dump()
        assert process.running
