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

"""Fewer wake-ups (issue 37): the duties of a node on one timer (session.cadence, on simulated time), and the bus
read by a thread that wakes its owner once per batch (rig.can.receiver, on python-can's virtual bus and on the
simulated rig), with the watchdog still tripping on a silent bus when only the slow periodic poll runs.

Nothing here asserts a duration: the waits are for events (a frame taken, a wake-up counted), bounded generously
so that a busy computer only makes them slower.
"""
import os
import threading
import time
import uuid

import can
import numpy as np
import pytest

from rubber_rig.rig import open_rig
from rubber_rig.rig.can.protocol import FAULT_WATCHDOG
from rubber_rig.rig.can.receiver import BusReceiver
from rubber_rig.session.cadence import Cadence

from support.waiting import poll_until

PATIENCE = 20.0   # [s] the longest any wait here waits for its event (a loaded machine is slow, never wrong)


def _until(condition, patience=PATIENCE, step=0.005):
    return bool(poll_until(condition, patience, period=step))


# ---- one timer per node ------------------------------------------------------------------------------------------
def test_a_cadence_runs_each_duty_at_its_own_period_from_one_tick():
    c = Cadence({'status': 0.1, 'heartbeat': 0.25, 'diagnostics': 1.0})
    assert c.tick_period() == 0.1
    runs = {name: 0 for name in c.periods}
    for k in range(100):                                  # 10 s of ticks at 0.1 s, each 1 ms late
        for name in c.due(k * 0.1 + 0.001):
            runs[name] += 1
    # due at the first tick, then once per period: 10 s / period (+ the first), never drifting with late ticks
    assert runs == {'status': 100, 'heartbeat': 40, 'diagnostics': 10}


def test_a_cadence_neither_skips_a_tick_that_comes_a_little_early_nor_bursts_after_a_stall():
    c = Cadence({'status': 0.1, 'diagnostics': 1.0})
    assert c.due(0.0) == ['status', 'diagnostics']
    assert c.due(0.095) == ['status']            # 5 ms early (timer and clock read apart): still this tick's
    assert c.due(0.12) == []
    assert c.due(5.0) == ['status', 'diagnostics']   # a 4.9 s stall: each once, not 49 times
    assert c.due(5.05) == [] and c.due(5.1) == ['status']   # and the period starts again from the late tick
    with pytest.raises(ValueError, match="'status'"):
        Cadence({'status': 0.0})
    with pytest.raises(ValueError):
        Cadence({})


# ---- the bus read in a thread --------------------------------------------------------------------------------------
def _frame(arbitration_id, k=0):
    return can.Message(arbitration_id=arbitration_id, data=bytes([k % 256]), is_extended_id=False)


def test_the_receiving_thread_keeps_every_frame_in_order_and_wakes_once_per_batch_of_sample_frames():
    channel = f'wakeups-{uuid.uuid4().hex}'
    rx, tx = can.Bus(interface='virtual', channel=channel), can.Bus(interface='virtual', channel=channel)
    wakes = []
    receiver = BusReceiver(rx, {0x100}, 10, lambda: wakes.append(threading.current_thread().name)).start()
    try:
        for k in range(9):                        # 9 sample frames and 3 others: no batch yet
            tx.send(_frame(0x100, k))
            if k % 3 == 0:
                tx.send(_frame(0x200, k))
        assert _until(lambda: len(receiver.frames) == 12)
        assert wakes == []
        tx.send(_frame(0x100, 9))                 # the 10th sample frame: one wake-up, from the receiving thread
        assert _until(lambda: wakes)
        assert wakes == ['can-receive'] and receiver.wakes == 1
        taken = receiver.take()
        assert [(m.arbitration_id, m.data[0]) for m in taken] == [
            (0x100, 0), (0x200, 0), (0x100, 1), (0x100, 2), (0x100, 3), (0x200, 3), (0x100, 4), (0x100, 5),
            (0x100, 6), (0x200, 6), (0x100, 7), (0x100, 8), (0x100, 9)]
        assert receiver.take() == []
        for k in range(25):                        # 25 more: at most two wake-ups (one per 10 whole), never more
            tx.send(_frame(0x100, k))
        assert _until(lambda: len(receiver.frames) == 25)
        assert 1 <= receiver.wakes - 1 <= 2
    finally:
        receiver.stop()
        rx.shutdown()
        tx.shutdown()
    assert not receiver.running and receiver.error is None   # stopped when asked: no error said


