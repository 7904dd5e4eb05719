"""The drivers `make soak` runs: every registered driver that names an in-process simulator.

Each driver package registers a :class:`~gimbal_driver_common.registry.DriverSpec` whose
``sim_handle`` names its :class:`~gimbal_driver_common.sim_handle.SimHandle` subclass: the
simulator started in the soak's process (so faults are injected through its own API) with
the faults it can inject and those its protocol cannot carry (``not_applicable``). The node
runs as a separate process with the spec's link parameters.
"""

from __future__ import annotations

from gimbal_driver_common.registry import DriverSpec, drivers
from gimbal_driver_common.sim_handle import make_handle

__all__ = ['make_handle', 'soak_targets']


def soak_targets() -> dict[str, DriverSpec]:
    """Driver name -> spec, for every registered driver with a simulator handle."""
    return {spec.name: spec for spec in drivers() if spec.sim_handle}
