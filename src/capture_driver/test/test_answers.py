"""The answer book in-process (no link): which written request each answer belongs to, and
when requests may overlap (capture_driver/answers.py)."""

from __future__ import annotations

import threading

import pytest

from capture_driver.answers import LATE_WINDOW_S, AnswerBook, Waiting
from capture_driver.errors import Preempted
from capture_driver.protocol import Frame, ReplyByte, ReplyCode, command

ACK, NACK = ReplyByte(ReplyCode.ACK), ReplyByte(ReplyCode.INVALID_COMMAND)


def getter(name: str, axis: int = 1) -> tuple[str, Frame, bool]:
    return name, command(name).frame(axis, None, 0), True


def setter(name: str, axis: int = 1, value: object = None) -> tuple[str, Frame, bool]:
    return name, command(name).frame(axis, value, 0), False


def data(name: str, axis: int = 1) -> Frame:
    return Frame(0, axis, command(name).opcode, b'\x00\x00\x00\x00')


class Wire:
    def __init__(self) -> None:
        self.writes: list[bytes] = []

    def __call__(self, data: bytes) -> None:
        self.writes.append(data)


class Clock:
    """The book's injected clock: time moves only when a test says so."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def known(book: AnswerBook, wire: Wire, *gets: tuple[str, Frame, bool]) -> None:
    """Answer ``gets`` with data once: the book then knows them as data-answered."""
    waitings = book.write(list(gets), wire, timeout=1.0) or []
    for waiting in waitings:
        book.deliver(Frame(0, waiting.frame.axis, waiting.frame.opcode, b'\x00' * 4))
        assert book.wait(waiting, 0.0) is not None


def test_data_goes_to_the_getter_of_its_opcode_and_axis_in_any_order() -> None:
    clock = Clock()
    book, wire = AnswerBook(clock), Wire()
    pan_get, tilt_get = getter('MOT_GetLoadPosition', 1), getter('MOT_GetLoadPosition', 2)
    known(book, wire, getter('IMU_GetRoll', 0), pan_get, tilt_get)
    [roll] = book.write([getter('IMU_GetRoll', 0)], wire, timeout=1.0)
    pan, tilt = book.write([pan_get, tilt_get], wire, timeout=1.0)
    assert book.deliver(data('MOT_GetLoadPosition', 2))
    assert book.deliver(data('MOT_GetLoadPosition', 1))
    assert book.wait(tilt, clock.now).axis == 2 and book.wait(pan, clock.now).axis == 1
    assert book.in_flight() == ['IMU_GetRoll']  # the slow one still waits
    assert book.wait(roll, clock.now) is None  # its deadline passed: it gives up
    assert book.late_possible
    assert not book.deliver(data('IMU_GetRoll', 0))  # the late reply: stale
    assert book.stale == 1 and not book.late_possible


def test_probe_an_any_packet_nack_for_a_known_getter_is_not_given_to_the_setter() -> None:
    """Issue 44 probe: a getter answered with data before may still be NACKed (0xF6: its
    packet came corrupted). A byte names no request, so that NACK is not the setter's
    while the getter could own it: once the setter's own ACK comes, the NACK is the
    getter's (the only candidate left)."""
    clock = Clock()
    book, wire = AnswerBook(clock), Wire()
    known(book, wire, getter('IMU_GetRoll', 0))
    [roll] = book.write([getter('IMU_GetRoll', 0)], wire, timeout=1.0)
    [speed] = book.write([setter('MOT_SetSpeed', 1, 5.0)], wire, timeout=1.0)
    checksum = ReplyByte(ReplyCode.WRONG_CHECKSUM)
    book.deliver(checksum)  # the getter's, as it happens
    book.deliver(ACK)  # the setter's
    assert book.wait(speed, clock.now) == ACK
    assert book.wait(roll, clock.now) == checksum


def test_a_nack_two_requests_could_own_names_both_when_it_stays_open() -> None:
    clock = Clock()
    book, wire = AnswerBook(clock), Wire()
    known(book, wire, getter('IMU_GetRoll', 0))
    [roll] = book.write([getter('IMU_GetRoll', 0)], wire, timeout=1.0)
    [speed] = book.write([setter('MOT_SetSpeed', 1, 5.0)], wire, timeout=1.0)
    book.deliver(ReplyByte(ReplyCode.EXECUTION_ERROR))
    assert book.wait(speed, clock.now) == ReplyByte(ReplyCode.EXECUTION_ERROR)
    assert 'IMU_GetRoll' in speed.doubt  # never given as certainly its own
    book.deliver(data('IMU_GetRoll', 0))
    assert isinstance(book.wait(roll, clock.now), Frame)