def test_a_bus_that_fails_under_the_receiving_thread_is_said_once_and_the_thread_ends():
    channel = f'wakeups-{uuid.uuid4().hex}'
    rx = can.Bus(interface='virtual', channel=channel)
    errors = []
    receiver = BusReceiver(rx, {0x100}, 1, lambda: None, errors.append).start()
    rx.shutdown()                                 # the bus goes away under the blocked receive
    assert _until(lambda: not receiver.running)
    assert len(errors) == 1 and receiver.error is errors[0]
    with pytest.raises(ValueError, match='frames_per_wake'):
        BusReceiver(rx, {0x100}, 0, lambda: None)


def test_the_driver_reads_the_simulated_rig_through_the_thread_and_its_watchdog_trips_on_a_silent_bus():
    # paced without bus timing: the simulated controller in its own thread on python-can's virtual bus
    with open_rig({'paced': True, 'bus_timing': False, 'sample_rate': 1000.0}) as rig:
        drv = rig.driver
        assert rig.wait_ready(PATIENCE)
        batch = threading.Event()
        receiver = drv.receive_in_thread(batch.set, 10)
        assert receiver is not None and drv.receive_in_thread(batch.set, 10) is None   # one thread per bus
        assert drv.tick_period == pytest.approx(min(0.25 * rig.config.watchdog_timeout,
                                                    0.5 * rig.config.heartbeat_period))
        x = 1e-4 * np.sin(np.linspace(0, 2 * np.pi, 300))
        assert drv.queue_setpoints(drv.next_sequence, x)
        drv.end_stream(drv.stream.stream_id)      # the whole program: no stream loss after it (the rig holds)
        got, first = 0, None
        while got < 300 and batch.wait(PATIENCE):   # polled only when the thread says a batch is in
            batch.clear()
            while (blk := drv.poll()) is not None:
                first = blk.first_sequence if first is None else first
                assert blk.first_sequence == first + got     # contiguous, in order
                got += len(blk)
        assert got >= 300 and drv.status.frames_lost == 0 and drv.faults == 0
        assert receiver.wakes >= 1 and receiver.wakes <= got // 10 + 1
        rig.sim.stop()                           # the controller falls silent: no frame wakes anybody now
        ok = _until(lambda: drv.poll() is None and bool(drv.faults & FAULT_WATCHDOG), step=drv.tick_period)
        assert ok, drv.fault_messages
        assert any('silent' in m or 'no feedback' in m for m in drv.fault_messages)
    assert not receiver.running               # closing the rig stopped the thread before the bus


def test_a_receiving_thread_that_stops_on_a_failed_bus_is_said_once_in_the_drivers_log():
    with open_rig({'paced': True, 'bus_timing': False, 'sample_rate': 1000.0}) as rig:
        drv = rig.driver
        assert rig.wait_ready(PATIENCE)
        receiver = drv.receive_in_thread(lambda: None, 10)
        drv.take_events()
        drv.bus.shutdown()                       # the interface goes away under the blocked receive
        assert _until(lambda: not receiver.running)
        drv.io.receive_all()
        drv.io.receive_all()
        said = [text for level, text in drv.take_events() if 'CAN receive stopped' in text]
        assert len(said) == 1 and 'the watchdog judges the silence' in said[0]


