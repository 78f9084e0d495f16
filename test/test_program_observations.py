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

"""What a program's result says, decided in the ROS-free core on simulated time: who stalled and who merely looked
silent (session.observed), and what happened to the recording (recording.outcome). The wiring into the
excitation node is tested with the nodes as separate processes in test_nodes_blame.py.
"""
import pytest

from rubber_rig.recording.outcome import RecorderReport, RecordingOutcome, cause_of
from rubber_rig.session.observed import BeatLog, ProgramWitness, StallWatch

SILENT, PERIOD = 0.75, 0.25
PEERS = ('/r4/rig_driver', '/r4/recorder', '/r4/element_model')


class Suite:
    """The excitation's view on simulated time: its own ticks every 20 ms, the peers' beats every 0.25 s (stamped
    on their clock = this clock + 1000 s), each delivered 2 ms after it was sent unless this node is stopped."""

    def __init__(self):
        self.stall, self.beats = StallWatch(SILENT), BeatLog(SILENT, PERIOD)
        self.t = 0.0
        self.counts = dict.fromkeys(PEERS, 0)
        self.queue = []            # beats sent while this node was stopped: delivered (the last 10) on resume
        self.witness = None

    def run(self, seconds, me_stopped=False, stopped_peers=()):
        end = self.t + seconds
        while self.t < end - 1e-9:
            self.t = round(self.t + 0.01, 6)
            if round(self.t / PERIOD, 6).is_integer():
                for p in PEERS:
                    if p not in stopped_peers:
                        self.counts[p] += 1
                        self.queue.append((p, self.counts[p], self.t + 1000.0))
            if me_stopped:
                continue
            self.stall.tick(self.t)
            for p, count, stamp in self.queue[-10:]:     # a depth-10 reader keeps the last 10 beats
                self.beats.beat(p, 7, count, stamp, self.t)
            self.queue = []
            if self.witness is not None:
                self.witness.watch(self.beats, self.stall, self.t)


def test_a_stall_of_this_node_is_not_a_silence_of_the_others():
    """The issue: the excitation SIGSTOPped for 3 s blamed rig_driver ('silent for 3.0 s') and the recorder ('gone').
    Its own stall is named, with the peers that beat on through it; no peer is silent."""
    s = Suite()
    s.run(2.0)
    s.witness = ProgramWitness('/r4/excitation', s.t)
    s.run(1.0)
    s.run(3.0, me_stopped=True)
    s.run(0.05)                                     # the first callbacks after SIGCONT
    assert s.stall.stalls[-1][1] - s.stall.stalls[-1][0] == pytest.approx(3.01, abs=0.02)
    assert s.beats.quiet(s.t, s.stall) == {}        # nobody is silent: they have had no time to be heard yet
    assert s.stall.since(3.0, s.t) < 0.1            # the driver's status seen just before the stall is not stale
    words = s.witness.words(s.beats, s.stall, s.t)
    assert len(words) == 1, words
    assert words[0].startswith('/r4/excitation (this node) stalled for 3.0 s')
    assert 'beat on through it (their own heartbeats show no gap): ' + ', '.join(sorted(PEERS)) in words[0]
    assert 'silent during' not in ' '.join(words)


def test_a_peer_that_stopped_is_silent_for_as_long_as_its_own_beats_show():
    s = Suite()
    s.run(1.0)
    s.witness = ProgramWitness('/r4/excitation', s.t)
    s.run(0.5)
    s.run(2.0, stopped_peers=('/r4/element_model',))
    assert s.beats.quiet(s.t, s.stall) == {'/r4/element_model': pytest.approx(2.0, abs=1e-6)}   # last beat at 1.5
    assert s.witness.words(s.beats, s.stall, s.t) == ['silent during the program: /r4/element_model up to 2.0 s '
                                                      '(still silent)']
    s.run(0.5)                                      # it beats again: the gap in its own stamps is the silence
    silence = s.beats.silences[-1]
    assert silence.node == '/r4/element_model' and silence.duration == pytest.approx(2.25, abs=1e-6)
    assert s.witness.words(s.beats, s.stall, s.t) == ['silent during the program: /r4/element_model up to 2.2 s '
                                                      '(beats again)']


