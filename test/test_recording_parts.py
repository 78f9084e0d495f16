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

"""Split recordings that know their parts: each file names its index, the recording's id and the samples it holds;
``rubber-rig info`` and ``recover`` on the directory or on any one part say which parts are missing and how many
samples that is, and agree. Files are checked with the mcap library's own reader.
"""
import json

import pytest
from mcap.reader import make_reader

from rubber_rig.cli.main import main as cli
from rubber_rig.recording import Recorder, load_recording
from rubber_rig.recording.metadata import decode_metadata
from rubber_rig.recording.parts import same_recording, survey

from support.recording import N, stream

PART_SAMPLES = 1500          # 1.5 s parts of the 6 s stream at 1 kHz (300 batches of N = 20)


def split_recording(tmp_path, name='r'):
    rec = Recorder(tmp_path, split_duration_s=1.5)
    rec.start(tmp_path / name)
    for topic, msg_type, msg, log in stream():
        assert rec.write(topic, msg_type, msg, log)
    files = rec.stop()
    assert len(files) == 4 and rec.parts[-1]['part_samples'] == PART_SAMPLES
    return rec, files


def records(path):
    """The rubber_rig and rubber_rig.close records of a file, read by the mcap library."""
    with open(path, 'rb') as f:
        found = {m.name: decode_metadata(dict(m.metadata)) for m in make_reader(f).iter_metadata()}
    return found['rubber_rig'], found.get('rubber_rig.close')


def info_json(path, capsys):
    assert cli(['info', str(path), '--json']) == 0
    return json.loads(capsys.readouterr().out)


def test_each_part_names_its_index_the_recording_and_its_samples(tmp_path):
    rec, files = split_recording(tmp_path)
    ids = set()
    for k, f in enumerate(files):
        header, close = records(f)
        ids.add(header['recording_id'])
        assert (header['part_index'], header['samples_before']) == (k, k * PART_SAMPLES)
        assert header['previous_last_sample'] == (None if k == 0 else k * PART_SAMPLES - 1)
        assert (close['part_index'], close['part_samples']) == (k, PART_SAMPLES)
        assert (close['first_sample'], close['last_sample']) == (k * PART_SAMPLES, (k + 1) * PART_SAMPLES - 1)
        assert close['next_part'] == ('' if k == 3 else f'r_{k + 1}.mcap') and close['final_part'] == (k == 3)
    assert ids == {rec.recording_id} and len(rec.recording_id) == 32
    report = survey(files[0].parent)
    assert report.complete and [p.index for p in report.present] == [0, 1, 2, 3]
    assert 'all 4 parts present' in report.lines()[0]


@pytest.mark.parametrize('gone', [[1], [0], [3], [1, 2]])
def test_info_and_recover_name_the_missing_parts_and_their_samples(tmp_path, capsys, gone):
    """The issue: with any one part deleted, `info DIR` said 'complete, 0 lost, 0 gaps'. Now the part, its samples
    and their sequence range are named, from the directory and from any remaining part alike, and recover says
    the same."""
    _, files = split_recording(tmp_path)
    for k in gone:
        files[k].unlink()
    left = [f for k, f in enumerate(files) if k not in gone]
    views = [info_json(files[0].parent, capsys)] + [info_json(f, capsys) for f in left]
    for info in views:
        parts = info['parts']
        assert not parts['complete'] and not info['complete']
        assert [m['index'] for m in parts['parts_missing']] == gone
        assert parts['samples_missing'] == PART_SAMPLES * len(gone) and not parts['samples_missing_unknown']
        for m in parts['parts_missing']:
            assert (m['first'], m['last']) == (m['index'] * PART_SAMPLES, (m['index'] + 1) * PART_SAMPLES - 1)
            assert m['file'] == f"r_{m['index']}.mcap"
    assert cli(['info', str(files[0].parent)]) == 0
    info_text = [line.removeprefix('parts:').strip() for line in capsys.readouterr().out.splitlines()
                 if line.startswith('parts:')]
    assert cli(['recover', str(files[0].parent)]) == 0
    out = capsys.readouterr().out
    assert 'every part was closed: nothing to recover' in out
    recover_text = [line.removeprefix('parts:').strip() for line in out.splitlines() if line.startswith('parts:')]
    assert recover_text == info_text and 'MISSING' in info_text[0]
    assert f'{PART_SAMPLES * len(gone)} samples of the recording are in missing parts' in ' '.join(info_text)


