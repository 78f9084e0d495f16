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

"""A single-threaded executor that keeps its wait set while the node's entities stay the same (issue 37).

rclpy's SingleThreadedExecutor (Jazzy, rclpy 7.1) does, in Python, on every wake-up: list every subscription,
timer, client, service, guard condition and waitable of every node through generators, filter each through its
callback group, enter every handle through an ExitStack, create a new ``rcl`` wait set, add everything, wait, then
look every entity up again in the lists of ready pointers (``x in list``: quadratic in the entity count). Our nodes
have 16-70 entities each (every publisher alone brings four QoS event handlers, each a waitable), so that was most
of the executor's share of the ~1 ms of CPU each wake-up cost (docs/benchmarks/headroom_notes.md). And every
callback it runs triggers the executor's own guard condition twice (after the take, after the callback), so each
message costs a second wake-up that finds nothing to do.

:class:`LeanExecutor` is that executor with those two costs taken out, nothing else changed:

* the entity lists, the ``rcl`` wait set and the pointer -> entity maps are built again only when an entity was
  created or destroyed (rclpy calls :meth:`wake` then: ``Node._wake_executor``) or a node added or removed; every
  wake-up then only clears the wait set, adds the same handles and waits;
* a handler no longer triggers the executor's guard condition after it ran: in a single thread the generator that
  yielded it resumes only after it has run, and the next ``spin_once`` runs pending tasks before it waits, as
  before.

What keeps rclpy's semantics: while any entity's handler is still pending (a callback that is a coroutine and
awaits, holding its callback group), the entity lists are filtered through the callback groups on every turn, as
rclpy does; tasks (``create_task``, an action's execute, futures' done callbacks) run exactly as in rclpy; a
node's guard conditions are re-triggered when they fired but were not handled; timers, subscriptions, services,
clients, waitables (actions, QoS events, lifecycle) are taken with rclpy's own ``_take_*`` methods. With
``nodes=`` given (``spin_until_future_complete`` on a subset, not used by the nodes) it falls back to rclpy's own.
Which executor a node gets (this one, rclpy's, or the opt-in EventsExecutor): nodes/executor_choice.py.

This is the installed rclpy's ``Executor`` API, partly its private methods (``_take_*``, ``_tasks``, ``_guard``,
``_sigint_gc``); test/test_executor.py exercises every entity kind through it, so an rclpy that changes them fails
there, not in a node.
"""
from __future__ import annotations

from typing import Callable, Optional

from rclpy.event_handler import EventHandler, QoSEventHandler
from rclpy.exceptions import InvalidHandle
from rclpy.executors import (
    ConditionReachedException,
    ExternalShutdownException,
    ShutdownException,
    SingleThreadedExecutor,
    TimeoutException,
    TimeoutObject,
)
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.task import Task
from rclpy.timer import Timer
from rclpy.utilities import timeout_sec_to_nsec
from rclpy.waitable import NumberOfEntities

from .draining import is_polled
from .rclpy_compat import RCLError

_EVENT_HANDLE = '_EventHandler__event'   # EventHandler's one rcl event handle (name-mangled private attribute)
_PLAIN_EVENT_HANDLERS = (EventHandler, QoSEventHandler)   # not subclasses that may add entities of their own


class _Entities:
    """What one wait set waits on: the entities of the executor's nodes, their handles and ready-pointer maps.

    Built once per change of entities; every wake-up then enters the same handles, adds them in the same order
    (so a QoS event keeps its index in the wait set) and looks the ready pointers up in dicts.
    """

    def __init__(self, executor: 'LeanExecutor', nodes, filtered: bool):
        keep = executor.can_execute if filtered else (lambda entity: True)
        self.timers, self.subscriptions, self.clients, self.services = [], [], [], []
        self.guards, self.waitables = [], []
        self.owner = {}   # entity -> its node
        for node in nodes:
            # a polled subscription wakes no one (nodes/draining.py), nor do its QoS events: Fast DDS signals them
            # on the reader's status condition, which data waiting in the reader also sets (a busy loop)
            polled = {id(entity) for sub in node.subscriptions if is_polled(sub)
                      for entity in [sub, *sub.event_handlers]}
            for kind, entities in ((self.timers, node.timers), (self.subscriptions, node.subscriptions),
                                   (self.clients, node.clients), (self.services, node.services),
                                   (self.guards, node.guards), (self.waitables, node.waitables)):
                for entity in entities:
                    if keep(entity) and id(entity) not in polled:
                        kind.append(entity)
                        self.owner[entity] = node
        self.node_guards = list(self.guards)
        self.guards += [executor._guard, executor._sigint_gc]
        self.count = NumberOfEntities(len(self.subscriptions), len(self.guards), len(self.timers),
                                      len(self.clients), len(self.services))
        # QoS event handlers (rclpy's EventHandler: two to four per publisher and subscription) are taken apart:
        # their one event handle is added directly, at a fixed index; other waitables go through their own API
        self.events: list[tuple[EventHandler, object]] = []
        self.other_waitables = []
        for waitable in self.waitables:
            self.count += waitable.get_num_entities()
            handle = getattr(waitable, _EVENT_HANDLE, None) if type(waitable) in _PLAIN_EVENT_HANDLERS else None
            if handle is not None:
                self.events.append((waitable, handle))
            else:
                self.other_waitables.append(waitable)
        self.sub_handles = [e.handle for e in self.subscriptions]
        self.client_handles = [e.handle for e in self.clients]
        self.service_handles = [e.handle for e in self.services]
        self.timer_handles = [e.handle for e in self.timers]
        self.guard_handles = [e.handle for e in self.guards]
        self.event_handles = [handle for _, handle in self.events]
        self.handles = (self.sub_handles + self.client_handles + self.service_handles + self.timer_handles
                        + self.guard_handles + self.event_handles)
        self.by_pointer = {kind: {e.handle.pointer: e for e in entities} for kind, entities in (
            ('timer', self.timers), ('subscription', self.subscriptions), ('client', self.clients),
            ('service', self.services))}
        self.wait_set = None

    def ready(self, wait_set, kind: str) -> list:
        """The entities of ``kind`` the wait set reports ready, in the order they were added."""
        pointers = wait_set.get_ready_entities(kind)
        if not pointers:
            return []
        table = self.by_pointer[kind]
        return [table[p] for p in pointers if p in table]


