"""The launch file and parameter YAML files this package installs (the shared checks of
gimbal_driver_testing.package_files, for this package)."""

from __future__ import annotations

import pytest

pytest.importorskip('gimbal_msgs', reason='needs the colcon-built workspace (make build)')

from gimbal_driver_testing.package_files import LaunchAndConfigSuite

pytestmark = pytest.mark.ros


class TestLaunchAndConfig(LaunchAndConfigSuite):
    __test__ = True
    package = 'capture_driver'
