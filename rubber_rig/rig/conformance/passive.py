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


"""The requirements a recording of the bus alone can show: frame periods and counters, CRCs, feedback rate,
timing, continuity and sequence width, status consistency, and the host's duties. Run on the live trace of a
conformance run and on a raw CAN log from a real rig (offline mode) alike.
"""
from __future__ import annotations

import numpy as np

from ..can.protocol import CMD_IDENTIFY, FAULT_NAMES, STATES, STATUS_SEQ_MOD, cycle_time

# (the feedback tolerances, with the others of a trace, are read from this module: spec_doc, docs/protocol.md)
from .feedback import JITTER_MAX, RATE_TOLERANCE, STALL_MAX, STATE_TICKING, check_feedback  # noqa: F401
from .host_timing import explains, not_judged, own_intervals
from .report import FAIL, NOT_TESTED, PASS, Results
from .trace import Trace

PERIODIC = {'ControllerHeartbeat': 'CTRL-HB-1', 'ControllerStatus': 'CTRL-ST-1', 'Temperature': 'CTRL-TEMP-1',
            'ControllerIdentity': 'CTRL-ID-2'}
PERIOD_TOLERANCE = 0.10   # the median interval within +-10 % of the DBC cycle time
GAP_FACTOR = 2.0          # 99 % of the intervals at most twice the cycle time (the host watchdog's margin)
HOST_SILENCE = 0.1        # [s] the driver's default watchdog_timeout: no periodic frame may be silent longer than
#                           this (or GAP_FACTOR periods, if longer): a host would fault (rig/can/liveness.py)
RUN_BREAK = 0.05          # [s] a status this much older than the feedback tells nothing of it (CTRL-ST-3)
STATUS_LEAD = 0.01        # [s] how far ST_LastSequence may be ahead of the feedback received
# the controller's state machine (docs/protocol.md): every change of ST_State must be one of these
TRANSITIONS = {('unconfigured', 'idle'), ('idle', 'running'), ('running', 'holding'), ('holding', 'running'),
               ('running', 'ramping_down'), ('holding', 'ramping_down'), ('ramping_down', 'idle'),
               ('ramping_down', 'fault'), ('idle', 'fault'), ('fault', 'idle'), ('unconfigured', 'fault')}
IDENTIFY_ANSWER = 0.1     # [s] a ControllerIdentity this soon after an IDENTIFY is its answer (CTRL-ID-1), not
#                           one of the periodic frames CTRL-ID-2 times
ABSENT_PERIODS = 5        # a trace of the controller this many periods long must hold its periodic frames


def controller_span(trace: Trace) -> float:
    """Time [s] from the controller's first well-formed frame to its last (0 without one)."""
    t = [f.t for f in trace.frames if f.host is False and not f.malformed]
    return t[-1] - t[0] if t else 0.0


def _absent(trace: Trace, name: str, count: int) -> str:
    """Why `count` frames called `name` fail their requirement ('' when the trace is too short to say): a
    controller heard for ABSENT_PERIODS of the frame's periods must have sent it (a silence is no pass).
    """
    span, period = controller_span(trace), cycle_time(name)
    if span < ABSENT_PERIODS * period:
        return ''
    return (f'{count} {name} frames in {span:.3f} s of controller traffic (specified every '
            f'{period * 1e3:.0f} ms)')


def check_periodic(trace: Trace, results: Results):
    """CTRL-HB-1, CTRL-ST-1, CTRL-TEMP-1, CTRL-ID-2: each periodic frame at its DBC cycle time; absent from a
    trace of the controller long enough to hold ABSENT_PERIODS of its periods, it fails.
    """
    for name, rid in PERIODIC.items():
        period = cycle_time(name)
        t = np.array(_periodic_times(trace, name))
        if t.size < 5:
            absent = _absent(trace, name, t.size)
            results.put(rid, FAIL if absent else NOT_TESTED, f'{t.size} frames',
                        absent or f'fewer than 5 {name} frames in the trace')
            continue
        dt = np.diff(t)
        med, p99, longest = float(np.median(dt)), float(np.percentile(dt, 99)), float(dt.max())
        why = _period_violation(dt, period, name)
        measured = (f'{name}: median {med * 1e3:.1f} ms, 99th percentile {p99 * 1e3:.1f} ms, longest '
                    f'{longest * 1e3:.1f} ms ({t.size} frames)')
        if why and trace.host_late:
            # each interval less the time this host was late around it: what the controller alone can be blamed for
            # (never shortened below the period); the median of all intervals, or of those where the host was on
            # time (a host late in most intervals, and the burst a paced controller sends when it catches up after
            # each, move the median of all)
            own, credited, late = own_intervals(trace.host_late, t, period)
            clean = dt[late == 0]
            if not _period_violation(own, period, name, (dt,) + ((clean,) if clean.size >= 5 else ())):
                results.put(rid, NOT_TESTED, measured + f'; less this host\'s lateness around each interval: 99th '
                            f'percentile {np.percentile(own, 99) * 1e3:.1f} ms, longest {own.max() * 1e3:.1f} ms; '
                            + (f'median where it was on time {np.median(clean) * 1e3:.1f} ms ({clean.size} '
                               'intervals)' if clean.size else 'late around every interval'),
                            not_judged(float(credited.max()), why))
                continue
        results.put(rid, FAIL if why else PASS, measured, why)


