"""OpenGoals: what a shutting-down node waits for before its executor stops (run.py
``answer_open_goals``), and the rejection of goals that come after."""

from __future__ import annotations

import threading

import pytest
from rclpy.action import GoalResponse

from gimbal_driver_common.ros.actions import OpenGoals


def test_a_goal_is_open_from_its_acceptance_to_the_end_of_its_execute_callback() -> None:
    goals = OpenGoals()
    release = threading.Event()
    execute = goals.tracked(lambda handle: release.wait(10.0) and 'result')
    assert goals.admit(object()) == GoalResponse.ACCEPT
    assert goals.count == 1
    assert not goals.wait_ended(0.0)  # accepted, its callback not run yet
    runner = threading.Thread(target=execute, args=(object(),))
    runner.start()
    assert not goals.wait_ended(0.05)
    release.set()
    assert goals.wait_ended(10.0)
    runner.join(10.0)
    assert goals.count == 0


def test_a_callback_that_raises_still_ends_its_goal() -> None:
    goals = OpenGoals()

    def broken(handle: object) -> None:
        raise RuntimeError('device gone')

    goals.admit(object())
    with pytest.raises(RuntimeError):
        goals.tracked(broken)(object())
    assert goals.wait_ended(0.0)


def test_after_close_new_goals_are_rejected_and_not_counted() -> None:
    goals = OpenGoals()
    goals.admit(object())
    goals.close()
    assert goals.admit(object()) == GoalResponse.REJECT
    assert goals.count == 1  # the goal accepted before still counts


def test_a_result_request_is_due_for_a_second_after_the_last_acceptance() -> None:
    now = [100.0]
    goals = OpenGoals(clock=lambda: now[0])
    assert goals.result_request_due() == 0.0  # nothing accepted: nothing to wait for
    goals.admit(object())
    now[0] += 0.25
    assert goals.result_request_due() == pytest.approx(OpenGoals.RESULT_REQUEST_S - 0.25)
    goals.admit(object())  # a later acceptance starts the wait again
    assert goals.result_request_due() == pytest.approx(OpenGoals.RESULT_REQUEST_S)
    goals.close()
    goals.admit(object())  # rejected: its answer went out at once, nobody asks for a result
    now[0] += OpenGoals.RESULT_REQUEST_S
    assert goals.result_request_due() == 0.0
