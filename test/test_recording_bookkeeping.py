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

"""A recording's bookkeeping (who, what specimen, messages written and dropped, loss) survives a conversion by a
rosbag2-compatible tool: rosbags-convert (MCAP -> sqlite3 -> MCAP) drops MCAP metadata records, so the writer
also writes them as a message (std_msgs/String on <namespace>/recording_info), and the reader falls back to it.
"""
import json
import subprocess
import sys
from pathlib import Path

from mcap.reader import make_reader

from rubber_rig.recording import RecordingWriter, load_recording

from support.recording import BATCH_T, batch

CONVERT = Path(sys.executable).parent / 'rosbags-convert'
META = {'operator': 'A. Tester', 'specimen': 'B-7', 'namespace': '/rig1', 'node': '/rig1/recorder'}


def write(path, lost_batch=None):
    with RecordingWriter(path, dict(META), bookkeeping_topic='/rig1/recording_info') as w:
        for k in range(100):
            if k == lost_batch:
                continue
            w.write_message('/rig1/samples', BATCH_T, batch(k), 1_700_000_000_000_000_000 + k * 20_000_000,
                            sequence=k + 1)
    return path


def test_the_bookkeeping_is_also_a_message_with_the_close_records_values(tmp_path):
    path = write(tmp_path / 'run.mcap', lost_batch=40)
    with open(path, 'rb') as f:
        reader = make_reader(f)
        records = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        [(schema, channel, message)] = [x for x in reader.iter_messages(topics=['/rig1/recording_info'])]
    assert schema.name == 'std_msgs/msg/String'
    rec = load_recording(path)
    text = rec.messages['/rig1/recording_info'][0][1].data
    carried = json.loads(text)
    assert carried['rubber_rig']['operator'] == 'A. Tester' == records['rubber_rig']['operator']
    close = carried['rubber_rig.close']
    assert close['messages_written'] == 99 and close['samples_lost'] == 20 == rec.samples_lost
    assert rec.closing[0]['messages_written'] == 99


def test_the_bookkeeping_survives_rosbags_convert_to_sqlite3_and_back(tmp_path):
    path = write(tmp_path / 'run.mcap', lost_batch=40)
    original = load_recording(path)
    sqlite = tmp_path / 'as_sqlite3'
    back = tmp_path / 'back'
    for src, dst, storage in ((path, sqlite, 'sqlite3'), (sqlite, back, 'mcap')):
        out = subprocess.run([str(CONVERT), '--src', str(src), '--dst', str(dst), '--dst-storage', storage],
                             capture_output=True, text=True, timeout=120)
        assert out.returncode == 0, out.stderr
    [converted] = sorted(back.glob('*.mcap'))
    with open(converted, 'rb') as f:
        names = {m.name for m in make_reader(f).iter_metadata()}
    assert 'rubber_rig' not in names and 'rubber_rig.close' not in names     # the tool dropped the records
    rec = load_recording(converted)
    assert rec.metadata['operator'] == 'A. Tester' and rec.metadata['specimen'] == 'B-7'
    assert rec.closing and rec.closing[0]['messages_written'] == original.closing[0]['messages_written'] == 99
    assert rec.closing[0]['samples_lost'] == original.closing[0]['samples_lost'] == 20
    assert rec.samples_lost == original.samples_lost
