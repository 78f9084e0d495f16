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

"""Start nodes of the suite inside one Python process: one single-threaded executor per node, each in its own thread.

Why not one MultiThreadedExecutor: measured on this machine (shared/notes/ros2-from-pypi.md, upstream rclpy
#1223/#1452) it collapses to tens of messages per second as soon as a timer publishes to a subscription in the
same process. One single-threaded executor per thread keeps kHz rates: the nodes' own LeanExecutor
(rubber_rig.nodes.executor: rclpy's SingleThreadedExecutor that keeps its wait set), as in their processes.

The launch files (launch/rig_*.launch.py) start the *same node classes* as separate processes with the *same
parameter files*: here every node gets ``--ros-args --params-file <file>`` exactly as launch_ros passes it, and
explicit overrides (command-line options of ``rubber-rig bench``, test settings) are applied on top, with the
same precedence launch_ros gives to a ``parameters=[file, {...}]`` list.
"""
from __future__ import annotations

import threading
import time
from typing import Callable, Iterable

import rclpy
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions

from ..dds import configure_dds
from ..nodes.executor_choice import make_executor
from ..nodes.params import undeclared_overrides


def _as_parameters(overrides: dict | None) -> list[Parameter]:
    return [Parameter(name, value=value) for name, value in (overrides or {}).items()]


class InProcessLauncher:
    """Owns an rclpy context and one executor thread per node; ``with`` shuts everything down cleanly."""

    def __init__(self, params_files: Iterable[str] = (), namespace: str = '', domain_id: int | None = None):
        self.params_files = [str(p) for p in params_files]
        self.namespace = namespace
        self.context = Context()
        # No rclpy signal handlers: Ctrl-C must reach the caller as KeyboardInterrupt (the main job then aborts
        # the program with the smooth ramp and closes the recording) instead of silently stopping every executor.
        init_kwargs = {'context': self.context, 'signal_handler_options': SignalHandlerOptions.NO}
        configure_dds()
        if domain_id is not None:
            init_kwargs['domain_id'] = domain_id
        rclpy.init(args=[], **init_kwargs)
        self._entries: list[tuple[Node, SingleThreadedExecutor, threading.Thread]] = []
        self.errors: list[BaseException] = []

    # -- starting nodes ---------------------------------------------------------------------------------
    def node_kwargs(self, overrides: dict | None = None) -> dict:
        """Keyword arguments for a node constructor: context, namespace, parameter files, overrides."""
        cli = ['--ros-args']
        for f in self.params_files:
            cli += ['--params-file', f]
        return {'context': self.context, 'namespace': self.namespace, 'cli_args': cli,
                'parameter_overrides': _as_parameters(overrides)}

    def start(self, node_factory: Callable[..., Node], overrides: dict | None = None, **kwargs) -> Node:
        """Construct a node (parameters validated in its constructor) and spin it in its own thread."""
        node = node_factory(**self.node_kwargs(overrides), **kwargs)
        undeclared_overrides(node)   # a misspelt key in a parameter file must not pass silently
        self.spin(node)
        return node

    def spin(self, node: Node) -> Node:
        """Spin an already constructed node (e.g. a test probe) in its own executor thread."""
        executor = make_executor(context=self.context, node=node)
        executor.add_node(node)
        thread = threading.Thread(target=self._spin, args=(executor,), name=f'spin-{node.get_name()}',
                                  daemon=True)
        self._entries.append((node, executor, thread))
        thread.start()
        return node

    def _spin(self, executor: SingleThreadedExecutor) -> None:
        try:
            executor.spin()
        except ExternalShutdownException:
            pass
        except BaseException as exc:  # surfaced to the caller by check()
            if self.context.ok():
                self.errors.append(exc)

    def check(self) -> None:
        """Raise the first exception a node's callback raised in its executor thread, if any."""
        if self.errors:
            raise RuntimeError(f'a node failed while spinning: {self.errors[0]!r}') from self.errors[0]

    def wait_for(self, predicate: Callable[[], bool], timeout: float, period: float = 0.02) -> bool:
        """Poll ``predicate`` until true or ``timeout`` seconds passed; re-raises node errors."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.check()
            if predicate():
                return True
            time.sleep(period)
        self.check()
        return bool(predicate())

    # -- shutting down ----------------------------------------------------------------------------------
    def shutdown(self) -> None:
        # Nodes first (reverse start order: the driver, started first, ramps down last), then executors.
        for node, _, _ in reversed(self._entries):
            close = getattr(node, 'close', None)
            if callable(close):
                try:
                    close()
                except Exception as exc:  # keep shutting the others down
                    print(f'[launcher] closing {node.get_name()} failed: {exc}')
        for node, executor, thread in reversed(self._entries):
            executor.shutdown(timeout_sec=2.0)
            thread.join(timeout=5.0)
            node.destroy_node()
        self._entries.clear()
        rclpy.try_shutdown(context=self.context)

    def __enter__(self) -> 'InProcessLauncher':
        return self

    def __exit__(self, *exc) -> None:
        self.shutdown()
