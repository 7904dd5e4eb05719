"""What the stop confirmation costs the two hot paths (issue 44 item 6), in process.

The confirmation (``gimbal_driver_common.stop_watch.StopWatch``) is on the device thread
(``observe``: every joint sample) and on the joint_command path (``superseded``: every
command that moves an axis). Both are meant to cost one look while no stop waits, the
usual case, and a short locked pass over the waiting axes while one does. Measured here
on the real class, per call, in the bench process, beside the cost of the work each call
rides on: filling one JointState message from a sample (``messages.JointStateMessage``,
what the device thread does for every sample anyway), so the figure reads as a fraction
of a cost the machine sets, not as an absolute that moves with the machine.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable

from gimbal_driver_common.controller import is_moving
from gimbal_driver_common.device import JointSample
from gimbal_driver_common.ros.messages import JointStateMessage
from gimbal_driver_common.stop_watch import StopWatch

JOINTS = ('pan', 'tilt')
CALLS = 20000


def per_call_us(call: Callable[[], object], calls: int = CALLS) -> float:
    """Median over 5 rounds of the mean time per call, in microseconds."""
    rounds = []
    for _ in range(5):
        start = time.perf_counter()
        for _ in range(calls):
            call()
        rounds.append((time.perf_counter() - start) / calls * 1e6)
    return sorted(rounds)[len(rounds) // 2]


def confirmation_cost() -> dict[str, float]:
    """Microseconds per call of observe and superseded, idle and with a stop waiting,
    and the JointState fill they ride beside."""
    watch = StopWatch(lambda: 0.5, lambda: 0.5, is_moving, logging.getLogger('bench'))
    moving = JointSample({j: 0.1 for j in JOINTS}, {j: 0.3 for j in JOINTS})
    message = JointStateMessage()
    figures = {
        'observe_idle_us': per_call_us(lambda: watch.observe(moving, 0.0)),
        'superseded_idle_us': per_call_us(lambda: watch.superseded(['pan'])),
    }
    watch.stopped(JOINTS)  # a stop waits (the samples keep it moving: never confirmed)
    figures['observe_waiting_us'] = per_call_us(lambda: watch.observe(moving, math.inf))
    figures['due_waiting_us'] = per_call_us(watch.due)

    def stop_then_supersede() -> None:
        watch.stopped(['pan'])
        watch.superseded(['pan'])

    figures['stop_and_supersede_us'] = per_call_us(stop_then_supersede)
    figures['joint_state_fill_us'] = per_call_us(
        lambda: message.fill(moving, list(JOINTS), None))
    fill = figures['joint_state_fill_us']
    figures['observe_idle_vs_joint_state_fill'] = figures['observe_idle_us'] / fill
    figures['observe_waiting_vs_joint_state_fill'] = figures['observe_waiting_us'] / fill
    return figures


if __name__ == '__main__':
    for name, value in confirmation_cost().items():
        print(f'{name}: {value:.3f}')
