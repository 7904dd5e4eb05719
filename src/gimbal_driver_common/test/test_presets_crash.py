"""A presets file survives a process killed in the middle of a write (real SIGKILLs).

A child process writes presets in a loop through ``PresetStore``; the test kills it with
SIGKILL at random moments, then checks that the file parses to a *complete* preset set: the
one of some generation ``g`` (each write adds generation ``g`` at index ``g % SLOTS`` with
every joint at ``g``), so a torn or half-renamed file, a mix of two generations or a missing
entry all fail. The next child loads the file the killed one left and carries on from there.
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

from gimbal_driver_common.presets import PresetStore
from gimbal_driver_testing import wait_for

SLOTS = 8
JOINTS = 60  # a file of several kB, so a kill often lands inside a write
KILLS = 25

WRITER = textwrap.dedent('''
    import sys
    from gimbal_driver_common.presets import PresetStore

    path, slots, joints = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    store = PresetStore(path)
    generation = max((int(p.name[3:]) for p in store.list()), default=-1) + 1
    print('writing from', generation, flush=True)
    while True:
        store.set(generation % slots, f'gen{generation}',
                  {f'j{i}': float(generation) for i in range(joints)})
        generation += 1
''')


def check_complete(path: Path) -> int:
    """The newest generation in the file; asserts the file holds exactly one whole set."""
    presets = PresetStore(str(path)).list()  # raises PresetError on a torn/malformed file
    generations = sorted(int(p.name[3:]) for p in presets)
    assert generations, f'{path} holds no preset (torn or emptied by a write)'
    newest = generations[-1]
    expected = list(range(max(0, newest - SLOTS + 1), newest + 1))
    assert generations == expected, f'not one complete set: generations {generations}'
    for preset in presets:
        generation = int(preset.name[3:])
        assert preset.index == generation % SLOTS
        assert preset.positions == {f'j{i}': float(generation) for i in range(JOINTS)}, (
            f'preset {preset.index} is incomplete or mixed')
    return newest


def test_presets_file_survives_sigkill_during_writes(tmp_path: Path) -> None:
    path = tmp_path / 'presets.yaml'
    rng = random.Random(14)
    newest = -1
    for kill in range(KILLS):
        child = subprocess.Popen(
            [sys.executable, '-c', WRITER, str(path), str(SLOTS), str(JOINTS)],
            stdout=subprocess.PIPE, text=True, env=dict(os.environ))
        try:
            assert child.stdout is not None
            child.stdout.readline()  # 'writing from N': the store has loaded the old file
            # let it write at least once past the old newest generation, then kill it at a
            # random moment (inside a write most of the time: writing is all it does)
            wait_for(lambda old=newest: check_complete_quietly(path) > old, 30,
                     'the writer to store a new generation', interval=0.001)
            time.sleep(rng.uniform(0.0, 0.05))  # the random kill moment (not a wait)
            child.send_signal(signal.SIGKILL)
            child.wait(10)
        finally:
            if child.poll() is None:
                child.kill()
                child.wait(10)
            if child.stdout is not None:
                child.stdout.close()
        generation = check_complete(path)
        assert generation >= newest, f'kill {kill}: the file went back to generation {generation}'
        newest = generation
    leftovers = [p.name for p in tmp_path.iterdir() if p.name != 'presets.yaml']
    # a killed write may leave its temporary file; never the presets file half-written
    assert all(name.startswith('.presets-') for name in leftovers), leftovers


def check_complete_quietly(path: Path) -> int:
    """Like check_complete, while the writer is alive (no file yet -> -1, try again)."""
    if not path.exists():
        return -1
    return check_complete(path)
