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

"""Awaitables for a node's async callbacks (an action's execute, a task): a bounded service call and a sleep,
both on the node's own timers and clock (simulated time with use_sim_time), so the executor keeps serving the
node's other callbacks while they wait.
"""
from __future__ import annotations

import math

from rclpy.node import Node
from rclpy.task import Future

SERVICE_POLL = 0.05    # [s] how often a call looks for its service while it is not there


async def call(node: Node, client, request, timeout: float):
    """Await a service response, or None after `timeout` seconds (or if the service is not there)."""
    for _ in range(math.ceil(timeout / SERVICE_POLL)):    # the waits are the node's timers: its clock
        if client.service_is_ready():
            break
        await sleep(node, SERVICE_POLL)
    else:
        return None
    done = Future()
    future = client.call_async(request)
    future.add_done_callback(lambda f: done.done() or done.set_result(f.result()))
    timer = node.create_timer(timeout, lambda: done.done() or done.set_result(None))
    try:
        return await done
    finally:
        node.destroy_timer(timer)


async def sleep(node: Node, seconds: float):
    """Wait `seconds` on a timer of `node`."""
    done = Future()
    timer = node.create_timer(seconds, lambda: done.done() or done.set_result(True))
    try:
        await done
    finally:
        node.destroy_timer(timer)
