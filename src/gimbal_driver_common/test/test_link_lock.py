"""LinkLock: the device's one link lock; every blocking hold settles a posted write first,
the callback's try does not, and a settle that fails gives the lock back."""

from __future__ import annotations

import threading

import pytest

from gimbal_driver_common.link_lock import LinkLock


def holder(lock: LinkLock) -> tuple[threading.Thread, threading.Event, threading.Event]:
    """A thread that takes ``lock`` and keeps it until its second event is set."""
    taken, done = threading.Event(), threading.Event()

    def hold() -> None:
        with lock:
            taken.set()
            done.wait(10.0)

    thread = threading.Thread(target=hold, daemon=True)
    thread.start()
    assert taken.wait(5.0)
    return thread, taken, done


def test_every_blocking_hold_settles_first_and_the_try_does_not() -> None:
    lock, calls = LinkLock(), []
    lock.before_use = lambda: calls.append('settle')
    assert lock.try_hold()
    lock.release()
    assert calls == []
    with lock:
        assert calls == ['settle']
        with lock:  # a nested exchange settles too (nothing left: a no-op in the core)
            assert calls == ['settle', 'settle']


def test_the_try_fails_while_another_thread_holds_the_link() -> None:
    lock = LinkLock()
    thread, _, done = holder(lock)
    try:
        assert not lock.try_hold()
    finally:
        done.set()
        thread.join(5.0)
    assert lock.try_hold()
    lock.release()


def test_a_settle_that_raises_gives_the_lock_back() -> None:
    lock = LinkLock()

    def fail() -> None:
        raise RuntimeError('link gone while settling')

    lock.before_use = fail
    with pytest.raises(RuntimeError, match='settling'), lock:
        pass
    lock.before_use = lambda: None
    thread, _, done = holder(lock)  # another thread can take it: it was released
    done.set()
    thread.join(5.0)
    assert not thread.is_alive()


def test_a_stop_preempts_the_holder_before_it_waits_and_ends_the_preemption_after() -> None:
    """``urgent`` calls ``preempt`` first, so a device can end the exchange in flight (its
    holder gives the lock up at once, not at a timeout), and ``preempt_done`` after the
    stop's hold; a device that sets neither has the stop wait for the holder."""
    lock, events = LinkLock(), []
    thread, _, done = holder(lock)

    def preempt() -> None:
        events.append('preempt')
        done.set()  # the device ends the holder's exchange: it gives the lock up

    lock.preempt = preempt
    lock.preempt_done = lambda: events.append('done')
    with lock.urgent():
        events.append('stop holds the lock')
        assert lock.held() and lock.held_urgently()
    thread.join(5.0)
    assert events == ['preempt', 'stop holds the lock', 'done']
    assert not lock.held()


def test_the_preemption_ends_even_when_the_settle_under_a_stop_raises() -> None:
    lock, events = LinkLock(), []
    lock.preempt = lambda: events.append('preempt')
    lock.preempt_done = lambda: events.append('done')

    def fail() -> None:
        raise RuntimeError('link gone while settling')

    lock.before_use = fail
    with pytest.raises(RuntimeError), lock.urgent():
        pass
    assert events == ['preempt', 'done']
