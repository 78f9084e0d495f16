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


"""The feedback checks a trace alone can show (part of passive.check_offline): runs of feedback frames, their
continuity and sequence width (CTRL-SEQ-1, CTRL-SEQ-2) across stalls of any length, and their rate and timing
judged on every sample (CTRL-FB-1, CTRL-FB-2), with this host's own lateness left out (host_timing).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..can.protocol import STATES, unwrap
from .host_timing import MARGIN, LateSpans, explains, late_between, late_total, not_judged
from .report import FAIL, NOT_TESTED, PASS, Results
from .trace import Trace

RATE_TOLERANCE = 0.005    # feedback sample rate within +-0.5 % of the configured rate
JITTER_MAX = 2e-3         # [s] 99th minus 1st percentile of the feedback arrival delays
STALL_MAX = 0.05          # [s] feedback silent this long while the controller ticks is a stall (CTRL-FB-2)
NARROW = 1 << 16          # the width a 32-bit sequence must not wrap at
STATE_TICKING = {STATES.index(s) for s in ('running', 'holding', 'ramping_down')}


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
        why = f'every gap ({lost} samples) falls where it was'
        results.put('CTRL-SEQ-1', NOT_TESTED, measured, not_judged(late, why))
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
    late = LateSpans(windows, MARGIN)
    for r in runs:
        seq, t = _every_sample(r)
        if windows:
            keep = ~late.covers(t)
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
