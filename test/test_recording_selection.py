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

"""Which topics the recorder records, from whom and how (recording.selection), without ROS. The recorder node's
discovery is tested in test_recording_node.py.
"""
from types import SimpleNamespace

from rubber_rig.recording.qos import qos_entry
from rubber_rig.recording.selection import in_arrival_order, recorded_publishers, recorded_topics, subscription_qos

GRAPH = [('/rig1/samples', ['msg_defs/msg/RigSampleBatch']), ('/rig1/run_program/_action/status', ['x/msg/S']),
         ('/rig1/rig_driver/setpoint_stream/rig1/excitation', ['msg_defs/msg/SetpointBatch']),
         ('/rig2/samples', ['msg_defs/msg/RigSampleBatch']), ('/rosout', ['rcl_interfaces/msg/Log'])]


def test_by_default_the_namespace_is_recorded_without_command_channels_and_hidden_topics():
    assert recorded_topics(GRAPH, '/rig1') == GRAPH[:1]
    assert recorded_topics(GRAPH, '/rig1', include_hidden=True) == GRAPH[:2]   # never the command channel
    assert recorded_topics(GRAPH, '/') == [GRAPH[0], GRAPH[3]]                   # the root: every suite's


def test_configured_topics_are_recorded_wherever_they_are():
    assert recorded_topics(GRAPH, '/rig1', ['/rig2/samples', '/rosout']) == [GRAPH[3], GRAPH[4]]


def test_the_recorder_records_its_suite_unless_topics_are_configured():
    pubs = [SimpleNamespace(node_name='rig_driver', node_namespace='/rig1'),
            SimpleNamespace(node_name='recorder', node_namespace='/rig1'),
            SimpleNamespace(node_name='rig_driver', node_namespace='/rig2')]
    assert recorded_publishers(pubs, ('recorder', '/rig1'), '/rig1', configured=False) == pubs[:1]
    assert recorded_publishers(pubs, ('recorder', '/rig1'), '/rig1', configured=True) == [pubs[0], pubs[2]]


def test_the_subscription_is_as_reliable_and_durable_as_every_publisher_and_deep_enough():
    latched = qos_entry(reliability='reliable', durability='transient_local', depth=1)
    stream = qos_entry(reliability='reliable', durability='volatile', depth=5000)
    best = qos_entry(reliability='best_effort', durability='volatile', depth=10)
    assert subscription_qos([latched], 1000) == (True, True, 1000)
    assert subscription_qos([latched, stream], 1000) == (True, False, 5000)
    assert subscription_qos([stream, best], 1000) == (False, False, 5000)


def test_topics_read_together_are_written_in_the_order_they_arrived():
    # the recorder reads every topic at once each read_period; a recorder woken per message would have written
    # them by arrival: so is this, and a topic's own order stands where times are equal
    samples = [(b's0', {'received_timestamp': 10}), (b's1', {'received_timestamp': 30}),
               (b's2', {'received_timestamp': 30})]
    predictions = [(b'p0', {'received_timestamp': 20}), (b'p1', {'received_timestamp': 30})]
    beats = [(b'b0', {'received_timestamp': 5})]
    merged = in_arrival_order([('samples', samples), ('prediction', predictions), ('heartbeat', beats), ('x', [])])
    assert [(key, taken[0]) for key, taken in merged] == [
        ('heartbeat', b'b0'), ('samples', b's0'), ('prediction', b'p0'), ('samples', b's1'), ('samples', b's2'),
        ('prediction', b'p1')]
    assert merged[0][1][1] is beats[0][1]        # the message info goes with its message