def test_a_missing_last_part_without_metadata_yaml_is_named_and_its_samples_unknown(tmp_path, capsys):
    _, files = split_recording(tmp_path)
    files[3].unlink()
    (files[0].parent / 'metadata.yaml').unlink()
    report = survey(files[1])
    assert not report.complete and [m['index'] for m in report.missing] == [3]
    assert report.missing[0]['samples'] is None and report.missing[0]['first'] == 3 * PART_SAMPLES
    assert report.samples_unknown and 'r_2.mcap says the recording continued in r_3.mcap' in report.after_last
    assert not load_recording(files[0].parent).complete


def test_recover_of_a_directory_recovers_the_unclosed_part_and_lists_the_parts(tmp_path, capsys):
    """The last part's recorder was killed (its file ends mid-chunk): recover DIR rebuilds it and lists the parts;
    info on the directory then agrees with it, and no part is missing."""
    _, files = split_recording(tmp_path)
    data = files[3].read_bytes()
    files[3].write_bytes(data[:len(data) * 6 // 10])
    (files[0].parent / 'metadata.yaml').unlink()     # a killed recorder's directory: no final metadata.yaml
    assert cli(['recover', str(files[0].parent)]) == 0
    out = capsys.readouterr().out
    assert 'r_3.mcap was truncated' in out and 'wrote' in out
    recovered = files[3].with_name('r_3.recovered.mcap')
    assert recovered.exists()
    parts = [line for line in out.splitlines() if line.startswith('parts:')]
    assert len(parts) == 1 and 'all 4 parts present' in parts[0], out
    info = info_json(files[0].parent, capsys)
    assert info['parts']['complete'] and info['parts']['parts_present'] == [0, 1, 2, 3]
    assert info['files'][-1].endswith('r_3.recovered.mcap')


def test_a_part_just_opened_whose_header_is_not_on_disk_yet_is_not_missing(tmp_path):
    """A live recording right after a split: the recorder has created r_3.mcap but not flushed its first records.
    It is the recording's part in progress (CI once caught `info` calling it MISSING between the two)."""
    _, files = split_recording(tmp_path)
    files[3].write_bytes(b'')
    (files[0].parent / 'metadata.yaml').unlink()     # a live recording's directory: no final metadata.yaml yet
    report = survey(files[0].parent)
    assert report.missing == [] and [p.index for p in report.present] == [0, 1, 2, 3]
    assert report.present[-1].closed is False


def test_a_part_of_another_recording_in_the_directory_is_not_taken_for_one(tmp_path):
    _, files = split_recording(tmp_path, 'a')
    _, other = split_recording(tmp_path, 'b')
    stray = files[0].parent / 'b_1.mcap'
    stray.write_bytes(other[1].read_bytes())         # a file of recording b copied into a's directory
    report = survey(files[2])
    assert report.complete and [p.index for p in report.present] == [0, 1, 2, 3]
    assert {p.recording_id for p in report.present} == {records(files[0])[0]['recording_id']}


def test_the_next_part_of_a_recording_is_the_same_recording():
    """What the excitation node asks when the recorder's file changes: a split is not a lost recording."""
    assert same_recording('/rec/r/r_0.mcap', '/rec/r/r_1.mcap')
    assert same_recording('/rec/r/r_3.mcap', '/rec/r/r_4.mcap')
    assert not same_recording('/rec/r/r_1.mcap', '/rec/r/r_0.mcap')       # back to part 0: a new recording
    assert not same_recording('/rec/r/r_0.mcap', '/rec/s/s_1.mcap')
    assert not same_recording('/rec/r/r_0.mcap', '/rec/r-1/r-1_1.mcap')
    assert not same_recording('/rec/r/r_0.mcap', '')
    assert N * 75 == PART_SAMPLES
