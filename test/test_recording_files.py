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

"""Recording files without ROS: splits, loss accounting, snapshots, crashes, full disks, bad files.

Files are checked with independent readers (the mcap library's reader; rosbags in the round-trip and
node tests); processes are really killed and file sizes really limited by the OS (RLIMIT_FSIZE).
"""
import json
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.writer import Writer as Ros2Writer

from rubber_rig.cli.main import main as cli
from rubber_rig.recording import (
    Recorder,
    RecordingError,
    RecordingWriteError,
    RecordingWriter,
    full_definition,
    load_recording,
    recover,
)

from support.recording import BATCH_T, DT, N, batch, stream

REPO = Path(__file__).resolve().parents[1]


def raw_messages(files):
    """Every message of the files as (topic, log_time, data), read by the mcap library."""
    out = []
    for f in files:
        with open(f, 'rb') as fh:
            for _, ch, m in make_reader(fh).iter_messages(log_time_order=False):
                out.append((ch.topic, m.log_time, m.data))
    return out


def record(tmp, name, **kw):
    rec = Recorder(tmp, metadata={'specimen': 'pad-3'}, **kw)
    rec.start(tmp / name)
    for topic, t, msg, log in stream():
        assert rec.write(topic, t, msg, log)
    return rec, rec.stop()


def test_split_by_size_and_duration_union_equals_unsplit(tmp_path):
    _, whole = record(tmp_path, 'whole')
    _, by_size = record(tmp_path, 'size', split_size_bytes=40_000)
    _, by_time = record(tmp_path, 'time', split_duration_s=1.5)
    assert len(whole) == 1 and len(by_size) >= 3 and len(by_time) == 4    # 6 s in 1.5 s files
    reference = raw_messages(whole)
    assert len(reference) == 306
    for files in (by_size, by_time):
        assert raw_messages(files) == reference                           # nothing lost or duplicated
        parts = [raw_messages([f]) for f in files]
        assert all(parts) and sum(map(len, parts)) == len(reference)
    for f in by_size[:-1]:
        assert f.stat().st_size < 40_000 + 16_000                          # size limit +- one chunk
    a, b = load_recording(whole[0].parent), load_recording(by_size[0].parent)
    for name in ('time', 'displacement', 'force', 'setpoint', 'temperature', 'status', 'sequence'):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert len(a) == 300 * N and a.samples_lost == 0
    assert b.metadata['specimen'] == 'pad-3' and len(b.closing) == len(by_size)


def test_gaps_and_unwritable_messages_are_counted_and_reported_at_close(tmp_path):
    rec = Recorder(tmp_path, split_duration_s=0.1)
    rec.start(tmp_path / 'gappy')
    log = 1_000_000_000
    firsts = [0, 20, 40, 75, 95, 115, 10, 30]          # gap of 15 after 40, then a restart at 10
    for k, first in enumerate(firsts):
        assert rec.write('/rig/samples', BATCH_T, batch(k, first), log + k * 60_000_000)
    assert not rec.write('/rig/x', 'no_such_pkg/msg/Thing', {'a': 1}, log)           # unknown type
    assert not rec.write('/rig/samples', BATCH_T, dict(batch(9), force='abc'), log)  # cannot encode
    stats = rec.stats()
    assert stats['sequence_gaps'] == 1 and stats['samples_lost'] == 15 and stats['sequence_restarts'] == 1
    assert stats['messages_dropped'] == 2
    files = rec.stop()
    assert len(files) == 4                                   # the gap at batch 3 spans a split
    r = load_recording(files[0].parent)
    closing = r.closing
    assert sum(c['samples_lost'] for c in closing) == 15
    assert sum(c['messages_dropped'] for c in closing) == 2
    dropped = {}
    for c in closing:
        for reason, n in c['dropped_by_reason'].items():
            dropped[reason] = dropped.get(reason, 0) + n
    assert dropped == {'unknown_type': 1, 'encode_error': 1}
    assert closing[-1]['total_samples_lost'] == 15
    assert r.samples_lost == 15 and [g['expected'] for g in r.gaps] == [60]   # from the data itself


