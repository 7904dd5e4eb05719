"""The URDF and the ros2_control example this package installs (the shared checks of
gimbal_driver_testing.description_files, for this package)."""

from __future__ import annotations

import pytest

pytest.importorskip('gimbal_msgs', reason='needs the colcon-built workspace (make build)')

from gimbal_driver_testing.description_files import DescriptionSuite


class TestDescriptionFiles(DescriptionSuite):
    __test__ = True
    package = 'ucamera_driver'
