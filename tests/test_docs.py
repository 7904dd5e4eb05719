"""The documents work from a fresh clone.

Every relative link (and its #anchor) in README.md, ARCHITECTURE.md, docs/*.md, bench/README.md
and the package READMEs resolves in the repository; nothing in the repository points outside
it (``../shared``); user documents name no issue numbers; and the commands the top README
shows are ones the workspace really has: its ``make`` targets exist in the Makefile and
``.ci/run`` runs its test command, its ``ros2 launch`` line loads and runs under the launch
stand-in (gimbal_driver_testing.launch_standin) with those arguments and starts the
node with the README's parameters file (keyed ``/**``, so it applies under a namespace
too), whose keys the driver's reference lists, and its ``ros2 topic``,
``ros2 action`` and ``ros2 service`` lines name interfaces of the reference with their
types and message fields that exist, and its Capture walkthrough (parameters file, move, jog,
stop, diagnostics) works as written against the Capture simulator. Every package has a
CHANGELOG.rst in the ROS format.
"""

from __future__ import annotations

import importlib
import re
import shlex
import subprocess
from pathlib import Path

import pytest
import yaml
from test_reference import COMMON_REFERENCE, reference_entries

from gimbal_driver_testing import launch_standin

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / 'README.md'


def documents() -> list[Path]:
    return sorted({README, ROOT / 'ARCHITECTURE.md', ROOT / 'bench' / 'README.md',
                   *(ROOT / 'docs').glob('*.md'), *(ROOT / 'src').glob('*/README.md')})


def user_documents() -> list[Path]:
    """What a user reads: the README, the reference and the driver manuals."""
    return [README, *sorted((ROOT / 'docs').glob('*.md')),
            *sorted((ROOT / 'src').glob('*/README.md'))]


_LINK = re.compile(r'(?<!!)\[[^\]]*\]\(([^)\s]+)\)')
_FENCE = re.compile(r'^```.*?^```', re.S | re.M)


def anchors(path: Path) -> set[str]:
    """GitHub's heading anchors: lower case, punctuation dropped, spaces to hyphens."""
    found: set[str] = set()
    for line in _FENCE.sub('', path.read_text()).splitlines():
        match = re.match(r'#{1,6}\s+(.*)', line)
        if match:
            slug = re.sub(r'[^\w\- ]', '', match.group(1).strip().lower()).replace(' ', '-')
            base, n = slug, 1
            while slug in found:
                slug, n = f'{base}-{n}', n + 1
            found.add(slug)
    return found


def links(path: Path) -> list[str]:
    return _LINK.findall(_FENCE.sub('', path.read_text()))


