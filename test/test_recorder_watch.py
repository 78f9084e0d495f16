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

"""What the excitation knows of the recorder (session.recorder_watch) on simulated time, at its boundaries: when a
program may start with require_recording, when the recorder is gone, what a restarted recorder or driver changes,
and the result's words on the recording. No ROS (the graph's publishers are plain ids here); the wiring is tested
with the nodes in test_nodes*.py and test_recording_node.py.
"""
from rubber_rig.session.observed import StallWatch
from rubber_rig.session.recorder_watch import RESULT_WAIT, RecorderView, RecorderWatch

SAMPLES, STATUS = '/rig1/samples', '/rig1/recorder_status'
RECORDERS, DRIVERS = frozenset({b'rec'}), frozenset({b'drv'})
T0 = 100.0


def watch(require=True, timeout=2.0):
    return RecorderWatch(require, timeout, SAMPLES, STATUS, StallWatch(0.75))


def recording(path='/data/run/run_0.mcap', publishers=1, lost=0):
    return RecorderView('recording', path, '', [SAMPLES], [publishers], lost)


def ready_watch():
    """A watch that has seen the graph and a recorder status after that, at T0 + 0.5."""
    w = watch()
    assert w.why_not_start(T0, RECORDERS, DRIVERS) == \
        "require_recording: no recorder status on 'recorder_status' (is the recorder running?)"
    w.on_status(recording(), T0)
    assert w.why_not_start(T0, RECORDERS, DRIVERS) == \
        'require_recording: waiting for a status of the recorder that runs now (it was restarted)'
    w.on_status(recording(), T0 + 0.25)
    # the samples' publishers are first looked at now: a status from before that counts the ones it knew
    assert w.why_not_start(T0 + 0.25, RECORDERS, DRIVERS).startswith(
        'require_recording: waiting for a recorder status newer than the last change of /rig1/samples')
    w.on_status(recording(), T0 + 0.5)
    assert w.why_not_start(T0 + 0.5, RECORDERS, DRIVERS) == ''
    return w


def test_without_require_recording_nothing_waits_for_the_recorder():
    w = watch(require=False)
    assert w.why_not_start(T0, RECORDERS, DRIVERS) == '' and w.why_stop(T0 + 1e6) == ''
    assert w.fresh(T0, T0, RECORDERS, DRIVERS)


def test_a_start_needs_a_status_at_most_recorder_timeout_old():
    w = ready_watch()
    assert w.why_not_start(T0 + 2.5, RECORDERS, DRIVERS) == ''      # exactly 2 s old
    assert w.why_not_start(T0 + 2.5 + 1 / 1024, RECORDERS, DRIVERS) == \
        'require_recording: no recorder status for 2.0 s'


def test_a_restarted_recorder_or_driver_is_waited_for_until_a_status_newer_than_the_change():
    w = ready_watch()
    assert w.why_not_start(T0 + 1.0, frozenset({b'rec2'}), DRIVERS) == \
        'require_recording: waiting for a status of the recorder that runs now (it was restarted)'
    w.on_status(recording(), T0 + 1.25)
    assert w.why_not_start(T0 + 1.25, frozenset({b'rec2'}), DRIVERS) == ''
    both = frozenset({b'drv', b'drv2'})                              # a restarted driver: a new samples publisher
    assert w.why_not_start(T0 + 1.5, frozenset({b'rec2'}), both).startswith(
        'require_recording: waiting for a recorder status newer than the last change of /rig1/samples')
    w.on_status(recording(publishers=1), T0 + 1.75)                  # the recorder matched only the old one
    assert w.why_not_start(T0 + 1.75, frozenset({b'rec2'}), both) == (
        'require_recording: the recorder is matched with 1 of the 2 publishers of /rig1/samples (it has not '
        'discovered the restarted rig_driver yet)')
    w.on_status(recording(publishers=2), T0 + 2.0)
    assert w.why_not_start(T0 + 2.0, frozenset({b'rec2'}), both) == ''


def test_a_recorder_that_does_not_record_the_samples_refuses_a_start():
    w = ready_watch()
    w.on_status(RecorderView('idle'), T0 + 1.0)
    assert w.why_not_start(T0 + 1.0, RECORDERS, DRIVERS) == 'require_recording: the recorder is idle'
    w.on_status(RecorderView('error', error='disk full'), T0 + 1.5)
    assert w.why_not_start(T0 + 1.5, RECORDERS, DRIVERS) == 'require_recording: the recorder is error: disk full'
    w.on_status(RecorderView('recording', '/d/x.mcap', topics=['/rig1/prediction']), T0 + 2.0)
    assert w.why_not_start(T0 + 2.0, RECORDERS, DRIVERS) == \
        'require_recording: the recorder does not record /rig1/samples yet'


def test_an_error_counts_for_a_goal_only_if_reported_since_the_goal_arrived():
    w = ready_watch()
    w.on_status(RecorderView('error', error='disk full'), T0 + 1.0)
    assert not w.fresh(T0 + 1.25, T0 + 1.5, RECORDERS, DRIVERS)      # a replaced recorder's error: wait
    assert w.fresh(T0 + 1.0, T0 + 1.5, RECORDERS, DRIVERS)          # an error since the goal: judge it


def test_a_running_program_stops_when_the_recorder_is_silent_for_more_than_recorder_timeout():
    w = ready_watch()
    w.start_program(T0 + 0.5)
    assert w.why_stop(T0 + 2.5) == ''                               # exactly 2 s without a status
    assert w.why_stop(T0 + 2.5 + 1 / 1024) == 'recording lost: no recorder status for 2.0 s (the recorder is gone)'
    assert w.check(T0 + 2.5, 1000) == ''
    assert w.check(T0 + 2.5 + 1 / 1024, 1000).startswith('recording lost from about sample 1000: recorder gone')
    assert w.check(T0 + 3.0, 1200) == ''                            # said once


def test_a_failed_recorder_stops_a_program_that_requires_recording_and_a_split_is_the_same_recording():
    w = ready_watch()
    w.start_program(T0 + 0.5)
    assert w.on_status(recording('/data/run/run_1.mcap'), T0 + 1.0, next_sample=500, measured=True) == ('', '')
    why, lost = w.on_status(RecorderView('error', '/data/run/run_1.mcap', 'disk full'), T0 + 1.5, 700, True)
    assert why == 'recording failed: disk full' and w.lost.startswith('recording lost from about sample 700: disk')


def test_the_result_waits_at_most_result_wait_for_word_from_the_recorder():
    w = ready_watch()
    w.start_program(T0 + 0.5)
    outcome = w.end_program()
    end = T0 + 1.0
    assert w.verdict(outcome, 900, end, end + RESULT_WAIT) is None  # no word yet
    assert w.verdict(outcome, 900, end, end + RESULT_WAIT, heard=end + 0.25) == \
        'recording complete in /data/run/run_0.mcap'   # the recorder's beat after the end confirms it
    assert outcome not in w.ended
    other = (w.start_program(end), w.end_program())[1]
    assert w.verdict(other, 900, end, end + RESULT_WAIT) is None
    assert w.verdict(other, 900, end, end + RESULT_WAIT + 1 / 1024).startswith(
        'recording not confirmed to the end (recorder gone?)')