def test_snapshot_keeps_the_last_seconds(tmp_path):
    rec = Recorder(tmp_path, snapshot_duration_s=0.5)
    for topic, t, msg, log in stream(100):                  # 2 s of data, not recording
        assert not rec.write(topic, t, msg, log)
    path = rec.snapshot(tmp_path / 'snap.mcap')
    r = load_recording(path)
    assert r.metadata['snapshot'] == 'true'
    # batches whose log time is within 0.5 s of the newest: 0.5 s / 20 ms + 1
    assert r.topics['/rig/samples']['count'] == 26
    assert r.sequence[-1] == 100 * N - 1 and r.sequence[0] == 74 * N


CHILD = textwrap.dedent('''
    import sys, time, numpy as np
    sys.path.insert(0, {test_dir!r})
    from support.recording import stream
    from rubber_rig.recording import Recorder
    rec = Recorder({out!r}, flush_interval_s=0, chunk_size=1 << 24)
    rec.start({out!r} + '/killed')
    msgs = stream(200)
    for i, (topic, t, msg, log) in enumerate(msgs):
        rec.write(topic, t, msg, log)
        if i == 149:
            rec.flush()
            print('FLUSHED', i + 1, flush=True)
    print('WRITTEN', len(msgs), rec.stats()['messages_flushed_current_file'], flush=True)
    time.sleep(600)             # the test kills this writer mid-file
''')


def test_sigkilled_writer_leaves_a_recoverable_file(tmp_path):
    code = CHILD.format(test_dir=str(Path(__file__).parent), out=str(tmp_path))
    child = subprocess.Popen([sys.executable, '-c', code], stdout=subprocess.PIPE, text=True, cwd=REPO)
    try:
        assert child.stdout.readline().split() == ['FLUSHED', '150']
        assert child.stdout.readline().split() == ['WRITTEN', '204', '150']
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
    path = tmp_path / 'killed' / 'killed_0.mcap'
    with pytest.raises(RecordingError, match='truncated.*rubber-rig recover'):
        load_recording(path)
    assert cli(['recover', str(path)]) == 0
    fixed = path.with_name('killed_0.recovered.mcap')
    recovered = raw_messages([fixed])
    assert len(recovered) == 150                      # every flushed message, nothing invented
    msgs = stream(200)[:150]
    r = load_recording(fixed)
    np.testing.assert_array_equal(
        r.force, np.concatenate([m[2]['force'] for m in msgs if m[0] == '/rig/samples']))
    assert r.metadata['recording'] == 'killed' and r.other_metadata['rubber_rig.recovered']
    assert load_recording(path.parent).files == [str(fixed)]   # the recovered file stands in
    with pytest.raises(RecordingError, match='exists already'):
        recover(path)                                  # never overwrites an earlier recovery
    # in place, keeping a backup
    result = recover(path, in_place=True)
    assert result.messages == 150 and Path(str(path) + '.bak').exists()
    assert len(load_recording(path)) == len(r)


FULL = textwrap.dedent('''
    import json, resource, signal, sys
    sys.path.insert(0, {test_dir!r})
    from support.recording import stream
    from rubber_rig.recording import Recorder
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)           # get EFBIG instead of being killed
    resource.setrlimit(resource.RLIMIT_FSIZE, (60_000, 60_000))
    rec = Recorder({out!r}, flush_interval_s=0.2)
    rec.start({out!r} + '/full')
    msgs = stream(600)
    accepted = sum(rec.write(*m[:2], m[2], m[3]) for m in msgs)
    print(json.dumps(dict(rec.stats(), accepted=accepted, total=len(msgs), files=[str(f) for f in rec.files],
                          reports=rec.reports)))
''')


