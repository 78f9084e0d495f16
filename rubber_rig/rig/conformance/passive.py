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

from dataclasses import dataclass, field

import numpy as np

from ..can.protocol import FAULT_NAMES, STATES, STATUS_SEQ_MOD, cycle_time, unwrap
from .host_timing import MARGIN, explains, late_between, late_total, not_judged
from .report import FAIL, NOT_TESTED, PASS, Results
from .trace import Trace

PERIODIC = {'ControllerHeartbeat': 'CTRL-HB-1', 'ControllerStatus': 'CTRL-ST-1', 'Temperature': 'CTRL-TEMP-1',
            'ControllerIdentity': 'CTRL-ID-2'}
PERIOD_TOLERANCE = 0.10   # the median interval within +-10 % of the DBC cycle time
GAP_FACTOR = 2.0          # 99 % of the intervals at most twice the cycle time (the host watchdog's margin)
HOST_SILENCE = 0.1        # [s] the driver's default watchdog_timeout: no periodic frame may be silent longer than
#                           this (or GAP_FACTOR periods, if longer): a host would fault (rig/can/liveness.py)
RATE_TOLERANCE = 0.005    # feedback sample rate within +-0.5 % of the configured rate
JITTER_MAX = 2e-3         # [s] 99th minus 1st percentile of the feedback arrival delays
RUN_BREAK = 0.05          # [s] a status this much older than the feedback tells nothing of it (CTRL-ST-3)
STALL_MAX = 0.05          # [s] feedback silent this long while the controller ticks is a stall (CTRL-FB-2)
STATUS_LEAD = 0.01        # [s] how far ST_LastSequence may be ahead of the feedback received
STATE_TICKING = {STATES.index(s) for s in ('running', 'holding', 'ramping_down')}
NARROW = 1 << 16          # the width a 32-bit sequence must not wrap at
# the controller's state machine (docs/protocol.md): every change of ST_State must be one of these
TRANSITIONS = {('unconfigured', 'idle'), ('idle', 'running'), ('running', 'holding'), ('holding', 'running'),
               ('running', 'ramping_down'), ('holding', 'ramping_down'), ('ramping_down', 'idle'),
               ('ramping_down', 'fault'), ('idle', 'fault'), ('fault', 'idle'), ('unconfigured', 'fault')}


@dataclass
class FeedbackRun:
    """Feedback frames of one stretch of ticking (from a status of a ticking state to one of a state that takes
    no tick): arrival time, full sequence of each frame's newest sample and its sample count. Silence inside a
    run never starts a new one: continuity is judged across stalls of any length, and the longest stall is kept.
    """

    t: list = field(default_factory=list)
    last: list = field(default_factory=list)
    count: list = field(default_factory=list)
    longest_stall: float = 0.0
    stall_at: int = 0       # sequence of the first sample after the longest stall
    gap_times: list = field(default_factory=list)    # (t before, t after, samples lost) of every gap
    stalls: list = field(default_factory=list)       # (t before, t after) of every silence above STALL_MAX
    next: int = 0
    offset: int = 0
    gaps: int = 0
    lost: int = 0
    repeats: int = 0
    narrow_wraps: int = 0
    crossings: int = 0      # 2**16 boundaries crossed with the right sequence numbers
    field_wraps: int = 0    # sequence field wrapped at its full width


def feedback_runs(trace: Trace) -> list:
    """The controller's feedback frames grouped into runs, sequences unwrapped and checked for continuity.

    A run ends only where a status frame reports a state that takes no tick (idle, fault, unconfigured): the next
    stream may then start anywhere. A silence of any length while ticking stays inside the run, so samples lost
    across it are counted (a run split at every pause would hide them).
    """
    runs, cur, prev_raw = [], None, None
    for f in trace.frames:
        if f.host is False and f.name == 'ControllerStatus' and not f.malformed \
                and int(f.signals['ST_State']) not in STATE_TICKING:
            cur = None    # the controller stopped ticking: the next stream may start anywhere (no gap)
            continue
        if f.host is not False or f.samples is None or f.malformed:
            continue
        raw, xs = int(f.samples[0]), f.samples[1]
        n, mod = len(xs), trace.modulus[f.name]
        if cur is None:
            cur = FeedbackRun(next=raw)
            runs.append(cur)
            prev_raw = raw
        else:
            if f.t - cur.t[-1] > STALL_MAX:
                cur.stalls.append((cur.t[-1], f.t))
            if f.t - cur.t[-1] > cur.longest_stall:
                cur.longest_stall = f.t - cur.t[-1]
                cur.stall_at = -1          # set below, once the frame's sequence is unwrapped
        full_raw = unwrap(raw, prev_raw, mod)
        if raw < prev_raw % mod and full_raw > prev_raw:
            cur.field_wraps += 1
        full = full_raw + cur.offset
        if full < cur.next and mod > NARROW and (cur.next - full) % NARROW == 0 and raw % NARROW == 0 \
                and cur.next % NARROW == 0:
            cur.narrow_wraps += 1           # restarted at 0 after 65535 in a wider field
            cur.offset += cur.next - full
            full = cur.next
        if full > cur.next:
            cur.gaps += 1
            cur.lost += full - cur.next
            cur.gap_times.append((cur.t[-1] if cur.t else f.t, f.t, full - cur.next))
        elif full < cur.next:
            cur.repeats += 1
        if full // NARROW != (full + n - 1) // NARROW or (full % NARROW == 0 and cur.t and full == cur.next):
            cur.crossings += 1
        prev_raw = full_raw
        if cur.stall_at == -1:
            cur.stall_at = full
        cur.next = max(cur.next, full + n)
        cur.t.append(f.t)
        cur.last.append(full + n - 1)
        cur.count.append(n)
    return runs


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
        t = np.array([f.t for f in trace.valid(name) if f.host is False])
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
            late = np.array([late_total(trace.host_late, a, b) for a, b in zip(t, t[1:], strict=False)])
            own = np.maximum(dt - late, 0.0)
            if not _period_violation(own, period, name):
                results.put(rid, NOT_TESTED, measured + f'; less this host\'s lateness around each interval: 99th '
                            f'percentile {np.percentile(own, 99) * 1e3:.1f} ms, longest {own.max() * 1e3:.1f} ms',
                            not_judged(float(late.max()), why))
                continue
        results.put(rid, FAIL if why else PASS, measured, why)