@pytest.mark.parametrize('path', documents(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_resolves(path: Path) -> None:
    broken = []
    for target in links(path):
        if re.match(r'[a-z]+:', target):  # https:, mailto:
            continue
        file_part, _, anchor = target.partition('#')
        resolved = (path.parent / file_part).resolve() if file_part else path
        outside = not resolved.exists() or ROOT not in (resolved, *resolved.parents)
        if outside or (anchor and resolved.suffix == '.md' and anchor not in anchors(resolved)):
            broken.append(target)
    assert not broken, f'{path.relative_to(ROOT)}: broken links {broken}'


def test_the_link_check_can_fail(tmp_path: Path) -> None:
    page = tmp_path / 'page.md'
    page.write_text('# Title here\n\n[a](#title-here) [b](#nowhere) [c](gone.md)\n')
    assert anchors(page) == {'title-here'}
    assert links(page) == ['#title-here', '#nowhere', 'gone.md']


def tracked_files() -> list[Path]:
    names = subprocess.run(['git', 'ls-files'], cwd=ROOT, capture_output=True, text=True,
                           check=True).stdout.split()
    return [ROOT / name for name in names if (ROOT / name).is_file()]


def test_nothing_points_outside_the_repository() -> None:
    outside = re.compile(r'\.\./shared|/work/shared')
    pointing = [str(path.relative_to(ROOT)) for path in tracked_files()
                if path.suffix not in ('.png', '.mcap', '.db3')
                and outside.search(path.read_text(errors='replace'))
                and path.name != 'test_docs.py']
    assert not pointing, f'these files point outside the repository: {pointing}'


def test_user_documents_name_no_issue_numbers_or_commits() -> None:
    issue = re.compile(r'\b[Ii]ssues? \d+|\(#\d+\)|\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])'
                       r'[0-9a-f]{7,40}\b')
    named = {str(path.relative_to(ROOT)): issue.findall(path.read_text())
             for path in user_documents()}
    assert not {name: found for name, found in named.items() if found}


def readme_commands() -> list[list[str]]:
    commands = []
    for block in re.findall(r'^```sh\n(.*?)^```', README.read_text(), re.S | re.M):
        for line in block.splitlines():
            line = line.split(' #')[0].strip()
            if line:
                commands.append(shlex.split(line))
    return commands


def readme_parameters_file() -> dict:
    block = re.search(r'^```yaml\n(.*?)^```', README.read_text(), re.S | re.M)
    assert block, 'the README shows no parameters file'
    return yaml.safe_load(block.group(1))


def test_readme_make_targets_exist_and_ci_runs_the_test_command() -> None:
    makefile = (ROOT / 'Makefile').read_text()
    targets = {match for match in re.findall(r'^([\w-]+):', makefile, re.M)}
    shown = [command[1] for command in readme_commands() if command[0] == 'make']
    assert 'test' in shown and 'build' in shown
    assert set(shown) <= targets, set(shown) - targets
    assert re.search(r'^make test$', (ROOT / '.ci' / 'run').read_text(), re.M)


def interface(package: str) -> dict[tuple[str, str], str]:
    return {**reference_entries(COMMON_REFERENCE.read_text()),
            **reference_entries((ROOT / 'src' / package / 'README.md').read_text())}


@pytest.mark.ros
def test_readme_launch_line_runs_with_its_arguments(monkeypatch, tmp_path: Path) -> None:
    launch_standin.install(monkeypatch)
    text = README.read_text()
    lines = [shlex.split(line.strip('` ')) for line in re.findall(
        r'^`?(ros2 launch [^`\n]+)', text, re.M)]
    assert lines, 'the README shows no ros2 launch line'
    params = readme_parameters_file()
    for command in lines:
        package, launch_file, *arguments = command[2:]
        path = ROOT / 'src' / package / 'launch' / launch_file
        assert path.is_file(), path
        given = dict(argument.split(':=', 1) for argument in arguments)
        description = launch_standin.load_description(path)
        declared = {argument.name for argument in description.declared_arguments()}
        assert set(given) <= declared, set(given) - declared
        if 'params_file' in given:  # the README's parameters file, written as it says
            written = tmp_path / given['params_file']
            written.write_text(yaml.safe_dump(params))
            given['params_file'] = str(written)
        context = launch_standin.run(description, given, tmp_path)
        node = context.launched[-1]
        assert node.package == package and node.parameters[1]['autostart'] is True
        if 'params_file' in given:
            assert node.parameters[0] == Path(given['params_file'])
            assert set(params) == {'/**'}, 'key the README parameters file /** (any namespace)'
            section = params['/**']['ros__parameters']
            # what the node gets from the launch's command line, under a namespace too
            for namespace in ('', 'robot/gimbal'):
                started = launch_standin.run(description, {**given, 'namespace': namespace},
                                             tmp_path).launched[-1]
                resolved = launch_standin.node_parameters(started.cmd)
                assert {k: resolved[k] for k in section} == section, namespace
            listed = {name for kind, name in interface(package) if kind == 'parameter'}
            assert set(section) <= listed, set(section) - listed


def message_type(name: str) -> type:
    package, kind, message = name.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), message)


def check_fields(msg_type: type, text: str) -> None:
    """The YAML of a ros2 CLI line sets fields that the message has, with values it takes."""
    message = msg_type()
    for field, value in yaml.safe_load(text).items():
        assert field in msg_type.get_fields_and_field_types(), f'{msg_type.__name__}.{field}'
        setattr(message, field, value)


