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

"""Helpers shared by the tests that run nodes in-process with real rclpy + Fast DDS."""
from contextlib import contextmanager

import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor

from msg_defs.msg import RigSampleBatch
from rubber_rig.nodes.auth import SAMPLES, signed

from support.waiting import poll_until, wait_for


@contextmanager
def ros_context(domain_id: int = None):
    """An initialised rclpy context of its own (on ``domain_id`` if given), shut down on exit."""
    ctx = rclpy.Context()
    if domain_id is None:
        rclpy.init(context=ctx)
    else:
        rclpy.init(context=ctx, domain_id=domain_id)
    try:
        yield ctx
    finally:
        rclpy.try_shutdown(context=ctx)


@contextmanager
def spinning(context, *nodes):
    """A SingleThreadedExecutor with ``nodes`` added; on exit the nodes are removed and destroyed and the
    executor shut down."""
    executor = SingleThreadedExecutor(context=context)
    for n in nodes:
        executor.add_node(n)
    try:
        yield executor
    finally:
        for n in nodes:
            executor.remove_node(n)
            n.destroy_node()
        executor.shutdown()


def spin_until(executor, condition, timeout=20.0, what=None):
    """Spin until ``condition()`` holds or ``timeout`` seconds pass; returns the condition's last value.

    With ``what``, a condition that never holds fails the test saying what did not happen (support.waiting).
    """
    def step():
        executor.spin_once(timeout_sec=0.01)
    if what is not None:
        return wait_for(condition, timeout, what, step=step)
    return poll_until(condition, timeout, step=step)


def sample_batch(first: int, n: int, *, period: float = 1e-3, frames_lost: int = 0, temperature: float = 23.0,
                 status_flags: int = 0) -> RigSampleBatch:
    """A RigSampleBatch of samples first..first+n-1 with deterministic signals (a function of the sequence
    only, so a recording can be compared value by value) and the stamp of its first sample; signed as the rig's
    driver signs its batches (publish in the order made: the receiver refuses a counter below one it took)."""
    m = RigSampleBatch()
    m.first_sequence = first
    m.sample_period = period
    m.header.stamp.sec, m.header.stamp.nanosec = divmod(first * 1_000_000, 1_000_000_000)
    k = np.arange(first, first + n)
    m.displacement = 1e-3 * np.sin(k * 0.01)
    m.force = 1e3 * np.cos(k * 0.01)
    m.setpoint = 1e-3 * np.sin(k * 0.01 + 0.1)
    m.temperature = temperature
    m.status_flags = status_flags
    m.frames_lost = frames_lost
    return signed(m, SAMPLES, '/test_fake_rig')   # signed with the session's rig key (conftest), as a driver signs