def test_probe_a_late_ack_answers_no_later_setter_and_a_stop_sees_a_real_nack() -> None:
    """Issue 44 probe: a setter that timed out may be ACKed late. The next setter is not
    written until that answer came (or the late window passed): it cannot take it. A stop
    goes out at once all the same, and owns every byte that comes while it is in flight:
    the NACK the device gave one of its steps is not lost as the late ACK's 'stale'."""
    clock = Clock()
    book, wire = AnswerBook(clock), Wire()
    [mode] = book.write([setter('MOT_SetSpeedMode', 1)], wire, timeout=1.0)
    assert book.wait(mode, clock.now) is None  # timed out: its ACK may come late
    assert book.write([setter('MOT_SetSpeed', 1, 0.0)], wire, block=False) is None
    stop = book.write([setter('MOT_SetSpeedMode', 1), setter('MOT_SetSpeed', 1, 0.0),
                       setter('MOT_Update', 1)], wire, urgent=True, block=False)
    assert stop is not None and len(wire.writes) == 2  # out at once, in one write
    for byte in (ACK, ACK, ACK, NACK):  # the late ACK first, then the stop's answers
        book.deliver(byte)
    for waiting in stop:
        book.wait(waiting, clock.now)
    exchange = stop[0].exchange
    assert exchange.whole and 'MOT_SetSpeedMode' in exchange.doubt
    assert NACK in exchange.received  # the refusal is the stop's to report


def stop_over_a_read(name: str, axis: int) -> tuple[Clock, AnswerBook, Waiting,
                                                   list[Waiting]]:
    """A getter known to answer with data waits while a stop's batch (one axis) goes out
    and is answered NACK, ACK, ACK: the NACK may be the getter's or the first step's."""
    clock = Clock()
    book, wire = AnswerBook(clock), Wire()
    known(book, wire, getter(name, axis))
    [read] = book.write([getter(name, axis)], wire, timeout=1.0)
    stop = book.write([setter('MOT_SetSpeedMode', 1), setter('MOT_SetSpeed', 1, 0.0),
                       setter('MOT_Update', 1)], wire, urgent=True) or []
    for byte in (NACK, ACK, ACK):
        book.deliver(byte)
    return clock, book, read, stop


def test_a_batch_counts_past_a_nack_a_getter_could_own_once_the_getter_has_its_data() -> None:
    """A stop's batch NACKed while the poll's getters wait: the NACK may be a getter's,
    so the batch's counting waits for it; the getters' data comes, the NACK is the
    batch's first step's for certain, and the later bytes count on from there."""
    clock, book, position, stop = stop_over_a_read('MOT_GetLoadPosition', 1)
    book.deliver(data('MOT_GetLoadPosition', 1))
    assert isinstance(book.wait(position, clock.now), Frame)
    assert [book.wait(w, clock.now) for w in stop] == [NACK, ACK, ACK]
    assert not any(w.doubt for w in stop) and not stop[0].exchange.whole


def test_a_batch_whose_nack_a_silent_getter_could_own_owns_its_bytes_as_a_whole() -> None:
    clock, book, roll, stop = stop_over_a_read('IMU_GetRoll', 0)
    assert book.wait(roll, clock.now) == NACK and 'MOT_SetSpeedMode' in roll.doubt
    for waiting in stop:
        book.wait(waiting, clock.now)
    exchange = stop[0].exchange
    assert exchange.whole and 'IMU_GetRoll' in exchange.doubt
    assert exchange.received == [NACK, ACK, ACK]  # the stop sees the NACK it may own


def test_after_a_timeout_the_late_ack_is_stale_and_the_next_setter_gets_its_own() -> None:
    clock = Clock()
    book, wire = AnswerBook(clock), Wire()
    [update] = book.write([setter('MOT_Update', 1)], wire, timeout=1.0)
    assert book.wait(update, clock.now) is None
    assert book.write([setter('MOT_Update', 1)], wire, block=False) is None
    assert not book.deliver(ACK)  # the late ACK: stale, and the link is in step again
    [again] = book.write([setter('MOT_Update', 1)], wire, block=False)
    book.deliver(NACK)
    assert book.wait(again, clock.now) == NACK and not again.doubt
    # a late answer that never comes holds the next setter only for the late window
    [lost] = book.write([setter('MOT_Update', 1)], wire, timeout=1.0)
    assert book.wait(lost, clock.now) is None
    assert book.write([setter('MOT_Update', 1)], wire, block=False) is None
    clock.now += LATE_WINDOW_S
    assert book.write([setter('MOT_Update', 1)], wire, block=False) is not None


