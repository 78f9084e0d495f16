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

"""The nodes' executor (rubber_rig.nodes.executor.LeanExecutor, issue 37) on real rclpy and Fast DDS: every kind of
entity a node has still works through it - timers, subscriptions, services and clients, guard conditions,
actions, a lifecycle node's transitions, QoS events, tasks and coroutines awaiting futures, entities created and
destroyed while it spins - and it builds its wait set again only when entities change, waking once per message.

Each test has a private context on a DDS domain of its own; the waits are for events, bounded generously (a busy
machine is slow, never wrong); nothing asserts a duration.
"""
import os
import threading
import time

import pytest
import rclpy
from rclpy.action import ActionClient, ActionServer, CancelResponse
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from std_msgs.msg import Int32
from std_srvs.srv import Trigger

from msg_defs.action import RunProgram
from rubber_rig.nodes import awaitables
from rubber_rig.nodes.executor import LeanExecutor
from rubber_rig.nodes.executor_choice import EXECUTOR_ENV, EventsLoop, make_executor

from support.waiting import poll_until

pytestmark = pytest.mark.ros   # every test here runs real rclpy on a DDS domain of its own

PATIENCE = 20.0   # [s] the longest any wait here waits for its event


def _until(condition, patience=PATIENCE, step=0.005):
    return bool(poll_until(condition, patience, period=step))


@pytest.fixture
def context():
    ctx = Context()
    rclpy.init(context=ctx, domain_id=200 + os.getpid() % 30)
    yield ctx
    rclpy.try_shutdown(context=ctx)


class Spinning:
    """A node spun by a LeanExecutor in a thread (as nodes/spin.py does); ``stop()`` ends it."""

    def __init__(self, node, context):
        self.node = node
        self.executor = LeanExecutor(context=context)
        self.executor.add_node(node)
        self.errors = []
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self):
        try:
            self.executor.spin()
        except BaseException as exc:   # noqa: BLE001 - the test asserts there is none
            self.errors.append(exc)

    def stop(self):
        self.executor.shutdown(timeout_sec=5.0)
        self.thread.join(5.0)
        assert not self.thread.is_alive()
        assert self.errors == []
        self.node.destroy_node()


def test_make_executor_gives_the_lean_executor_unless_the_environment_asks_for_another(context, monkeypatch):
    monkeypatch.delenv(EXECUTOR_ENV, raising=False)
    assert type(make_executor(context)) is LeanExecutor
    monkeypatch.setenv(EXECUTOR_ENV, 'rclpy')
    assert type(make_executor(context)) is SingleThreadedExecutor
    monkeypatch.setenv(EXECUTOR_ENV, 'events')
    plain, guarded = Node('lean_plain', context=context), Node('lean_guarded', context=context)
    guarded.create_guard_condition(lambda: None)
    assert type(make_executor(context, plain)) is EventsLoop
    assert type(make_executor(context, guarded)) is LeanExecutor      # EventsExecutor refuses guard conditions

    raw = Node('lean_raw', context=context)
    raw.create_subscription(Int32, 'lean_raw', lambda data: None, 10, raw=True)
    assert type(make_executor(context, raw)) is LeanExecutor           # nor raw subscriptions (the recorder's)

    class WillGuard(Node):
        events_executor_refuses = 'a guard condition'                  # as rig_driver, whose configure makes one

    assert type(make_executor(context, WillGuard('lean_will_guard', context=context))) is LeanExecutor


