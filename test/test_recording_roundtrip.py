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

"""Round trip of every msg_defs message type and of the std_msgs / diagnostic_msgs types.

Each type is filled with non-default values, written by RecordingWriter (once as the rosidl message,
encoded by the core, once as rclpy's own CDR bytes), and read back by two independent readers: rosbags
(AnyReader, types taken from the schema in the file) and the mcap reader with mcap_ros2's decoder.
"""
import dataclasses
import importlib
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from rubber_rig.recording import RecordingWriter, full_definition, type_hash
from rubber_rig.recording.qos import parse_offered_qos

SHARE = Path(importlib.import_module('msg_defs').__file__).resolve().parents[4] / 'share'


def message_types(package):
    return sorted(f'{package}/msg/{p.stem}' for p in (SHARE / package / 'msg').glob('*.msg'))


TYPES = message_types('msg_defs') + message_types('std_msgs') + message_types('diagnostic_msgs')


def msg_class(type_name):
    pkg, sub, name = type_name.split('/') if type_name.count('/') == 2 else (
        type_name.split('/')[0], 'msg', type_name.split('/')[1])
    return getattr(importlib.import_module(f'{pkg}.{sub}'), name)


def scalar(base, i):
    if base == 'boolean':
        return i % 2 == 0
    if base == 'octet':
        return bytes([(7 + i) % 256])
    if base in ('float', 'double'):
        return 1.25 + 0.5 * i
    if base.startswith('int') or base.startswith('uint') or base == 'char':
        return 3 + i
    if base.startswith('string'):
        return f'text {i} \u00e9'
    return fill(msg_class(base)(), i + 1)


def value_for(ftype, i):
    m = re.fullmatch(r'sequence<([^,>]+)(?:, (\d+))?>', ftype)
    if m:
        return [scalar(m.group(1), i + k) for k in range(3 if m.group(2) is None else 2)]
    m = re.fullmatch(r'(.+)\[(\d+)\]', ftype)
    if m:
        values = [scalar(m.group(1), i + k) for k in range(int(m.group(2)))]
        return values if m.group(1) in ('octet', 'string') or '/' in m.group(1) else np.array(values)
    return scalar(ftype, i)


def fill(msg, i=0):
    for k, (name, ftype) in enumerate(msg.get_fields_and_field_types().items()):
        setattr(msg, name, value_for(ftype, i + k))
    return msg


def plain(value):
    """Any reader's message -> nested dicts/lists of Python values, for comparison."""
    if hasattr(value, 'get_fields_and_field_types'):               # rclpy: a byte field is bytes
        return {n: getattr(value, n)[0] if t == 'octet' else plain(getattr(value, n))
                for n, t in value.get_fields_and_field_types().items()}
    if hasattr(value, '__dataclass_fields__'):                      # rosbags: skip its extras
        skip = ('__msgtype__', 'structure_needs_at_least_one_member')
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)
                if f.name not in skip and not f.name.isupper()}            # constants are fields too
    if hasattr(value, '__slots__') and not isinstance(value, (bytes, str)):   # mcap_ros2
        return {n: plain(getattr(value, n)) for n in value.__slots__}
    if isinstance(value, SimpleNamespace):                         # rubber_rig's numpy decoder
        return {n: plain(v) for n, v in vars(value).items()}
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if hasattr(value, 'tolist'):
        return plain(value.tolist())
    if isinstance(value, (list, tuple)):
        flat = [plain(v) for v in value]
        if flat and all(isinstance(v, list) and len(v) == 1 for v in flat):   # rclpy byte lists
            return [v[0] for v in flat]
        return flat
    return value


@pytest.fixture(scope='module')
def recorded(tmp_path_factory):
    path = tmp_path_factory.mktemp('roundtrip') / 'all_types.mcap'
    originals = {}
    with RecordingWriter(path, metadata={'specimen': 'roundtrip'}) as writer:
        for k, type_name in enumerate(TYPES):
            msg = fill(msg_class(type_name)(), k)
            originals[type_name] = msg
            qos = [dict(history='keep_last', depth=10, reliability='reliable', durability='volatile')]
            writer.write_message(f'/obj/{type_name}', type_name, msg, log_time_ns=1_000 + k, qos=qos)
            writer.write_message(f'/cdr/{type_name}', type_name, serialize_message(msg),
                                 log_time_ns=1_000 + k)
    return path, originals


def test_type_list_is_complete():
    # every .msg in the source tree is installed and round-tripped below
    sources = sorted(p.stem for p in (Path(__file__).parents[1] / 'msg_defs' / 'msg').glob('*.msg'))
    assert [t.split('/')[-1] for t in message_types('msg_defs')] == sources
    assert len(sources) >= 13
    assert 'std_msgs/msg/Header' in TYPES and 'diagnostic_msgs/msg/DiagnosticArray' in TYPES