def _periodic_times(trace: Trace, name: str) -> list:
    """Arrival times [s] of the controller's periodic `name` frames: for ControllerIdentity without the first one
    within IDENTIFY_ANSWER of each IDENTIFY the host sent (an answer on demand, not the periodic frame: five
    answers in a short trace would make the median period look like 0.3 s).
    """
    times = [f.t for f in trace.valid(name) if f.host is False]
    if name != 'ControllerIdentity':
        return times
    asked = sorted(f.t for f in trace.valid('HostCommand') if f.host and int(f.signals['CMD_Code']) == CMD_IDENTIFY)
    answers = set()
    for t_ask in asked:
        answer = next((t for t in times if t_ask <= t <= t_ask + IDENTIFY_ANSWER and t not in answers), None)
        if answer is not None:
            answers.add(answer)
    return [t for t in times if t not in answers]


def _period_violation(dt, period: float, name: str, median_of=()) -> str:
    """'' when intervals dt [s] meet a period [s] (median within PERIOD_TOLERANCE, 99 % within GAP_FACTOR, none
    longer than the silence a host faults at: HOST_SILENCE, or GAP_FACTOR periods if longer); with `median_of`
    (sets of intervals [s]) the median may meet the period in any one of them instead.
    """
    meds = [float(np.median(x)) for x in (dt, *median_of)]
    med = meds[0]
    p99, longest = float(np.percentile(dt, 99)), float(np.max(dt))
    silence = max(HOST_SILENCE, GAP_FACTOR * period)
    if all(abs(m - period) > PERIOD_TOLERANCE * period for m in meds):
        return f'median interval {med * 1e3:.1f} ms, specified {period * 1e3:.0f} ms +-{PERIOD_TOLERANCE * 100:.0f} %'
    if p99 > GAP_FACTOR * period:
        return f'99 % of the intervals must be at most {GAP_FACTOR * period * 1e3:.0f} ms'
    if longest > silence:
        return (f'{name} silent for {longest * 1e3:.0f} ms: a host faults after {silence * 1e3:.0f} ms of its '
                'silence')
    return ''


