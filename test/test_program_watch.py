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

"""The excitation's start and stop rules (session.program_watch) on simulated time, at their boundaries in numbers:
no ROS, no wall clock. The excitation node feeds them (test_nodes*.py prove the wiring); the scenario harness takes
the same detector and rig-status decisions (test_scenario*.py).

Times are chosen exactly representable in binary (status_timeout 0.5 s, so 3 x 0.5 = 1.5 s exactly).
"""
from types import SimpleNamespace

import pytest

from rubber_rig.session.observed import StallWatch
from rubber_rig.session.program_watch import (
    ProgramWatch,
    RigView,
    Throttle,
    detector_action,
    links_verdict,
    why_rig_stopped,
)

ME = '/rig1/excitation'
T0 = 100.0


def watch(status_timeout=0.5, hold_timeout=4.0, start_timeout=2.0):
    return ProgramWatch(status_timeout, hold_timeout, start_timeout, StallWatch(0.75), '/rig1/rig_driver')


def idle(**kw):
    return RigView('idle', **kw)


def test_a_start_needs_a_status_at_most_three_status_timeouts_old():
    w = watch()
    assert w.why_not_start(T0, ME, busy=False) == "no rig status received on 'status' yet (is rig_driver active?)"
    w.on_rig_status(idle(), T0)
    assert w.why_not_start(T0 + 1.5, ME, busy=False) == ''            # exactly 3 x 0.5 s old: still counts
    assert w.why_not_start(T0 + 1.5 + 1 / 1024, ME, busy=False) == \
        'the rig status is 1.5 s old (is rig_driver running?)'
    w.on_rig_status(idle(), T0 + 10.0)                               # a new status makes it young again
    assert w.why_not_start(T0 + 10.25, ME, busy=False) == ''


@pytest.mark.parametrize('rig, busy, links, recording, why', [
    (RigView('fault', True, ['watchdog', 'x over limit', 'load cell stuck']), False, '', '',
     'rig is fault: x over limit; load cell stuck (rig_driver/reset to acknowledge)'),
    (RigView('ramping_down'), False, '', '', 'rig is ramping_down'),
    (idle(stream_owner='/other/excitation'), False, '', '', 'the rig is streaming for /other/excitation'),
    (idle(stream_owner=ME), False, '', '', ''),                      # our own stream (a resume) is no other's
    (RigView('holding'), True, '', '', 'a program is already running'),
    (RigView('running'), False, 'waiting for discovery', 'require_recording: x', 'waiting for discovery'),
    (idle(), False, '', 'require_recording: the recorder is idle', 'require_recording: the recorder is idle'),
])
def test_a_start_is_refused_for_the_first_reason_in_order(rig, busy, links, recording, why):
    w = watch()
    w.on_rig_status(rig, T0)
    assert w.why_not_start(T0, ME, busy, links, recording) == why


def test_a_goal_waits_for_a_status_at_most_one_status_timeout_old_and_the_links():
    w = watch()
    assert not w.statuses_fresh(T0, True, '')
    w.on_rig_status(idle(), T0)
    assert w.statuses_fresh(T0 + 0.5, True, '')                      # exactly status_timeout old
    assert not w.statuses_fresh(T0 + 0.5 + 1 / 1024, True, '')
    assert not w.statuses_fresh(T0, False, '') and not w.statuses_fresh(T0, True, 'waiting for discovery')
    assert not w.start_wait_over(T0, T0 + 2.0 - 1 / 1024) and w.start_wait_over(T0, T0 + 2.0)   # start_timeout 2 s


def test_a_held_program_ends_after_exactly_hold_timeout():
    w = watch(hold_timeout=4.0)
    w.on_hold(T0)
    assert w.why_stop(T0 + 4.0, held=True, streaming=True) == ''     # exactly hold_timeout: still held
    assert w.why_stop(T0 + 4.0 + 1 / 1024, held=True, streaming=True) == \
        'held for 4 s without a resume (hold_timeout): ramp to rest'
    # while held the driver's and the recorder's silences are not judged (the driver holds the rig)
    assert w.why_stop(T0 + 1.0, held=True, streaming=True, recorder='recording lost') == ''