def test_the_opt_in_events_loop_spins_timers_and_subscriptions_and_stops(context):
    node = Node('events_loop', context=context)
    received, ticks = [], []
    pub = node.create_publisher(Int32, 'events_numbers', 10)
    node.create_subscription(Int32, 'events_numbers', lambda m: received.append(m.data), 10)
    node.create_timer(0.01, lambda: ticks.append(1))
    loop = EventsLoop(context=context)
    loop.add_node(node)
    thread = threading.Thread(target=loop.spin, daemon=True)
    thread.start()
    try:
        assert _until(lambda: len(ticks) >= 5)
        assert _until(lambda: pub.get_subscription_count() == 1)
        for k in range(20):
            pub.publish(Int32(data=k))
            time.sleep(0.001)
        assert _until(lambda: len(received) == 20), received
        assert received == list(range(20))
    finally:
        loop.shutdown(timeout_sec=5.0)
        thread.join(5.0)
        assert not thread.is_alive()
        node.destroy_node()


def test_timers_subscriptions_services_and_guard_conditions_run_and_the_wait_set_is_built_once(context):
    node = Node('lean_basic', context=context)
    received, guard_runs, timer_runs = [], [], []
    pub = node.create_publisher(Int32, 'lean_numbers', 10)
    node.create_subscription(Int32, 'lean_numbers', lambda m: received.append(m.data), 10)
    node.create_service(Trigger, 'lean_trigger', lambda req, resp: setattr(resp, 'success', True) or resp)
    guard = node.create_guard_condition(lambda: guard_runs.append(1))
    node.create_timer(0.01, lambda: timer_runs.append(1))
    spinning = Spinning(node, context)
    try:
        assert _until(lambda: len(timer_runs) >= 5)
        assert _until(lambda: pub.get_subscription_count() == 1)
        rebuilds = spinning.executor.rebuilds
        for k in range(200):
            pub.publish(Int32(data=k))
            time.sleep(0.001)
        assert _until(lambda: len(received) == 200), f'{len(received)} of 200 messages taken'
        assert received == list(range(200))                        # in order, none lost, none twice
        for _ in range(3):
            count = len(guard_runs)
            guard.trigger()                                        # from another thread, as the CAN reader does
            assert _until(lambda count=count: len(guard_runs) == count + 1)
        assert spinning.executor.rebuilds == rebuilds              # nothing created or destroyed: no rebuild
        caller = Node('lean_caller', context=context)
        client = caller.create_client(Trigger, 'lean_trigger')
        assert client.wait_for_service(PATIENCE)
        future = client.call_async(Trigger.Request())
        rclpy.spin_until_future_complete(caller, future, executor=LeanExecutor(context=context),
                                         timeout_sec=PATIENCE)
        assert future.done() and future.result().success           # client side through a LeanExecutor too
        caller.destroy_node()
    finally:
        spinning.stop()


def test_one_wake_up_per_message_where_rclpy_needs_two(context):
    node = Node('lean_turns', context=context)
    received = []
    pub = node.create_publisher(Int32, 'lean_turns', 10)
    node.create_subscription(Int32, 'lean_turns', lambda m: received.append(m.data), 10)
    for k in range(10):   # the entities of a small node: more publishers, their QoS event handlers
        node.create_publisher(Int32, f'lean_other_{k}', 10)
    spinning = Spinning(node, context)
    try:
        assert _until(lambda: pub.get_subscription_count() == 1)
        time.sleep(0.2)
        turns = spinning.executor.turns
        for k in range(50):
            pub.publish(Int32(data=k))
            assert _until(lambda k=k: len(received) == k + 1)       # one at a time: each message its own wake-up
        # rclpy's SingleThreadedExecutor waits twice per message (its own guard condition wakes it after each
        # callback); here once, plus the odd turn for something else (a graph event, a QoS event)
        assert spinning.executor.turns - turns <= 50 + 5
    finally:
        spinning.stop()


