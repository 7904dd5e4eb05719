"""The answer book in-process (no link): which written request each answer belongs to, and
when requests may overlap (capture_driver/answers.py)."""

from __future__ import annotations

import threading

import pytest

from capture_driver.answers import AnswerBook
from capture_driver.protocol import Frame, ReplyByte, ReplyCode, command
from gimbal_driver_testing import wait_for

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


def test_data_goes_to_the_getter_of_its_opcode_and_axis_in_any_order() -> None:
    book, wire = AnswerBook(), Wire()
    [roll] = book.write([getter('IMU_GetRoll', 0)], wire, timeout=1.0)
    pan, tilt = book.write([getter('MOT_GetLoadPosition', 1),
                            getter('MOT_GetLoadPosition', 2)], wire, timeout=1.0)
    assert len(wire.writes) == 2  # each write() call is one write
    assert book.deliver(data('MOT_GetLoadPosition', 2))
    assert book.deliver(data('MOT_GetLoadPosition', 1))
    assert book.wait(tilt, 0.0).axis == 2 and book.wait(pan, 0.0).axis == 1
    assert book.in_flight() == ['IMU_GetRoll']  # the slow one still waits
    assert book.wait(roll, 0.0) is None  # its deadline passed: it gives up
    assert book.late_possible
    assert not book.deliver(data('IMU_GetRoll', 0))  # the late reply: stale
    assert book.stale == 1 and not book.late_possible


def test_a_reply_byte_goes_to_the_setter_in_flight_not_to_a_getter() -> None:
    book, wire = AnswerBook(), Wire()
    [roll] = book.write([getter('IMU_GetRoll', 0)], wire, timeout=1.0)
    book.deliver(data('IMU_GetRoll', 0))  # answered with data once: trusted
    [roll] = book.write([getter('IMU_GetRoll', 0)], wire, timeout=1.0)
    [speed] = book.write([setter('MOT_SetSpeed', 1, 5.0)], wire, timeout=1.0)
    assert book.deliver(NACK)
    assert book.wait(speed, 0.0) == NACK
    assert book.in_flight() == ['IMU_GetRoll']
    book.deliver(ACK)  # no setter in flight: a byte answers the oldest getter
    assert book.wait(roll, 0.0) == ACK


def test_an_untrusted_getter_and_a_setter_do_not_overlap_but_a_stop_does() -> None:
    book, wire = AnswerBook(), Wire()
    [pn] = book.write([getter('COM_GetPn', 0)], wire, timeout=1.0)  # never answered yet
    assert book.write([setter('MOT_SetSpeed', 1, 5.0)], wire, block=False) is None
    [stop] = book.write([setter('MOT_SetSpeed', 1, 0.0)], wire, urgent=True, block=False)
    book.deliver(ACK)
    assert book.wait(stop, 0.0) == ACK  # the stop takes the byte
    assert book.in_flight() == ['COM_GetPn']
    released = threading.Event()

    def send_setter() -> None:
        book.write([setter('MOT_Update', 1)], wire, timeout=5.0)
        released.set()

    thread = threading.Thread(target=send_setter, daemon=True)
    thread.start()
    assert not released.wait(0.05)  # waits for the untrusted getter
    book.deliver(data('COM_GetPn', 0))
    assert book.wait(pn, 0.0) is not None
    wait_for(released.is_set, 5.0, 'the setter written once the getter is answered')
    # and now trusted: a setter overlaps it
    book.write([getter('COM_GetPn', 0)], wire, timeout=1.0)
    assert book.write([setter('MOT_SetSpeed', 1, 5.0)], wire, block=False) is not None


def test_a_getter_left_unanswered_is_trusted_to_answer_nothing() -> None:
    book, wire = AnswerBook(), Wire()
    [roll] = book.write([getter('IMU_GetRoll', 0)], wire, timeout=1.0)
    assert book.wait(roll, 0.0) is None
    book.write([getter('IMU_GetRoll', 0)], wire, timeout=1.0)
    assert book.write([setter('MOT_SetSpeed', 1, 5.0)], wire, block=False) is not None


def test_an_ack_that_may_be_late_is_noted_not_taken_by_a_getter() -> None:
    book, wire = AnswerBook(), Wire()
    [update] = book.write([setter('MOT_Update', 1)], wire, timeout=1.0)
    assert book.wait(update, 0.0) is None  # its ACK may still come
    [fw] = book.write([getter('COM_GetFw', 0)], wire, timeout=1.0)
    assert not book.deliver(ACK)  # the late ACK, most likely
    assert fw.unexpected == 'ACK' and not fw.done
    assert not book.late_possible  # that late reply came


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
