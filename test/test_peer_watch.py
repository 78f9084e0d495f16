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

"""What the excitation says besides its setpoints (session.peer_watch) on simulated time: which peer went silent
and beats again, this node's own stall and for how long /diagnostics shows it, the diagnostics' level and words, and
the result's message. No ROS; the wiring is tested with the nodes in test_nodes_blame.py.
"""
from types import SimpleNamespace

from rubber_rig.session.peer_watch import STALL_SHOWN, PeerWatch, program_diagnosis, result_message

ME, DRIVER = '/rig1/excitation', '/rig1/rig_driver'


def beats(watch, node, start, end, count=0, period=0.25):
    """``node`` beats every ``period`` from ``start`` up to ``end`` [s] (stamped on a clock 1000 s ahead)."""
    t = start
    while t <= end:
        watch.beat(node, 42, count, t + 1000.0, t)
        t, count = t + period, count + 1
    return count


def test_a_peer_is_named_silent_after_silent_seconds_and_beating_again_once():
    w = PeerWatch(ME)
    n = beats(w, DRIVER, 0.0, 1.0)
    assert w.watch(1.75, running=False).silent == {}                # exactly 0.75 s after its last beat
    news = w.watch(1.875, running=False)
    assert news.silent == {DRIVER: 0.875} and news.changed
    assert w.watch(2.0, running=False).silent == {}                 # said once per silence
    w.beat(DRIVER, 42, n, 2.0 + 1000.0, 2.0)
    news = w.watch(2.0, running=False)
    assert news.beating_again == [DRIVER] and news.changed and w.silent_now == {}
    w.beat(ME, 1, 0, 0.0, 2.0)                                       # its own beat is no peer's
    assert ME not in w.beats.last


def run(watch, start, end, running, peers=()):
    """This node's 0.125 s watch timer from ``start`` to ``end`` [s], with ``peers`` beating every 0.25 s."""
    t = start
    while t <= end:
        for node in peers:
            if t % 0.25 == 0:
                watch.beat(node, 42, int(t * 4), t + 1000.0, t)
        watch.watch(t, running)
        t += 0.125


def test_a_silence_during_a_program_is_kept_for_its_result_but_one_from_before_is_not():
    w = PeerWatch(ME)
    recorder = '/rig1/recorder'
    run(w, 0.0, 1.0, False, (DRIVER, recorder))
    run(w, 1.125, 2.0, False, (recorder,))                          # the driver falls silent before the program
    assert DRIVER in w.silent_now
    w.start_program(2.0)
    run(w, 2.125, 3.0, True, (recorder,))
    assert w.silent_seen == {}
    run(w, 3.125, 4.0, True)                                         # the recorder stops beating during it
    assert w.silent_seen == {recorder: 1.0}
    assert w.words(4.0) == [f'silent during the program: {recorder} up to 1.0 s (still silent)']


def test_this_nodes_stall_is_said_for_stall_shown_seconds():
    w = PeerWatch(ME)
    w.watch(0.0, running=False)
    assert w.watch(2.0, running=False).stall == (0.0, 2.0)           # 2 s without a callback: its own stall
    assert w.stalled(2.0 + STALL_SHOWN - 1 / 1024) == 'this node stalled for 2.0 s (its callbacks did not run)'
    assert w.stalled(2.0 + STALL_SHOWN) == ''


def test_the_diagnostics_warn_for_what_an_operator_must_look_at_and_say_the_first_of_it():
    record = SimpleNamespace(action='record', message='cycle 10 judged')
    hold = SimpleNamespace(action='hold', message='residual 6 > 5')
    ok = program_diagnosis('running', 'p', [record], '', '', {}, '')
    assert not ok.warn and ok.message == 'program running' and ok.values['detector_events'] == 1
    held = program_diagnosis('held', 'p', [record, hold], '', '', {}, '')
    assert held.warn and held.message == 'residual 6 > 5' and held.values['last_event'] == 'residual 6 > 5'
    silent = program_diagnosis('running', 'p', [], 'no cycle_metrics', 'recording lost', {DRIVER: 1.25}, '')
    assert silent.warn and silent.message == f'nodes silent: {DRIVER} (1.2 s)'
    stalled = program_diagnosis('idle', '', [], '', '', {DRIVER: 1.25}, 'this node stalled for 2.0 s')
    assert stalled.message == 'this node stalled for 2.0 s'          # its own stall first: not the others' fault


def test_the_result_says_what_else_happened():
    assert result_message('completed') == 'completed'
    assert result_message('completed', 'no cycle_metrics', 'recording complete in a.mcap', 'lost', ['x']) == \
        'completed (detectors were blind: no cycle_metrics) (recording complete in a.mcap) (x)'
    assert result_message('aborted', lost='recording lost from about sample 5') == \
        'aborted (recording lost from about sample 5)'
