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

"""Recording: MCAP files in the ros2 profile that ros2 bag, Foxglove and rosbags read (ROS-free core).

Writing (no rclpy needed)::

    with RecordingWriter('run.mcap', metadata={'specimen': 'B-7', 'temperature': 23.0}) as w:
        w.write_message('/rig/samples', 'msg_defs/msg/RigSampleBatch', msg_or_dict_or_cdr, log_time_ns)

    rec = Recorder('recordings', metadata=..., split_size_bytes=..., split_duration_s=...,
                   snapshot_duration_s=...)          # what the recorder node drives
    rec.start(); rec.write(topic, msg_type, msg, log_time_ns); rec.split(); rec.snapshot(); rec.stop()

Reading::

    r = load_recording('recordings/rubber_rig_20261122-042000')   # file, directory or list
    r.time, r.displacement, r.force, r.setpoint, r.prediction, r.residual, r.temperature, r.status,
    r.sequence, r.block_index, r.metadata, r.gaps, r.samples_lost, r.messages[topic]

Crashes: :func:`recover` (``rubber-rig recover FILE``) rebuilds a file whose writer was killed.
Modules: parts (the parts of a split recording), outcome (what happened to a program's recording, for its result),
msgdefs (ros2msg schema texts), qos (rosbag2 QoS YAML), gaps (the loss ledger: sequence-gap accounting),
writer (the file), channels (schemas, channels, CDR encoding), gapcheck (gap check while writing),
metadata (record names, value codec), plain (messages as plain values), rawfile (unbuffered file),
session (Recorder), reader, mcapio (checked file access), cdr (numpy CDR decoder), recover,
bagmeta (rosbag2 metadata.yaml), mcap_compat (the private mcap_ros2 parts, with their checked version).
"""
from .bagmeta import write_bag_metadata
from .errors import RecordingError, RecordingWriteError
from .gaps import GapTracker, LossLedger
from .msgdefs import full_definition, normalize_type, register_definition, type_hash
from .qos import offered_qos_yaml, qos_entry
from .reader import SIGNALS, Recording, load_recording
from .recover import RecoverResult, recover
from .session import Recorder
from .writer import CLOSE_METADATA_NAME, METADATA_NAME, RecordingWriter

__all__ = ['RecordingError', 'RecordingWriteError', 'GapTracker', 'LossLedger', 'full_definition', 'normalize_type',
           'register_definition', 'type_hash', 'offered_qos_yaml', 'qos_entry', 'CLOSE_METADATA_NAME',
           'METADATA_NAME', 'RecordingWriter', 'SIGNALS', 'Recording', 'load_recording', 'Recorder',
           'RecoverResult', 'recover', 'write_bag_metadata']
