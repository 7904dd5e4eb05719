"""Start a new driver package from the reference driver (src/virtual_gimbal_driver).

    python scripts/new_driver.py NAME [--dest DIR] [--port PORT] [--title TITLE]

Copies the reference package to ``DIR/NAME_driver`` (default ``src/``) under the new names:
the package ``NAME_driver``, the executables ``NAME_driver_node`` and ``NAME_sim``, the
registry name ``NAME``, the classes ``<Name>Node``, ``<Name>Device``, ``<Name>Client``,
``<Name>Sim``, the reader thread ``NAME-reader`` and the simulator's TCP port ``PORT``.
The copy builds, and passes the conformance suite as it is: it still speaks the reference's
invented line protocol. Each module that must become your device's starts with a
``NEW DRIVER:`` comment that says what to replace; ARCHITECTURE.md's "Adding a driver" is
the checklist, and its last step (the thread-list row, the rows of README.md and
docs/interface.md) is printed when the copy is done.
"""

from __future__ import annotations

import argparse
import re
import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
REFERENCE = ROOT / 'src' / 'virtual_gimbal_driver'
REFERENCE_PORT = '4950'
NAME = re.compile(r'[a-z][a-z0-9]*(_[a-z0-9]+)*')
#: files of the reference that are not copied (build output, editor state)
SKIPPED = re.compile(r'(__pycache__|\.pyc$|\.egg-info|\.pytest_cache)')

#: module (relative to the package's Python package) -> what its NEW DRIVER comment says
STUBS = {
    'protocol/__init__.py': 'the codec of YOUR device: replace the invented line protocol '
                            '(request formatting, reply parsing; pure functions, no I/O) '
                            'and put every byte example of its document in '
                            'test/test_protocol_vectors.py',
    'client.py': 'the session over your link: keep one reader thread (the core\'s '
                 'Session), match each reply to its request, raise the core\'s errors',
    'device.py': 'the adapter: your device in SI units and REP-103 signs (Device, and the '
                 'capabilities it has: Homing, DevicePresets, DeviceScans, StatusReport)',
    'node.py': 'the node: your default joints and limits, your link parameters '
               '(DriverSpec.link_parameters), your device\'s own services and topics',
    'sim.py': 'the simulator: your wire protocol on 127.0.0.1 with the shared motion model '
              'and control verbs (SimControl)',
    'registration.py': 'the DriverSpec: joints, a reachable move_goal, link_parameters, '
                       'the simulator arguments, demo/soak/bench settings',
    'probe.py': 'the read-only probe: your handshake and identity reads, nothing else',
    'sim_handle.py': 'the in-process simulator handle: classify your requests '
                     '(changing, motion), your optional faults and not_applicable',
}


def camel(name: str) -> str:
    return ''.join(part.capitalize() for part in name.split('_'))


def renames(name: str, title: str, port: int) -> list[tuple[str, str]]:
    """(reference text, new text), longest first so no rename eats a longer one."""
    return [
        ('virtual_gimbal_driver', f'{name}_driver'),
        ('virtual_gimbal_sim', f'{name}_sim'),
        ('VirtualGimbal', camel(name)),
        ('virtual_gimbal', name),
        ('virtual-gimbal', name.replace('_', '-')),
        ('Virtual gimbal', title),
        ('virtual gimbal', title.lower()),
        ('vgimbal', name.replace('_', '')),
        (REFERENCE_PORT, str(port)),
    ]


def renamed(text: str, pairs: list[tuple[str, str]]) -> str:
    for old, new in pairs:
        text = text.replace(old, new)
    return text


def stub(relative: str, text: str) -> str:
    """The ``NEW DRIVER:`` comment for a module that must become the device's own, right
    after its docstring (which stays the module's ``__doc__``)."""
    note = STUBS.get(relative)
    if note is None:
        return text
    comment = f'\n# NEW DRIVER: {note}.\n'
    if text.startswith('"""'):
        end = text.index('"""', 3) + 3
        return text[:end] + comment + text[end:]
    return comment.lstrip('\n') + text


def changelog(package: str, title: str) -> str:
    heading = f'Changelog for package {package}'
    return ('^' * len(heading) + f'\n{heading}\n' + '^' * len(heading) + '\n\n'
            'Forthcoming\n-----------\n'
            f'* Driver for the {title}, started from the reference driver\n')


def generate(name: str, dest: Path, port: int, title: str) -> Path:
    """Write the package ``dest/<name>_driver``; returns its directory."""
    if not NAME.fullmatch(name) or name.endswith('_driver'):
        raise ValueError(f'{name!r}: a lower-case ROS package stem (letters, digits, '
                         "underscores; without '_driver', which is added)")
    package = f'{name}_driver'
    target = dest / package
    if target.exists():
        raise FileExistsError(f'{target} exists already')
    pairs = renames(name, title, port)
    module_root = REFERENCE / 'virtual_gimbal_driver'
    for source in sorted(REFERENCE.rglob('*')):
        relative = source.relative_to(REFERENCE)
        if SKIPPED.search(str(relative)) or source.is_dir():
            continue
        out = target / renamed(str(relative), pairs)
        out.parent.mkdir(parents=True, exist_ok=True)
        if relative.name == 'CHANGELOG.rst':
            out.write_text(changelog(package, title), encoding='utf-8')
            continue
        try:
            text = source.read_text(encoding='utf-8')
        except UnicodeDecodeError:
            shutil.copyfile(source, out)
            continue
        inside = source.is_relative_to(module_root)
        text = renamed(text, pairs)
        if inside:
            text = stub(str(source.relative_to(module_root)), text)
        out.write_text(text, encoding='utf-8')
    return target


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('name', help="the package stem: 'pelco_d' makes pelco_d_driver")
    parser.add_argument('--dest', type=Path, default=ROOT / 'src')
    parser.add_argument('--port', type=int, default=4960,
                        help="the simulator's TCP port (the reference's is 4950)")
    parser.add_argument('--title', default='', help="the device's name for people")
    args = parser.parse_args(argv)
    title = args.title or args.name.replace('_', ' ')
    try:
        target = generate(args.name, args.dest, args.port, title)
    except (ValueError, FileExistsError) as exc:
        parser.error(str(exc))
    package = target.name
    print(f'new_driver: wrote {target}')
    print('new_driver: next (ARCHITECTURE.md, "Adding a driver"): replace each module marked '
          'NEW DRIVER:, then add outside the package')
    print(f"  ARCHITECTURE.md thread list: | `{args.name.replace('_', '')}-reader` | "
          f'`{args.name}` | always | ... |')
    print(f'  README.md: | {title} | [{package}](src/{package}/README.md) | <link> |')
    print(f'  docs/interface.md: | `{package}` | `{package}_node`, `{args.name}_sim` |  and a '
          '"Drivers at a glance" row')
    return 0


if __name__ == '__main__':
    sys.exit(main())