def check_counters(trace: Trace, results: Results):
    """CTRL-HB-2 and CTRL-ST-2: counters step by one, states and fault bits are defined values, HB_State is the
    state the status frames report.
    """
    status = [f for f in trace.valid('ControllerStatus') if f.host is False]
    hb = [f for f in trace.valid('ControllerHeartbeat') if f.host is False]
    defined_faults = sum(FAULT_NAMES)
    for rid, frames, counter, modulus in (('CTRL-ST-2', status, 'ST_Counter', 16),
                                          ('CTRL-HB-2', hb, 'HB_Counter', 256)):
        if len(frames) < 2:
            absent = _absent(trace, 'ControllerStatus' if rid == 'CTRL-ST-2' else 'ControllerHeartbeat',
                             len(frames))
            results.put(rid, FAIL if absent else NOT_TESTED, f'{len(frames)} frames',
                        f'no counter to judge: {absent}' if absent else 'too few frames in the trace')
            continue
        c = np.array([int(f.signals[counter]) for f in frames])
        skipped = np.flatnonzero((np.diff(c) - 1) % modulus)
        skips = int(skipped.size)
        # a frame missing where this host was late may be one it failed to read in time
        host_skips = [explains(trace.host_late, frames[i].t, frames[i + 1].t,
                               0.5 * (frames[i + 1].t - frames[i].t)) for i in skipped]
        host_skips = [x for x in host_skips if x]
        states = [int(f.signals['ST_State' if rid == 'CTRL-ST-2' else 'HB_State']) for f in frames]
        bad_state = sum(1 for s in states if s >= len(STATES))
        problems = []
        if skips:
            problems.append(f'{counter} skipped or repeated {skips} times')
        if bad_state:
            problems.append(f'{bad_state} frames with an undefined state')
        if rid == 'CTRL-ST-2':
            undefined = sum(1 for f in frames if int(f.signals['ST_Faults']) & ~defined_faults)
            if undefined:
                problems.append(f'{undefined} frames with undefined fault bits')
            named = [STATES[x] if x < len(STATES) else None for x in states]
            # a change is judged between consecutive frames only: across a frame lost (the counter skipped) the
            # states between are unknown
            steps = (np.diff(c) % modulus) == 1
            # a step of one across a silence where this host was late may be a whole counter cycle it lost (16
            # frames): the states between are unknown then too
            t = np.array([f.t for f in frames])
            for i in np.flatnonzero(steps & (np.diff(t) > 1.5 * cycle_time('ControllerStatus'))):
                steps[i] = not explains(trace.host_late, t[i], t[i + 1], 0.5 * (t[i + 1] - t[i]))
            changes = {(a, b) for a, b, ok in zip(named, named[1:], steps, strict=False)
                       if ok and a != b and a is not None and b is not None}
            illegal = sorted(changes - TRANSITIONS)
            if illegal:
                problems.append('state changes the state machine does not have: '
                                + ', '.join(f'{a} -> {b}' for a, b in illegal))
        else:
            problems += _heartbeat_state(status, hb)
        measured = f'{len(frames)} frames, {skips} counter steps other than +1'
        if rid == 'CTRL-ST-2':
            measured += f', {len(changes)} kinds of state change, all in the state machine' if not illegal else ''
        if skips and len(host_skips) == skips and len(problems) == 1:
            results.put(rid, NOT_TESTED, measured, not_judged(max(host_skips), problems[0]))
            continue
        results.put(rid, FAIL if problems else PASS, measured, '; '.join(problems))


def _heartbeat_state(status: list, hb: list) -> list:
    """HB_State must be the state of the status frame just before or just after the heartbeat."""
    if not status:
        return []
    ts = np.array([f.t for f in status])
    st = [int(f.signals['ST_State']) for f in status]
    wrong = 0
    for f in hb:
        k = int(np.searchsorted(ts, f.t))
        near = {st[i] for i in (k - 1, k) if 0 <= i < len(st)}
        wrong += int(f.signals['HB_State']) not in near
    return [f'{wrong} heartbeats state something no status frame around them does'] if wrong else []


def check_frames(trace: Trace, results: Results):
    """CTRL-FRAME-1: every frame of a controller identifier has its DBC length and a valid CRC."""
    ours = [f for f in trace.frames if f.host is False]
    bad = sum(1 for f in ours if f.malformed)
    if not ours:
        results.put('CTRL-FRAME-1', NOT_TESTED, '', 'no controller frame in the trace')
        return
    results.put('CTRL-FRAME-1', FAIL if bad else PASS, f'{bad} of {len(ours)} controller frames malformed',
                'wrong length or CRC' if bad else '')