def _period_violation(dt, period: float, name: str) -> str:
    """'' when intervals dt [s] meet a period [s] (median within PERIOD_TOLERANCE, 99 % within GAP_FACTOR, none
    longer than the silence a host faults at: HOST_SILENCE, or GAP_FACTOR periods if longer).
    """
    med, p99, longest = float(np.median(dt)), float(np.percentile(dt, 99)), float(np.max(dt))
    silence = max(HOST_SILENCE, GAP_FACTOR * period)
    if abs(med - period) > PERIOD_TOLERANCE * period:
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
            named = [STATES[x] for x in states if x < len(STATES)]
            changes = {(a, b) for a, b in zip(named, named[1:], strict=False) if a != b}
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


def check_feedback(trace: Trace, results: Results, runs: list = None):
    """CTRL-SEQ-1, CTRL-SEQ-2, CTRL-FB-1, CTRL-FB-2 from the runs of feedback frames."""
    runs = feedback_runs(trace) if runs is None else runs
    if not runs:
        for rid in ('CTRL-SEQ-1', 'CTRL-SEQ-2', 'CTRL-FB-1', 'CTRL-FB-2'):
            results.put(rid, NOT_TESTED, '', 'no feedback frame in the trace')
        return
    samples = sum(r.last[-1] - r.last[0] + 1 for r in runs)
    gaps, lost, repeats = (sum(getattr(r, k) for r in runs) for k in ('gaps', 'lost', 'repeats'))
    measured = f'{len(runs)} runs, {samples} samples, {gaps} gaps ({lost} samples), {repeats} repeats'
    # a gap across a stretch in which this host was late may be frames this host failed to read in time
    host_gaps = [(a, b, n) for r in runs for a, b, n in r.gap_times if explains(trace.host_late, a, b, 0.5 * (b - a))]
    if gaps and not repeats and len(host_gaps) == gaps:
        late = max(late_total(trace.host_late, a, b) for a, b, _ in host_gaps)
        results.put('CTRL-SEQ-1', NOT_TESTED, measured, not_judged(late, f'every gap ({lost} samples) falls where '
                                                                          'it was'))
    else:
        results.put('CTRL-SEQ-1', FAIL if gaps or repeats else PASS, measured,
                    'feedback sequences must be contiguous' if gaps or repeats else '')
    narrow, crossings, wraps = (sum(getattr(r, k) for r in runs) for k in ('narrow_wraps', 'crossings', 'field_wraps'))
    measured = f'{crossings} crossings of a 2^16 boundary, {wraps} wraps of the sequence field'
    if narrow:
        results.put('CTRL-SEQ-2', FAIL, measured, f'the sequence restarted at 0 after 65535 {narrow} times in a '
                    'field the DBC makes wider (32 bit)')
    elif crossings or wraps:
        results.put('CTRL-SEQ-2', PASS, measured)
    else:
        results.put('CTRL-SEQ-2', NOT_TESTED, measured, 'the trace never crosses a 2^16 sequence boundary')
    long_runs = [r for r in runs if len(r.t) >= 100 and r.t[-1] - r.t[0] >= 0.5]
    if not long_runs:
        for rid in ('CTRL-FB-1', 'CTRL-FB-2'):
            results.put(rid, NOT_TESTED, '', 'no feedback run of 0.5 s or more')
        return
    _judge_feedback_timing(trace, results, long_runs, runs)


