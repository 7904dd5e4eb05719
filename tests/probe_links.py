"""gimbal_probe's command line for a driver's link (tests/test_probe.py and
tests/test_runtime_without_test_tools.py; a module of its own, since a test module's name,
test_probe, is not unique across the packages' test directories)."""

from __future__ import annotations


def link_arguments(parameters: dict, password: str = '') -> list[str]:
    """gimbal_probe's arguments for the link a driver's node parameters name."""
    if 'can_channel' in parameters:
        return ['--can', parameters['can_channel'], '--can-interface',
                parameters['can_interface']]
    if 'serial_port' in parameters:
        return ['--serial', parameters['serial_port']]
    arguments = ['--tcp', f'{parameters["host"]}:{parameters["port"]}']
    return arguments + (['--password', password] if password else [])
