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

"""ProgramSession, step by step as the excitation node drives it: a grant, the stream kept `lead` ahead of the
measurement, a hold and a resume on a new grant with the cycles the block had not run, the end once measured.
"""
import numpy as np
import pytest

from rubber_rig.excitation import Program
from rubber_rig.rig.can.stream import StreamGrant
from rubber_rig.safety import Limits
from rubber_rig.session import ProgramSession

from support.rig import FastRig

FS = 1000.0
LIFE = Program.from_yaml_text('name: life\nblocks:\n'
                              '  - {name: life, waveform: sine, frequency: 10 Hz, amplitude: 1 mm, cycles: 20}\n')


def session(first=100):
    grant = StreamGrant(stream_id=7, owner='test', first_sequence=first, position=0.0, velocity=0.0)
    return ProgramSession.on_grant(LIFE, FS, Limits(), grant, lead=500, chunk=50, detectors=[])


class Sink:
    """The batches a session hands on, as (first_sequence, setpoints, block, end)."""

    def __init__(self):
        self.batches = []

    def __call__(self, first, x, block, end):
        self.batches.append((first, np.asarray(x, dtype=float), block, end))

    def setpoints(self, start=0):
        return np.concatenate([x for _, x, _, _ in self.batches[start:]])


def test_the_stream_starts_at_the_grant_and_stays_lead_ahead_of_the_measurement():
    s, sink = session(), Sink()
    s.stream(sink)
    assert sink.batches[0][0] == 100 and sink.setpoints().size == 500     # lead ahead of the grant
    assert s.before_stream(50, 50) and not s.before_stream(60, 50)       # samples before the grant: not ours
    s.measured(100, sink.setpoints()[:200])
    assert s.next_sample == 300 and s.elapsed == 0.2
    s.stream(sink)
    assert sink.setpoints().size == 700 and s.runner.sequence == 800


def test_the_view_says_how_far_the_owner_streamed_and_measured_and_how_old_its_latest_samples_are():
    s, sink = session(), Sink()
    assert s.view(10.0) == ('streamed to sample 100, measured to 100, rig playing unknown, '
                            'latest sample batch never')
    s.stream(sink, now=10.0)
    s.measured(100, sink.setpoints()[:200], now=10.25)      # samples up to 299 arrived at 10.25 s
    # 0.6 s later the rig plays 300 + 600 (its pace from that batch), the owner streamed 100 + 500
    assert s.view(10.85) == ('streamed to sample 600, measured to 300, rig playing 900, '
                             'latest sample batch 0.600 s ago')


def test_a_resumed_block_runs_the_cycles_it_had_not_run_and_ends_once_measured():
    s, sink = session(), Sink()
    while s.measured_sequence < 1100:   # 10 cycles (10 Hz at 1 kHz) measured in 100-sample batches
        s.stream(sink)
        s.measured(s.measured_sequence, sink.setpoints()[s.measured_sequence - 100:][:100])
    assert s.runner.sequence == 1500 and s.why_not_hold() == ''            # 4 more cycles were queued
    s.hold()
    assert s.held and s.held_at == 1100 and s.why_not_hold() == 'cannot hold: the program is held'
    s.measured(1100, np.zeros(300))                 # the hold ramp: counted nowhere
    assert s.elapsed == 1.0
    s.resume(StreamGrant(stream_id=8, owner='test', first_sequence=5000, position=0.0, velocity=0.0))
    assert (s.stream_id, s.start_sequence, s.next_sample, s.held) == (8, 5000, None, False)
    first = len(sink.batches)
    while not s.measured_to_end:                    # the rig measures everything the session hands on
        s.stream(sink)
        s.measured(s.measured_sequence, sink.setpoints(first)[s.measured_sequence - 5000:])
    moving = np.abs(np.diff(sink.setpoints(first))) > 1e-9
    cycles = moving.sum() / FS * 10
    # by the hold (10 cycles measured) the taper cycle and 9 of the 20 full ones had run: the other 11 run, with a
    # taper in and out 13 (a block restarted from its beginning would run 22)
    assert 12.5 < cycles < 13.5, cycles
    assert s.runner.where.cycles_before == {0: 9}
    assert s.runner.finished and not s.runner.aborted