def test_full_disk_stops_cleanly_and_keeps_what_was_written(tmp_path):
    code = FULL.format(test_dir=str(Path(__file__).parent), out=str(tmp_path))
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, cwd=REPO,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    stats = json.loads(out.stdout)
    assert not stats['recording'] and 'file too large' in stats['error']
    assert 'rubber-rig recover' in stats['error']
    # the message whose write failed is 'write_error'; all later ones 'not recorded after error'
    assert stats['not_recorded_after_error'] == stats['total'] - stats['accepted'] - 1 > 0
    path = Path(stats['files'][0])
    assert path.stat().st_size <= 60_000
    result = recover(path, tmp_path / 'fixed.mcap')
    lost_in_chunk = stats['messages_dropped'] - stats['not_recorded_after_error']
    assert result.messages > 0
    assert result.messages + lost_in_chunk == stats['accepted'] + 1      # every message accounted for
    r = load_recording(tmp_path / 'fixed.mcap')
    assert r.samples_lost == 0 and len(r) == N * r.topics['/rig/samples']['count']


def test_unwritable_path_gives_a_clear_error(tmp_path):
    blocker = tmp_path / 'a_file'
    blocker.write_text('x')
    with pytest.raises(RecordingWriteError, match='cannot create recording directory .*a_file/sub'):
        Recorder(tmp_path).start(blocker / 'sub')
    with pytest.raises(RecordingWriteError, match='cannot create recording .*missing/x.mcap: No such file'):
        RecordingWriter(tmp_path / 'missing' / 'x.mcap')
    existing = tmp_path / 'exists.mcap'
    existing.write_bytes(b'keep me')
    with pytest.raises(RecordingWriteError, match='File exists'):
        RecordingWriter(existing)                      # never overwrites a recording silently
    assert existing.read_bytes() == b'keep me'


@pytest.fixture(scope='module')
def good_file(tmp_path_factory):
    path = tmp_path_factory.mktemp('good') / 'good.mcap'
    with RecordingWriter(path, flush_interval_s=0.1) as w:
        for topic, t, msg, log in stream(100):
            w.write_message(topic, t, msg, log)
    return path


