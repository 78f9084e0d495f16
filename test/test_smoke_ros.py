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

"""Foundation smoke test: a real rclpy publisher and subscriber exchange a generated msg_defs message."""
import threading
import time

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor

from msg_defs.msg import RigSampleBatch, RigStatus


def test_msg_defs_is_generated_by_rosidl():
    # Generated classes carry the rosidl type support, never hand-written Python.
    assert RigSampleBatch.__module__ == 'msg_defs.msg._rig_sample_batch'
    assert hasattr(RigSampleBatch, '_TYPE_SUPPORT') or hasattr(type(RigSampleBatch), '_TYPE_SUPPORT')
    assert RigStatus.STATE_FAULT == 5 and RigStatus.FAULT_WATCHDOG == 1


@pytest.mark.ros
def test_pub_sub_rig_sample_batch_over_fast_dds():
    rclpy.init()
    try:
        pub_node = rclpy.create_node('smoke_pub')
        sub_node = rclpy.create_node('smoke_sub')
        received = []
        done = threading.Event()

        def on_batch(msg):
            received.append(msg)
            done.set()

        sub_node.create_subscription(RigSampleBatch, 'smoke/samples', on_batch, 10)
        pub = pub_node.create_publisher(RigSampleBatch, 'smoke/samples', 10)
        executor = SingleThreadedExecutor()
        executor.add_node(pub_node)
        executor.add_node(sub_node)

        msg = RigSampleBatch()
        msg.first_sequence = 1000
        msg.sample_period = 1e-3
        msg.displacement = [0.0, 0.5e-3, 1.0e-3]
        msg.force = [0.0, 6.1e3, 12.3e3]
        msg.setpoint = [0.0, 0.5e-3, 1.0e-3]
        msg.temperature = 20.0
        deadline = time.monotonic() + 10.0
        while not done.is_set() and time.monotonic() < deadline:
            pub.publish(msg)  # discovery takes a moment: republish until the subscriber matched
            executor.spin_once(timeout_sec=0.05)
        assert done.is_set(), 'no RigSampleBatch received over Fast DDS within 10 s'
        got = received[0]
        assert got.first_sequence == 1000
        assert got.sample_period == pytest.approx(1e-3)
        assert list(got.force) == [0.0, 6.1e3, 12.3e3]
        assert list(got.displacement) == [0.0, 0.5e-3, 1.0e-3]
        assert rclpy.get_rmw_implementation_identifier() == 'rmw_fastrtps_cpp'
        executor.shutdown()
        pub_node.destroy_node()
        sub_node.destroy_node()
    finally:
        rclpy.shutdown()
