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

"""rosbag2 bag metadata (version 9) for our recordings, so rosbag2 and rosbags treat a recording
directory of split files as one bag (`ros2 bag info/play DIR`, rosbags' rosbag2.Reader).

- ``metadata.yaml`` in the recording directory, rebuilt from the files' MCAP summaries (at stop, at
  each split, and by ``recover`` when it sits next to a recovered file);
- a ``rosbag2`` metadata record (key ``serialized_metadata``) in every closed file, as rosbag2's MCAP
  storage writes it.
"""
from pathlib import Path

import yaml
from mcap.reader import make_reader

from .mcapio import check_file, recording_files
from .qos import parse_offered_qos

VERSION = 9
METADATA_FILE = 'metadata.yaml'


def make_bag_info(files, topics, custom_data: dict = None) -> dict:
    """files: [{'path', 'start_ns', 'end_ns', 'count'}]; topics: [{'name', 'type', 'qos', 'hash', 'count'}];
    custom_data: rosbag2's map of strings (ours: the parts of a split recording, see parts.PARTS_KEY).
    """
    starts = [f['start_ns'] for f in files if f['count']]
    ends = [f['end_ns'] for f in files if f['count']]
    start = min(starts) if starts else 0
    return {
        'version': VERSION,
        'storage_identifier': 'mcap',
        'duration': {'nanoseconds': (max(ends) - start) if ends else 0},
        'starting_time': {'nanoseconds_since_epoch': start},
        'message_count': sum(f['count'] for f in files),
        'topics_with_message_count': [{
            'topic_metadata': {'name': t['name'], 'type': t['type'], 'serialization_format': 'cdr',
                               'offered_qos_profiles': parse_offered_qos(t['qos']),
                               'type_description_hash': t['hash']},
            'message_count': t['count']} for t in topics],
        'compression_format': '',
        'compression_mode': '',
        'relative_file_paths': [Path(f['path']).name for f in files],
        'files': [{'path': Path(f['path']).name,
                   'starting_time': {'nanoseconds_since_epoch': f['start_ns'] if f['count'] else 0},
                   'duration': {'nanoseconds': (f['end_ns'] - f['start_ns']) if f['count'] else 0},
                   'message_count': f['count']} for f in files],
        'custom_data': {str(k): str(v) for k, v in custom_data.items()} if custom_data else None,
        'ros_distro': 'jazzy',
    }


def dump(info: dict) -> str:
    return yaml.safe_dump(info, default_flow_style=False, sort_keys=False)


def file_summary(path: Path):
    """(file entry, {topic: topic entry}) from an MCAP file's summary; None if it has none."""
    with open(path, 'rb') as f:
        summary = make_reader(f).get_summary()
    if summary is None or summary.statistics is None:
        return None
    st = summary.statistics
    topics = {}
    for cid, ch in summary.channels.items():
        schema = summary.schemas.get(ch.schema_id)
        t = topics.setdefault(ch.topic, {'name': ch.topic, 'type': schema.name if schema else '',
                                         'qos': ch.metadata.get('offered_qos_profiles', ''),
                                         'hash': ch.metadata.get('topic_type_hash', ''), 'count': 0})
        t['count'] += st.channel_message_counts.get(cid, 0)
    entry = {'path': str(path), 'start_ns': st.message_start_time, 'end_ns': st.message_end_time,
             'count': st.message_count}
    return entry, topics


def read_custom_data(directory) -> dict:
    """The custom_data of ``directory/metadata.yaml`` ({} if there is none, or it cannot be read)."""
    try:
        info = yaml.safe_load((Path(directory) / METADATA_FILE).read_text(encoding='utf-8'))
        data = info['rosbag2_bagfile_information'].get('custom_data') or {}
    except (OSError, ValueError, KeyError, TypeError, AttributeError, yaml.YAMLError):
        return {}
    return {str(k): str(v) for k, v in data.items()} if isinstance(data, dict) else {}


def write_bag_metadata(directory, files=None, summaries: dict = None, custom_data: dict = None) -> Path:
    """Write ``directory/metadata.yaml`` for its complete .mcap files (in split order).

    ``summaries``: {Path: file_summary(path)} of closed files read before; a complete file not in it
    is read and added (the Recorder keeps one, so each split reads only the file just closed).
    ``custom_data``: rosbag2's custom_data (the recorder's list of parts); None keeps what the file had (a
    rewrite by ``recover`` must not forget the parts of the recording, missing ones included).
    """
    directory = Path(directory)
    if custom_data is None:
        custom_data = read_custom_data(directory)
    files = recording_files(directory) if files is None else [Path(f) for f in files]
    entries, topics = [], {}
    for f in files:
        if summaries is not None and f in summaries:
            summary = summaries[f]
        else:
            if not f.exists() or not check_file(f):
                continue                     # killed mid-file: recover it first
            summary = file_summary(f)
            if summaries is not None:
                summaries[f] = summary
        if summary is None:
            continue
        entry, file_topics = summary
        entries.append(entry)
        for name, t in file_topics.items():
            if name in topics:
                topics[name]['count'] += t['count']
            else:
                topics[name] = dict(t)
    target = directory / METADATA_FILE
    tmp = target.with_suffix('.yaml.tmp')
    tmp.write_text(dump({'rosbag2_bagfile_information': make_bag_info(entries, list(topics.values()),
                                                                      custom_data)}))
    tmp.replace(target)
    return target