def test_a_peer_stopped_during_this_nodes_stall_is_told_apart_from_those_that_beat_on():
    s = Suite()
    s.run(1.0)
    s.witness = ProgramWitness('/r4/excitation', s.t)
    s.run(0.5)
    # both stopped for 2 s; the element model longer: it stays stopped after this node resumed
    s.run(2.0, me_stopped=True, stopped_peers=('/r4/element_model',))
    s.run(1.5, stopped_peers=('/r4/element_model',))
    words = s.witness.words(s.beats, s.stall, s.t)
    assert 'beat on through it (their own heartbeats show no gap): /r4/recorder, /r4/rig_driver' in words[0]
    assert 'not heard from since' not in words[0]
    # silent for what this node could observe: since it resumed (its beats might have been lost while it was stopped)
    assert words[1] == 'silent during the program: /r4/element_model up to 1.5 s (still silent)'
    s.run(0.5)                                      # it beats again: its own stamps show the whole silence
    assert s.witness.words(s.beats, s.stall, s.t)[1] == ('silent during the program: /r4/element_model up to '
                                                         '3.8 s (beats again)')   # beats at 1.5 and 5.25


def test_a_silence_before_the_program_is_not_the_programs():
    s = Suite()
    s.run(1.0)
    s.run(1.5, stopped_peers=('/r4/element_model',))
    quiet = s.beats.quiet(s.t, s.stall)
    s.witness = ProgramWitness('/r4/excitation', s.t, silent_before=set(quiet))
    s.run(1.0, stopped_peers=('/r4/element_model',))
    assert s.witness.words(s.beats, s.stall, s.t) == []


def test_beats_missed_in_transport_are_no_silence():
    log = BeatLog(SILENT, PERIOD)
    assert log.beat('/a', 1, 1, 100.0, 0.0) is None
    assert log.beat('/a', 1, 9, 102.0, 2.0) is None         # 7 beats not heard, sent at the beat period
    assert log.beat('/a', 1, 10, 103.5, 3.5).duration == pytest.approx(1.5)   # one step, 1.5 s apart: silent
    assert log.beat('/a', 2, 0, 104.0, 4.0) is None         # a restarted node (new pid) starts afresh


# ---- the recording's outcome ------------------------------------------------------------------------------------

FILE = '/rec/r/r_0.mcap'


def report(t, state='recording', path=FILE, error='', lost=0, records=True):
    return RecorderReport(t, state, path, error, records, lost)


def started(t=10.0):
    o = RecordingOutcome(2.0, '/r4/samples')
    o.start(report(t - 0.2), t)
    return o


def test_a_complete_recording_is_confirmed_by_word_from_the_recorder_after_the_end():
    o = started()
    o.observe(report(10.5), 500)
    assert o.verdict(11.0, 1000, ended=10.9) is None                   # nothing since the end yet: wait
    assert o.verdict(11.1, 1000, ended=10.9, heard=11.05) == 'recording complete in /rec/r/r_0.mcap'
    o = started()
    o.observe(report(10.5, lost=0), 500)
    o.latest = report(11.2, lost=12)
    assert o.verdict(11.2, 1000, ended=10.9) == ('recording complete in /rec/r/r_0.mcap (12 samples lost in '
                                                 'transport or writing, counted by the recorder and in the file)')


def test_a_split_is_the_same_recording_not_a_lost_one():
    """The issue: at a normal split the excitation reported 'recording lost ... recorder switched to ..._1.mcap'."""
    o = started()
    assert o.observe(report(10.5, path='/rec/r/r_1.mcap'), 500) == ''
    assert o.observe(report(11.0, path='/rec/r/r_2.mcap'), 1000) == ''
    o.latest = report(12.1, path='/rec/r/r_2.mcap')
    assert o.verdict(12.1, 2000, ended=12.0) == 'recording complete in /rec/r (parts r_0.mcap..r_2.mcap)'
    o = started()
    assert 'another recording, /rec/s/s_0.mcap' in o.observe(report(10.5, path='/rec/s/s_0.mcap'), 500)


