"""Run a driver's node executable with a SIGUSR1 handler that reports its Python threads.

``python tests/node_thread_probe.py OUT EXECUTABLE [ARGS...]`` runs the console script
``EXECUTABLE`` (its installed entry point) in this process; each SIGUSR1 writes the names of
the process's threads (``threading.enumerate()``) to ``OUT`` as JSON. The handler runs in
the main thread, so the probe adds no thread of its own (Python before 3.14 does not give
its threads' names to the OS, so /proc cannot tell them apart).
"""

from __future__ import annotations

import json
import signal
import sys
import threading
from importlib.metadata import entry_points
from pathlib import Path


def main() -> int:
    out, executable, *arguments = sys.argv[1:]
    (entry,) = entry_points(group='console_scripts', name=executable)

    def report(signum: int, frame: object) -> None:
        partial = Path(f'{out}.partial')
        partial.write_text(json.dumps(sorted(t.name for t in threading.enumerate())))
        partial.replace(out)

    signal.signal(signal.SIGUSR1, report)
    sys.argv = [executable, *arguments]
    return entry.load()() or 0


if __name__ == '__main__':
    sys.exit(main())
