"""The launch file's docstring states the defaults the launch really declares."""

from pathlib import Path

from gimbal_driver_testing.launch_doc import launch_docstring_errors

LAUNCH_FILE = Path(__file__).resolve().parent.parent / 'launch' / 'virtual_gimbal_driver.launch.py'


def test_launch_docstring_states_the_declared_defaults() -> None:
    assert launch_docstring_errors(LAUNCH_FILE, 'virtual_gimbal_driver') == []
