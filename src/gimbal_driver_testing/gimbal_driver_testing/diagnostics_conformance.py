"""The diagnostics part of the conformance suite: /diagnostics as ROS tools show it.

- The package's ``config/<package>_diagnostics.yaml`` (installed), loaded through
  diagnostic_aggregator's rules (:mod:`gimbal_driver_testing.diagnostic_aggregator`)
  and fed the node's real /diagnostics: every status of the node is claimed by the
  package's analyzer alone and shown as ``/<path>/<part>``, nothing lands in Other, and
  every ``expected`` name is one the node publishes.
- The joint_states frequency status restarts its window when ``publish_rate`` changes
  (diagnostic_updater's ``FrequencyStatus.clear()``): one "measuring" status, then the new
  rate, instead of a window that mixes both and reads "too low" for a while.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import pytest
from ament_index_python.packages import get_package_share_directory
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

from gimbal_driver_testing import wait_for
from gimbal_driver_testing.conformance_rig import OK, ConformanceHelpers, ConformanceRig
from gimbal_driver_testing.diagnostic_aggregator import Aggregator, level_of

FREQUENCY = 'joint_states frequency'


class DiagnosticsConformance(ConformanceHelpers):
    """Mixed into :class:`~gimbal_driver_testing.conformance.DriverConformance`."""

    def analyzer_file(self) -> Path:
        return Path(get_package_share_directory(self.package), 'config',
                    f'{self.package}_diagnostics.yaml')

    @pytest.mark.ros
    def test_the_aggregator_analyzer_shows_every_status_under_its_path(
            self, rig: ConformanceRig) -> None:
        aggregator = Aggregator.from_yaml(self.analyzer_file().read_text())
        assert list(aggregator.analyzers) == [self.package]
        analyzer = aggregator.analyzers[self.package]
        assert analyzer.ignored == [], f'keys the aggregator does not read: {analyzer.ignored}'

        def measured(array: DiagnosticArray) -> bool:   # every part is there once active
            return any(s.name == f'{self.node_name}: {FREQUENCY}' and s.message != 'measuring'
                       for s in array.status)

        array = rig.ros.wait_for_message('/diagnostics', DiagnosticArray, measured, timeout=40)
        statuses = self.node_statuses(array)
        now = time.monotonic()
        aggregator.feed(array.status, now)
        output = {status.name: status for status in aggregator.report(now)}
        for status in statuses:
            assert aggregator.claimed_by(status.name) == [self.package], status.name
            shown = output[f'{analyzer.path}/{status.name.split(": ", 1)[1]}']
            assert (shown.level, shown.message) == (level_of(status.level), status.message)
        names = {status.name for status in statuses}
        missing = [name for name in analyzer.expected if name not in names]
        assert not missing, f'expected by the analyzer, not published: {missing}'
        assert not [name for name in output if name.startswith('/Other')], sorted(output)
        # no item left "Missing" (a STALE item among live ones turns the analyzer ERROR)
        assert not [status.name for status in output.values() if status.message == 'Missing']

    @pytest.mark.ros
    def test_the_frequency_window_restarts_when_publish_rate_changes(
            self, rig: ConformanceRig) -> None:
        ros, name = rig.ros, self.node_name
        default = ros.get_parameter(name, 'publish_rate')
        ros.wait_for_diagnostic(name, FREQUENCY, lambda s: s.message != 'measuring',
                                timeout=40)
        received = ros.subscribe('/diagnostics', DiagnosticArray)
        start = len(received)   # before the set: the restart may be published before its reply

        def frequency(predicate: Callable[[DiagnosticStatus], bool]) -> bool:
            return any(s.name == f'{name}: {FREQUENCY}' and predicate(s)
                       for array in list(received[start:]) for s in array.status)

        try:
            assert ros.set_parameter(name, 'publish_rate', default / 2).successful
            # the window starts again at the first diagnostics period after the change
            wait_for(lambda: frequency(lambda s: s.message == 'measuring'), 30.0,
                     'the frequency window to restart')
            status = ros.wait_for_diagnostic(
                name, FREQUENCY, lambda s: s.level[0] == OK and s.message != 'measuring',
                timeout=40)
            values = {kv.key: kv.value for kv in status.values}
            assert float(values['expected_hz']) <= default / 2 + 1e-6, values
        finally:
            assert ros.set_parameter(name, 'publish_rate', default).successful