def test_a_polled_subscription_wakes_no_one_and_its_node_reads_it_in_order(context):
    # the recorder, the excitation's samples, the peers' heartbeats (nodes/draining.py): LeanExecutor leaves a
    # polled subscription out of its wait set; the node reads it from its tick with drain(). Whether a message
    # was handled is asserted once the reader has acknowledged it (reliable QoS: it sits in the reader's queue)
    from rubber_rig.nodes.draining import create_draining_subscription
    node = Node('lean_polled', context=context)
    polled, woken = [], []
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    sub = create_draining_subscription(node, Int32, 'lean_polled', lambda m: polled.append(m.data), qos, polled=True)
    node.create_subscription(Int32, 'lean_woken', lambda m: woken.append(m.data), qos)
    pub_polled = node.create_publisher(Int32, 'lean_polled', qos)
    pub_woken = node.create_publisher(Int32, 'lean_woken', qos)
    spinning = Spinning(node, context)
    try:
        assert _until(lambda: pub_polled.get_subscription_count() == 1 and pub_woken.get_subscription_count() == 1)
        turns = spinning.executor.turns
        for k in range(30):
            pub_polled.publish(Int32(data=k))
        assert pub_polled.wait_for_all_acked(rclpy.duration.Duration(seconds=PATIENCE))
        pub_woken.publish(Int32(data=1))
        assert _until(lambda: woken == [1])
        assert polled == [] and spinning.executor.turns - turns <= 5      # 30 queued, none woke the node
        node.create_timer(0.01, sub.drain)                               # the node's tick reads them
        assert _until(lambda: len(polled) == 30) and polled == list(range(30))
    finally:
        spinning.stop()


def test_under_rclpys_own_executor_a_polled_subscription_still_delivers(context):
    # RUBBER_RIG_EXECUTOR=rclpy: rclpy's executor knows nothing of polling; the messages wake the node as before
    from rubber_rig.nodes.draining import create_draining_subscription
    node = Node('rclpy_polled', context=context)
    got = []
    create_draining_subscription(node, Int32, 'rclpy_polled', lambda m: got.append(m.data), 100, polled=True)
    pub = node.create_publisher(Int32, 'rclpy_polled', 100)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        assert _until(lambda: executor.spin_once(timeout_sec=0.01) or pub.get_subscription_count() == 1)
        for k in range(10):
            pub.publish(Int32(data=k))
        assert _until(lambda: executor.spin_once(timeout_sec=0.01) or len(got) == 10) and got == list(range(10))
    finally:
        executor.shutdown()
        node.destroy_node()


def test_entities_created_and_destroyed_while_spinning_and_coroutines_awaiting_timers(context):
    node = Node('lean_dynamic', context=context)
    log = []

    async def task():
        for k in range(3):
            await awaitables.sleep(node, 0.02)        # a timer created, awaited and destroyed each time
            log.append(k)
        return 'done'

    spinning = Spinning(node, context)
    try:
        rebuilds = spinning.executor.rebuilds
        future = spinning.executor.create_task(task)
        assert _until(future.done)
        assert future.result() == 'done' and log == [0, 1, 2]
        assert spinning.executor.rebuilds > rebuilds                # each new timer made it build anew
        assert list(node.timers) == []
        late = []
        node.create_timer(0.01, lambda: late.append(1))            # created from this thread while it waits
        assert _until(lambda: len(late) >= 3)
    finally:
        spinning.stop()


def test_a_future_completed_by_a_callback_resumes_its_task_without_another_event(context):
    node = Node('lean_future', context=context)
    done, seen = Future(), []

    async def waiter():
        seen.append(await done)

    pub = node.create_publisher(Int32, 'lean_future', 10)
    node.create_subscription(Int32, 'lean_future', lambda m: done.done() or done.set_result(m.data), 10)
    spinning = Spinning(node, context)
    try:
        spinning.executor.create_task(waiter)
        assert _until(lambda: pub.get_subscription_count() == 1)
        pub.publish(Int32(data=7))                                  # nothing else happens after this message
        assert _until(lambda: seen == [7])
    finally:
        spinning.stop()


