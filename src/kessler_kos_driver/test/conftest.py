"""Shared pytest configuration for kessler_kos_driver tests."""

import os

from hypothesis import HealthCheck, settings

settings.register_profile(
    'kos', max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile(os.environ.get('HYPOTHESIS_PROFILE', 'kos'))


def pytest_configure(config):
    config.addinivalue_line('markers', 'ros: needs the colcon-built workspace and rclpy')
