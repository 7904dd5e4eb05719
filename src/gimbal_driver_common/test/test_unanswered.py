"""The book of unanswered requests: counted by name, a doubling back-off, cleared by an answer."""

from __future__ import annotations

import pytest

from gimbal_driver_common.errors import DeviceTimeout
from gimbal_driver_common.unanswered import BackingOff, ConnectReads, Unanswered
from gimbal_driver_testing import ManualClock


def test_the_back_off_doubles_with_every_timeout_in_a_row_up_to_the_longest() -> None:
    clock = ManualClock()
    book = Unanswered(first=1.0, longest=5.0, clock=clock)
    book.check('IMU_GetRoll')  # never unanswered: ask now
    waits = []
    for _ in range(5):
        record = book.timed_out('IMU_GetRoll')
        waits.append(record.retry_at - clock.now)
        with pytest.raises(BackingOff) as raised:
            book.check('IMU_GetRoll')
        assert isinstance(raised.value, DeviceTimeout)  # callers treat it as a timeout
        assert 'IMU_GetRoll' in str(raised.value) and 'asked again in' in str(raised.value)
        clock.now = record.retry_at  # the back-off ran out: asked again
        book.check('IMU_GetRoll')
    assert waits == [1.0, 2.0, 4.0, 5.0, 5.0]


def test_an_answer_clears_the_back_off_and_keeps_the_total() -> None:
    clock = ManualClock()
    book = Unanswered(first=1.0, longest=8.0, clock=clock)
    book.timed_out('ERR_OperationRegister')
    book.timed_out('ERR_OperationRegister')
    book.answered('ERR_OperationRegister')
    book.check('ERR_OperationRegister')
    assert book.silent() == []
    record = book.timed_out('ERR_OperationRegister')
    assert (record.in_a_row, record.total) == (1, 3)
    assert record.retry_at - clock.now == 1.0  # the back-off starts over


def test_each_request_has_its_own_record_and_diagnostics_name_it() -> None:
    clock = ManualClock()
    book = Unanswered(first=2.0, longest=8.0, clock=clock)
    book.timed_out('IMU_GetRoll')
    book.timed_out('IMU_GetRoll')
    book.timed_out('GPS_GetHeading')
    book.check('MOT_GetPosition')  # another request is not held back
    clock.now += 1.0
    assert book.diagnostics() == [
        ('unanswered.GPS_GetHeading', '1 time(s) in a row (1 in all); asked again in 1.0 s'),
        ('unanswered.IMU_GetRoll', '2 time(s) in a row (2 in all); asked again in 3.0 s'),
    ]
    book.clear()
    assert book.diagnostics() == []


def test_bad_back_off_settings_are_refused() -> None:
    with pytest.raises(ValueError):
        Unanswered(first=0.0)
    with pytest.raises(ValueError):
        Unanswered(first=5.0, longest=1.0)


def test_a_best_effort_read_at_connect_is_named_and_connecting_goes_on() -> None:
    warned: list[str] = []
    reads = ConnectReads(warned.append)

    def silent() -> str:
        raise DeviceTimeout('no reply to ID within 1 s')

    assert reads.read('ID', silent) is None
    assert reads.read('TelemetryRateRequest', lambda: 50.0) == 50.0
    assert 'ID' in reads and 'TelemetryRateRequest' not in reads and len(reads) == 1
    assert warned == ['ID unanswered at connect, connecting without it: '
                      'no reply to ID within 1 s']
    assert reads.diagnostics() == [('unanswered.ID', 'no reply to ID within 1 s')]
    assert reads.summary() == 'unanswered at connect: ID'
    with pytest.raises(ValueError):  # only the errors it is told about count as unanswered
        reads.read('GUID', lambda: int('x'))
    assert reads.read('ID', lambda: 'ID vg 1 2') == 'ID vg 1 2'  # answered: not named
    reads.missed('IDS', 'no IDS response')
    assert [key for key, _ in reads.diagnostics()] == ['unanswered.IDS']
    reads.clear()
    assert not reads and reads.summary() == ''
