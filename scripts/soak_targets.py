"""The drivers `make soak` runs: every registered driver that names an in-process simulator.

Each driver package registers a :class:`~gimbal_driver_common.registry.DriverSpec` whose
``sim_handle`` names its :class:`~gimbal_driver_common.sim_handle.SimHandle` subclass: the
simulator started in the soak's process (so faults are injected through its own API) with
the faults it can inject and those its protocol cannot carry (``not_applicable``). The node
runs as a separate process with the spec's link parameters.
"""

from __future__ import annotations

from pathlib import Path

from gimbal_driver_common.registry import DriverSpec, drivers, resolve
from gimbal_driver_common.sim_handle import SimHandle


def soak_targets() -> dict[str, DriverSpec]:
    """Driver name -> spec, for every registered driver with a simulator handle."""
    return {spec.name: spec for spec in drivers() if spec.sim_handle}


def make_handle(spec: DriverSpec, workdir: Path) -> SimHandle:
    """The driver's in-process simulator handle (not started yet)."""
    return resolve(spec.sim_handle)(spec, workdir)
