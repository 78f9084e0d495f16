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

"""The owners' command channels rig_driver listens to (``<driver>/setpoint_stream/<owner>``, topics.py): one
subscription per owner the graph shows, created while the rig is configured and destroyed with it. Which batch may
move the rig is the core's StreamGate's to say (rig.can.gate); a channel it mutes for flooding is unsubscribed, so
DDS drops what it sends at no cost here.
"""
from __future__ import annotations

from typing import Callable

from rclpy.node import Node

from msg_defs.msg import SetpointBatch
from rubber_rig.nodes import topics
from rubber_rig.nodes.draining import create_draining_subscription
from rubber_rig.rig.can.gate import MUTE_AFTER, MUTE_FOR, StreamGate

MAX_CHANNELS = 16   # owners' command channels the driver listens to at once


class CommandChannels:
    """The command channels of rig_driver ``node`` for one configuration: ``gate`` (the open rig's StreamGate) says who
    is muted, ``driver`` (its RigDriver) whose stream is open; ``on_setpoints(msg, owner)`` takes every batch.
    """

    def __init__(self, node: Node, gate: StreamGate, driver, on_setpoints: Callable[[SetpointBatch, str], None]):
        self.node, self.gate, self.driver, self.on_setpoints = node, gate, driver, on_setpoints
        self.prefix = topics.setpoint_stream_topic(node.get_fully_qualified_name(), '')
        self.subscriptions: dict[str, object] = {}   # owner -> subscription to its command channel

    def find(self) -> None:
        """Subscribe to every owner's command channel the graph shows (so a program's first batch finds us)."""
        for name, _ in self.node.get_topic_names_and_types():
            owner = '/' + name[len(self.prefix):]
            if name.startswith(self.prefix) and len(name) > len(self.prefix) and not self.gate.muted(owner):
                self.listen_to(owner)

    def mute(self, channel: str) -> None:
        """Stop listening to a flooding channel the gate muted."""
        sub = self.subscriptions.pop(channel, None)
        if sub is not None:
            self.node.destroy_subscription(sub)
        self.node.get_logger().warning(f'more than {MUTE_AFTER} batches from {channel} refused within 1 s: its '
                                       f'channel is muted for {MUTE_FOR:g} s (what it sends meanwhile is dropped '
                                       'uncounted)')

    def listen_to(self, owner: str) -> str:
        """Subscribe to `owner`'s command channel if not yet done; '' or why it cannot be."""
        self.gate.unmute(owner)    # (an owner that asks for a stream is heard again at once)
        if owner in self.subscriptions:
            return ''
        if len(self.subscriptions) >= MAX_CHANNELS:    # the oldest channel not the open stream's makes room
            current = self.driver.stream.owner if self.driver.stream else None
            old = next((o for o in self.subscriptions if o != current), None)
            if old is not None:
                self.node.destroy_subscription(self.subscriptions.pop(old))
        topic = topics.setpoint_stream_topic(self.node.get_fully_qualified_name(), owner)
        try:
            self.subscriptions[owner] = create_draining_subscription(   # a backlog is read in one wake-up
                self.node, SetpointBatch, topic, lambda msg: self.on_setpoints(msg, owner), topics.STREAM_QOS)
        except Exception as exc:   # noqa: BLE001 - rclpy raises several types for a name it cannot take
            return f'owner {owner!r} gives no valid topic name ({exc})'
        self.node.get_logger().info(f'listening for setpoints of {owner} on {topic}')
        return ''

    def close(self) -> None:
        """Unsubscribe from every channel (cleanup)."""
        for sub in self.subscriptions.values():
            self.node.destroy_subscription(sub)
        self.subscriptions.clear()