def _feedback_timing(runs: list, windows: list, fs: float) -> tuple:
    """(rates [Hz], spreads [s], samples left out) of the runs, from every sample outside the host-late windows."""
    rates, spreads, left_out = [], [], 0
    for r in runs:
        seq, t = _every_sample(r)
        if windows:
            keep = np.ones(t.size, dtype=bool)
            for a, b in windows:
                keep &= ~((t >= a - MARGIN) & (t <= b + MARGIN))
            left_out += int(t.size - keep.sum())
            seq, t = seq[keep], t[keep]
        if t.size < 100:
            continue
        slope, icpt = np.polyfit(seq - seq[0], t, 1)
        resid = t - (icpt + slope * (seq - seq[0]))
        rates.append(1.0 / slope)
        spreads.append(float(np.percentile(resid, 99) - np.percentile(resid, 1)))
    return rates, spreads, left_out


def _judge_feedback_timing(trace: Trace, results: Results, long_runs: list, runs: list):
    """CTRL-FB-1 and CTRL-FB-2; a verdict that fails only where this host was late is not judged."""
    fs, windows = trace.sample_rate, trace.host_late
    rates, spreads, _ = _feedback_timing(long_runs, [], fs)
    stalls = [st for r in runs for st in r.stalls]
    longest = max(runs, key=lambda r: r.longest_stall)
    rate_bad = [r for r in rates if abs(r / fs - 1) > RATE_TOLERANCE]
    spread = max(spreads, default=0.0)
    own_stalls = [(a, b) for a, b in stalls if not explains(windows, a, b, (b - a) - STALL_MAX)]
    late = max((late_between(windows, r.t[0], r.t[-1]) for r in runs), default=0.0)
    kept_rates, kept_spreads, left_out = _feedback_timing(long_runs, windows, fs) if windows else (rates, spreads, 0)
    rate_text = f'{len(rates)} runs, rate {min(rates):.2f}..{max(rates):.2f} Hz (configured {fs:g} Hz)'
    if not rate_bad:
        results.put('CTRL-FB-1', PASS, rate_text)
    elif windows and all(abs(r / fs - 1) <= RATE_TOLERANCE for r in kept_rates):
        # (no run left long enough once this host's late stretches are left out: nothing to judge either)
        kept = (f'rate {min(kept_rates):.2f}..{max(kept_rates):.2f} Hz' if kept_rates else
                'no run of 100 samples left')
        results.put('CTRL-FB-1', NOT_TESTED, rate_text + f'; {left_out} samples where this host was late left out: '
                    + kept, not_judged(late, 'within the runs'))
    else:
        results.put('CTRL-FB-1', FAIL, rate_text, f'off by more than {RATE_TOLERANCE * 100:g} %')
    measured = (f'arrival jitter of every sample (99th - 1st percentile) {spread * 1e3:.2f} ms (worst of '
                f'{len(spreads)} runs), longest silence while ticking {longest.longest_stall * 1e3:.1f} ms')
    why = [f'jitter more than {JITTER_MAX * 1e3:g} ms'] if spread > JITTER_MAX else []
    if stalls:
        why.append(f'feedback stalled {longest.longest_stall * 1e3:.1f} ms before sample {longest.stall_at} while '
                   f'ticking (at most {STALL_MAX * 1e3:g} ms)')
    if not why:
        results.put('CTRL-FB-2', PASS, measured)
        return
    kept_spread = max(kept_spreads, default=0.0)     # no run left once this host's late stretches are out
    if windows and not own_stalls and kept_spread <= JITTER_MAX:
        kept = f'jitter {kept_spread * 1e3:.2f} ms' if kept_spreads else 'no run of 100 samples left'
        results.put('CTRL-FB-2', NOT_TESTED, measured + f'; {left_out} samples where this host was late left out: '
                    f'{kept}, {len(stalls)} stalls all where it was late',
                    not_judged(late, '; '.join(why)))
        return
    results.put('CTRL-FB-2', FAIL, measured, '; '.join(why))


def _every_sample(run: FeedbackRun) -> tuple:
    """(sequence, arrival time [s]) of every sample of a run: each sample of a frame that packs several arrives
    with its frame, so a controller that gathers samples into late frames shows their latency.
    """
    count = np.asarray(run.count)
    last = np.repeat(np.asarray(run.last, dtype=float), count)
    back = np.concatenate([np.arange(n - 1, -1, -1) for n in run.count]) if len(count) else np.empty(0)
    return last - back, np.repeat(np.asarray(run.t), count)


def check_status_sequence(trace: Trace, results: Results):
    """CTRL-ST-3: while ticking, ST_LastSequence is at or ahead of the feedback received, by at most
    STATUS_LEAD of samples (plus one frame's worth).
    """
    lead = int(STATUS_LEAD * trace.sample_rate) + 6
    last_fb, last_t, diffs = None, 0.0, []
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
    if not diffs:
        results.put('CTRL-ST-3', NOT_TESTED, '', 'no status frame while the controller was ticking')
        return
    lo, hi = min(diffs), max(diffs)
    ok = lo >= -6 and hi <= lead
    results.put('CTRL-ST-3', PASS if ok else FAIL, f'ST_LastSequence - last feedback received: {lo}..{hi} samples '
                f'({len(diffs)} status frames)', '' if ok else f'must be within -6..{lead}')


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
