"""Bench-only instrumentation of a driver node process; never installed, never in a driver.

``bench/driver_bench.start_node`` puts this directory first on the node's PYTHONPATH when
one of these variables is set, and Python imports this module at start-up:

* ``BENCH_TRACE_DIR``: for every joint_command the node handles, the publish time (the
  stream publisher's ``header.stamp``), the callback's entry and return and the time of
  each device write made inside it (``gimbal_driver_common.transport`` streams and
  python-can's slcan ``send``); written as JSON to ``<dir>/trace_<pid>.json`` when the node exits.
  Splits the command path into rclpy delivery, the driver's work before its first byte
  (validation, the client lock) and the protocol's own round trips. Each joint_states
  publication (start, end) is recorded too, to relate a command's delay to its phase in
  the node's device cycle, and the sample's stamp, to split ``sim_to_subscriber`` into the
  node's share and the delivery's.
* ``BENCH_EXECUTOR=events``: ``run_driver`` spins ``rclpy.experimental.EventsExecutor``
  instead of ``InlineGroupExecutor(num_threads=4)`` (an experiment; see bench/HISTORY.md,
  "EventsExecutor experiment").
* ``BENCH_EXECUTOR=single``: ``rclpy.executors.SingleThreadedExecutor`` (an experiment:
  it serialises the blocking action callbacks, so ``~/stop`` waits behind a ``move_to``).

The executor is swapped from here, outside the driver: ``run_driver`` builds
``run.InlineGroupExecutor(num_threads=4)``, a module global looked up when it runs, so this
hook replaces that name with a class of the experiment (see ``_experiment_executor``);
nothing in ``gimbal_driver_common`` exists for the bench's sake.
* ``BENCH_SWITCH_INTERVAL_S``: the GIL switch interval instead of the driver's 1 ms.
* ``BENCH_THREAD_CPU_DIR``: the node writes ``<dir>/threads_<pid>.json`` (native thread id
  -> Python thread name) every 0.5 s, so the bench can split the node's CPU by thread.
"""

from __future__ import annotations

import os


def _experiment_executor(name: str) -> type:
    """A stand-in for ``run.InlineGroupExecutor``: called as ``run_driver`` calls it
    (``num_threads=4``), it returns the executor ``BENCH_EXECUTOR`` names. It is a class, not
    a function, because ``run.answer_open_goals`` asks ``isinstance(executor,
    InlineGroupExecutor)`` (false here: the experiment has no pool tasks to wait for).
    rclpy's ``EventsExecutor`` is a factory function, so this builds and does not subclass."""
    import rclpy.executors
    import rclpy.experimental

    if name == 'events':
        make = rclpy.experimental.EventsExecutor
    elif name == 'single':
        make = rclpy.executors.SingleThreadedExecutor
    else:
        raise ValueError(f"BENCH_EXECUTOR={name!r}: expected 'events' or 'single'")

    class ExperimentExecutor:
        def __new__(cls, num_threads: int = 4, *, context: object = None) -> object:
            return make(context=context)

    return ExperimentExecutor


def _install() -> None:
    import atexit
    import json
    import threading
    import time
    from pathlib import Path

    from gimbal_driver_common import transport
    from gimbal_driver_common.ros import base_node, run

    executor = os.environ.get('BENCH_EXECUTOR', '')
    if executor:
        run.InlineGroupExecutor = _experiment_executor(executor)
    interval = os.environ.get('BENCH_SWITCH_INTERVAL_S')
    if interval:
        run.GIL_SWITCH_INTERVAL_S = float(interval)   # run_driver applies it

    thread_dir = os.environ.get('BENCH_THREAD_CPU_DIR')
    if thread_dir:
        def write_thread_names() -> None:
            path = Path(thread_dir, f'threads_{os.getpid()}.json')
            while True:
                names = {t.native_id: t.name for t in threading.enumerate() if t.native_id}
                partial = path.with_suffix('.part')  # whole or not at all: the bench reads
                partial.write_text(json.dumps(names))  # it while this thread writes
                partial.replace(path)
                time.sleep(0.5)

        threading.Thread(target=write_thread_names, name='bench-thread-names',
                         daemon=True).start()

    trace_dir = os.environ.get('BENCH_TRACE_DIR')
    if not trace_dir:
        return
    local = threading.local()
    records: list[dict] = []

    def traced_write(write):
        def wrapper(self, *args, **kwargs):
            writes = getattr(local, 'writes', None)
            if writes is not None:
                writes.append(time.time())
            return write(self, *args, **kwargs)
        return wrapper

    for stream in (transport.TcpStream, transport.SerialStream):
        stream.write = traced_write(stream.write)
    try:   # the turret's CAN link: python-can loads interfaces lazily, slcan on the bench
        from can.interfaces.slcan import slcanBus

        slcanBus.send = traced_write(slcanBus.send)
    except ImportError:
        pass

    from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

    wait = _rclpy.WaitSet.wait
    last_wait_return = [0.0]

    def traced_wait(self, *args):
        try:
            return wait(self, *args)
        finally:
            last_wait_return[0] = time.time()

    _rclpy.WaitSet.wait = traced_wait

    on_joint_command = base_node.GimbalDriverNode._on_joint_command

    def traced_on_joint_command(self, msg, info):
        entry = time.time()
        local.writes = []
        try:
            return on_joint_command(self, msg, info)
        finally:
            records.append({
                'index': msg.header.frame_id,
                'published': msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9,
                'waited': last_wait_return[0], 'entry': entry, 'writes': local.writes,
                'returned': time.time(),
                'thread': threading.current_thread().name})
            local.writes = None

    base_node.GimbalDriverNode._on_joint_command = traced_on_joint_command

    publish_joint_state = base_node.GimbalDriverNode._publish_joint_state
    joint_states: list[tuple[float, float, float]] = []

    def traced_publish_joint_state(self, sample):
        start = time.time()
        try:
            return publish_joint_state(self, sample)
        finally:
            joint_states.append((start, time.time(), sample.stamp))

    base_node.GimbalDriverNode._publish_joint_state = traced_publish_joint_state

    def dump() -> None:
        path = Path(trace_dir, f'trace_{os.getpid()}.json')
        path.write_text(json.dumps({'executor': executor or 'InlineGroupExecutor(4)',
                                    'records': records, 'joint_states': joint_states}))

    atexit.register(dump)


if any(os.environ.get(name) for name in ('BENCH_TRACE_DIR', 'BENCH_EXECUTOR',
                                          'BENCH_SWITCH_INTERVAL_S', 'BENCH_THREAD_CPU_DIR')):
    _install()
