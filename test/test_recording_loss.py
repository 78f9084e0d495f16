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

"""One loss ledger: the recorder's own bookkeeping (live stats and close record), ``rubber-rig info``,
``recover`` and the bench summary count lost samples the same way and agree to the sample; ``recover`` refuses a
corrupt file (naming the record and its offset) and recovers the readable part of a truncated one.

The files are written by the project's Recorder (no ROS), killed for real (SIGKILL), cut and corrupted byte by
byte; the numbers are checked against the truth the test run was built with (support.recording.loss_run) and
the messages against the mcap library's own reader.
"""
import json
import signal
import struct
import subprocess
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from rubber_rig.cli.main import main as cli
from rubber_rig.recording import Recorder, RecordingError, RecordingWriter, load_recording, recover
from rubber_rig.recording.gaps import (
    BATCH,
    MAX_EVENTS,
    RESTART,
    SAMPLE,
    STRAY,
    LossLedger,
    StrayOrRestart,
    StreamOrder,
    sample_topic,
    stray_or_restart,
)
from rubber_rig.recording.loss import recording_loss

from support.recording import BATCH_T, RUN_TOTALS, N, batch, loss_run

REPO = Path(__file__).resolve().parents[1]
KEYS = tuple(RUN_TOTALS)


def ledger(counts: dict) -> dict:
    return {key: counts[key] for key in KEYS}


def write_run(tmp: Path, name: str, messages, **kw):
    """The run recorded by the project's Recorder; (its live stats before stop, the file)."""
    rec = Recorder(tmp, **kw)
    rec.start(tmp / name)
    for topic, msg_type, msg, log, pub in messages:
        assert rec.write(topic, msg_type, msg, log, log, pub)
    stats = rec.stats()
    [path] = rec.stop()
    return stats, path


def independent(path: Path):
    """(messages as (topic, log_time, sequence), recorded sample sequences) read by the mcap library."""
    messages, seqs = [], []
    with open(path, 'rb') as f:
        for schema, channel, message, decoded in make_reader(f, decoder_factories=[DecoderFactory()]) \
                .iter_decoded_messages(log_time_order=False):
            messages.append((channel.topic, message.log_time, message.sequence))
            if schema.name == BATCH:
                seqs.extend(range(decoded.first_sequence, decoded.first_sequence + len(decoded.displacement)))
    return messages, seqs


