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

"""Which executor a node spins (issue 37): :class:`~rubber_rig.nodes.executor.LeanExecutor` unless the environment
says ``RUBBER_RIG_EXECUTOR=rclpy`` (rclpy's SingleThreadedExecutor: for comparing, or should an rclpy update break
the lean one) or ``RUBBER_RIG_EXECUTOR=events`` (opt-in: rclpy's experimental EventsExecutor for the nodes it
serves, :class:`EventsLoop`). Used by nodes/spin.py and launching/inprocess.py.
"""
from __future__ import annotations

import os
from typing import Optional

from rclpy.executors import SingleThreadedExecutor
from rclpy.logging import get_logger
from rclpy.utilities import get_default_context

from .executor import LeanExecutor

EXECUTOR_ENV = 'RUBBER_RIG_EXECUTOR'   # 'rclpy' or 'events' instead of the default LeanExecutor
EVENTS_SPIN_ONCE = 0.1    # [s] how long one spin_once of EventsLoop waits: how soon it sees a stop request


class EventsLoop:
    """rclpy's experimental EventsExecutor (``RUBBER_RIG_EXECUTOR=events``, opt-in), driven by ``spin_once``.

    It dispatches from C++ callbacks of the middleware, with no wait set at all (about half of LeanExecutor's CPU
    per message in the measurement of headroom_notes.md). What keeps it opt-in, as found in this rclpy (ros-rclpy
    7.1.6): its ``spin()`` dispatched nothing (no timer callback in seconds, in the main thread or another), so
    this loop calls ``spin_once``; it refuses any node that has a guard condition (``EventsExecutor::
    UpdateEntitiesFromNodes`` raises "Guard conditions not supported") and fails on the first message of a raw
    subscription ("SystemError: null argument to internal routine"), so :func:`make_executor` gives a node with
    either (rig_driver: its bus-reading thread wakes it through a guard condition; the recorder: it writes the
    bytes it receives) a LeanExecutor; the excitation keeps one too: its program runs as tasks that await futures,
    and under EventsExecutor it took 31 % of a core at 5 wake-ups/s during a program (busy, never waiting; 14.5 %
    under LeanExecutor in the same session). It is experimental upstream. What remains is element_model (and
    the Foxglove view).
    """

    def __init__(self, context=None):
        from rclpy.experimental import EventsExecutor  # noqa: PLC0415 - only when asked for
        self._context = context if context is not None else get_default_context()
        self._executor = EventsExecutor(context=context)
        self._stopped = False

    def add_node(self, node) -> bool:
        return self._executor.add_node(node)

    def create_task(self, callback, *args, **kwargs):
        return self._executor.create_task(callback, *args, **kwargs)

    def spin(self) -> None:
        while not self._stopped and self._context.ok():
            self._executor.spin_once(EVENTS_SPIN_ONCE)

    def shutdown(self, timeout_sec: Optional[float] = None) -> bool:
        self._stopped = True
        return self._executor.shutdown(timeout_sec)


def make_executor(context=None, node=None):
    """The executor a node spins (nodes/spin.py, launching/inprocess.py): :class:`LeanExecutor`; rclpy's
    SingleThreadedExecutor when the environment sets ``RUBBER_RIG_EXECUTOR=rclpy``; :class:`EventsLoop` with
    ``RUBBER_RIG_EXECUTOR=events``, unless ``node`` has or will have what EventsExecutor refuses (its class
    says so in ``events_executor_refuses``).
    """
    choice = os.environ.get(EXECUTOR_ENV, 'lean').strip().lower()
    if choice == 'rclpy':
        return SingleThreadedExecutor(context=context)
    if choice == 'events':
        why = _events_refuse(node)
        if not why:
            return EventsLoop(context=context)
        node.get_logger().info(f'{EXECUTOR_ENV}=events: rclpy\'s EventsExecutor refuses {why}; spinning a '
                               'LeanExecutor')
    elif choice not in ('', 'lean'):
        get_logger('rubber_rig').warning(f'{EXECUTOR_ENV}={choice!r} is not "lean", "rclpy" or "events"; using lean')
    return LeanExecutor(context=context)


def _events_refuse(node) -> str:
    """What of ``node`` rclpy's EventsExecutor refuses ('' if nothing): a guard condition ("Guard conditions not
    supported"), or a raw subscription (``SystemError: null argument to internal routine`` on its first message,
    found with the recorder), now or, as the node's class declares, later.
    """
    if node is None:
        return ''
    if list(node.guards):
        return 'a guard condition'
    if any(sub.raw for sub in node.subscriptions):
        return 'raw subscriptions'
    return getattr(node, 'events_executor_refuses', '')
