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

"""Topic names and QoS profiles shared by every node of the suite (and the recorder).

QoS choices:
- Streams that must not lose a sample (``samples``, ``setpoints``, ``prediction``): RELIABLE with a deep
  KEEP_LAST history. Sensor-data QoS (best effort) would silently drop batches under load, and the suite
  promises to count every gap; batching keeps the message rate low (10 ms of samples per batch by default:
  100 msg/s at any rate).
- Per-cycle results (``cycle_metrics``): RELIABLE, moderate depth.
- State that a late joiner must see at once (``status``, ``model_parameters``, ``program``): RELIABLE +
  TRANSIENT_LOCAL, depth 1 (the last value is latched, like a ROS 1 latched topic).

Commands and observations travel apart: a stream owner sends its batches on a channel of its own to its
driver, ``<rig_driver>/setpoint_stream/<owner node>`` (setpoint_stream_topic), and the same batches on
``setpoints`` for everyone who watches. The driver subscribes to each owner's channel (found in the graph, or
when the owner opens a stream) and takes commands only from the channel of the open stream's owner. Traffic on
``setpoints`` (a test script, `ros2 bag play` of a recording) never reaches the rig, and traffic on another
channel is refused and counted; however much of either arrives, it cannot delay the owner's batches, which
wait in a queue of their own (the executor serves each subscription in turn). The recorder leaves the channels
out by default, so replaying a recording cannot command a rig. A process that publishes on the owner's own
channel claims to be the owner; what keeps it out is the signature every batch carries (nodes/auth.py, README "Who
may move the rig"), not the topic name.
"""
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from rubber_rig.recording.selection import COMMAND_CHANNEL

SAMPLES = 'samples'                  # msg_defs/msg/RigSampleBatch, rig_driver -> all
SETPOINTS = 'setpoints'              # msg_defs/msg/SetpointBatch, excitation -> observers (model, recorder)
SETPOINT_STREAM = COMMAND_CHANNEL   # msg_defs/msg/SetpointBatch, owner -> its driver (setpoint_stream_topic)
STATUS = 'status'                    # msg_defs/msg/RigStatus, rig_driver (latched)
PREDICTION = 'prediction'            # msg_defs/msg/ModelPrediction, element_model
CYCLE_METRICS = 'cycle_metrics'      # msg_defs/msg/CycleMetrics, element_model
MODEL_PARAMETERS = 'model_parameters'  # msg_defs/msg/ModelParameters, element_model (latched)
PROGRAM = 'program'                  # std_msgs/msg/String (program YAML), excitation (latched)
EVENTS = 'events'                    # msg_defs/msg/DetectorEvent, excitation (detector trips)
RIG_CONFIGURATION = 'rig_configuration'  # std_msgs/msg/String (YAML), rig_driver (latched): the sensors' calibration
RECORDER_STATUS = 'recorder_status'  # msg_defs/msg/RecorderStatus, recorder (latched)
HEARTBEAT = 'heartbeat'              # msg_defs/msg/Heartbeat, every node, every 0.25 s
DIAGNOSTICS = '/diagnostics'         # diagnostic_msgs/msg/DiagnosticArray (absolute, as in every ROS 2 system)


def setpoint_stream_topic(rig_driver: str, owner: str) -> str:
    """The command channel of stream owner `owner` (a fully qualified node name) to driver `rig_driver`."""
    return f'{rig_driver.rstrip("/")}/{SETPOINT_STREAM}/{owner.lstrip("/")}'


STREAM_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                        reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
EVENT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                       reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
HEARTBEAT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                           reliability=ReliabilityPolicy.BEST_EFFORT, durability=DurabilityPolicy.VOLATILE)
# The run_program action's goal, result and cancel services, on both ends. rclpy's default
# (qos_profile_services_default, KEEP_LAST 10) keeps the newest 10 requests the server has not taken yet, and every
# client reads every answer on the reply topic and keeps its own, also in a queue of 10: a burst of 200 goals from
# 40 clients got 15 answers although the server answered each. A deep queue costs nothing until it fills.
REQUEST_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                         reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
ACTION_SERVICES_QOS = {f'{kind}_service_qos_profile': REQUEST_QOS for kind in ('goal', 'result', 'cancel')}
