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

"""The schemas and channels of one MCAP file in the ros2 profile, and the CDR encoders of their types.

The rules of the ros2 profile in one place, apart from the writer's file I/O: one ``ros2msg`` schema per type
with the full concatenated definition (msgdefs.full_definition), one ``cdr`` channel per topic with the
metadata rosbag2 writes (``offered_qos_profiles``, ``topic_type_hash``) and ours (``rubber_rig.sequence``),
and a topic keeps its first type. Records are written through the writer's ``guard``, so that a write error
stops the writer whichever record hit it.
"""
from mcap.records import Schema

from . import mcap_compat
from .errors import RecordingError
from .metadata import SEQUENCE_SOURCE_KEY
from .msgdefs import full_definition, normalize_type, type_hash
from .plain import plain
from .qos import offered_qos_yaml


class ChannelTable:
    """Schemas, channels, encoders and writer-side sequence numbers of one file.

    ``mcap``: the file's ``mcap.writer.Writer``; ``guard(fn, *args)``: calls ``fn`` and turns an OSError into
    the writer's RecordingWriteError.
    """

    def __init__(self, mcap, guard):
        self._mcap, self._guard = mcap, guard
        self._schemas = {}                 # msg_type -> its Schema record (for decoders)
        self._channels = {}                # topic -> (channel id, msg_type)
        self._sequences = {}               # channel id -> last sequence written
        self._publication = set()          # channel ids whose stored sequence is the DDS publication sequence
        self._qos, self._hash = {}, {}     # topic -> offered QoS YAML, type hash (for the bag info)
        self._encoders = {}                # msg_type -> CDR encoder

    def add(self, topic: str, msg_type: str, qos=None, topic_type_hash: str = None,
            sequence_source: str = 'writer') -> int:
        """The channel id of ``topic``, registered (with the schema of its type) on first use."""
        msg_type = normalize_type(msg_type)
        known = self._channels.get(topic)
        if known is not None:
            if known[1] != msg_type:
                raise RecordingError(f'topic {topic} already recorded as {known[1]}, got {msg_type}')
            return known[0]
        schema = self._schemas.get(msg_type)
        if schema is None:
            text = full_definition(msg_type).encode()
            schema_id = self._guard(self._mcap.register_schema, msg_type, 'ros2msg', text)
            schema = self._schemas[msg_type] = Schema(schema_id, text, 'ros2msg', msg_type)
        metadata = {'offered_qos_profiles': offered_qos_yaml(qos or []),
                    'topic_type_hash': topic_type_hash if topic_type_hash is not None
                    else type_hash(msg_type), SEQUENCE_SOURCE_KEY: sequence_source}
        self._qos[topic] = metadata['offered_qos_profiles']
        self._hash[topic] = metadata['topic_type_hash']
        channel_id = self._guard(self._mcap.register_channel, topic, 'cdr', schema.id, metadata)
        self._channels[topic] = (channel_id, msg_type)
        self._sequences[channel_id] = 0
        if sequence_source == 'publication':
            self._publication.add(channel_id)
        return channel_id

    def publication_sequenced(self, channel_id: int) -> bool:
        """True if the channel's metadata says its stored sequence is the publication sequence (readers trust it)."""
        return channel_id in self._publication

    def schema(self, msg_type: str) -> Schema:
        return self._schemas[msg_type]

    def encode(self, msg_type: str, msg) -> bytes:
        """CDR bytes of a rosidl message or dict of fields (the encoder raises many types on a bad message)."""
        fn = self._encoders.get(msg_type)
        if fn is None:
            fn = self._encoders[msg_type] = mcap_compat.encoder(msg_type, full_definition(msg_type))
        return fn(plain(msg))

    def sequence(self, channel_id: int, given: int = None) -> int:
        """The sequence to store: ``given`` (the publication's) or, without one, the channel's last plus one."""
        sequence = self._sequences[channel_id] + 1 if given is None else given
        self._sequences[channel_id] = sequence
        return sequence

    def bag_topics(self, counts: dict) -> list:
        """The topic entries of bagmeta.make_bag_info; ``counts``: topic -> messages written."""
        return [{'name': topic, 'type': msg_type, 'qos': self._qos.get(topic, ''), 'hash': self._hash.get(topic, ''),
                 'count': counts.get(topic, 0)} for topic, (_, msg_type) in self._channels.items()]
