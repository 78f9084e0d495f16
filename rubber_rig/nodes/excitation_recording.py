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

"""The excitation node's view of the recorder, as plain values for the ROS-free rules of
rubber_rig.session.recorder_watch.RecorderWatch: a RecorderStatus message as a RecorderView, and the graph's facts
(which endpoints publish the recorder status and the samples, which node is the recorder).
"""
from __future__ import annotations

from rclpy.node import Node

from msg_defs.msg import RecorderStatus
from rubber_rig.nodes import topics
from rubber_rig.session.recorder_watch import RecorderView

STATES = {RecorderStatus.STATE_IDLE: 'idle', RecorderStatus.STATE_RECORDING: 'recording',
          RecorderStatus.STATE_ERROR: 'error'}


def recorder_view(msg: RecorderStatus) -> RecorderView:
    """msg_defs/RecorderStatus -> RecorderView."""
    return RecorderView(STATES.get(msg.state, msg.state_name), msg.path, msg.error, list(msg.topics),
                        list(msg.topic_publishers), int(msg.samples_lost))


def samples_topic(node: Node) -> str:
    """The fully qualified samples topic of ``node``'s namespace (what must be recorded)."""
    return f'{node.get_namespace().rstrip("/")}/{topics.SAMPLES}'


def recorder_topic(node: Node) -> str:
    """The fully qualified recorder status topic of ``node``'s namespace."""
    return f'{node.get_namespace().rstrip("/")}/{topics.RECORDER_STATUS}'


def publishers(node: Node, topic: str) -> frozenset:
    """The endpoint gids of the publishers the graph shows on ``topic`` (a restarted node is a new one)."""
    return frozenset(bytes(i.endpoint_gid) for i in node.get_publishers_info_by_topic(topic))


def recorder_name(node: Node) -> str:
    """Fully qualified name of the node publishing this namespace's recorder status ('' if none): whose heartbeat
    confirms a recording.
    """
    infos = node.get_publishers_info_by_topic(recorder_topic(node))
    return f'{infos[0].node_namespace.rstrip("/")}/{infos[0].node_name}' if infos else ''