# ---- hold and resume on a rig: the cycle count is exact --------------------------------------------------------------
def run_until(rig, session, stop_at: int, lag: int) -> None:
    """Stream the program to the rig until the rig has run every setpoint before `stop_at`, the session
    measuring `lag` samples behind the rig (what the latency of the bus, the network and the executor does).
    """
    drv, queued = rig.drv, session.start_sequence
    for _ in range(100000):
        if rig.sim.next_seq >= stop_at:         # the simulator's own count (feedback frames carry several)
            return
        measured = max(min(drv.controller_sequence + 1, rig.sim.next_seq) - lag, session.start_sequence)
        rig.feed(session, measured)
        for c in session.due(measured) if queued < stop_at else ():
            n = min(c.displacement.size, stop_at - c.first_sequence)
            assert drv.queue_setpoints(c.first_sequence, c.displacement[:n], session.stream_id), drv.refusal
            queued = c.first_sequence + n
            if queued >= stop_at:
                break
        rig.poll()
        assert not drv.faults, drv.status.fault_messages
    raise AssertionError(f'the rig did not reach sample {stop_at}')


def hold_and_resume(rig, session, stop_at: int, lag: int) -> None:
    """Hold when the rig has run to `stop_at` and the session measured `lag` samples less; resume once held."""
    run_until(rig, session, stop_at, lag)
    assert session.why_not_hold() == ''
    session.hold()
    assert rig.drv.stop_stream(session.stream_id, session.runner.hold_target, 'test hold', hold=True) == ''
    for _ in range(200):                          # the controller's hold ramp, measured while held
        rig.poll()
        if rig.drv.controller_state == 'idle':
            break
    rig.feed(session, 1 << 62)
    assert rig.drv.controller_state == 'idle' and not rig.drv.faults
    session.resume(rig.drv.open_stream('test', session.lead))


def run_to_end(rig, session) -> None:
    for _ in range(100000):
        if session.measured_to_end:
            return
        rig.feed(session, 1 << 62)
        session.stream(lambda first, x, block, end: (
            len(x) and rig.drv.queue_setpoints(first, x, session.stream_id), end and rig.drv.end_stream(
                session.stream_id)))
        rig.poll()
        assert not rig.drv.faults, rig.drv.status.fault_messages
    raise AssertionError('the program did not end')


def full_cycles(rig, amplitude: float, per_cycle: int, mean: float = 0.0) -> int:
    """Complete full-amplitude cycles of the sine in the command the rig applied: `per_cycle` samples from a
    rising crossing of the mean that follow amplitude * sin(2 pi k / per_cycle) to the 0.1 um of the frames (open
    loop: the command is the program's). A taper cycle does not, nor does a cycle cut short by a hold ramp.
    """
    seq = np.array(sorted(rig.samples))
    assert np.all(np.diff(seq) == 1), 'samples lost on the simulated bus'
    u = np.array([rig.samples[k][0] for k in seq]) - mean
    ideal = amplitude * np.sin(2 * np.pi * np.arange(per_cycle) / per_cycle)
    rising = np.nonzero((u[:-1] < -1e-9) & (u[1:] >= -1e-9))[0] + 1
    return sum(1 for a in rising if a + per_cycle <= u.size and np.abs(u[a:a + per_cycle] - ideal).max() < 2e-7)


def durability(cycles=20, mean='0 mm', extra=''):
    return Program.from_yaml_text(f'name: life\ninitial_position: {mean}\nblocks:\n  - {{name: life, waveform: sine, '
                                  f'frequency: 10 Hz, amplitude: 1 mm, mean: {mean}, cycles: {cycles}}}\n' + extra)


@pytest.fixture
def rig():
    r = FastRig()
    r.wait_ready()
    yield r
    r.close()


# where the rig is, in samples of the block (10 Hz at 1 kHz: 100 a cycle; the taper cycle first), when the hold
# reaches it -> the full cycles it had run; the session measures `lag` samples behind the rig
HOLD_PHASES = {
    'taper-in': (50, 0),
    'end of the taper': (100, 0),
    'start of a cycle': (800, 7),
    'a sample before a cycle ends': (799, 6),
    'a sample into a cycle': (801, 7),
    'mid-cycle': (850, 7),
    'last full cycle': (2050, 19),
    'taper-out': (2150, 20),
}


