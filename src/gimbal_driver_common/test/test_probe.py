"""gimbal_probe's core with fake probes (no device, no ROS): the attempt loop, its time limit,
the report, the parameters file and the command line. The probes of the drivers against
their simulators are tests/test_probe.py."""

from __future__ import annotations

import io
import threading

import pytest
import yaml

from gimbal_driver_common import probe_cli
from gimbal_driver_common.errors import DeviceTimeout
from gimbal_driver_common.probe import (
    Attempt,
    Found,
    NoAnswer,
    ProbeLink,
    WatchedStream,
    line_verdict,
    registered_probes,
    run_probes,
)
from gimbal_driver_common.registry import DriverSpec
from gimbal_driver_common.transport import ByteStream


def spec(name: str) -> DriverSpec:
    return DriverSpec(name=name, title=name, package=f'{name}_driver', node_executable='n',
                      node_name=f'{name}_driver', sim_executable='s', node_class='m:C',
                      description='d.urdf', joints=('pan',), move_goal=(0.0,))


def found(port: int) -> Found:
    return Found(device='fake', protocol='fake protocol', link={'port': port},
                 identity={'serial': 'S1'}, parameters={'host': 'h', 'port': port})


class FakeProbe:
    """Attempts on TCP only; ``answers`` maps a port to a Found or an exception to raise."""

    def __init__(self, answers: dict, default_port: int) -> None:
        self.answers = answers
        self.default_port = default_port
        self.ran: list[int] = []

    def __call__(self, link: ProbeLink) -> list[Attempt]:
        if link.kind != 'tcp':
            return []
        port = link.port or self.default_port
        return [Attempt(f'port {port}', f'tcp {port}', lambda: self.attempt(port),
                        documented=port == self.default_port)]

    def attempt(self, port: int) -> Found:
        self.ran.append(port)
        answer = self.answers.get(port, NoAnswer('silent'))
        if isinstance(answer, BaseException):
            raise answer
        return answer


def test_an_answer_is_reported_with_the_driver_and_node_name() -> None:
    a, b = FakeProbe({}, 1000), FakeProbe({1001: found(1001)}, 1001)
    report = run_probes(ProbeLink('tcp', host='h'), [(spec('a'), a), (spec('b'), b)])
    [device] = report.found
    assert (device.driver, device.node_name) == ('b', 'b_driver')
    assert [o.reason for o in report.outcomes] == ['silent', '']


def test_a_port_where_a_device_answered_is_not_tried_by_the_others() -> None:
    a, b = FakeProbe({7: found(7)}, 1000), FakeProbe({7: found(7)}, 7)
    report = run_probes(ProbeLink('tcp', host='h', port=7), [(spec('a'), a), (spec('b'), b)])
    # b documents port 7: it goes first, and a never sends its bytes there
    assert [d.driver for d in report.found] == ['b']
    assert (a.ran, b.ran) == ([], [7])


def test_errors_of_an_attempt_are_reasons_not_tracebacks() -> None:
    a = FakeProbe({1: DeviceTimeout('no reply within 0.1 s')}, 1)
    b = FakeProbe({2: KeyError('opcode 0x99')}, 2)
    report = run_probes(ProbeLink('tcp', host='h'), [(spec('a'), a), (spec('b'), b)])
    assert not report.found
    assert report.outcomes[0].reason == 'DeviceTimeout: no reply within 0.1 s'
    assert report.outcomes[1].reason.startswith('unexpected answer (KeyError')


def test_an_attempt_that_hangs_is_abandoned_at_its_time_limit() -> None:
    release = threading.Event()

    def hanging(link: ProbeLink) -> list[Attempt]:
        return [Attempt('hangs', 'tcp 1', lambda: release.wait(60) and found(1))]

    try:
        report = run_probes(ProbeLink('tcp', host='h', timeout=0.1), [(spec('a'), hanging)])
    finally:
        release.set()
    assert 'attempt abandoned' in report.outcomes[0].reason
    assert not report.found


def test_a_probe_that_cannot_plan_is_reported() -> None:
    def broken(link: ProbeLink) -> list[Attempt]:
        raise ValueError('no such channel')

    report = run_probes(ProbeLink('tcp', host='h'), [(spec('a'), broken)])
    assert report.outcomes[0].reason == 'probe not run: no such channel'


def test_a_probe_that_does_not_load_is_reported_and_the_others_run() -> None:
    broken = DriverSpec(**{**spec('broken').__dict__, 'probe': 'no_such_module:probe'})
    fine = DriverSpec(**{**spec('fine').__dict__, 'probe': 'gimbal_driver_common.probe:Found'})
    probes = registered_probes([broken, fine])
    assert [(s.name, f is Found) for s, f in probes] == [('broken', False), ('fine', True)]
    report = run_probes(ProbeLink('tcp', host='h'),
                        [probes[0], (spec('other'), FakeProbe({1: found(1)}, 1))])
    assert report.outcomes[0].reason.startswith("probe not run: 'no_such_module:probe' does "
                                                'not load')
    assert [d.driver for d in report.found] == ['other']


