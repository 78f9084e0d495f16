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
"""
from __future__ import annotations

import inspect
from typing import Callable

from rclpy.exceptions import InvalidHandle
from rclpy.node import Node
from rclpy.subscription import Subscription

DRAIN_MOST = 100    # messages taken after the one the executor handed over (1 s of sample batches at 100/s)


def create_draining_subscription(node: Node, msg_type, topic: str, callback: Callable, qos,
                                 most: int = DRAIN_MOST, **kwargs) -> Subscription:
    """``node.create_subscription(msg_type, topic, callback, qos, **kwargs)`` whose callback also handles, in
    order, up to `most` messages already queued behind the one the executor took. `callback` takes the message (its
    serialized bytes with ``raw=True``), or the message and its rmw MessageInfo dict, as rclpy's callbacks do.
    """
    subscription = None
    with_info = len(inspect.signature(callback).parameters) == 2

    def drain() -> None:
        for _ in range(most):
            try:
                with subscription.handle:
                    taken = subscription.handle.take_message(subscription.msg_type, subscription.raw)
            except InvalidHandle:     # destroyed meanwhile (the node is shutting down)
                return
            if taken is None:
                return
            callback(*taken) if with_info else callback(taken[0])

    def on_message(msg) -> None:
        callback(msg)
        drain()

    def on_message_with_info(msg, info) -> None:
        callback(msg, info)
        drain()

    subscription = node.create_subscription(msg_type, topic, on_message_with_info if with_info else on_message, qos,
                                            **kwargs)
    return subscription