def test_a_driver_silent_for_more_than_status_timeout_ends_the_program_and_samples_count_as_heard():
    w = watch(status_timeout=0.5)
    w.on_rig_status(RigView('running', stream_owner=ME, stream_id=7), T0)
    assert w.why_stop(T0 + 0.5, held=False, streaming=True) == ''
    w.on_samples(T0 + 0.25)                                          # a batch proves it alive as a status does
    assert w.why_stop(T0 + 0.75, held=False, streaming=True) == ''
    assert w.why_stop(T0 + 0.75 + 1 / 1024, held=False, streaming=True).startswith(
        '/rig1/rig_driver silent for 0.5 s (no status, no samples)')
    assert w.why_stop(T0 + 9.0, held=False, streaming=False) == ''   # no stream (opening, or between programs)
    # the recorder's verdict comes first
    assert w.why_stop(T0 + 9.0, held=False, streaming=True, recorder='recording lost: gone') == 'recording lost: gone'


def test_a_stall_of_this_node_is_not_the_drivers_silence():
    w = watch(status_timeout=0.5)
    w.on_rig_status(idle(), T0)
    w.stall.tick(T0)
    assert w.stall.tick(T0 + 3.0) == (T0, T0 + 3.0)                  # this node did not run for 3 s
    assert w.why_stop(T0 + 3.0 + 0.5, held=False, streaming=True) == ''   # the driver gets its full 0.5 s again
    assert w.driver_silent(T0 + 3.75) == 0.75
    assert 'silent for 0.8 s' in w.why_stop(T0 + 3.75, held=False, streaming=True)


def test_the_rig_ends_a_program_on_a_fault_or_when_it_takes_the_stream_away():
    assert why_rig_stopped(RigView('fault', True, ['watchdog: no heartbeat']), 7, False) == \
        'rig fault: watchdog: no heartbeat'
    assert why_rig_stopped(RigView('running', True, ['limit']), 7, True) == 'rig fault: limit'   # also at the end
    assert why_rig_stopped(RigView('running', stream_id=7), 7, False) == ''
    assert why_rig_stopped(RigView('ramping_down', stream_id=0, last_event='operator abort'), 7, False) == \
        'the rig stopped the program: operator abort'
    assert why_rig_stopped(RigView('idle'), 7, False) == 'the rig stopped the program: idle'
    assert why_rig_stopped(RigView('idle'), 7, True) == ''           # the program ended its own stream


def event(action, kind='residual', detector='residual', message='residual 6.0 > 5.0'):
    return SimpleNamespace(action=action, kind=kind, detector=detector, message=message)


def test_the_strongest_detector_action_is_taken_once():
    assert detector_action([], held=False) is None
    assert detector_action([event('record'), event('warn')], held=False) is None
    hold = detector_action([event('warn'), event('hold')], held=False)
    assert (hold.kind, hold.reason) == ('hold', 'detector residual')
    assert hold.failed('the block has ended') == \
        'detector residual asked for a hold, which failed (the block has ended): residual 6.0 > 5.0'
    assert detector_action([event('hold')], held=True) is None      # held already: nothing more to do
    end = detector_action([event('hold'), event('end', 'stiffness_change', 'stiffness', 'K_dyn -12 %')], held=True)
    assert (end.kind, end.reason, end.success) == ('end', 'ended by detector: K_dyn -12 %', False)
    for trigger in ('cycle_count', 'elapsed_time'):                  # an end-of-test trigger is a success
        assert detector_action([event('end', trigger, trigger, 'done')], held=False).success


def test_links_wait_for_every_endpoint_the_graph_shows_and_for_the_acknowledgement():
    ok = (('samples subscription', 1, 1), ('setpoint stream publisher', 2, 2))
    assert links_verdict(ok, acked=True) == ''
    assert links_verdict((('samples subscription', 0, 0),), acked=True) == \
        'waiting for discovery: our samples subscription is matched with 0 of 1 endpoints'   # nobody yet: wait
    assert links_verdict((('setpoints publisher', 1, 2),), acked=True) == \
        'waiting for discovery: our setpoints publisher is matched with 1 of 2 endpoints'
    assert links_verdict(ok, acked=False).startswith('waiting for rig_driver to acknowledge')


def test_the_feedback_throttle_lets_one_through_per_period():
    t = Throttle(0.25)
    assert [t.due(x) for x in (0.0, 0.125, 0.24, 0.25, 0.375, 0.5)] == [True, False, False, True, False, True]
