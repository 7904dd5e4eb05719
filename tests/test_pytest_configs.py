"""Every pytest configuration of the repository freezes the collected heap and reports the
nodes a failed test left running.

A full garbage collection stops every thread of a test process; with an in-process
simulator and a client in it, one pause as long as a request timeout failed a test
(gimbal_driver_testing/frozen_heap.py, docs/testing.md "Pauses"). The plugin works
only where a configuration loads it: the root one (``make test``) and each package's own
(``colcon test``). gimbal_msgs has no in-process simulator and does not depend on the core.
The node reports (testing/node_reports.py: a thread dump and the log of each node) likewise.
"""

from __future__ import annotations

import configparser
import gc
import itertools
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PLUGINS = ('gimbal_driver_testing.frozen_heap',
           'gimbal_driver_testing.node_reports')
CONFIGS = [ROOT / 'pytest.ini', *sorted(
    p for p in (ROOT / 'src').glob('*/pytest.ini') if p.parent.name != 'gimbal_msgs')]


def loaded_plugins(config: Path) -> list[str]:
    """The ``-p NAME`` options of a pytest.ini's addopts."""
    parser = configparser.ConfigParser()
    parser.read(config)
    words = shlex.split(parser.get('pytest', 'addopts', fallback=''))
    return [name for option, name in itertools.pairwise(words) if option == '-p']


@pytest.mark.parametrize('plugin', PLUGINS, ids=lambda name: name.rsplit('.', 1)[-1])
@pytest.mark.parametrize('config', CONFIGS, ids=lambda p: str(p.relative_to(ROOT)))
def test_the_configuration_loads_the_plugins(config: Path, plugin: str) -> None:
    assert plugin in loaded_plugins(config), f'{config} does not load {plugin}'


def test_the_reader_finds_a_plugin_and_misses_none(tmp_path: Path) -> None:
    config = tmp_path / 'pytest.ini'
    config.write_text('[pytest]\naddopts = -ra -p no:cacheprovider\n    -p some.plugin\n')
    assert loaded_plugins(config) == ['no:cacheprovider', 'some.plugin']
    config.write_text('[pytest]\ntestpaths = test\n')
    assert loaded_plugins(config) == []


def test_this_process_has_frozen_its_collected_heap() -> None:
    assert gc.get_freeze_count() > 10_000, 'the frozen_heap plugin did not run in this process'