def test_probe_an_unknown_getters_nack_is_not_taken_by_a_stops_first_step() -> None:
    """Issue 44 probe: a getter the device has not answered yet may be answered by a byte.
    A stop does not wait for it: the getter can no longer take a byte (it still takes its
    data), and the stop owns the bytes as a whole, so a NACK among them is reported with
    the doubt, never read as its first step's refusal by guess."""
    clock = Clock()
    book, wire = AnswerBook(clock), Wire()
    [pn] = book.write([getter('COM_GetPn', 0)], wire, timeout=1.0)  # not known yet
    stop = book.write([setter('MOT_SetSpeedMode', 1), setter('MOT_SetSpeed', 1, 0.0),
                       setter('MOT_Update', 1)], wire, urgent=True, block=False) or []
    assert len(stop) == 3 and pn.superseded
    for byte in (NACK, ACK, ACK, ACK):  # the getter's NACK, then the stop's ACKs
        book.deliver(byte)
    assert [book.wait(w, clock.now) for w in stop] == [NACK, ACK, ACK]
    assert all('COM_GetPn' in w.doubt for w in stop)  # counted, not owned one by one
    assert stop[0].exchange.received == [NACK, ACK, ACK, ACK]
    book.deliver(data('COM_GetPn', 0))  # its data is named: still its own
    assert isinstance(book.wait(pn, clock.now), Frame)


def test_a_getter_answered_by_a_byte_stays_byte_answered_and_waits_its_turn() -> None:
    """Issue 44 probe: a getter NACKed with a code other than 0xA6 is not data-answered;
    it is one byte-answered exchange like a setter, every time: it waits for the one in
    flight instead of sharing its bytes."""
    clock = Clock()
    book, wire = AnswerBook(clock), Wire()
    [pn] = book.write([getter('COM_GetPn', 0)], wire, timeout=1.0)
    book.deliver(ReplyByte(ReplyCode.EXECUTION_ERROR))
    assert book.wait(pn, clock.now) == ReplyByte(ReplyCode.EXECUTION_ERROR)
    [speed] = book.write([setter('MOT_SetSpeed', 1, 5.0)], wire, timeout=1.0)
    assert book.write([getter('COM_GetPn', 0)], wire, block=False) is None
    book.deliver(ACK)
    assert book.wait(speed, clock.now) == ACK
    assert book.write([getter('COM_GetPn', 0)], wire, block=False) is not None


def test_probe_a_retried_getter_does_not_take_its_first_attempts_late_data() -> None:
    """Issue 44 probe: a getter that timed out may be answered late with data that names
    the same opcode and axis as its retry's. The retry is written only once that data
    came (counted stale) or the late window passed, so it never publishes an old value."""
    clock = Clock()
    book, wire = AnswerBook(clock), Wire()
    position = getter('MOT_GetLoadPosition', 1)
    known(book, wire, position)
    [first] = book.write([position], wire, timeout=1.0)
    assert book.wait(first, clock.now) is None
    assert book.write([position], wire, block=False) is None  # its late data may come
    old = Frame(0, 1, position[1].opcode, b'\x01\x00\x00\x00')
    assert not book.deliver(old)  # the first attempt's: stale
    [retry] = book.write([position], wire, block=False)
    fresh = Frame(0, 1, position[1].opcode, b'\x02\x00\x00\x00')
    book.deliver(fresh)
    assert book.wait(retry, clock.now) == fresh


def test_a_getter_left_unanswered_answers_data_or_nothing() -> None:
    clock = Clock()
    book, wire = AnswerBook(clock), Wire()
    [roll] = book.write([getter('IMU_GetRoll', 0)], wire, timeout=1.0)
    assert book.wait(roll, clock.now) is None
    clock.now += LATE_WINDOW_S  # its answer did not come: taken as lost
    book.write([getter('IMU_GetRoll', 0)], wire, timeout=1.0)
    assert book.write([setter('MOT_SetSpeed', 1, 5.0)], wire, block=False) is not None


def test_a_lost_link_fails_what_is_in_flight_and_a_new_one_starts_clean() -> None:
    book, wire = AnswerBook(), Wire()
    [pos] = book.write([getter('MOT_GetLoadPosition', 1)], wire, timeout=1.0)
    book.fail_all(ConnectionError('gone'))
    with pytest.raises(ConnectionError, match='gone'):
        book.wait(pos, 10.0)
    assert book.idle()
    book.reset(ConnectionError('new connection'))
    [speed] = book.write([setter('MOT_SetSpeed', 1, 5.0)], wire, timeout=1.0)
    book.deliver(ACK)
    assert book.wait(speed, 0.0) == ACK


