"""The drivers the demo runs: one :class:`~demo.DemoTarget` per registered driver.

Every driver comes from the driver registry (:mod:`gimbal_driver_common.registry`): its
executables, simulator arguments, link parameters, move goal, jog, scan and its own extra
steps (``module:function`` references into its package) are in the package's
``registration.py``. A driver whose package is not built is not registered and so not run.
Every target keeps its pseudo-terminal links, presets file and password file in the demo's
temporary directory (``target.workdir``), so nothing is left in /tmp and two demos on one
machine do not collide. Each simulator binds 127.0.0.1 only.
"""

from __future__ import annotations

from demo import DemoTarget

from gimbal_driver_common.registry import DriverSpec, drivers, resolve
from gimbal_driver_common.sim_control import parse_ready_line
from gimbal_driver_testing.ros import RosTestClient
from gimbal_msgs.action import Home
from gimbal_msgs.srv import StartScan


def common_parameters(target: DemoTarget) -> dict[str, object]:
    """Parameters every driver gets in the demo: a modest rate (2 shared cores), quick
    reconnects, and driver-side presets in the demo's temporary directory."""
    return {'publish_rate': 20.0, 'reconnect_period': 0.5, 'diagnostics_period': 0.5,
            'presets_file': str(target.workdir / f'{target.node_name}_presets.yaml')}


def simulator_ready(target: DemoTarget) -> bool:
    """The simulator accepts a link: it printed its JSON ready line (``sim_control``).
    The one place that reads simulator output."""
    return target.sim is not None and parse_ready_line(
        target.sim.output(), target.spec.sim_executable) is not None


def run_home(target: DemoTarget, ros: RosTestClient) -> str:
    """The common ``~/home`` action, for drivers whose spec lists a ``home`` step."""
    target.commanded('home')
    result, _, feedback = ros.run_action(Home, target.ns('home'), Home.Goal(), timeout=60)
    if not result.success:
        raise RuntimeError(result.message)
    return f'{result.message} ({len(feedback)} feedback messages)'


#: steps a spec names by label alone (no ``module:function``)
COMMON_STEPS = {'home': run_home}


def demo_target(spec: DriverSpec) -> DemoTarget:
    steps = [(label, resolve(reference) if reference else COMMON_STEPS[label])
             for label, reference in spec.demo.extra_steps]
    scan = StartScan.Request(**spec.demo.scan) if spec.demo.scan is not None else None
    return DemoTarget(spec=spec, scan=scan, extra_steps=steps)


def driver_targets() -> list[DemoTarget]:
    """Every registered driver (the reference virtual gimbal first)."""
    return [demo_target(spec) for spec in drivers()]
