"""The virtual gimbal's line protocol: request tags (pure functions)."""

from __future__ import annotations

import pytest

from virtual_gimbal_driver.protocol import MAX_TAG, split_tag, tagged, verb


def test_a_tag_goes_on_the_end_and_comes_off_again() -> None:
    assert tagged('MOVE pan 0.100000 0.000000', 7) == 'MOVE pan 0.100000 0.000000 #7'
    assert split_tag('MOVE pan 0.100000 0.000000 #7') == ('MOVE pan 0.100000 0.000000', 7)
    assert split_tag('OK #65535\r\n') == ('OK', MAX_TAG)
    assert verb(split_tag('get #3')[0]) == 'GET'


@pytest.mark.parametrize('line', ['OK', 'OK #', 'OK #0', 'OK #65536', 'OK #x1', '#5', 'ERR #a b'])
def test_what_is_not_a_tag_stays_in_the_line(line: str) -> None:
    assert split_tag(line) == (line, None)