def test_readme_ros2_lines_name_real_interfaces() -> None:
    checked = 0
    for command in readme_commands():
        if command[0] != 'ros2' or command[1] not in ('topic', 'action', 'service'):
            continue
        words, skip = [], False
        for word in command[2:]:
            if skip or word.startswith('-'):
                skip = word in ('-r', '--rate')  # an option that takes a value
                continue
            words.append(word)
        _verb, name, *rest = words
        package = 'capture_driver'  # the README's device
        names = {key[1]: value for key, value in interface(package).items()}
        short = name.replace(f'/{package}/', '~/').lstrip('/')
        listed = names.get(short, names.get(name))
        assert listed, f'{name} is not in the reference of {package}'
        if rest:
            assert rest[0] == listed, f'{name}: {rest[0]} but the reference says {listed}'
            msg_type = message_type(listed)
            if command[1] == 'action':
                msg_type = msg_type.Goal
            elif command[1] == 'service':
                msg_type = msg_type.Request
            if len(rest) > 1:
                check_fields(msg_type, rest[1])
        checked += 1
    assert checked >= 4


_VERSION_HEADING = re.compile(r'^(Forthcoming|\d+\.\d+\.\d+ \(\d{4}-\d{2}-\d{2}\))$')


@pytest.mark.parametrize('package', sorted(p.parent.name for p in (ROOT / 'src').glob(
    '*/package.xml')))
def test_every_package_has_a_ros_changelog(package: str) -> None:
    """CHANGELOG.rst as catkin_generate_changelog and bloom read it: the title between two
    rows of ``^`` as long as it, then version sections (``Forthcoming`` or ``X.Y.Z
    (YYYY-MM-DD)``) underlined with ``-``, each a bullet list; no issue numbers or hashes."""
    lines = (ROOT / 'src' / package / 'CHANGELOG.rst').read_text().splitlines()
    title = f'Changelog for package {package}'
    assert lines[:3] == ['^' * len(title), title, '^' * len(title)], lines[:3]
    sections = [i for i, line in enumerate(lines) if _VERSION_HEADING.match(line)]
    assert sections, f'{package}: no version section'
    for start in sections:
        assert lines[start + 1] == '-' * len(lines[start]), lines[start:start + 2]
        assert lines[start + 2].startswith('* '), f'{package}: {lines[start]} has no bullets'
    versions = [lines[i] for i in sections if lines[i] != 'Forthcoming']
    assert versions == sorted(versions, reverse=True), 'newest version first'
    text = '\n'.join(lines)
    assert not re.search(r'\b[Ii]ssues? \d+|#\d+|\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*\d)'
                         r'[0-9a-f]{7,40}\b', text), f'{package}: issue numbers or hashes'


def test_the_probe_section_links_its_manual() -> None:
    """The README's "Probe first" section links docs/probe.md (the link check above then
    covers it)."""
    text = README.read_text()
    section = text.split("## Don't know the settings? Probe first.", 1)
    assert len(section) == 2, 'the README has no "Probe first" section'
    body = section[1].split('\n## ', 1)[0]
    assert '](docs/probe.md)' in body, 'link docs/probe.md in the Probe first section'
    assert (ROOT / 'docs' / 'probe.md').is_file()


@pytest.mark.ros
def test_readme_workspace_commands_exist_and_take_their_options() -> None:
    """The README's commands for this workspace: the scripts it sources exist, and each
    installed executable it runs exists and takes the options (simulator) or parameters
    (node, ``-p name:=value``) the line gives it."""
    if not (ROOT / 'install' / 'setup.bash').exists():
        pytest.skip('the workspace is not built (make build)')
    checked = 0
    for command in readme_commands():
        if command[0] == 'source' and not command[1].startswith('/'):  # not /opt/ros
            assert (ROOT / command[1]).is_file(), command
            continue
        if not command[0].startswith('install/'):
            continue
        executable = ROOT / command[0]
        assert executable.is_file(), command[0]
        package = executable.parent.name
        if '--ros-args' in command:
            given = [command[i + 1].split(':=')[0] for i, word in enumerate(command)
                     if word == '-p']
            listed = {name for kind, name in interface(package) if kind == 'parameter'}
            assert set(given) <= listed, set(given) - listed
        else:
            options = [word for word in command[1:] if word.startswith('--')]
            usage = subprocess.run([str(executable), '--help'], capture_output=True,
                                   text=True, timeout=60).stdout
            assert all(option in usage for option in options), (options, usage)
        checked += 1
    assert checked >= 2