def check_status_sequence(trace: Trace, results: Results):
    """CTRL-ST-3: while ticking, ST_LastSequence is at or ahead of the feedback received, by at most
    STATUS_LEAD of samples (plus one frame's worth).
    """
    lead = int(STATUS_LEAD * trace.sample_rate) + 6
    last_fb, last_t, diffs, host = None, 0.0, [], []
    for f in trace.frames:
        if f.host is not False or f.malformed:
            continue
        if f.samples is not None:
            last_fb, last_t = int(f.samples[0]) + len(f.samples[1]) - 1, f.t
        elif f.name == 'ControllerStatus' and int(f.signals['ST_State']) not in STATE_TICKING:
            last_fb = None     # a new stream starts from scratch
        elif f.name == 'ControllerStatus' and last_fb is not None and f.t - last_t <= RUN_BREAK:
            d = (int(f.signals['ST_LastSequence']) - last_fb) % STATUS_SEQ_MOD
            diffs.append(d - STATUS_SEQ_MOD if d >= STATUS_SEQ_MOD // 2 else d)
            beyond = max(diffs[-1] - lead, -6 - diffs[-1])
            if beyond > 0:
                # the feedback of the last |d| samples this host did not read (or a status the simulator on this
                # host sent late): this host's when it was late for at least half the samples beyond the bound
                span = abs(diffs[-1]) / trace.sample_rate
                host.append(explains(trace.host_late, f.t - span, f.t, 0.5 * beyond / trace.sample_rate))
    if not diffs:
        results.put('CTRL-ST-3', NOT_TESTED, '', 'no status frame while the controller was ticking')
        return
    lo, hi = min(diffs), max(diffs)
    ok = lo >= -6 and hi <= lead
    measured = f'ST_LastSequence - last feedback received: {lo}..{hi} samples ({len(diffs)} status frames)'
    if not ok and all(host):
        results.put('CTRL-ST-3', NOT_TESTED, measured + f', {len(host)} out of range where this host was late',
                    not_judged(max(host), f'must be within -6..{lead}'))
        return
    results.put('CTRL-ST-3', PASS if ok else FAIL, measured, '' if ok else f'must be within -6..{lead}')


def check_host(trace: Trace, results: Results):
    """HOST-HB-1, HOST-LIM-1, HOST-STREAM-1 from the host's frames (a log written by the host's driver)."""
    sp = [f for f in trace.frames if f.host and f.samples is not None and not f.malformed]
    if not sp:
        for rid in ('HOST-HB-1', 'HOST-LIM-1', 'HOST-STREAM-1'):
            results.put(rid, NOT_TESTED, '', 'no host setpoint frame in the trace')
        return
    first = sp[0].t
    limits = [f for f in trace.valid('HostLimits') if f.t <= first]
    starts = trace.valid('HostStreamStart')
    if not any(f.t <= first for f in starts):
        results.put('HOST-LIM-1', NOT_TESTED, '', 'the log starts in the middle of a stream')
        results.put('HOST-STREAM-1', NOT_TESTED, '', 'the log starts in the middle of a stream')
    else:
        results.put('HOST-LIM-1', PASS if limits else FAIL, f'{len(limits)} HostLimits frames before the first '
                    'setpoint', '' if limits else 'no HostLimits before the first setpoint')
        unannounced = _unannounced_streams(trace)
        results.put('HOST-STREAM-1', FAIL if unannounced else PASS, f'{len(starts)} HostStreamStart frames, '
                    f'{unannounced} streams without one', '')
    hb = np.array([f.t for f in trace.valid('HostHeartbeat')])
    period = cycle_time('HostHeartbeat')
    spans = _spans([f.t for f in sp], 0.1)
    dts = np.concatenate([np.diff(hb[(hb >= a) & (hb <= b)]) for a, b in spans] + [np.empty(0)])
    if dts.size < 5:
        results.put('HOST-HB-1', NOT_TESTED, f'{dts.size} intervals', 'too few host heartbeats while streaming')
        return
    p99 = float(np.percentile(dts, 99))
    ok = p99 <= GAP_FACTOR * period
    results.put('HOST-HB-1', PASS if ok else FAIL, f'HostHeartbeat while streaming: median {np.median(dts) * 1e3:.1f} '
                f'ms, 99th percentile {p99 * 1e3:.1f} ms, longest {dts.max() * 1e3:.1f} ms',
                '' if ok else f'99 % of the intervals must be at most {GAP_FACTOR * period * 1e3:.0f} ms')


def _spans(times: list, gap: float) -> list:
    out = []
    for t in times:
        if out and t - out[-1][1] <= gap:
            out[-1][1] = t
        else:
            out.append([t, t])
    return out


def _unannounced_streams(trace: Trace) -> int:
    """Setpoint runs after the controller came to rest with no HostStreamStart in between."""
    need, count, prev_state, started = False, 0, None, False
    for f in trace.frames:
        if f.malformed or f.host is None:
            continue
        if f.name == 'HostStreamStart':
            need, started = False, True
        elif f.name == 'ControllerStatus':
            state = STATES[int(f.signals['ST_State'])] if int(f.signals['ST_State']) < len(STATES) else None
            if prev_state == 'ramping_down' and state in ('idle', 'fault'):
                need = True
            prev_state = state
        elif f.host and f.samples is not None and started and need:
            count += 1
            need = False
    return count


def check_offline(trace: Trace) -> Results:
    """Every requirement a trace alone can show (Requirement.offline), on `trace`."""
    results = Results()
    check_frames(trace, results)
    check_periodic(trace, results)
    check_counters(trace, results)
    check_feedback(trace, results)
    check_status_sequence(trace, results)
    check_host(trace, results)
    return results