class LeanExecutor(SingleThreadedExecutor):
    """rclpy's SingleThreadedExecutor without rebuilding its wait set on every wake-up (see the module docstring).

    ``rebuilds``: how often the entity lists and wait set were built (tests and benchmarks look at it);
    ``turns``: how often it waited.
    """

    def __init__(self, *, context=None) -> None:
        super().__init__(context=context)
        self._entities: Optional[_Entities] = None
        self._stale = True
        self.rebuilds = 0
        self.turns = 0

    # -- what makes the cached wait set stale ------------------------------------------------------------------

    def wake(self) -> None:
        """An entity was created or destroyed (rclpy calls this from ``Node._wake_executor``): build anew."""
        self._stale = True
        super().wake()

    def add_node(self, node) -> bool:
        self._stale = True
        return super().add_node(node)

    def remove_node(self, node) -> None:
        self._stale = True
        super().remove_node(node)

    def shutdown(self, timeout_sec: Optional[float] = None) -> bool:
        done = super().shutdown(timeout_sec)
        self._entities = None
        self._stale = True
        return done

    # -- handlers ----------------------------------------------------------------------------------------------

    def _make_handler(self, entity, node, take_from_wait_list: Callable) -> Task:
        """The handler of rclpy without the guard-condition triggers after the take and after the callback.

        In one thread nothing else waits while it runs, and the generator that yielded it resumes only after it
        ran (the executor's ``spin_once``), so there is no wait set to wake. When the callback group refuses (a
        coroutine of the same mutually exclusive group still pending), the guard is triggered as in rclpy, so the
        entity is looked at again.
        """
        entity._executor_event = True
        guard, is_shutdown, work_tracker = self._guard, self._is_shutdown, self._work_tracker

        async def handler():
            if is_shutdown or not entity.callback_group.beginning_execution(entity):
                entity._executor_event = False
                guard.trigger()
                return
            with work_tracker:
                call_coroutine = take_from_wait_list(entity)
                entity._executor_event = False
                try:
                    if call_coroutine is not None:
                        await call_coroutine()
                finally:
                    entity.callback_group.ending_execution(entity)

        task = Task(handler, executor=self)
        with self._tasks_lock:
            self._tasks.append((task, entity, node))
        return task

    # -- waiting -----------------------------------------------------------------------------------------------

    def _current_entities(self, busy: bool) -> _Entities:
        if busy:   # a callback group may be held: filter as rclpy does, this turn only
            self._stale = True
            return self._build(filtered=True)
        if self._stale or self._entities is None:
            self._stale = False
            self._entities = self._build(filtered=False)
        return self._entities

    def _build(self, filtered: bool) -> _Entities:
        self.rebuilds += 1
        entities = _Entities(self, self.get_nodes(), filtered)
        count = entities.count
        entities.wait_set = _rclpy.WaitSet(count.num_subscriptions, count.num_guard_conditions, count.num_timers,
                                           count.num_clients, count.num_services, count.num_events,
                                           self._context.handle)
        return entities

    def _wait_for_ready_callbacks(self, timeout_sec=None, nodes=None, condition: Callable[[], bool] = lambda: False):
        if nodes is not None:
            yield from super()._wait_for_ready_callbacks(timeout_sec, nodes, condition)
            return
        timeout_timer = None
        timeout_nsec = timeout_sec_to_nsec(
            timeout_sec.timeout if isinstance(timeout_sec, TimeoutObject) else timeout_sec)
        if timeout_nsec > 0:
            timeout_timer = Timer(None, None, timeout_nsec, self._clock, context=self._context)
        try:
            yielded_work = False
            while not yielded_work and not self._is_shutdown and not condition():
                if self._tasks:   # tasks in progress run before waiting for new work (as rclpy)
                    with self._tasks_lock:
                        tasks = list(self._tasks)
                    for task, entity, node in reversed(tasks):
                        if not task.executing() and not task.done():
                            yielded_work = True
                            yield task, entity, node
                    with self._tasks_lock:
                        self._tasks = [t for t in self._tasks if not t[0].done() and not t[0].cancelled()]
                busy = any(entity is not None for _, entity, _ in self._tasks)
                entities = self._current_entities(busy)
                ready = self._wait(entities, timeout_timer, timeout_nsec)
                if ready is None:   # an entity went away while we entered the handles: build anew
                    self._stale = True
                    continue
                timers_ready, subs_ready, clients_ready, services_ready, waitables_ready, timed_out = ready
                # in rclpy's order; the lazy filters look at a timer or guard only when its turn comes (the
                # handlers yielded before it have run by then)
                for ready_kind, take in ((waitables_ready, self._take_waitable),
                                         (self._timers_due(timers_ready), self._take_timer),
                                         (subs_ready, self._take_subscription),
                                         ((gc for gc in entities.node_guards if gc._executor_triggered),
                                          self._take_guard_condition),
                                         (clients_ready, self._take_client), (services_ready, self._take_service)):
                    for entity in ready_kind:
                        if entity.callback_group.can_execute(entity):
                            yielded_work = True
                            node = entities.owner[entity]
                            yield self._make_handler(entity, node, take), entity, node
                if timeout_nsec == 0 or timed_out:
                    raise TimeoutException()
        finally:
            if timeout_timer is not None:
                timeout_timer.destroy()
        if self._is_shutdown:
            raise ShutdownException()
        if condition():
            raise ConditionReachedException()

    def _timers_due(self, timers):
        """The `timers` the wait reported that are still ready now; one destroyed since the wait (a lifecycle
        transition) is skipped and the entity list rebuilt.
        """
        for tmr in timers:
            try:
                ready_now = tmr.handle.is_timer_ready()
            except (InvalidHandle, RCLError):
                self._stale, ready_now = True, False
            if ready_now:
                yield tmr

    def _wait(self, entities: _Entities, timeout_timer, timeout_nsec: int):
        """Fill the kept wait set, wait, and return the ready entities; None when a handle is no longer valid."""
        self.turns += 1
        for gc in entities.node_guards:   # a guard condition that fired but was not handled fires again
            if gc._executor_triggered:
                gc.trigger()
        handles = entities.handles
        if timeout_timer is not None:
            handles = handles + [timeout_timer.handle]
        entered = []   # entered so that no other thread destroys them while rcl waits on them (as rclpy)
        try:
            try:
                for handle in handles:
                    handle.__enter__()
                    entered.append(handle)
                for waitable in entities.other_waitables:
                    waitable.__enter__()
                    entered.append(waitable)
                self._context.handle.__enter__()
                entered.append(self._context.handle)
            except InvalidHandle:
                return None
            wait_set = entities.wait_set
            if timeout_timer is not None:   # the timeout timer is one more timer than the kept wait set holds
                wait_set = self._one_off_wait_set(entities)
            wait_set.clear_entities()
            for handle in entities.sub_handles:
                wait_set.add_subscription(handle)
            for handle in entities.client_handles:
                wait_set.add_client(handle)
            for handle in entities.service_handles:
                wait_set.add_service(handle)
            for handle in entities.timer_handles:
                wait_set.add_timer(handle)
            if timeout_timer is not None:
                wait_set.add_timer(timeout_timer.handle)
            for handle in entities.guard_handles:
                wait_set.add_guard_condition(handle)
            for waitable, handle in entities.events:
                waitable._event_index = wait_set.add_event(handle)
            for waitable in entities.other_waitables:
                waitable.add_to_wait_set(wait_set)
            wait_set.wait(timeout_nsec)
            if self._is_shutdown:
                raise ShutdownException()
            if not self._context.ok():
                raise ExternalShutdownException()
            guards_ready = wait_set.get_ready_entities('guard_condition')
            if guards_ready:   # auto-taken by the wait: marked before anything runs (as rclpy)
                for gc in entities.node_guards:
                    if gc.handle.pointer in guards_ready:
                        gc._executor_triggered = True
            timed_out = timeout_timer is not None and timeout_timer.handle.pointer in wait_set.get_ready_entities(
                'timer')
            waitables_ready = [w for w, _ in entities.events
                               if w._ready_to_take_data or wait_set.is_ready('event', w._event_index)]
            for waitable in waitables_ready:   # what EventHandler.is_ready records for its take_data
                waitable._ready_to_take_data = True
            waitables_ready += [w for w in entities.other_waitables if w.is_ready(wait_set)]
            return (entities.ready(wait_set, 'timer'), entities.ready(wait_set, 'subscription'),
                    entities.ready(wait_set, 'client'), entities.ready(wait_set, 'service'), waitables_ready,
                    timed_out)
        finally:
            for item in reversed(entered):
                item.__exit__(None, None, None)

    def _one_off_wait_set(self, entities: _Entities):
        count = entities.count
        return _rclpy.WaitSet(count.num_subscriptions, count.num_guard_conditions, count.num_timers + 1,
                              count.num_clients, count.num_services, count.num_events, self._context.handle)
