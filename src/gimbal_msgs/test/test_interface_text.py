"""What ``ros2 interface show`` prints is for users: every numeric field says its unit,
and no file points at the project's issue tracker.

Reads only this package's own ``msg/``, ``srv/`` and ``action/`` files, so it runs under
``colcon test`` without anything else built.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent
INTERFACES = sorted(path for folder in ('msg', 'srv', 'action')
                    for path in (PACKAGE / folder).iterdir()
                    if path.suffix in ('.msg', '.srv', '.action'))

#: rosidl's numeric primitive types (rosidl_adapter/parser.py PRIMITIVE_TYPES without
#: bool, string, wstring)
NUMERIC = {'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
           'int32', 'uint32', 'int64', 'uint64'}

#: what a numeric field's comment starts with: an SI or other unit, or the words that say
#: the value is a count, an index, a fraction (dimensionless) or one of the file's constants
UNIT = re.compile(r'(rad/s|rad|m/s|m|s|deg|Hz|A|N\*m|count|index|fraction|one of)\b')

#: ``type name`` with an optional trailing comment; constants (``NAME=value``) excluded
FIELD = re.compile(r'^(?P<type>[\w/]+)(\[[^\]]*\])?\s+(?P<name>\w+)\s*(#\s*(?P<comment>.*))?$')


def numeric_fields(text: str) -> list[tuple[str, str]]:
    """(field name, comment) of every numeric field in one interface file's text."""
    fields = []
    for line in text.splitlines():
        line = line.strip()
        if not line or line.startswith('#') or line == '---' or '=' in line.split('#')[0]:
            continue
        match = FIELD.match(line)
        assert match, f'unparsed line: {line!r}'
        if match['type'] in NUMERIC:
            fields.append((match['name'], match['comment'] or ''))
    return fields


def test_every_interface_file_is_checked() -> None:
    assert len(INTERFACES) == 19  # as listed in CMakeLists.txt's rosidl_generate_interfaces


@pytest.mark.parametrize('path', INTERFACES, ids=lambda p: p.name)
def test_numeric_fields_state_their_unit(path: Path) -> None:
    missing = [name for name, comment in numeric_fields(path.read_text())
               if not UNIT.match(comment)]
    assert not missing, f'{path.name}: no unit in the comment of {missing}'


@pytest.mark.parametrize('path', INTERFACES, ids=lambda p: p.name)
def test_no_issue_tracker_references(path: Path) -> None:
    assert not re.search(r'\bissues?\b', path.read_text(), re.IGNORECASE), path.name


def test_the_checks_can_fail() -> None:
    """A field without a unit and a comment that is not a unit are both caught."""
    text = 'uint8 A_CONST=1  # no unit needed\nfloat64 speed\nuint32 total  # photos\n' \
           'float64 ok  # rad/s\nfloat64[] rates  # rad/s\n---\nstring name\n'
    fields = numeric_fields(text)
    assert [name for name, comment in fields if not UNIT.match(comment)] == ['speed', 'total']
    assert [name for name, _ in fields] == ['speed', 'total', 'ok', 'rates']
