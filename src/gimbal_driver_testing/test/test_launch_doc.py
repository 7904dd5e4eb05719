"""The launch-docstring check (testing/launch_doc.py) reads the real declarations and
fails on a docstring that states another default."""

from pathlib import Path

from gimbal_driver_testing.launch_doc import (
    DESCRIPTION_LAUNCH,
    declared_defaults,
    launch_docstring_errors,
)

#: a registered package: its link arguments come from its DriverSpec.link_parameters
PKG = 'virtual_gimbal_driver'
TRUE_DOC = '''"""Launch it.

    params_file:=''          parameter YAML
    autostart:=true          configures and activates itself
    namespace:=''            namespace
    use_description:=false   robot_state_publisher too
    description_file:=share/virtual_gimbal_driver/urdf/virtual_gimbal_driver.urdf
    sim:=false               simulator too
    log_level:=''            the node's log level
    host:=''                 device address
    port:=''                 device port
"""
'''


def test_declared_defaults_are_read_from_the_shared_launch_description() -> None:
    assert declared_defaults(PKG) == {
        'params_file': '', 'autostart': 'true', 'namespace': '', 'use_description': 'false',
        'description_file': f'share/{PKG}/urdf/{PKG}.urdf', 'sim': 'false',
        'log_level': '', 'host': '', 'port': ''}


def test_a_true_docstring_passes(tmp_path: Path) -> None:
    launch_file = tmp_path / f'{PKG}.launch.py'
    launch_file.write_text(TRUE_DOC)
    assert launch_docstring_errors(launch_file, PKG) == []


def test_a_wrong_or_missing_default_fails(tmp_path: Path) -> None:
    launch_file = tmp_path / f'{PKG}.launch.py'
    launch_file.write_text(TRUE_DOC.replace('autostart:=true', 'autostart:=false')
                           .replace("    namespace:=''            namespace\n", '')
                           .replace("    port:=''                 device port\n", ''))
    assert launch_docstring_errors(launch_file, PKG) == [
        'namespace: not in the docstring', 'port: not in the docstring',
        "autostart: docstring says 'false', the launch 'true'"]


def test_a_changed_declaration_fails(tmp_path: Path) -> None:
    """The other direction: the launch changes its default and the docstring is stale."""
    launch_file = tmp_path / f'{PKG}.launch.py'
    launch_file.write_text(TRUE_DOC)
    source = DESCRIPTION_LAUNCH.read_text().replace("('sim', 'false',", "('sim', 'true',")
    assert launch_docstring_errors(launch_file, PKG, source) == [
        "sim: docstring says 'false', the launch 'true'"]