@pytest.mark.parametrize('error, cause', [
    ('writing /rec/r/r_0.mcap failed (disk full); the file is kept up to its last complete chunk', 'disk full'),
    ('writing /rec/r/r_0.mcap failed (file too large); ...', 'file too large'),
    ('cannot create recording directory /x: Permission denied', 'unwritable')])
def test_a_recorder_that_cannot_write_is_in_the_result_whatever_ended_the_program(error, cause):
    """The issue: disk full 4.5 s in, then a load fault ended the program and the result did not mention it."""
    o = started()
    o.observe(report(14.5, 'error', error=error), 4500)
    words = o.verdict(20.0, 9000, ended=19.9)
    assert words.startswith(f'recording lost from about sample 4500: {cause}: the recorder failed: {error}')
    assert cause_of(error) == cause


def test_a_recorder_killed_just_before_the_end_is_not_confirmed():
    """The issue: the recorder killed, the goal ended 0.5 s later, its result did not mention the recording."""
    o = started()
    o.observe(report(10.4), 400)                    # its last status; killed at 10.5
    assert o.check(11.0, 1000) == ''                # 0.6 s: not yet gone by recorder_timeout
    assert o.verdict(11.2, 1000, ended=11.0, heard=10.45) is None
    words = o.verdict(11.8, 1000, ended=11.0, heard=10.45)
    assert words.startswith('recording not confirmed to the end (recorder gone?): no word from the recorder for '
                            '0.8 s after the program ended (its last status 1.4 s ago)')
    assert 'may end before sample 1000' in words


def test_a_recorder_gone_mid_program_and_no_recording_at_all():
    o = started()
    assert o.check(12.5, 2000) == ('recording lost from about sample 2000: recorder gone: no recorder status for '
                                   '2.7 s (the recorder is gone); the samples after it are not in /rec/r/r_0.mcap')
    assert o.verdict(13.0, 3000, ended=12.9).startswith('recording lost from about sample 2000: recorder gone')
    none = RecordingOutcome(2.0, '/r4/samples')
    none.start(None, 10.0)
    assert none.verdict(11.0, 100, ended=10.9) == ('no recording: no recorder was recording /r4/samples when the '
                                                   'program started')


def test_a_stall_of_this_node_does_not_make_the_recorder_gone():
    o = started()
    o.observe(report(10.4), 400)
    # this node stopped from 10.5 to 13.5 and resumed: the recorder's last status is 3.1 s old, but counted from
    # the resume it is 0.1 s
    assert o.check(13.6, 500, since=13.5) == '' and not o.lost
    o.latest = report(13.7)
    assert o.verdict(13.8, 600, ended=13.65, since=13.5) == 'recording complete in /rec/r/r_0.mcap'


def test_a_recorder_replaced_before_the_first_sample_is_where_the_program_is_recorded():
    """The program started on the last status of a recorder that had just been replaced; the new recorder's status
    came before the program's first sample: nothing was lost, the program is recorded in the new recording."""
    o = started()                                   # on the old recorder's status: /rec/r/r_0.mcap
    new = '/rec/s/s_0.mcap'
    assert o.observe(report(10.1, path=new), 1000, measured=False) == ''
    assert o.observe(report(10.6, path=new), 1400) == ''
    o.latest = report(11.2, path=new)
    assert o.verdict(11.2, 2000, ended=11.0) == 'recording complete in /rec/s/s_0.mcap'
    # once samples were measured, another recording is a loss, from the next sample on
    assert 'recording lost from about sample 1400: switched' in o.observe(report(11.3, path='/rec/t/t_0.mcap'), 1400)
