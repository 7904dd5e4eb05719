"""The device drivers the demo runs, each against its own simulator.

A target is skipped by the demo while its package is not built.
"""

from __future__ import annotations

from demo import DemoTarget


def driver_targets() -> list[DemoTarget]:
    return []
