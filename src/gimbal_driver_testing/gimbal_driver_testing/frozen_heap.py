"""pytest plugin: freeze what imports and collection built, so a full collection is short.

Why: a test that runs a simulator and a client in one process gives each request a
timeout of half a second, and a full (generation 2) garbage collection stops every thread
of that process while it runs. In a pytest worker the heap after collection holds some
130,000 objects (rclpy, hypothesis, every test module); traversing them took up to 0.20 s
of CPU and 0.48 s of wall time with eight workers on two cores, and a collection over
30 ms came 62 times in one full run while tests ran. One such pause between a setter's
write and its ACK failed ``test_software_limit_stops_the_axis[pty]`` with "no reply within
0.5 s" (the setter is not retried). ``gc.freeze()`` moves those objects to the permanent
generation, which no collection traverses; what the tests make is still collected.
docs/testing.md, "Pauses", has the measurement.

Load it with ``-p gimbal_driver_testing.frozen_heap`` (every package's pytest.ini).
"""

from __future__ import annotations

import gc

import pytest


def pytest_collection_finish(session: pytest.Session) -> None:
    """After collection, in every worker: collect once, then freeze what survives."""
    gc.collect()
    gc.freeze()
