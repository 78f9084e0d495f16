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

"""The ``main()`` of every node: init, spin one SingleThreadedExecutor, shut down cleanly.

SingleThreadedExecutor, not MultiThreadedExecutor: with a timer publishing to a subscription in the same
process, rclpy's MultiThreadedExecutor collapses to tens of callbacks per second (rclpy #1223, measured here).

The DDS configuration (rubber_rig.dds.configure_dds: transport, discovery) is chosen before rclpy.init and
logged with the ready line.
"""
from __future__ import annotations

import os
from typing import Callable

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

from ..dds import configure_dds
from .params import undeclared_overrides
from .rclpy_compat import RCLError


def spin_node(node_factory: Callable[[], Node], args=None) -> None:
    """Create the node, spin it until Ctrl-C / SIGTERM / context shutdown, then release it.

    A node with a ``close()`` method (open bus, open file) has it called before ``destroy_node()``.
    """
    dds = configure_dds()   # before the first participant exists
    rclpy.init(args=args)
    node = None
    try:
        node = node_factory()
        undeclared_overrides(node)   # a misspelt key in a parameter file must not pass silently
        node.get_logger().info(f'DDS: {dds}')
        node.get_logger().info(f'ready (pid {os.getpid()})')   # launchers and the fault-matrix tests wait for it
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RCLError:
        # rclpy's SIGINT/SIGTERM handler shuts the context down; when that lands while the executor builds
        # its wait set, rcl reports "context is not valid" instead of ExternalShutdownException. That is a
        # normal stop; any RCLError while the context is still valid is a real error.
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            close = getattr(node, 'close', None)
            if callable(close):
                close()
            node.destroy_node()
        rclpy.try_shutdown()
