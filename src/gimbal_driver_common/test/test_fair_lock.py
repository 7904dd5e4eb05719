"""FairRLock: reentrant, and a waiter gets the lock before its releasing holder asks again."""

from __future__ import annotations

import threading

import pytest

from gimbal_driver_common.fair_lock import FairRLock
from gimbal_driver_testing import wait_for


def test_a_waiter_goes_before_the_holder_that_asks_again() -> None:
    """What starved the Capture poll: the holder releases and asks again at once."""
    lock, order = FairRLock(), []
    lock.acquire()

    def waiter() -> None:
        with lock:
            order.append('waiter')

    thread = threading.Thread(target=waiter)
    thread.start()
    wait_for(lambda: lock._waiters, 5.0, 'the waiter to queue')
    lock.release()
    with lock:  # at once, as a command stream's next command does
        order.append('holder')
    thread.join(5.0)
    assert order == ['waiter', 'holder']


def test_waiters_are_served_in_the_order_they_asked() -> None:
    lock, order = FairRLock(), []
    lock.acquire()
    threads = []
    for index in range(5):
        thread = threading.Thread(target=lambda i=index: (lock.acquire(), order.append(i),
                                                          lock.release()))
        thread.start()
        wait_for(lambda n=index + 1: len(lock._waiters) == n, 5.0, f'waiter {index}')
        threads.append(thread)
    lock.release()
    for thread in threads:
        thread.join(5.0)
    assert order == [0, 1, 2, 3, 4]


def test_an_urgent_waiter_goes_before_every_other_waiter() -> None:
    """A stop queued behind three reads is next after the holder; urgent ones in turn."""
    lock, order = FairRLock(), []
    lock.acquire()
    threads = []
    for index, urgent in enumerate([False, False, True, False, True]):
        thread = threading.Thread(target=lambda i=index, u=urgent: (
            lock.acquire(urgent=u), order.append(i), lock.release()))
        thread.start()
        wait_for(lambda n=index + 1: lock.waiting() == n, 5.0,
                 f'waiter {index}')
        threads.append(thread)
    lock.release()
    for thread in threads:
        thread.join(5.0)
    assert order == [2, 4, 0, 1, 3]


def test_it_is_reentrant_and_only_its_holder_releases_it() -> None:
    lock, refused = FairRLock(), []

    def release_from_elsewhere() -> None:
        try:
            lock.release()
        except RuntimeError as exc:
            refused.append(str(exc))

    with lock, lock:
        other = threading.Thread(target=release_from_elsewhere)
        other.start()
        other.join(5.0)
    assert refused == ['cannot release a FairRLock held by another thread']
    with lock:  # free again after the nested holds
        pass
    with pytest.raises(RuntimeError, match='held by another thread'):
        lock.release()


def test_a_non_blocking_acquire_fails_while_another_thread_holds_it() -> None:
    """The command callback's try: it must never wait behind the poll."""
    lock, results = FairRLock(), []
    lock.acquire()
    other = threading.Thread(target=lambda: results.append(lock.acquire(blocking=False)))
    other.start()
    other.join(5.0)
    assert results == [False]
    assert lock.acquire(blocking=False)  # its holder takes it again (reentrant)
    lock.release()
    lock.release()
    other = threading.Thread(target=lambda: (results.append(lock.acquire(blocking=False)),
                                             lock.release()))
    other.start()
    other.join(5.0)
    assert results == [False, True]
