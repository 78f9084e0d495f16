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

"""A subscription that reads its whole queue when the executor wakes it, not one message per wake-up.

rclpy's executor takes one message per ready subscription and then waits again, rebuilding its wait set (about
1 ms of Python on this machine). At 100 sample batches per second that is fine while the node keeps up; once a
busy computer has delayed it, the backlog drains only as fast as the executor cycles, and a cycle slower than
10 ms never drains it. The soak saw it (issue 34): the excitation's stream ticks ran on time while the samples it
measured lagged the rig by 2 s, so its stream, kept at most ``lead_time`` past the measurement, ran the rig dry.
Here the callback, after the message the executor handed it, takes what is already queued (at most
``DRAIN_MOST`` more, so timers and other subscriptions still get their turn) and handles each in order.

A *polled* subscription (``polled=True``) does not wake its node at all: nodes.executor.LeanExecutor leaves it
out of its wait set, and the node reads it from the periodic tick it has anyway (``subscription.drain()``). Every
wake-up of a node process costs 0.2-1 ms of CPU here (a cold cache, a publish's network stack, the executor's
Python), most of it whatever the callback does: the recorder woke ~250 times a second for messages it only
writes, the excitation 100 times for samples its stream tick (every 20 ms) reads anyway (issue 37). Under rclpy's
own executor (RUBBER_RIG_EXECUTOR=rclpy) a polled subscription also wakes the node, and then drains as above.
A polled queue must hold what arrives between two polls: the QoS depth is the node's to choose. Its QoS events
(an incompatible publisher) are not waited on either (executor.py says why): polling suits topics whose QoS the
suite fixes on both ends or, as the recorder's, adapts to the publishers it found.
"""
from __future__ import annotations

import inspect
from typing import Callable

from rclpy.exceptions import InvalidHandle
from rclpy.node import Node
from rclpy.subscription import Subscription

DRAIN_MOST = 100    # messages taken after the one the executor handed over (1 s of sample batches at 100/s)


def take_queued(subscription: Subscription, most: int = DRAIN_MOST) -> list:
    """Up to `most` (message, MessageInfo dict) already queued on `subscription`, oldest first, without waiting;
    [] once it is destroyed (the node is shutting down).
    """
    taken_all = []
    for _ in range(most):
        try:
            with subscription.handle:
                taken = subscription.handle.take_message(subscription.msg_type, subscription.raw)
        except InvalidHandle:
            break
        if taken is None:
            break
        taken_all.append(taken)
    return taken_all


def is_polled(subscription) -> bool:
    """True for a subscription its node reads from its own tick (an executor need not wait on it)."""
    return getattr(subscription, 'polled', False)


def create_draining_subscription(node: Node, msg_type, topic: str, callback: Callable, qos,
                                 most: int = DRAIN_MOST, polled: bool = False, **kwargs) -> Subscription:
    """``node.create_subscription(msg_type, topic, callback, qos, **kwargs)`` whose callback also handles, in
    order, up to `most` messages already queued behind the one the executor took. `callback` takes the message (its
    serialized bytes with ``raw=True``), or the message and its rmw MessageInfo dict, as rclpy's callbacks do.
    The subscription's ``drain()`` handles what is queued now; with ``polled=True`` the node calls it from its
    tick, and LeanExecutor does not wake the node for it (module docstring).
    """
    subscription = None
    with_info = len(inspect.signature(callback).parameters) == 2

    def drain() -> None:
        for taken in take_queued(subscription, most):
            callback(*taken) if with_info else callback(taken[0])

    def on_message(msg) -> None:
        callback(msg)
        drain()

    def on_message_with_info(msg, info) -> None:
        callback(msg, info)
        drain()

    subscription = node.create_subscription(msg_type, topic, on_message_with_info if with_info else on_message, qos,
                                            **kwargs)
    subscription.drain, subscription.polled = drain, polled
    if polled:
        node._wake_executor()   # an executor that already holds the node leaves it out of its wait set from now
    return subscription