def info_json(path, capsys) -> dict:
    assert cli(['info', '--json', str(path)]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.fixture(scope='module')
def run_file(tmp_path_factory):
    """The run, recorded to completion in chunks of 32 KiB: (messages, truth, published, live stats, file)."""
    messages, truth, published = loss_run()
    stats, path = write_run(tmp_path_factory.mktemp('run'), 'run', messages, chunk_size=32 << 10,
                            flush_interval_s=0)
    return messages, truth, published, stats, path


def test_recorder_info_recover_and_the_mcap_reader_agree_to_the_sample(run_file, tmp_path, capsys):
    """The run that once disagreed: setpoint streams that start again below their last number (a resumed hold, a
    second excitation, a restarted driver) and predictions that skip and repeat batches used to be counted as
    millions of lost samples by recover and by the recorder, but not by info. They are not samples."""
    messages, truth, published, stats, path = run_file
    assert ledger(stats) == RUN_TOTALS and stats['samples_lost_total'] == RUN_TOTALS['samples_lost']
    assert stats['sample_topic'] == '/rig/samples'
    r = load_recording(path)
    [close] = r.closing
    assert ledger(close) == RUN_TOTALS and close['total_samples_lost'] == RUN_TOTALS['samples_lost']
    assert close['total_sequence_gaps'] == RUN_TOTALS['sequence_gaps']
    assert ledger(r.loss) == RUN_TOTALS and r.samples_lost == 107 and r.sequence_gaps == len(r.gaps) == 3
    assert [(g['expected'], g['received'], g['lost']) for g in r.gaps] == [
        (3_500_800, 3_500_840, 40), (3_501_200, 3_501_207, 7), (3_503_107, 60, 60)]
    info = info_json(path, capsys)
    assert ledger(info['loss']) == RUN_TOTALS
    assert (info['sequence_gaps'], info['samples_lost']) == (3, 107)
    # recover of the complete file: a copy, with the same count; and info of the copy
    result = recover(path, tmp_path / 'copy.mcap')
    assert result.was_complete and not result.summary_error and result.messages == len(messages)
    assert ledger(result.loss) == RUN_TOTALS and (result.sequence_gaps, result.samples_lost) == (3, 107)
    assert ledger(info_json(tmp_path / 'copy.mcap', capsys)['loss']) == RUN_TOTALS
    # the truth, read by the mcap library: every published sample that is not in the file, plus the driver's
    # bus loss (never published), is the ledger's loss; the jump of 700 samples is not in it
    got, recorded = independent(path)
    assert got == [(t, log, pub) for t, _, _, log, pub in messages]
    assert len(recorded) == len(set(recorded))
    assert len(set(published) - set(recorded)) + RUN_TOTALS['frames_lost'] == RUN_TOTALS['samples_lost']
    assert independent(tmp_path / 'copy.mcap')[0] == got
    # the recorded setpoint and prediction streams are still complete messages
    assert r.topics['/rig/setpoints']['count'] == sum(m[0] == '/rig/setpoints' for m in messages)


KILLED = textwrap.dedent('''
    import json, sys, time
    sys.path.insert(0, {test_dir!r})
    from support.recording import loss_run
    from rubber_rig.recording import Recorder
    messages, _, _ = loss_run()
    rec = Recorder({out!r}, flush_interval_s=0, chunk_size=1 << 24)
    rec.start({out!r} + '/killed')
    for i, (topic, msg_type, msg, log, pub) in enumerate(messages):
        rec.write(topic, msg_type, msg, log, log, pub)
        if i + 1 == {flush_at}:
            rec.flush()
            print(json.dumps(rec.stats()), flush=True)
    print('WRITTEN', flush=True)
    time.sleep(600)             # the test kills this recorder mid-file
''')


@pytest.mark.parametrize('flush_at', [300, 430])
def test_a_killed_recorder_recover_and_info_count_what_the_recorder_counted(tmp_path, capsys, flush_at):
    """SIGKILL after a flush: the file holds the first ``flush_at`` messages; the recorder's count at that flush,
    info of the killed file, recover and info of the recovered file are the same numbers, and those of the truth
    (at 300 the driver restart is not in the file yet)."""
    messages, truth, _ = loss_run()
    code = KILLED.format(test_dir=str(Path(__file__).parent), out=str(tmp_path), flush_at=flush_at)
    child = subprocess.Popen([sys.executable, '-c', code], stdout=subprocess.PIPE, text=True, cwd=REPO)
    try:
        at_flush = json.loads(child.stdout.readline())
        assert child.stdout.readline().strip() == 'WRITTEN'
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
    expected = truth[flush_at - 1]
    assert expected != RUN_TOTALS if flush_at == 300 else expected == RUN_TOTALS
    assert ledger(at_flush) == expected and at_flush['messages_flushed_current_file'] == flush_at
    path = tmp_path / 'killed' / 'killed_0.mcap'
    r = load_recording(path, allow_truncated=True)
    assert r.tail_unaccounted and ledger(r.loss) == expected
    assert cli(['recover', str(path)]) == 0
    out = capsys.readouterr().out
    assert 'was truncated' in out and 'unaccounted' in out
    assert f"{expected['samples_lost']} samples lost in {expected['sequence_gaps']} sequence gaps" in out
    fixed = path.with_name('killed_0.recovered.mcap')
    assert ledger(info_json(fixed, capsys)['loss']) == expected
    got, _ = independent(fixed)
    assert got == [(t, log, pub) for t, _, _, log, pub in messages[:flush_at]]
    recovered = load_recording(fixed).other_metadata['rubber_rig.recovered']
    assert (int(recovered['samples_lost']), int(recovered['sequence_gaps'])) == \
        (expected['samples_lost'], expected['sequence_gaps'])


def test_truncated_at_every_kind_of_offset_recover_and_info_agree(run_file, tmp_path):
    """Cut at chunk starts, inside chunk headers and data, at chunk ends and in the summary: info reads the intact
    prefix, recover copies exactly it, and both count the loss of that prefix as it truly is."""
    messages, truth, _, _, path = run_file
    data = path.read_bytes()
    with open(path, 'rb') as f:
        summary = make_reader(f).get_summary()
    chunks = sorted((c.chunk_start_offset, c.chunk_length) for c in summary.chunk_indexes)
    assert len(chunks) >= 5
    cuts = {len(data) - 1, len(data) - 40, (chunks[-1][0] + chunks[-1][1] + len(data)) // 2}
    for start, length in chunks:
        cuts.update({start, start + 5, start + 30, start + length // 2, start + length - 1, start + length})
    seen = set()
    for cut in sorted(cuts):
        p = tmp_path / f'cut{cut}.mcap'
        p.write_bytes(data[:cut])
        r = load_recording(p, allow_truncated=True)
        result = recover(p, tmp_path / f'fixed{cut}.mcap')
        got, _ = independent(tmp_path / f'fixed{cut}.mcap')
        m = len(got)
        assert got == [(t, log, pub) for t, _, _, log, pub in messages[:m]], cut   # a prefix, nothing invented
        expected = truth[m - 1] if m else dict.fromkeys(KEYS, 0)
        assert not result.was_complete and result.messages == m, cut
        assert ledger(result.loss) == ledger(r.loss) == expected, cut
        assert ledger(load_recording(tmp_path / f'fixed{cut}.mcap').loss) == expected, cut
        assert result.intact_end <= cut and sum(v['count'] for v in r.topics.values()) == m
        seen.add(m)
    assert len(seen) >= len(chunks) and max(seen) == len(messages)
    # a power cut: the tail the file system had not written reads back as zeros
    start, length = chunks[3]
    p = tmp_path / 'zeros.mcap'
    p.write_bytes(data[:start + length] + bytes(8192))
    result = recover(p, tmp_path / 'zeros_fixed.mcap')
    m = len(independent(tmp_path / 'zeros_fixed.mcap')[0])
    assert not result.was_complete and result.intact_end == start + length and ledger(result.loss) == truth[m - 1]


def flip(data: bytes, *offsets) -> bytes:
    bad = bytearray(data)
    for offset in offsets:
        bad[offset] ^= 0xFF
    return bytes(bad)


def test_a_corrupt_file_is_refused_naming_the_record_and_its_offset(run_file, tmp_path, capsys):
    """Bytes flipped in a chunk (its data, its CRC, its length), complete or truncated afterwards: recover exits
    non-zero with one message naming the file, the chunk and its offset, writes nothing, never says 'already
    complete'; info refuses it the same way."""
    _, _, _, _, path = run_file
    data = path.read_bytes()
    with open(path, 'rb') as f:
        chunks = sorted((c.chunk_start_offset, c.chunk_length) for c in make_reader(f).get_summary().chunk_indexes)
    start, length = chunks[2]
    header = 9 + 8 + 8 + 8                             # opcode, length, start/end time, uncompressed size
    cases = {
        'data_middle': (flip(data, start + length // 2), 'Chunk'),
        'data_last_byte': (flip(data, start + length - 1), 'Chunk'),
        'crc': (flip(data, start + header + 1), 'checksum'),
        'length': (flip(data, start + 8), 'past the end of the file'),
        'length_low_byte': (flip(data, start + 1), 'Chunk record does not parse'),
        'opcode': (flip(data, start), 'not a record of the MCAP specification'),
        'truncated_after': (flip(data, start + length // 2)[:chunks[4][0] + 100], 'Chunk'),
    }
    for name, (content, what) in cases.items():
        p = tmp_path / f'{name}.mcap'
        p.write_bytes(content)
        out = tmp_path / f'{name}.recovered.mcap'
        with pytest.raises(RecordingError, match=f'corrupt MCAP file: .*{what}.* at byte offset {start} '):
            recover(p, out)
        assert not out.exists()
        assert cli(['recover', str(p), '-o', str(out)]) == 2, name
        captured = capsys.readouterr()
        assert 'already complete' not in captured.out and 'wrote' not in captured.out
        [line] = captured.err.strip().splitlines()
        assert str(p) in line and f'byte offset {start} ' in line and 'corrupt' in line, line
        assert not out.exists()
        if name.startswith(('length', 'opcode')):   # the indexed reader finds the chunk by the summary instead
            continue
        with pytest.raises(RecordingError, match=f'byte offset {start} '):
            load_recording(p, allow_truncated=True)
        assert cli(['info', str(p)]) == 2 and f'byte offset {start} ' in capsys.readouterr().err


def test_a_damaged_summary_is_rebuilt_from_the_intact_data(run_file, tmp_path, capsys):
    """A byte flipped in the summary section (after DataEnd): info cannot use the index and says to recover;
    recover reads the data section, which is whole, and says what it rebuilt."""
    messages, _, _, _, path = run_file
    data = path.read_bytes()
    footer = len(data) - 8 - 29                        # Footer: opcode, length, summary_start, ...; magic
    summary_start = struct.unpack('<Q', data[footer + 9:footer + 17])[0]
    assert data[summary_start] == 0x03                 # the first summary record: a Schema (opcode, length, id,
    p = tmp_path / 'summary.mcap'                      # name length, name): its name's first byte is damaged
    p.write_bytes(flip(data, summary_start + 15))
    with pytest.raises(RecordingError, match='summary section of the MCAP file is damaged.*rubber-rig recover'):
        load_recording(p)
    assert cli(['recover', str(p), '-o', str(tmp_path / 'rebuilt.mcap')]) == 0
    assert 'damaged summary section' in capsys.readouterr().out
    assert ledger(load_recording(tmp_path / 'rebuilt.mcap').loss) == RUN_TOTALS
    assert len(independent(tmp_path / 'rebuilt.mcap')[0]) == len(messages)


def test_the_bench_summary_counts_a_transport_loss_once(tmp_path, capsys):
    """The bench adds the published samples the file does not hold to the file's loss; a batch lost in transport
    is a gap in the file and must not count a second time as 'not recorded'. The recorder started 5 batches late
    and stopped 3 early; 2 batches in between never reached it."""
    rec = Recorder(tmp_path)
    rec.start(tmp_path / 'bench')
    for k in range(100):
        if 5 <= k < 97 and k not in (40, 41):
            assert rec.write('/rig/samples', BATCH_T, batch(k), 10**18 + k * 10**7, None, k + 1)
    [path] = rec.stop()
    published = SimpleNamespace(first=0, next=100 * N, samples=100 * N)
    loss = recording_loss(path, published, rec.stats())
    info = info_json(path, capsys)
    assert loss['samples_lost_in_file'] == info['samples_lost'] == rec.stats()['samples_lost_total'] == 2 * N
    assert loss['gaps'] == info['sequence_gaps'] == 1
    assert loss['samples_not_recorded'] == (5 + 3) * N
    _, recorded = independent(path)
    assert loss['samples_lost'] == len(set(range(100 * N)) - set(recorded)) == 10 * N


def test_ledger_rules():
    """The rules the four tools share: only the sample stream counts; a publisher going on without a skip is no
    loss even where its numbers go back; every gap is counted, not only the first MAX_EVENTS kept in detail."""
    g = LossLedger()
    g.observe('/rig/setpoints', 'msg_defs/msg/SetpointBatch', {'first_sequence': 10**6, 'displacement': [0.0]}, 1, 7)
    g.observe('/rig/setpoints', 'msg_defs/msg/SetpointBatch', {'first_sequence': 5, 'displacement': [0.0]}, 2, 8)
    assert g.topic is None and g.samples_lost == 0 and g.trackers == {}
    for first, pub in ((100, 10), (120, 11), (40, 12)):              # renumbered, nothing skipped: not loss
        g.observe('/a/samples', BATCH, {'first_sequence': first, 'displacement': [0.0] * 20}, 0, pub)
    assert g.samples_lost == 0 and g.summary()['sequence_restarts'] == 1
    g.observe('/a/samples', BATCH, {'first_sequence': 80, 'displacement': [0.0] * 20}, 0, 15)   # skipped: lost
    assert g.samples_lost == 20 and g.sequence_gaps == 1
    assert sample_topic({'/b/raw': BATCH, '/a/samples': BATCH, '/c/samples': SAMPLE}) == '/a/samples'
    assert sample_topic({'/b/raw': BATCH, '/a/x': BATCH}) == '/a/x'
    assert sample_topic({'/x': SAMPLE, '/p': 'msg_defs/msg/ModelPrediction'}) == '/x' and sample_topic({}) is None


def test_info_counts_every_gap_beyond_the_events_it_lists(tmp_path, capsys):
    path = tmp_path / 'many.mcap'
    gaps = MAX_EVENTS + 5
    with RecordingWriter(path) as w:
        for k in range(gaps + 1):
            first = 2 * k                          # every other sample lost in transport (publication skipped)
            w.write_message('/rig/samples', SAMPLE, {'sequence': first, 'displacement': 0.0}, 10**9 + k, None,
                            2 * k + 1)
    r = load_recording(path)
    assert r.sequence_gaps == r.closing[0]['sequence_gaps'] == gaps and len(r.gaps) == MAX_EVENTS
    assert r.samples_lost == gaps
    info = info_json(path, capsys)
    assert (info['sequence_gaps'], info['samples_lost']) == (gaps, gaps)
    assert np.array_equal(r.sequence, 2 * np.arange(gaps + 1))


def test_a_stale_or_foreign_batch_is_a_stray_not_a_restart_and_not_loss():
    """One batch with old sample numbers from another publisher amid the driver's stream (a spoofed or late copy):
    with the restart rule alone it counted every sample before it lost (its publisher had published before) and
    the stream's return a second gap. The stream going on where it was makes it a stray: no restart, no loss."""
    g = LossLedger()
    for k in range(10):
        g.observe('/a/samples', BATCH, {'first_sequence': 20 * k, 'displacement': [0.0] * 20}, k, k + 1)
    g.observe('/a/samples', BATCH, {'first_sequence': 40, 'displacement': [0.0] * 20, 'frames_lost': 5}, 10, 77)
    for k in range(10, 15):
        g.observe('/a/samples', BATCH, {'first_sequence': 20 * k, 'displacement': [0.0] * 20}, k + 1, k + 1)
    s = g.summary()
    assert (g.samples_lost, s['sequence_gaps'], s['sequence_restarts'], s['sequence_strays']) == (0, 0, 0, 1)
    assert [e['kind'] for e in g.tracker.events] == ['stray']
    # a restarted driver: its stream goes on from the new numbers - a restart (with what it published before we
    # matched it counted lost)
    g.observe('/a/samples', BATCH, {'first_sequence': 100, 'displacement': [0.0] * 20}, 20, 3)
    g.observe('/a/samples', BATCH, {'first_sequence': 120, 'displacement': [0.0] * 20}, 21, 4)
    s = g.summary()
    assert (s['sequence_restarts'], s['sequence_strays'], g.samples_lost) == (1, 1, 100)


# ---- the stray-or-restart rule: one implementation, the recorder's ledger and the element model follow it ---------
@pytest.mark.parametrize('next_first, verdict', [
    (120, RESTART),          # continues the batch that went back: a restarted driver numbering from 100
    (500, STRAY),            # the stream goes on where it was: the batch was stale or foreign
    (560, STRAY),            # ... after a gap of its own: still the old stream
    (300, RESTART),          # neither: a new stream that lost a batch (below where the old one was)
    (40, RESTART),           # went back again: what went back first was the new stream's first batch
])
def test_stray_or_restart_is_told_by_the_batch_after_the_one_that_went_back(next_first, verdict):
    """A batch of 20 samples at sequence 100 while the stream expected 500; the next batch decides."""
    assert stray_or_restart(100, 20, 500, next_first) == verdict
    rule = StrayOrRestart()
    assert rule.judge(next_first) is None                 # nothing went back: nothing to say
    rule.went_back(100, 20, 500, payload='held batch')
    assert rule.judge(next_first) == (verdict, 'held batch')
    assert rule.judge(next_first) is None                 # judged once


def test_a_live_consumer_holds_a_batch_that_went_back_until_the_next_one_says_restart_or_stray():
    """StreamOrder, as the element model takes its sample batches: expected next 500; a 20-sample batch at 100."""
    order = StreamOrder()
    assert order.arrive(480, 20, 480, 'a') == (None, True)           # in order: taken
    assert order.arrive(100, 20, 500, 'b') == (None, False)          # went back: held
    assert order.arrive(500, 20, 500, 'c') == ((STRAY, 'b'), True)   # the stream went on: 'b' was a stray
    assert order.strays == 1
    assert order.arrive(0, 20, 520, 'd') == (None, False)            # a restarted driver numbering from 0 ...
    # ... continued by its own next batch: a restart; the consumer starts afresh from 'd', then takes 'e'
    assert order.arrive(20, 20, 520, 'e') == ((RESTART, 'd'), True)
    assert order.strays == 1
    assert order.arrive(10, 20, 40, 'f') == (None, False)            # judged against where the restart went on


def test_a_stray_followed_by_a_gap_of_the_old_stream_is_a_stray_and_the_gap_counts():
    """The stream goes on after the stray but 40 samples later than it was due: the stray is taken back and the
    40 samples are the old stream's gap (publication sequence skipped: lost), not a restart."""
    g = LossLedger()
    for k in range(10):
        g.observe('/a/samples', BATCH, {'first_sequence': 20 * k, 'displacement': [0.0] * 20}, k, k + 1)
    g.observe('/a/samples', BATCH, {'first_sequence': 40, 'displacement': [0.0] * 20}, 10, 77)
    g.observe('/a/samples', BATCH, {'first_sequence': 240, 'displacement': [0.0] * 20}, 11, 13)
    s = g.summary()
    assert (s['sequence_restarts'], s['sequence_strays'], s['sequence_gaps'], g.samples_lost) == (0, 1, 1, 40)
    assert [e['kind'] for e in g.tracker.events] == ['stray', 'gap']