def test_the_parameters_file_has_the_ros2_params_shape() -> None:
    device = found(4949)
    device.node_name = 'capture_driver'
    document = yaml.safe_load(probe_cli.parameters_yaml([device]))
    assert document == {'/**': {'ros__parameters': {'host': 'h', 'port': 4949}}}
    # several devices: one section each, still under any namespace
    other = found(5520)
    other.node_name = 'kessler_kos_driver'
    document = yaml.safe_load(probe_cli.parameters_yaml([device, other]))
    assert document == {'/**/capture_driver': {'ros__parameters': {'host': 'h', 'port': 4949}},
                        '/**/kessler_kos_driver': {'ros__parameters': {'host': 'h',
                                                                      'port': 5520}}}


@pytest.mark.parametrize(('text', 'expected'), [
    ('10.0.0.2', ('10.0.0.2', 0)), ('10.0.0.2:4949', ('10.0.0.2', 4949)),
    ('[::1]:5520', ('::1', 5520)), ('::1', ('::1', 0)), ('pedestal.local', ('pedestal.local', 0)),
])
def test_host_and_port(text: str, expected: tuple[str, int]) -> None:
    assert probe_cli.split_host_port(text) == expected


@pytest.mark.parametrize('text', [':4949', 'h:port', 'h:0', 'h:70000'])
def test_a_bad_tcp_address_is_a_usage_error(text: str, capsys: pytest.CaptureFixture) -> None:
    assert probe_cli.main(['--tcp', text]) == probe_cli.EXIT_USAGE
    assert '--tcp' in capsys.readouterr().err


def test_one_link_is_required(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as exit_info:
        probe_cli.main([])
    assert exit_info.value.code == probe_cli.EXIT_USAGE
    with pytest.raises(SystemExit):
        probe_cli.main(['--serial', '/dev/x', '--tcp', 'h'])


def run_cli(monkeypatch: pytest.MonkeyPatch, probes: list, argv: list[str]) -> tuple[int, str]:
    monkeypatch.setattr(probe_cli, 'registered_probes', lambda: probes)
    out = io.StringIO()
    return probe_cli.main(argv, out=out), out.getvalue()


def test_the_cli_prints_the_device_and_writes_the_file(monkeypatch: pytest.MonkeyPatch,
                                                        tmp_path) -> None:
    seen: list[ProbeLink] = []

    def recording(link: ProbeLink) -> list[Attempt]:
        seen.append(link)
        return FakeProbe({5520: found(5520)}, 5520)(link)

    output = tmp_path / 'params.yaml'
    status, text = run_cli(monkeypatch, [(spec('kos'), recording)],
                           ['--tcp', '127.0.0.1', '--password', 's3cret-word', '--output',
                            str(output)])
    assert status == probe_cli.EXIT_FOUND
    assert seen[0].password == 's3cret-word'   # the probes get it ...
    assert 's3cret-word' not in text             # ... and it is never printed
    assert 's3cret-word' not in repr(seen[0])
    assert 'Found: fake (kos driver, node kos_driver)' in text
    assert 'identity: serial S1' in text
    written = yaml.safe_load(output.read_text())
    assert written == {'/**': {'ros__parameters': {'host': 'h', 'port': 5520}}}


def test_nothing_found_says_what_was_tried_and_exits_1(monkeypatch: pytest.MonkeyPatch,
                                                       tmp_path) -> None:
    output = tmp_path / 'params.yaml'
    status, text = run_cli(monkeypatch, [(spec('a'), FakeProbe({}, 1)), (spec('b'), FakeProbe(
        {}, 2))], ['--tcp', 'h', '--output', str(output)])
    assert status == probe_cli.EXIT_NOTHING
    assert 'No device answered on TCP h' in text and 'a port 1; b port 2' in text
    assert not output.exists()


class ScriptedLine(ByteStream):
    """A line that answers each write with ``reply(data)``."""

    def __init__(self, reply) -> None:
        self.reply = reply
        self.pending = b''

    description = 'scripted'
    is_open = True

    def open(self) -> None:
        pass

    def close(self) -> None:
        pass

    def write(self, data: bytes) -> None:
        self.pending += self.reply(data)

    def read(self, max_bytes: int, timeout: float) -> bytes:
        data, self.pending = self.pending[:max_bytes], self.pending[max_bytes:]
        return data


@pytest.mark.parametrize(('reply', 'verdict'), [
    (lambda data: b'', 'silent: no byte came back'),
    (lambda data: data, 'the line echoes what is sent'),
    (lambda data: data[:2], 'the line echoes what is sent'),
    (lambda data: b'\xde\xad\xbe\xef', '4 byte(s) came back, not a X answer (first: de ad be ef)'),
])
def test_what_the_line_did_is_said(reply, verdict: str) -> None:
    line = WatchedStream(ScriptedLine(reply))
    line.write(b'\x01\x02\x03')
    line.read(100, 0.0)
    assert line_verdict([line], 'X', DeviceTimeout('no reply')).startswith(verdict)
