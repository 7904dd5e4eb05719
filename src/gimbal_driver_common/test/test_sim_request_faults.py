"""The shared request faults of the simulator control protocol (``mute``, ``delay``) in
process: the verbs, their answers and the held replies. Each simulator's own tests drive
them over its real transport."""

from __future__ import annotations

import json
import math

import pytest

from gimbal_driver_common.sim_control import SimControl
from gimbal_driver_common.sim_requests import LateReplies, RequestFaults, resolve_request
from gimbal_driver_testing import ManualClock

NAMES = ('IMU_GetRoll', 'MOT_GetPosition', 'RESET')


@pytest.fixture
def control() -> SimControl:
    return SimControl('test_sim', lambda: {'axes': {}}, request_names=lambda: NAMES)


def state_of(control: SimControl) -> dict:
    answer = control.execute('state')
    assert answer.startswith('ok {'), answer
    return json.loads(answer[3:])


def test_mute_and_delay_set_the_faults_the_simulator_consults(control) -> None:
    faults = control.request_faults
    assert control.execute('mute IMU_GetRoll') == 'ok IMU_GetRoll never answered'
    assert control.execute('delay MOT_GetPosition 0.4') == \
        'ok MOT_GetPosition answered 0.4 s late'
    assert faults.muted('IMU_GetRoll') and not faults.muted('MOT_GetPosition')
    assert faults.delay_of('MOT_GetPosition') == 0.4 and faults.delay_of('IMU_GetRoll') == 0.0
    state = state_of(control)
    assert state['muted'] == ['IMU_GetRoll']
    assert state['delayed'] == {'MOT_GetPosition': 0.4}


def test_clear_undoes_mutes_and_delays(control) -> None:
    control.execute('mute IMU_GetRoll')
    control.execute('delay RESET 1.5')
    assert control.execute('clear') == 'ok'
    assert not control.request_faults.muted('IMU_GetRoll')
    assert control.request_faults.delay_of('RESET') == 0.0
    assert state_of(control)['muted'] == [] and state_of(control)['delayed'] == {}


def test_mute_off_and_delay_zero_undo_one_request(control) -> None:
    control.execute('mute IMU_GetRoll')
    control.execute('mute RESET')
    assert control.execute('mute IMU_GetRoll off') == 'ok IMU_GetRoll answered'
    assert state_of(control)['muted'] == ['RESET']
    control.execute('delay MOT_GetPosition 2')
    assert control.execute('delay MOT_GetPosition 0') == 'ok MOT_GetPosition answered at once'
    assert state_of(control)['delayed'] == {}


def test_the_last_of_mute_and_delay_wins(control) -> None:
    control.execute('mute RESET')
    control.execute('delay RESET 0.5')
    assert state_of(control)['muted'] == [] and state_of(control)['delayed'] == {'RESET': 0.5}
    control.execute('mute RESET')
    assert state_of(control)['muted'] == ['RESET'] and state_of(control)['delayed'] == {}


def test_an_unknown_request_is_refused_with_the_known_names(control) -> None:
    answer = control.execute('mute IMU_GetYaw')
    assert answer == ("error mute: unknown request 'IMU_GetYaw'; known: IMU_GetRoll, "
                      'MOT_GetPosition, RESET')
    assert control.execute('delay nothing 1').startswith("error delay: unknown request 'nothing'")
    assert control.execute('mute').startswith('error mute: usage: mute REQUEST [off]; known: ')
    assert state_of(control)['muted'] == []


def test_a_name_matches_ignoring_case_when_it_is_unambiguous(control) -> None:
    assert control.execute('mute reset') == 'ok RESET never answered'
    assert resolve_request('imu_getroll', NAMES) == 'IMU_GetRoll'
    with pytest.raises(LookupError):
        resolve_request('get', ('GET', 'Get'))


@pytest.mark.parametrize('seconds', ['-1', 'nan', 'inf', 'soon'])
def test_a_delay_must_be_finite_seconds_at_least_zero(control, seconds) -> None:
    assert control.execute(f'delay RESET {seconds}').startswith('error delay: ')
    assert control.request_faults.delay_of('RESET') == 0.0
    with pytest.raises(ValueError):
        RequestFaults().delay('RESET', -0.1)
    with pytest.raises(ValueError):
        RequestFaults().delay('RESET', math.nan)


def test_wrong_argument_counts_are_refused(control) -> None:
    assert control.execute('delay RESET').startswith('error delay: usage: ')
    assert control.execute('mute RESET off now').startswith('error mute: usage: ')
    assert control.execute('mute RESET maybe').startswith('error mute: expected on or off')


def test_help_shows_the_verbs_and_the_request_names(control) -> None:
    answer = control.execute('help')
    assert 'mute REQUEST [off]' in answer and 'delay REQUEST SECONDS' in answer
    assert '(requests: IMU_GetRoll, MOT_GetPosition, RESET)' in answer
    many = SimControl('big', dict, request_names=lambda: [f'R{n}' for n in range(100)])
    assert '(100 request names: `mute` alone lists them)' in many.execute('help')


def test_a_simulator_without_request_names_refuses_the_verbs() -> None:
    control = SimControl('bare', dict)
    assert control.execute('mute X') == 'error mute: not applicable to bare: no request ' \
        'names given'
    assert 'muted' not in state_of(control)


def test_late_replies_come_out_when_due_in_order() -> None:
    clock = ManualClock(0.0)  # binary fractions: the due times compare exactly
    late: LateReplies[bytes] = LateReplies(clock)
    late.hold([b'a1', b'a2'], 0.5)
    clock.now += 0.25
    late.hold([b'b'], 0.125)  # due before the first request's answer
    late.hold([b'c'], 0.25)   # due with it: after it, as held
    assert late.due() == [] and len(late) == 4
    clock.now += 0.125
    assert late.due() == [b'b']
    assert late.due(clock.now + 0.0625) == []
    clock.now += 0.125
    assert late.due() == [b'a1', b'a2', b'c']
    assert len(late) == 0 and late.due(clock.now + 10) == []


def test_ignore_takes_a_request_without_acting_on_it_for_its_seconds() -> None:
    clock = ManualClock()
    control = SimControl('test_sim', lambda: {'axes': {}}, request_names=lambda: NAMES,
                         request_faults=RequestFaults(clock=clock))
    faults = control.request_faults
    assert control.execute('ignore reset 1.3') == 'ok RESET answered but not acted on for 1.3 s'
    assert faults.ignored('RESET') and not faults.ignored('IMU_GetRoll')
    assert not faults.muted('RESET') and faults.delay_of('RESET') == 0.0  # still answered
    assert state_of(control)['ignored'] == {'RESET': 1.3}
    clock.now += 1.2
    assert faults.ignored('RESET')
    clock.now += 0.2
    assert not faults.ignored('RESET')  # ends by itself
    assert state_of(control)['ignored'] == {}


def test_ignore_zero_and_clear_act_on_the_request_again(control) -> None:
    control.execute('ignore RESET 100')
    assert control.execute('ignore RESET 0') == 'ok RESET acted on again'
    assert not control.request_faults.ignored('RESET')
    control.execute('ignore RESET 100')
    control.execute('clear')
    assert not control.request_faults.ignored('RESET')
    for bad in ('ignore RESET', 'ignore RESET -1', 'ignore RESET nan', 'ignore NOPE 1'):
        assert control.execute(bad).startswith('error ignore'), bad
