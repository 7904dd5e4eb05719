"""Check that a driver's launch file docstring states the defaults its launch really has.

Each ``launch/<package>.launch.py`` lists its arguments in its docstring, one per line as
``    name:=default   meaning``; the real defaults are the ``arguments`` of
``ros/description_launch.py``'s ``driver_launch_description``. Both are read as text
(``ast``): ``launch`` is not installable in the pip environment, so the module cannot be
imported here.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import gimbal_driver_common
from gimbal_driver_common.registry import driver_of_package

#: read as a file beside the (ROS-free) package it belongs to, never imported
DESCRIPTION_LAUNCH = Path(gimbal_driver_common.__file__).resolve().parent / 'ros' / \
    'description_launch.py'

#: one argument line of a launch file docstring: four spaces, ``name:=default``
ARGUMENT_LINE = re.compile(r'^ {4}(?P<name>\w+):=(?P<default>\S+)', re.MULTILINE)


def declared_defaults(package: str, source: str | None = None) -> dict[str, str]:
    """The launch arguments and defaults ``driver_launch_description(package)`` declares.

    ``description_file``'s default is a call, ``default_description(package)``: it is
    given as ``share/<package>/urdf/<package>.urdf``, as the docstrings write it. The link
    arguments are the registry's ``link_parameters`` of the package, each defaulting to ''.
    """
    text = DESCRIPTION_LAUNCH.read_text(encoding='utf-8') if source is None else source
    function = next(node for node in ast.walk(ast.parse(text))
                    if isinstance(node, ast.FunctionDef)
                    and node.name == 'driver_launch_description')
    listing = next(node.value for node in ast.walk(function)
                   if isinstance(node, ast.Assign)
                   and [getattr(t, 'id', None) for t in node.targets] == ['arguments'])
    assert isinstance(listing, ast.List), ast.dump(listing)
    defaults: dict[str, str] = {}
    for entry in listing.elts:
        if isinstance(entry, ast.Starred):  # the link arguments: the spec's, default ''
            assert 'link_parameters' in ast.unparse(entry), ast.unparse(entry)
            defaults.update(dict.fromkeys(driver_of_package(package).link_parameters, ''))
            continue
        assert isinstance(entry, ast.Tuple) and isinstance(entry.elts[0], ast.Constant)
        name, default = entry.elts[0].value, entry.elts[1]
        if isinstance(default, ast.Constant):
            defaults[name] = str(default.value)
        else:
            assert (isinstance(default, ast.Call)
                    and getattr(default.func, 'id', None) == 'default_description'), \
                f'{name}: default {ast.unparse(default)} not understood'
            defaults[name] = f'share/{package}/urdf/{package}.urdf'
    return defaults


def documented_defaults(launch_file: Path | str) -> dict[str, str]:
    """``name -> default`` as the launch file's docstring states them (``''`` read as
    the empty string)."""
    text = Path(launch_file).read_text(encoding='utf-8')
    docstring = ast.get_docstring(ast.parse(text), clean=False) or ''
    return {match['name']: '' if match['default'] == "''" else match['default']
            for match in ARGUMENT_LINE.finditer(docstring)}


def launch_docstring_errors(launch_file: Path | str, package: str,
                            source: str | None = None) -> list[str]:
    """Where the docstring and the declared arguments disagree (empty when they agree)."""
    declared = declared_defaults(package, source)
    documented = documented_defaults(launch_file)
    errors = [f'{name}: not in the docstring' for name in declared if name not in documented]
    errors += [f'{name}: in the docstring, not declared' for name in documented
               if name not in declared]
    errors += [f'{name}: docstring says {documented[name]!r}, the launch {default!r}'
               for name, default in declared.items()
               if name in documented and documented[name] != default]
    return errors