@pytest.mark.ros
def test_a_draining_subscription_reads_a_backlog_in_a_few_wake_ups_in_order():
    # a node delayed by a busy computer finds 150 batches queued: rclpy's executor hands over one per wake-up (150
    # wake-ups, each rebuilding its wait set); the draining subscription handles what is queued behind it, at most
    # DRAIN_MOST (100) more per wake-up, in order. Bound: 2 wake-ups once all are queued; 15 leaves room for a busy
    # computer that delivers them to the reader in pieces (the same process, over loopback)
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_msgs.msg import Int32

    from rubber_rig.nodes import topics
    from rubber_rig.nodes.draining import create_draining_subscription

    from support.ros import ros_context, spin_until
    with ros_context(20 + os.getpid() % 20) as context:
        node = Node('drained', context=context)
        got = []
        create_draining_subscription(node, Int32, 'backlog', lambda m: got.append(m.data), topics.STREAM_QOS)
        pub = node.create_publisher(Int32, 'backlog', topics.STREAM_QOS)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        try:
            assert spin_until(executor, lambda: pub.get_subscription_count() == 1, 10.0)
            for i in range(150):
                pub.publish(Int32(data=i))
            time.sleep(0.5)                     # nothing runs the callbacks meanwhile: the reader's queue fills
            wake_ups, deadline = 0, time.monotonic() + 20.0
            while len(got) < 150 and time.monotonic() < deadline:
                before = len(got)
                executor.spin_once(timeout_sec=0.1)
                wake_ups += len(got) > before
        finally:
            executor.shutdown()
            node.destroy_node()
    assert got == list(range(150)) and 2 <= wake_ups <= 15, (wake_ups, len(got))     # one per message: 150


@pytest.mark.ros
def test_ticks_from_events_hold_the_timer_back_and_it_ticks_again_when_they_stop():
    # rig_driver's frames wake it once per batch and tick its duties then (NodeTicks.tick_now): the timer, kept for
    # a silent bus (the watchdog), must not wake it a second time while batches come. On simulated time (the node
    # takes /clock), stepped by the test: events every 0.05 s against a 0.1 s timer, then none for 0.3 s
    from builtin_interfaces.msg import Time
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rosgraph_msgs.msg import Clock

    from rubber_rig.nodes.executor import LeanExecutor
    from rubber_rig.nodes.ticks import NodeTicks

    from support.ros import ros_context
    with ros_context(11 + os.getpid() % 9) as context:   # its own: its /clock must reach no other test's node
        node = Node('ticked', context=context, parameter_overrides=[Parameter('use_sim_time', value=True)])
        clock_pub = Node('sim_clock', context=context).create_publisher(Clock, '/clock', 10)
        executor = LeanExecutor(context=context)
        executor.add_node(node)
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()

        def set_time(seconds):
            clock_pub.publish(Clock(clock=Time(sec=int(seconds), nanosec=round(seconds % 1 * 1e9))))
            assert _until(lambda: abs(node.get_clock().now().nanoseconds * 1e-9 - seconds) < 1e-6), seconds

        try:
            assert _until(lambda: clock_pub.get_subscription_count() >= 1)
            set_time(1.0)
            ticks_seen, events_ticked, duty_runs = [0], [0], [0]
            ticks = NodeTicks(node, {'status': (0.1, lambda: duty_runs.__setitem__(0, duty_runs[0] + 1))})
            ticks.every_tick(lambda: ticks_seen.__setitem__(0, ticks_seen[0] + 1), 0.1)

            def on_event():
                ticks.tick_now()
                events_ticked[0] += 1
            event = node.create_guard_condition(on_event)
            for k in range(1, 21):
                set_time(1.0 + 0.05 * k)
                event.trigger()
                assert _until(lambda k=k: events_ticked[0] == k)
            assert ticks_seen[0] == 20                  # every tick was an event's: the timer never fired
            assert 10 <= duty_runs[0] <= 11             # the 0.1 s duty ran on schedule from the events (1 s)
            set_time(2.0 + 0.3)                         # no event for 0.3 s: the timer ticks again
            assert _until(lambda: ticks_seen[0] > 20)
        finally:
            executor.shutdown()
            spinner.join(5.0)
            node.destroy_node()
