# Copyright 2026 rubber_rig developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""The ``main()`` of every node: init, spin one single-threaded executor, shut down cleanly.

Single-threaded, not MultiThreadedExecutor: with a timer publishing to a subscription in the same process,
rclpy's MultiThreadedExecutor collapses to tens of callbacks per second (rclpy #1223, measured here). The executor
is :class:`rubber_rig.nodes.executor.LeanExecutor`, rclpy's SingleThreadedExecutor that keeps its wait set while
the node's entities stay the same (about half the CPU per message, issue 37); ``RUBBER_RIG_EXECUTOR=rclpy`` runs
rclpy's own instead (for comparing, or should an rclpy update break the lean one).

The DDS configuration (rubber_rig.dds.configure_dds: transport, discovery) is chosen before rclpy.init and
logged with the ready line.

Stopping (SIGINT from Ctrl-C or ``ros2 launch``, SIGTERM): rclpy's own handlers are not installed. They shut the
context down the moment the signal lands, so everything the node does on its way out (the driver's ramp to rest
and "rig closed" line, the recorder's "closed" line) was logged to a dead context - "Failed to publish log message
to rosout: publisher's context is invalid" after every stop - and they raise KeyboardInterrupt wherever the main
thread happens to be: a second SIGINT (a terminal's Ctrl-C reaches both ``ros2 launch`` and its nodes, and launch
forwards its own) interrupted the clean-up half way, with a traceback, a bus not shut down, or no clean-up at all.
Here the executor spins in a thread; a signal only sets a flag that the main thread sees within STOP_POLL seconds;
the main thread then stops the executor, lets a running callback finish (at most CALLBACK_GRACE seconds), calls
the node's ``close()``, destroys the node and only then shuts the context down. Further signals while that runs
are ignored. A signal during start-up (imports aside) abandons the start. Exit status 0.

A node constructor that refuses its parameters (:class:`ParameterError`: a value that cannot work, e.g. a
parameter_set file that is missing or not YAML) ends the process with that one line, logged as FATAL, and exit
status EXIT_BAD_PARAMETER (2, the usage-error status of the command-line tools), not a traceback: a plain node has
no "unconfigured" state to wait in, and ``ros2 launch`` shows the line next to "process has died [exit code 2]".
(rig_driver, a lifecycle node, stays up unconfigured instead when only its CAN bus cannot carry the sample_rate.)
"""
from __future__ import annotations

import gc
import os
import signal
import threading
from typing import Callable

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.logging import get_logger
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from ..cpu import EXECUTOR_THREAD, name_this_thread, run_profiled
from ..dds import configure_dds
from ..rig.priority import set_process_nice
from .executor_choice import make_executor
from .params import ParameterError, undeclared_overrides
from .rclpy_compat import RCLError

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
STOP_POLL = 0.05          # [s] how often the main thread looks at the stop flag while the executor spins
CALLBACK_GRACE = 1.0      # [s] a callback still running at the stop gets this long before close() goes ahead
EXIT_BAD_PARAMETER = 2    # exit status when the node refuses its parameters at start


class _Stop:
    """The stop request, set from a signal handler: a plain flag (taking a lock in a handler can deadlock)."""

    def __init__(self):
        self.requested = False
        self.started = False   # the executor runs: from now on a signal only sets the flag

    def __call__(self, signum, frame):
        self.requested = True
        if not self.started:
            raise KeyboardInterrupt   # still starting: abandon the start (nothing to clean up but the context)


def _spin(executor, errors: list, name: str = 'node') -> None:
    name_this_thread(EXECUTOR_THREAD)   # benchmarks count its wake-ups and CPU (rubber_rig.cpu)
    try:
        run_profiled(executor.spin, name)   # under cProfile if RUBBER_RIG_PROFILE_DIR is set
    except ExternalShutdownException:
        pass
    except BaseException as exc:   # noqa: BLE001 - handed to the main thread, which cleans up and re-raises
        errors.append(exc)


def with_process_nice(node_factory: Callable[[], Node]) -> Callable[[], Node]:
    """A factory for a node that runs as a process of its own: the node, then the process's niceness set from its
    parameter (``node.params.nice``, rubber_rig.rig.priority; logged, or a warning saying why not). Not done in the
    node class: a node started in another process (in-process launch, tests) leaves that process's priority alone.
    """
    def create() -> Node:
        node = node_factory()
        why = set_process_nice(node.params.nice)
        if why:
            node.get_logger().warning(why)
        elif node.params.nice:
            node.get_logger().info(f'process niceness {node.params.nice} (parameter nice)')
        return node
    return create


def spin_node(node_factory: Callable[[], Node], args=None) -> None:
    """Create the node, spin it until SIGINT / SIGTERM / context shutdown, then release it.

    A node with a ``close()`` method (open bus, open file) has it called before ``destroy_node()``, while the
    context is still valid (its log lines reach /rosout). Raises SystemExit(EXIT_BAD_PARAMETER) when the node
    refuses its parameters at start; an exception from a callback is re-raised after the clean-up.
    """
    dds = configure_dds()   # before the first participant exists
    stop = _Stop()
    previous = {sig: signal.signal(sig, stop) for sig in STOP_SIGNALS}
    node = executor = thread = None
    errors: list[BaseException] = []
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
        try:
            node = node_factory()
        except ParameterError as exc:
            get_logger(exc.logger_name).fatal(str(exc))
            raise SystemExit(EXIT_BAD_PARAMETER) from None
        undeclared_overrides(node)   # a misspelt key in a parameter file must not pass silently
        # what start-up made (rclpy, numpy, scipy, the node: ~100 000 objects) lives as long as the process: out of
        # the collector's sight, a full collection no longer walks it (0.11 s each on a loaded 2-core machine,
        # a pause of the node's executor that nobody scheduled)
        gc.collect()
        gc.freeze()
        executor = make_executor(node=node)
        executor.add_node(node)
        thread = threading.Thread(target=_spin, args=(executor, errors, node.get_fully_qualified_name()),
                                  name='executor', daemon=True)
        stop.started = True
        if not stop.requested:
            thread.start()
            node.get_logger().info(f'DDS: {dds}')
            node.get_logger().info(f'ready (pid {os.getpid()})')   # launchers and the fault-matrix tests wait for it
            while not stop.requested and thread.is_alive():
                thread.join(STOP_POLL)   # interruptible: the signal handler runs here
    except KeyboardInterrupt:
        pass
    except RCLError:
        # a signal during rclpy.init or the constructor can leave rcl saying "context is not valid"
        if rclpy.ok():
            raise
    finally:
        stop.started = True          # from here on a signal changes nothing: the clean-up runs to its end
        if executor is not None:
            executor.shutdown(timeout_sec=0)
            if thread is not None and thread.is_alive():
                thread.join(CALLBACK_GRACE)
                if thread.is_alive() and node is not None:
                    node.get_logger().warning(f'a callback still runs {CALLBACK_GRACE:g} s after the stop; '
                                              'closing anyway')
        if node is not None:
            close = getattr(node, 'close', None)
            if callable(close):
                close()
            node.destroy_node()
        rclpy.try_shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if errors:
        raise errors[0]
