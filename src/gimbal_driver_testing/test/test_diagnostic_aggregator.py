"""The Python model of diagnostic_aggregator's rules (testing/diagnostic_aggregator.py),
checked against what the C++ does: the cases below are those of its own sources and tests
(ros/diagnostics, ros2-jazzy: status_item.hpp's removeLeadingNameChaff comment, the
all_analyzers test's output before any status arrives)."""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest

from gimbal_driver_testing.diagnostic_aggregator import (
    OK,
    STALE,
    WARN,
    Aggregator,
    AnalyzerConfigError,
    node_parameters,
    remove_leading_name_chaff,
)


@dataclass
class KeyValue:
    key: str
    value: str


@dataclass
class Diag:
    """The fields of diagnostic_msgs/DiagnosticStatus the aggregator reads (level as
    rclpy gives it: bytes)."""

    name: str
    level: bytes = b'\x00'
    message: str = 'OK'
    hardware_id: str = ''
    values: list[KeyValue] = field(default_factory=list)


FIRST = """
analyzers:
  ros__parameters:
    path: BASIC
    prefix1:
      type: diagnostic_aggregator/GenericAnalyzer
      path: First
      remove_prefix: ['prefix1']
      startswith: ['pref1']
      contains: ['contains1a']
      name: ['name1']
      expected: ['prefix1: expected1a', 'prefix1: expected1c']
"""


def names(output) -> dict[str, tuple[int, str]]:
    return {status.name: (status.level, status.message) for status in output}


def test_the_leading_name_chaff_goes_as_status_item_hpp_says() -> None:
    # "Turns "/PREFIX/base_hokuyo_node: Connection Status" to "/PREFIX/Connection Status""
    assert remove_leading_name_chaff('/PREFIX/base_hokuyo_node: Connection Status',
                                     'base_hokuyo_node') == '/PREFIX/Connection Status'
    assert remove_leading_name_chaff('/P/gimbal: pan', 'gimbal:') == '/P/pan'
    # a name that does not start with it keeps it; a leading ':' goes all the same
    assert remove_leading_name_chaff('/P/other: pan', 'gimbal') == '/P/other: pan'
    assert remove_leading_name_chaff('/P/: pan', 'gimbal') == '/P/pan'
    assert remove_leading_name_chaff('/P/x', '') == '/P/x'


def test_expected_items_are_missing_until_they_arrive_and_name_matches_nothing() -> None:
    aggregator = Aggregator.from_yaml(FIRST)
    first = aggregator.analyzers['prefix1']
    assert first.path == '/BASIC/First' and first.ignored == ['name']
    # the all_analyzers test's output before the publisher runs
    assert names(aggregator.report(0.0))['/BASIC/First/expected1c'] == (STALE, 'Missing')
    assert aggregator.claimed_by('name1') == []   # `name` is not read in Jazzy
    # nor does `expected` match: 'prefix1: ...' does not start with 'pref1', so the
    # published 'prefix1: expected1c' goes to Other and the item stays Missing, which is
    # why upstream's expected output lists it so while its publisher sends it
    assert aggregator.claimed_by('prefix1: expected1c') == []
    assert aggregator.claimed_by('xx contains1a yy') == ['prefix1']
    aggregator.feed([Diag('pref1a', b'\x01', 'low'), Diag('name1'),
                     Diag('prefix1: expected1c')], now=1.0)
    output = names(aggregator.report(2.0))
    assert output['/BASIC/First/pref1a'] == (WARN, 'low')
    assert output['/BASIC/First/expected1c'] == (STALE, 'Missing')
    assert output['/BASIC/Other/prefix1: expected1c'] == (OK, 'OK')
    assert output['/BASIC/First'] == (2, 'Error')   # STALE among live items reads ERROR
    assert output['/BASIC'] == (2, 'Error')   # the group's header (there is a base path)
    assert output['/BASIC/Other/name1'] == (OK, 'OK')   # claimed by no analyzer
    # no status for more than timeout (5 s): STALE; the header reads STALE when all are
    output = names(aggregator.report(7.0))
    assert output['/BASIC/First/pref1a'][0] == STALE
    assert output['/BASIC/First'][0] == STALE
    assert '/BASIC/Other/name1' not in output   # Other discards stale items


def test_every_analyzer_is_made_from_the_parameters_in_name_order() -> None:
    text = """
/**:
  ros__parameters:
    b_second:
      type: diagnostic_aggregator/GenericAnalyzer
      path: Second
      find_and_remove_prefix: ['node_b:']
      regex: ['node_.: (pan|tilt)']
    a_first:
      type: diagnostic_aggregator/GenericAnalyzer
      path: First
      find_and_remove_prefix: ['node_a:']
      num_items: 2
      discard_stale: true
"""
    aggregator = Aggregator.from_yaml(text, node='/robot/analyzers')
    assert list(aggregator.analyzers) == ['a_first', 'b_second']
    # regex is a whole-name match; a status may be claimed by more than one analyzer
    assert aggregator.claimed_by('node_a: pan') == ['a_first', 'b_second']
    assert aggregator.claimed_by('node_c: pan!') == []
    aggregator.feed([Diag('node_a: pan'), Diag('node_b: tilt')], now=0.0)
    output = names(aggregator.report(0.0))
    assert output['/First/pan'] == (OK, 'OK') and output['/Second/tilt'] == (OK, 'OK')
    assert output['/Second/node_a: pan'] == (OK, 'OK')   # not its prefix: kept
    assert output['/First'] == (2, 'Expected 2, found 1')
    assert '/First' in output and '' not in output   # no base path: no group header


@pytest.mark.parametrize(('analyzer', 'reason'), [
    ("startswith: 'gimbal'", 'not a string array'),
    ('timeout: 5', 'not a double'),
    ("name: ['gimbal: pan']", 'not initialized with any way'),
    ("expected: ['gimbal: pan']", 'not initialized with any way'),
])
def test_what_the_aggregator_refuses(analyzer: str, reason: str) -> None:
    text = f"""
analyzers:
  ros__parameters:
    gimbal:
      type: diagnostic_aggregator/GenericAnalyzer
      path: Gimbal
      {analyzer}
"""
    with pytest.raises(AnalyzerConfigError, match=reason):
        Aggregator.from_yaml(text)


def test_only_the_entries_for_the_node_apply() -> None:
    document = {'/**': {'ros__parameters': {'a': {'b': 1}}},
                'other_node': {'ros__parameters': {'c': 2}},
                '/ns/analyzers': {'ros__parameters': {'d': 3}}}
    assert node_parameters(document, '/ns/analyzers') == {'a.b': 1, 'd': 3}
    assert node_parameters(document) == {'a.b': 1}