@pytest.mark.parametrize('lag', [0, 300])
@pytest.mark.parametrize('phase', list(HOLD_PHASES))
def test_a_held_durability_block_runs_exactly_the_cycles_it_still_owes(rig, phase, lag):
    """20 full cycles at 10 Hz held at every phase of the block, the measurement 0 or 300 samples behind the rig
    (the lead the excitation streams ahead is 500): the resumed block runs the full cycles the rig had not
    finished where its hold ramp began - 20 full-amplitude cycles in the applied command in all, never one more
    or less - and the summary counts the block's 20.
    """
    at, done = HOLD_PHASES[phase]
    program = durability()
    grant = rig.drv.open_stream('test', 500)
    s = ProgramSession.on_grant(program, FS, rig.cfg.limits, grant, lead=500, chunk=50, detectors=[])
    start = grant.first_sequence
    hold_and_resume(rig, s, start + at, lag)
    assert s.left_at == start + at, (s.held_at, s.left_at)     # found in the applied command, not the measurement
    assert s.runner.where.cycles_before.get(0, 0) == (done if done < 20 else 0)
    run_to_end(rig, s)
    assert full_cycles(rig, 1e-3, 100) == 20
    summary = s.runner.block_summaries[0]
    assert summary.cycles == 20 and summary.completed, summary


def test_a_hold_near_a_block_end_resumes_the_block_the_rig_was_in_not_the_one_generated_next(rig):
    """Streamed ahead into the second block when the hold reaches the rig 30 samples before the end of the first:
    the first block runs its last cycle again (with its tapers), then the second runs whole: 20 + 5 full cycles.
    """
    program = durability(extra='  - {name: after, waveform: sine, frequency: 10 Hz, amplitude: 1 mm, cycles: 5}\n')
    grant = rig.drv.open_stream('test', 500)
    s = ProgramSession.on_grant(program, FS, rig.cfg.limits, grant, lead=500, chunk=50, detectors=[])
    start = grant.first_sequence
    hold_and_resume(rig, s, start + 2070, lag=400)
    assert s.runner.where.cycles_before == {0: 19}
    run_to_end(rig, s)
    assert full_cycles(rig, 1e-3, 100) == 25
    assert [(b.cycles, b.completed) for b in s.runner.block_summaries] == [(20, True), (5, True)]


def test_a_hold_during_the_approach_restarts_the_program_from_its_start(rig):
    """A block about a 0.3 mm mean: the rig approaches it from 0 first. Held on the approach, the program
    starts from its beginning on resume and runs its 20 full cycles.
    """
    program = durability(mean='0.3 mm')
    grant = rig.drv.open_stream('test', 500)
    s = ProgramSession.on_grant(program, FS, rig.cfg.limits, grant, lead=500, chunk=50, detectors=[])
    assert s.runner.state == 'approaching'
    hold_and_resume(rig, s, grant.first_sequence + 20, lag=0)
    assert s.runner.where.cycles_before == {}
    run_to_end(rig, s)
    assert full_cycles(rig, 1e-3, 100, mean=0.3e-3) == 20


def test_goal_admission_reserves_at_acceptance_and_counts_every_goal_it_turns_away():
    from rubber_rig.session import GoalAdmission
    admission = GoalAdmission()
    assert admission.reject() == '' and admission.rejected == 0          # nothing runs: a goal may start
    admission.reserve()                                                  # accepted, not yet executing
    assert admission.reject().startswith('busy: goal accepted is running')
    admission.start(bytes.fromhex('1a2b3c4d5e6f'))
    why = admission.reject('durability')
    assert why == "busy: program 'durability' of goal 1a2b3c4d is running; one program at a time"
    assert (admission.rejected, admission.last_rejection) == (2, why)
    admission.finish()
    assert admission.reject() == '' and admission.rejected == 2


def test_rig_time_counts_samples_from_the_latest_batch_stamp():
    from rubber_rig.session import RigTime
    clock = RigTime()
    assert clock.of(100, 1e-3, now=5.0) == 5.0                           # before any sample: the first applies now
    assert clock.of(150, 1e-3, now=9.0) == pytest.approx(5.05)
    clock.observe(1000, 12.0)
    assert clock.of(1500, 1e-3, now=0.0) == pytest.approx(12.5) and clock.of(990, 1e-3, now=0.0) == pytest.approx(11.99)