def test_core_encoding_is_what_rclpy_decodes(recorded):
    path, originals = recorded
    with open(path, 'rb') as f:
        reader = make_reader(f)
        data = {ch.topic: msg.data for _, ch, msg in reader.iter_messages()}
    for type_name, msg in originals.items():
        # Fast CDR pads to 4 bytes and leaves padding uninitialised: compare what rclpy decodes
        ours, theirs = data[f'/obj/{type_name}'], data[f'/cdr/{type_name}']
        assert theirs[:len(ours)][:4] == ours[:4] and len(theirs) - len(ours) in (0, 1, 2, 3), type_name
        assert deserialize_message(ours, msg_class(type_name)) == msg, type_name
        assert deserialize_message(theirs, msg_class(type_name)) == msg, type_name


def test_ros2_profile_schema_and_channel_metadata(recorded):
    path, _ = recorded
    with open(path, 'rb') as f:
        reader = make_reader(f)
        header, summary = reader.get_header(), reader.get_summary()
    assert header.profile == 'ros2'
    assert summary.statistics.message_count == 2 * len(TYPES)
    assert summary.chunk_indexes and all(c.compression == 'zstd' for c in summary.chunk_indexes)
    assert all(c.message_index_offsets for c in summary.chunk_indexes)        # message indexes present
    schemas = {s.name: s for s in summary.schemas.values()}
    assert set(schemas) == set(TYPES)
    assert all(s.encoding == 'ros2msg' for s in schemas.values())
    text = schemas['msg_defs/msg/CycleMetrics'].data.decode()
    assert text == full_definition('msg_defs/msg/CycleMetrics')
    for dep in ('MSG: std_msgs/Header', 'MSG: builtin_interfaces/Time', 'MSG: msg_defs/CycleProperties'):
        assert dep in text
    for ch in summary.channels.values():
        assert ch.message_encoding == 'cdr'
        t = summary.schemas[ch.schema_id].name
        assert ch.metadata['topic_type_hash'] == type_hash(t) and ch.metadata['topic_type_hash'].startswith('RIHS01_')
        if ch.topic.startswith('/obj/'):
            q = parse_offered_qos(ch.metadata['offered_qos_profiles'])
            assert q[0]['reliability'] == 'reliable' and q[0]['deadline'] == {'sec': 9223372036, 'nsec': 854775807}


def test_rosbags_reads_identical_values(recorded):
    path, originals = recorded
    seen = 0
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for conn, _, raw in reader.messages():
            got = reader.deserialize(raw, conn.msgtype)
            type_name = conn.topic.split('/', 2)[2]
            assert plain(got) == plain(originals[type_name]), conn.topic
            seen += 1
    assert seen == 2 * len(TYPES)


def test_mcap_reader_reads_identical_values(recorded):
    path, originals = recorded
    seen = 0
    with open(path, 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, _, decoded in reader.iter_decoded_messages():
            expected = plain(originals[schema.name])
            got = plain(decoded)
            if schema.name == 'std_msgs/msg/Empty':
                got = {}                         # the decoder shows no field; CDR has one pad byte
            assert got == expected, channel.topic
            seen += 1
    assert seen == 2 * len(TYPES)


def test_numpy_cdr_decoder_matches_mcap_ros2(recorded):
    """The reader's fast decoder gives the same values as mcap_ros2's reference decoder."""
    from rubber_rig.recording.cdr import make_decoder
    from rubber_rig.recording.mcap_compat import reference_decoder
    path, originals = recorded
    with open(path, 'rb') as f:
        for schema, channel, msg in make_reader(f).iter_messages():
            text = schema.data.decode()
            fast = make_decoder(schema.name, text)
            assert fast is not None, schema.name
            reference = reference_decoder(schema)(msg.data)
            assert plain(fast(msg.data)) == plain(reference), channel.topic
            assert plain(fast(msg.data)) == plain(originals[schema.name]) or schema.name == 'std_msgs/msg/Empty'


def test_the_writer_split_keeps_import_paths_and_the_metadata_codec_round_trips():
    """encode_metadata and the record names moved to recording.metadata; writer and mcapio still export them."""
    from rubber_rig.recording import mcapio, writer
    from rubber_rig.recording.metadata import decode_metadata, encode_metadata
    assert writer.encode_metadata is encode_metadata and mcapio.decode_metadata is decode_metadata
    assert (writer.METADATA_NAME, writer.CLOSE_METADATA_NAME, writer.SEQUENCE_SOURCE_KEY) == \
        ('rubber_rig', 'rubber_rig.close', 'rubber_rig.sequence')
    batch = msg_class('msg_defs/msg/SetpointBatch')(first_sequence=3, displacement=[1e-3, 2e-3])
    encoded = encode_metadata({'specimen': 'B-7', 'temperature': 23.5, 'limits': np.array([1.0, 2.0]),
                               'batch': batch})
    assert all(isinstance(v, str) for v in encoded.values())
    decoded = decode_metadata(encoded)
    assert (decoded['specimen'], decoded['temperature'], decoded['limits']) == ('B-7', 23.5, [1.0, 2.0])
    assert decoded['batch']['first_sequence'] == 3 and decoded['batch']['displacement'] == [1e-3, 2e-3]