def test_an_action_goal_runs_to_its_result_with_feedback_and_a_cancel_is_honoured(context):
    server_node = Node('lean_action_server', context=context)

    async def execute(goal_handle):
        cycles = int(goal_handle.request.program_yaml)
        for k in range(cycles):
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
                return RunProgram.Result(success=False, message=f'cancelled after {k}')
            goal_handle.publish_feedback(RunProgram.Feedback(cycle=k, cycles_total=cycles))
            await awaitables.sleep(server_node, 0.01)
        goal_handle.succeed()
        return RunProgram.Result(success=True, message=f'{cycles} cycles')

    ActionServer(server_node, RunProgram, 'lean_run', execute_callback=execute,
                 cancel_callback=lambda _: CancelResponse.ACCEPT)
    client_node = Node('lean_action_client', context=context)
    client = ActionClient(client_node, RunProgram, 'lean_run')
    feedback = []
    server, caller = Spinning(server_node, context), Spinning(client_node, context)
    try:
        assert client.wait_for_server(PATIENCE)
        sent = client.send_goal_async(RunProgram.Goal(program_yaml='6'), feedback_callback=feedback.append)
        assert _until(sent.done) and sent.result().accepted
        result = sent.result().get_result_async()
        assert _until(result.done)
        assert result.result().result.success and result.result().result.message == '6 cycles'
        assert [f.feedback.cycle for f in feedback] == list(range(6))
        sent = client.send_goal_async(RunProgram.Goal(program_yaml='100000'))
        assert _until(sent.done) and sent.result().accepted
        cancel = sent.result().cancel_goal_async()
        assert _until(cancel.done)
        result = sent.result().get_result_async()
        assert _until(result.done)
        assert result.result().result.message.startswith('cancelled after')
    finally:
        caller.stop()
        server.stop()


class _Lifecycle(LifecycleNode):
    def __init__(self, context):
        super().__init__('lean_lifecycle', context=context)
        self.pub = None

    def on_configure(self, state):
        self.pub = self.create_lifecycle_publisher(Int32, 'lean_lifecycle_out', 10)
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state):
        self.destroy_publisher(self.pub)
        return TransitionCallbackReturn.SUCCESS


def test_a_lifecycle_node_changes_state_through_its_services(context):
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState, GetState
    node = _Lifecycle(context)
    caller = Node('lean_lifecycle_caller', context=context)
    spinning = Spinning(node, context)
    executor = LeanExecutor(context=context)
    try:
        change = caller.create_client(ChangeState, 'lean_lifecycle/change_state')
        get = caller.create_client(GetState, 'lean_lifecycle/get_state')
        assert change.wait_for_service(PATIENCE) and get.wait_for_service(PATIENCE)
        for transition, label in ((Transition.TRANSITION_CONFIGURE, 'inactive'),
                                  (Transition.TRANSITION_ACTIVATE, 'active'),
                                  (Transition.TRANSITION_DEACTIVATE, 'inactive'),
                                  (Transition.TRANSITION_CLEANUP, 'unconfigured')):
            future = change.call_async(ChangeState.Request(transition=Transition(id=transition)))
            rclpy.spin_until_future_complete(caller, future, executor=executor, timeout_sec=PATIENCE)
            assert future.done() and future.result().success, label
            future = get.call_async(GetState.Request())
            rclpy.spin_until_future_complete(caller, future, executor=executor, timeout_sec=PATIENCE)
            assert future.result().current_state.label == label
    finally:
        caller.destroy_node()
        spinning.stop()


def test_an_incompatible_qos_event_reaches_its_callback(context):
    from rclpy.event_handler import SubscriptionEventCallbacks
    node = Node('lean_qos', context=context)
    events = []
    node.create_publisher(Int32, 'lean_qos', QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))
    node.create_subscription(Int32, 'lean_qos', lambda m: None,
                             QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE),
                             event_callbacks=SubscriptionEventCallbacks(incompatible_qos=events.append))
    spinning = Spinning(node, context)
    try:
        assert _until(lambda: len(events) >= 1)
        assert events[0].total_count >= 1
    finally:
        spinning.stop()