def test_truncated_and_malformed_files_give_clear_errors(tmp_path, good_file, capsys):
    data = good_file.read_bytes()
    cases = {'empty.mcap': (b'', 'not an MCAP file \\(empty file\\)'),
             'text.mcap': (b'hello world, not mcap' * 10, 'not an MCAP file \\(bad magic'),
             'header_only.mcap': (data[:40], 'truncated'),
             'half.mcap': (data[:len(data) // 2], 'truncated'),
             'no_magic_end.mcap': (data[:-3], 'truncated')}
    for name, (content, pattern) in cases.items():
        p = tmp_path / name
        p.write_bytes(content)
        with pytest.raises(RecordingError, match=pattern):
            load_recording(p)
    with pytest.raises(RecordingError, match='no such file'):
        load_recording(tmp_path / 'nothing.mcap')
    # a flipped byte inside the first chunk: checksum error, named
    with open(good_file, 'rb') as f:
        chunk = make_reader(f).get_summary().chunk_indexes[0]
    bad = bytearray(data)
    bad[chunk.chunk_start_offset + chunk.chunk_length // 2] ^= 0xFF
    p = tmp_path / 'corrupt.mcap'
    p.write_bytes(bytes(bad))
    with pytest.raises(RecordingError, match='corrupt|malformed'):
        load_recording(p)
    # every truncation point is either read (prefix, with allow_truncated) or refused clearly
    full = len(raw_messages([good_file]))
    for cut in range(0, len(data), max(1, len(data) // 40)):
        p = tmp_path / 'cut.mcap'
        p.write_bytes(data[:cut])
        with pytest.raises(RecordingError):
            load_recording(p)
        if cut >= 8:
            r = load_recording(p, allow_truncated=True)
            assert sum(v['count'] for v in r.topics.values()) <= full
    assert cli(['info', str(tmp_path / 'text.mcap')]) == 2
    assert 'not an MCAP file' in capsys.readouterr().err


def lists(msg):
    return {k: v.tolist() if hasattr(v, 'tolist') else v for k, v in msg.items()}


def test_reader_on_a_plain_ros2_profile_file(tmp_path):
    """A file like `ros2 bag record` writes: ros2 profile only, no rubber_rig metadata."""
    path = tmp_path / 'rosbag2.mcap'
    with open(path, 'wb') as f:
        w = Ros2Writer(f)
        schemas = {t: w.register_msgdef(t, full_definition(t).replace('MSG: std_msgs/Header',
                                                                      'MSG: std_msgs/msg/Header'))
                   for t in (BATCH_T, 'msg_defs/msg/ModelPrediction', 'msg_defs/msg/SetpointBatch',
                             'std_msgs/msg/String', 'msg_defs/msg/ModelParameters')}
        w.write_message('/program', schemas['std_msgs/msg/String'], {'data': 'blocks: []'}, 10**9)
        w.write_message('/model_parameters', schemas['msg_defs/msg/ModelParameters'], {
            'model_name': 'seed000', 'parameter_set': 'seed000_20C', 'temperature': 20.0,
            'names': ['k0', 'alpha'], 'values': [1e6, 0.4]}, 10**9)
        for k in range(10):
            t = 10**9 + k * 20_000_000
            b = batch(k)
            w.write_message('/samples', schemas[BATCH_T], lists(b), t)
            if k < 8:                                  # prediction missing for the last 2 batches
                w.write_message('/prediction', schemas['msg_defs/msg/ModelPrediction'], {
                    'header': b['header'], 'first_sequence': b['first_sequence'], 'sample_period': DT,
                    'displacement': list(b['displacement']), 'measured_force': list(b['force']),
                    'predicted_force': list(b['force'] * 0.9), 'residual': list(b['force'] * 0.1),
                    'branches': []}, t)
            w.write_message('/setpoints', schemas['msg_defs/msg/SetpointBatch'], {
                'first_sequence': k * N, 'sample_period': DT, 'displacement': list(b['setpoint']),
                'block_index': k // 5}, t)
        w.add_metadata('rosbag2', {'serialized_metadata': 'version: 9'})
        w.finish()
    r = load_recording(path)
    assert r.closing == [] and r.other_metadata['rosbag2']
    # no rubber_rig record: what fitting needs comes from the latched topics
    assert r.metadata == {'test_program': 'blocks: []', 'model': 'seed000', 'parameter_set': 'seed000_20C',
                          'model_temperature': 20.0, 'model_parameters': {'k0': 1e6, 'alpha': 0.4}}
    assert len(r) == 200 and r.samples_lost == 0
    force = np.concatenate([batch(k)['force'] for k in range(10)])
    np.testing.assert_array_equal(r.force, force)
    np.testing.assert_array_equal(r.prediction[:160], force[:160] * 0.9)
    np.testing.assert_array_equal(r.residual[:160], force[:160] * 0.1)
    assert np.isnan(r.prediction[160:]).all()
    np.testing.assert_array_equal(r.block_index, np.repeat([0, 1], 100))
    np.testing.assert_allclose(r.time, np.arange(200) * DT, atol=1e-12)
    assert r.sample_period == DT and r.temperature[-1] == 23.009 and r.status[-1] == 1


def test_info_command_shows_topics_counts_metadata_and_gaps(tmp_path, capsys):
    path = tmp_path / 'info.mcap'
    with RecordingWriter(path, metadata={'specimen': 'arm-joint 4', 'model_parameters': {'k0': 1e6}}) as w:
        for k, first in enumerate([0, 20, 50]):
            w.write_message('/rig/samples', BATCH_T, batch(k, first), 10**9 + k)
    assert cli(['info', str(path)]) == 0
    out = capsys.readouterr().out
    assert '/rig/samples' in out and 'msg_defs/msg/RigSampleBatch' in out and '3 msgs' in out
    assert '1 sequence gaps, 10 samples lost' in out and 'arm-joint 4' in out
    assert cli(['info', '--json', str(path)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info['metadata']['model_parameters'] == {'k0': 1e6} and info['samples'] == 60


def test_split_recording_is_one_rosbag2_bag_for_rosbags(tmp_path):
    """metadata.yaml (rosbag2 v9) lets rosbags' rosbag2 reader open the directory of split files."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import Reader as Rosbag2Reader
    from rosbags.typesys import Stores, get_typestore

    _, files = record(tmp_path, 'bag', split_size_bytes=40_000)
    bag = files[0].parent
    assert (bag / 'metadata.yaml').exists() and len(files) >= 3
    reference = raw_messages(files)
    with Rosbag2Reader(bag) as reader:
        assert reader.message_count == len(reference) == 306
        assert {c.topic: c.msgcount for c in reader.connections} == {'/rig/samples': 300, '/rig/status': 6}
        got = [(c.topic, t, bytes(d)) for c, t, d in reader.messages()]
    assert sorted(got) == sorted(reference)                    # same messages, same bytes
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        conn = [c for c in reader.connections if c.topic == '/rig/samples']
        seqs = [reader.deserialize(d, c.msgtype).first_sequence for c, _, d in reader.messages(connections=conn)]
    assert seqs == [k * N for k in range(300)]
    # every closed file carries rosbag2's own metadata record
    with open(files[0], 'rb') as f:
        names = [m.name for m in make_reader(f).iter_metadata()]
    assert names == ['rubber_rig', 'rubber_rig.close', 'rosbag2']


def test_core_works_without_rclpy(tmp_path):
    """Writing, reading and recovering never import rclpy (fitting and offline tools run without ROS)."""
    code = textwrap.dedent(f'''
        import sys
        from rubber_rig.recording import RecordingWriter, load_recording, recover
        with RecordingWriter({str(tmp_path / 'norclpy.mcap')!r}, metadata={{'specimen': 'x'}}) as w:
            w.write_message('/rig/status', 'msg_defs/msg/RigStatus', {{'state_name': 'idle'}}, 1)
        empty = RecordingWriter({str(tmp_path / 'empty.mcap')!r}); empty.close()
        r, e = load_recording({str(tmp_path / 'norclpy.mcap')!r}), load_recording({str(tmp_path / 'empty.mcap')!r})
        assert r.messages['/rig/status'][0][1].state_name == 'idle' and len(r) == 0 and len(e) == 0
        assert e.duration == 0 and e.topics == {{}}
        print('rclpy' in sys.modules)
    ''')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, cwd=REPO, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == 'False'


def test_a_restarted_publisher_matched_late_counts_what_it_published_before():
    """A restarted rig numbers its samples from 0; if its first message to reach the recorder is not its first
    publication, the samples it numbered before were published unseen: lost, not a silent restart."""
    from rubber_rig.recording.gaps import GapTracker
    g = GapTracker()
    for k in range(3):
        g.observe('/s', k * 50, 50, publication_sequence=k + 1)
    on_time = g.observe('/s', 0, 50, publication_sequence=1)            # new driver, matched from its start
    assert on_time['kind'] == 'restart' and on_time['lost'] == 0 and g.samples_lost == 0
    g.observe('/s', 50, 100, publication_sequence=2)                    # expected next: 150
    late = g.observe('/s', 120, 30, publication_sequence=6)             # another new driver, matched 5 messages late
    assert late['kind'] == 'gap' and late['restart'] and late['lost'] == 120
    assert g.samples_lost == 120 and g.restarts == 2