def test_a_failed_write_leaves_nothing_in_flight() -> None:
    book = AnswerBook()

    def broken(data: bytes) -> None:
        raise OSError('broken pipe')

    with pytest.raises(OSError):
        book.write([getter('MOT_GetLoadPosition', 1)], broken, timeout=1.0)
    assert book.idle()


def test_a_writer_held_by_a_late_answer_goes_out_when_the_window_ends_without_any_answer() -> None:
    """The late window ends by time, not by an answer: a setter waiting behind a late ACK
    that never comes is written once the window passed, though nothing arrives to wake it
    (real time here, a short window: only that it is written is checked)."""
    book, wire = AnswerBook(late_window=0.05), Wire()
    [update] = book.write([setter('MOT_Update', 1)], wire, timeout=1.0)
    assert book.wait(update, 0.0) is None
    assert book.write([setter('MOT_Update', 1)], wire, timeout=30.0) is not None


STOP = [setter('MOT_SetSpeedMode', 1), setter('MOT_SetSpeed', 1, 0.0), setter('MOT_Update', 1)]


def in_another_thread(call):
    """What ``call`` returns when run by another thread (one that holds no motion set-up)."""
    result: list[object] = []
    thread = threading.Thread(target=lambda: result.append(call()), daemon=True)
    thread.start()
    thread.join(10.0)
    return result[0]


def test_a_stop_preempts_the_setter_of_the_lock_holder_and_owns_its_late_byte() -> None:
    """Issue 44 item 1: a stop never waits for the exchange in flight. ``preempt`` (the link
    lock's hook, before the stop waits for the lock) ends the holder's setter at once, with
    Preempted, not at its timeout; the holder's next step is not written, a writer without
    the lock waits its turn; the stop goes out at once and counts the preempted setter's
    late ACK with its own, as a whole. After the stop the late window holds, as after any
    request that ended without its answer."""
    clock = Clock()
    book, wire = AnswerBook(clock), Wire()
    [acc] = book.write([setter('MOT_SetAcceleration', 1, 50.0)], wire, timeout=1.0,
                       holds_lock=True)
    book.preempt()
    with pytest.raises(Preempted, match=r'MOT_SetAcceleration \(axis 1\): preempted by a stop'):
        book.wait(acc, clock.now + 60.0)  # ends at once: it was preempted
    with pytest.raises(Preempted, match=r'MOT_SetSpeed \(axis 1\): not written'):
        book.write([setter('MOT_SetSpeed', 1, 5.0)], wire, timeout=1.0, holds_lock=True)
    assert book.write([getter('COM_GetPn', 0)], wire, block=False) is None
    assert len(wire.writes) == 1
    stop = book.write(STOP, wire, urgent=True, block=False) or []
    assert len(stop) == 3 and len(wire.writes) == 2  # the next bytes on the wire
    for byte in (ACK, ACK, ACK, ACK):  # the late ACK of the preempted setter, then the stop's
        book.deliver(byte)
    assert [book.wait(w, clock.now) for w in stop] == [ACK, ACK, ACK]
    exchange = stop[0].exchange
    assert exchange.whole and 'MOT_SetAcceleration' in exchange.doubt
    assert exchange.received == [ACK, ACK, ACK, ACK]
    book.preempt_done()
    assert book.write([setter('MOT_SetSpeed', 1, 5.0)], wire, block=False) is None
    clock.now += LATE_WINDOW_S
    assert book.write([setter('MOT_SetSpeed', 1, 5.0)], wire, block=False) is not None
    assert book.preempted == 1


def test_a_stop_preempts_a_getter_under_the_lock_whose_late_data_is_then_stale() -> None:
    """A getter written under the link lock (one a stop would wait for) is preempted too;
    its data, named, is counted stale when it comes, never given to a later read."""
    clock = Clock()
    book, wire = AnswerBook(clock), Wire()
    [roll] = book.write([getter('IMU_GetRoll', 0)], wire, timeout=1.0, holds_lock=True)
    book.preempt()
    with pytest.raises(Preempted, match='IMU_GetRoll: preempted by a stop'):
        book.wait(roll, clock.now + 60.0)
    book.write(STOP, wire, urgent=True, block=False)
    assert not book.deliver(data('IMU_GetRoll', 0))  # its own late data: stale
    book.preempt_done()
    [again] = book.write([getter('IMU_GetRoll', 0)], wire, block=False) or []
    assert again.data_answered  # answers data or nothing: it overlaps from now on