def readme_line(prefix: str) -> list[str]:
    return next(command for command in readme_commands() if command[:3] == prefix.split())


@pytest.mark.ros
def test_readme_capture_walkthrough_works_against_the_simulator(tmp_path: Path) -> None:
    """Steps 2 to 5 of the README, as written, against the Capture simulator: the node runs
    with the README's parameters file (only the address swapped for the simulator's), the
    README's move_to goal reaches its positions, its jog moves pan the way it says, its stop
    answers, and its diagnostics read the parts the README names, all OK."""
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState
    from std_srvs.srv import Trigger

    from gimbal_driver_common.registry import drivers
    from gimbal_driver_common.sim_handle import make_handle
    from gimbal_driver_testing import DomainLease, ManagedProcess, wait_for
    from gimbal_driver_testing.ros import RosTestClient, joint_positions
    from gimbal_msgs.action import MoveTo

    spec = next(spec for spec in drivers() if spec.package == 'capture_driver')
    params = tmp_path / 'my_pedestal.yaml'
    params.write_text(yaml.safe_dump(readme_parameters_file()))
    device = make_handle(spec, tmp_path, process_tests=True)
    device.start()
    try:
        with DomainLease() as domain, RosTestClient(domain, 'readme_check') as ros:
            diagnostics = ros.subscribe('/diagnostics', DiagnosticArray)
            node = ManagedProcess.ros(spec.package, spec.node_executable, domain, [
                '--ros-args', '--params-file', str(params),
                '-p', 'host:=127.0.0.1', '-p', f'port:={device.port}'])
            try:
                ros.wait_for_message('/joint_states', JointState, timeout=60)
                # 4. the move
                action = readme_line('ros2 action send_goal')
                words = [w for w in action[3:] if not w.startswith('-')]
                goal = MoveTo.Goal()
                for field, value in yaml.safe_load(words[2]).items():
                    setattr(goal, field, value)
                result, _, _ = ros.run_action(MoveTo, words[0], goal, timeout=60)
                assert result.success, result.message
                reached = dict(zip(goal.joint_names, result.positions, strict=True))
                for joint, wanted in zip(goal.joint_names, goal.positions, strict=True):
                    assert abs(reached[joint] - wanted) < 0.02, (joint, reached)
                # the jog: published at 10 Hz for as long as it runs
                jog = readme_line('ros2 topic pub')
                words = [w for w in jog[3:] if not w.startswith('-') and w != '10']
                command = yaml.safe_load(words[2])
                joint, velocity = command['name'][0], command['velocity'][0]
                start = joint_positions(ros.wait_for_message(
                    '/joint_states', JointState, timeout=10))[joint]

                def jogged() -> bool:
                    ros.publish(words[0], JointState(**command))
                    now = joint_positions(ros.wait_for_message(
                        '/joint_states', JointState, timeout=10))[joint]
                    return (now - start) * velocity > 0.05

                wait_for(jogged, 30, f'{joint} to jog at {velocity} rad/s', interval=0.1)
                # the stop
                stop = readme_line('ros2 service call')
                assert ros.call(Trigger, stop[3], Trigger.Request(), timeout=30).success
                # 5. diagnostics: the parts the README names, all OK
                named = set(re.findall(r'`(capture_driver: [^`]+)`', README.read_text()))
                assert len(named) >= 5, named

                def healthy() -> bool:
                    if not diagnostics:
                        return False
                    # a byte field: rclpy gives bytes
                    levels = {s.name: ord(s.level) for s in diagnostics[-1].status}
                    return named <= set(levels) and all(
                        level == 0 for name, level in levels.items() if name in named)

                try:
                    wait_for(healthy, 60, 'diagnostics all OK', interval=0.2)
                except TimeoutError:
                    last = diagnostics[-1].status if diagnostics else []
                    pytest.fail(f'diagnostics {sorted(named)} not all OK: ' + ', '.join(
                        f'{s.name}={ord(s.level)} {s.message}' for s in last))
            finally:
                node.stop()
    finally:
        device.stop()