def test_a_stop_does_not_preempt_a_read_written_without_the_lock() -> None:
    """A read nobody holds the lock for does not hold up the stop: superseded, it still
    takes its named data."""
    clock = Clock()
    book, wire = AnswerBook(clock), Wire()
    [pn] = book.write([getter('COM_GetPn', 0)], wire, timeout=1.0)
    book.preempt()
    book.write(STOP, wire, urgent=True, block=False)
    book.deliver(data('COM_GetPn', 0))
    assert isinstance(book.wait(pn, clock.now), Frame) and book.preempted == 0
    book.preempt_done()


def test_a_motion_set_up_goes_out_over_a_read_not_answered_yet() -> None:
    """Issue 44 (the conformance gap ('jog', 'IMU_GetRoll')): a read the device has not
    answered yet no longer holds up a motion set-up. Inside ``motion_first`` the read is
    data-answered (data, a NACK or nothing: an ACK is never its own), the set-up's setter is
    written at once, another thread's unknown read waits until the set-up ends, and a
    NACK either could own is held until the other is answered."""
    clock = Clock()
    book, wire = AnswerBook(clock), Wire()
    [roll] = book.write([getter('IMU_GetRoll', 0)], wire, timeout=1.0)
    assert book.write([setter('MOT_SetSpeedMode', 1)], wire, block=False) is None  # before
    with book.motion_first():
        [mode] = book.write([setter('MOT_SetSpeedMode', 1)], wire, block=False,
                            holds_lock=True) or []
        assert in_another_thread(
            lambda: book.write([getter('COM_GetPn', 0)], wire, block=False)) is None
        book.deliver(NACK)  # the read's or the setter's: held, nobody's yet
        assert not mode.done and not roll.done
        book.deliver(ACK)  # the setter's: a read is never answered by an ACK
        assert book.wait(mode, clock.now) == ACK and not mode.doubt
        assert book.wait(roll, clock.now) == NACK  # the held NACK: the read's
    assert in_another_thread(
        lambda: book.write([getter('COM_GetPn', 0)], wire, block=False)) is not None


def test_a_motion_set_up_does_not_wait_for_the_late_window_of_a_read() -> None:
    """A read that timed out may still be answered: the next setter waits for its late
    window, but a motion set-up does not (its late NACK is held, its data is named)."""
    clock = Clock()
    book, wire = AnswerBook(clock), Wire()
    [roll] = book.write([getter('IMU_GetRoll', 0)], wire, timeout=1.0)
    assert book.wait(roll, clock.now) is None
    assert book.write([setter('MOT_SetSpeedMode', 1)], wire, block=False) is None
    with book.motion_first():
        [mode] = book.write([setter('MOT_SetSpeedMode', 1)], wire, block=False,
                            holds_lock=True) or []
        book.deliver(data('IMU_GetRoll', 0))  # the read's late data: stale, not the step's
        book.deliver(ACK)
        assert book.wait(mode, clock.now) == ACK


def test_a_stop_does_not_preempt_another_stop_in_flight() -> None:
    """Two stops at once (the dead-man stop, a resent one, ~/stop): the second does not cut
    the first's answers short; both are written."""
    clock = Clock()
    book, wire = AnswerBook(clock), Wire()
    first = book.write(STOP, wire, urgent=True, holds_lock=True) or []
    book.preempt()
    assert not any(w.done for w in first) and book.preempted == 0
    assert book.write(STOP, wire, urgent=True, block=False) is not None
    book.preempt_done()
    assert len(wire.writes) == 2


def test_a_read_the_device_answered_with_an_ack_still_holds_up_a_motion_set_up() -> None:
    """A getter this device answers with an ACK (a controller that acknowledges what it does
    not know) could own the set-up's ACK: it is not trusted, and the setter waits."""
    clock = Clock()
    book, wire = AnswerBook(clock), Wire()
    [pn] = book.write([getter('COM_GetPn', 0)], wire, timeout=1.0)
    book.deliver(ACK)
    assert book.wait(pn, clock.now) == ACK
    [again] = book.write([getter('COM_GetPn', 0)], wire, timeout=1.0) or []
    with book.motion_first():
        assert book.write([setter('MOT_SetSpeedMode', 1)], wire, block=False,
                          holds_lock=True) is None
    assert not again.data_answered
