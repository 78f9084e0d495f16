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

"""Conformance scenarios of a controller that runs: listening, identification, streaming and stale setpoints
(the ramps, hold and reset while moving: active_ramps); scenarios of active.SCENARIOS, each a function of the
run's link.
"""
from __future__ import annotations

import math

from ..can.protocol import (
    CMD_IDENTIFY,
    PROTOCOL_VERSION,
    unwrap,
)
from .active_ramps import _judge_ramp
from .host_timing import explains, late_total, not_judged
from .link import (
    BUFFER_IN_FLIGHT,
    BUFFER_OUTLIERS,
    IDENTIFY_REPEATS,
    IDENTIFY_TIMEOUT,
    LEAD,
    LSB,
    TOO_FAST_FACTOR,
    Aborted,
    judges,
)
from .report import FAIL, NOT_TESTED, PASS, Stretch


@judges()
def s_listen(link):
    """Listen 1.5 s to the idle controller."""
    link._sleep(1.5)
    if link.state not in ('idle', 'fault', 'unconfigured'):
        raise Aborted(f'the controller is {link.state}, not at rest: conformance starts from rest')
    link.to_rest()


@judges('CTRL-ID-1', 'CTRL-ID-3')
def s_identify(link):
    """IDENTIFY, asked IDENTIFY_REPEATS times (CTRL-ID-1, CTRL-ID-3)."""
    latencies, sig, late = [], None, 0.0
    for k in range(IDENTIFY_REPEATS):
        if k:
            link._sleep(0.25)
        t = link.now()
        link.command(CMD_IDENTIFY)
        if not link._wait(lambda t=t: link.identity is not None and link.identity[0] >= t, 1.0):
            latencies.append(math.inf)
            continue
        at, sig = link.identity
        latencies.append(at - t)
        if at - t > IDENTIFY_TIMEOUT:
            link.merge_host_timing()
            host = explains(link.trace.host_late, t, at, at - t - IDENTIFY_TIMEOUT)
            late = max(late, host) if host else math.inf      # inf: late beyond what this host explains
    if sig is None:
        link.results.put('CTRL-ID-1', FAIL, f'no ControllerIdentity within 1 s of any of {IDENTIFY_REPEATS} '
                         'IDENTIFY', '')
        link.results.put('CTRL-ID-3', FAIL, 'no ControllerIdentity', 'no rated velocity stated')
        return
    version = int(sig['CI_Protocol'])
    slow = [x for x in latencies if x > IDENTIFY_TIMEOUT]
    ok = not slow and version == PROTOCOL_VERSION
    measured = (f'{IDENTIFY_REPEATS} IDENTIFY answered in ' + ', '.join(
        f'{x * 1e3:.1f}' if math.isfinite(x) else 'never' for x in latencies) + f' ms: protocol {version}, '
        f'device 0x{int(sig["CI_Device"]):04x}, firmware {int(sig["CI_Firmware"])}, host timeout '
        f'{float(sig["CI_HostTimeout"]):g} s, rated velocity {float(sig["CI_VelocityMax"]):g} m/s')
    if not ok and version == PROTOCOL_VERSION and 0 < late < math.inf and all(math.isfinite(x) for x in slow):
        link.results.put('CTRL-ID-1', NOT_TESTED, measured, not_judged(late, 'while an answer was due'))
    else:
        link.results.put('CTRL-ID-1', PASS if ok else FAIL, measured,
                         '' if ok else f'every IDENTIFY must be answered with protocol {PROTOCOL_VERSION} within '
                         f'{IDENTIFY_TIMEOUT * 1e3:.0f} ms')
    _judge_rated_velocity(link, float(sig['CI_VelocityMax']))


def _judge_rated_velocity(link, stated: float):
    """CTRL-ID-3: a rated velocity above 0 and at most the envelope's bound is taken as stated; any other is
    flagged here, and CTRL-LIM-3 is tested at the envelope's value instead (s_too_fast).
    """
    bound = link.env.velocity_max
    ok = 0.0 < stated <= bound
    link.results.put('CTRL-ID-3', PASS if ok else FAIL,
                     f'CI_VelocityMax {stated:g} m/s (plausible: above 0, at most {bound:g} m/s, the envelope '
                     'bound)', '' if ok else f'an implausible rated velocity (0, wrong scale or byte order?): '
                     f'CTRL-LIM-3 is tested at the envelope value '
                     f'{link.env.test_velocity(link.fs, TOO_FAST_FACTOR):g} m/s instead')


@judges('CTRL-STREAM-1', 'CTRL-STREAM-3', 'CTRL-STREAM-4', 'CTRL-ST-4', 'CTRL-RAMP-1')
def s_stream(link):
    """Stream, underrun, resume, underrun, ABORT (CTRL-STREAM-1/3/4, CTRL-ST-4, CTRL-RAMP-1)."""
    link.limits(link.env.lower, link.env.upper)
    a = 0.4 * link.env.half
    first, p0 = 1000, link.position
    t0 = link.now()
    # setpoints below HS_FirstSequence, after it was announced: never the start of the stream (CTRL-STREAM-1)
    link.send('HostStreamStart', {'HS_FirstSequence': first})
    per = link.frames.setpoints_per_frame
    for k in range(first - 3 * per, first, per):
        link.send_setpoints(k, [p0] * per, record=False)
    end = link.stream(first, link.smooth(p0, a), 2.0, start=False)
    link._sleep(LEAD + 0.3)                       # underrun: the controller holds
    t_hold = link.now()
    link._sleep(0.3)
    held = link._samples_since(t_hold)
    samples = [s for s in link._samples_since(t0) if first <= s.seq < end]
    # CTRL-STREAM-1: started at the first setpoint with that setpoint
    starts = [s for s in link._samples_since(t0)]
    ok = bool(starts) and starts[0].seq == first and abs(starts[0].u - link.sent[first]) <= 1.5 * LSB
    link.results.put('CTRL-STREAM-1', PASS if ok else FAIL,
                     f'first sample {starts[0].seq if starts else None} (stream start {first}; setpoints from '
                     f'{first - 3 * per} sent after HostStreamStart)',
                     '' if ok else 'the first applied sample must be the first setpoint of the stream: none below '
                     'HS_FirstSequence')
    _judge_applied(link, samples, first, end, 'stream')
    _judge_buffer(link, t0, t_hold)
    # CTRL-STREAM-3: held the last command without a fault
    last = link.sent[end - 1]
    still = held and all(abs(s.u - last) <= 1.5 * LSB for s in held)
    states = {s[1] for s in link._states_since(t_hold)}
    faults = [s[2] for s in link._states_since(t_hold) if s[2]]
    ok = bool(still) and 'holding' in states and not faults
    # resume from the held position, after the controller's current tick
    first2 = link.next_sequence()
    t1 = link.now()
    end2 = link.stream(first2, link.smooth(last, -0.5 * a), 0.5, start=False)
    link._sleep(2 * LEAD + 0.2)                   # the resumed stream starts LEAD ahead and is sent LEAD ahead
    resumed = [s for s in link._samples_since(t1) if first2 <= s.seq < end2]
    ok_resume = len(resumed) == end2 - first2 and all(abs(s.u - link.sent[s.seq]) <= 1.5 * LSB for s in resumed)
    measured = (f'held {len(held)} samples at {last * 1e3:.4f} mm, states {sorted(states)}, resumed '
                f'{len(resumed)} of {end2 - first2} setpoints')
    late = _sent_after_its_tick(link, first2) if ok and not ok_resume else 0.0
    link.results.put('CTRL-STREAM-3', NOT_TESTED if late else PASS if ok and ok_resume else FAIL, measured,
                     not_judged(late, "the resumed stream's first setpoint was sent after its tick: this host's "
                                "view of the controller lagged") if late else '' if ok and ok_resume else
                     'an underrun must hold the last command without a fault and the stream must resume with the '
                     'setpoints that follow', Stretch(t_hold - LEAD, link.now()))
    _judge_ramp(link, target=-a)


def _judge_applied(link, samples: list, first: int, end: int, what: str):
    """CTRL-STREAM-4: every setpoint applied once, at its own sequence. A setpoint this host sent after the
    feedback of its sequence had arrived was late by the host's fault: not judged (counted).
    """
    seqs = [s.seq for s in samples]
    late = {s.seq for s in samples if link.sent_at.get(s.seq, -math.inf) > s.t - 1e-3}
    wrong = sum(1 for s in samples if s.seq not in late and abs(s.u - link.sent.get(s.seq, math.inf)) > 1.5 * LSB)
    ok = seqs == list(range(first, end)) and wrong == 0 and len(late) < 0.05 * len(samples)
    measured = (f'{what}: {len(samples)} of {end - first} setpoints applied, {wrong} different from the '
                f'setpoint of their sequence, {len(late)} sent too late by this host (not judged)')
    # nothing applied wrong: samples never received where this host was late, or setpoints it sent after their
    # tick (more than 5 %: a stall of this host longer than LEAD), are this host's, not the controller's
    contiguous = seqs == list(range(first, end))
    host_late = _missing_while_host_late(link, samples) if not ok and wrong == 0 and not contiguous else 0.0
    sent_late = max((link.sent_at[s.seq] - s.t for s in samples if s.seq in late), default=0.0)
    if not ok and wrong == 0 and seqs == sorted(set(seqs)) and (contiguous or host_late):
        link.results.put('CTRL-STREAM-4', NOT_TESTED, measured, not_judged(
            max(host_late, sent_late), 'every sample never received falls where it was, and every setpoint '
            'applied otherwise was sent after its tick'))
        return
    link.results.put('CTRL-STREAM-4', PASS if ok else FAIL, measured,
                     '' if ok else 'each setpoint must be applied at its sequence')


def _sent_after_its_tick(link, seq: int) -> float:
    """How late [s] this host sent the setpoint of `seq` after the controller had ticked it (the arrival of the
    first sample of that sequence or later: held samples count), 0 if it was in time or that is unknown.
    """
    with link.lock:
        sent = link.sent_at.get(seq)
        ticked = min((s.t for s in link.samples if s.seq >= seq), default=None)
    return sent - ticked if sent is not None and ticked is not None and sent > ticked - 1e-3 else 0.0


def _missing_while_host_late(link, samples: list) -> float:
    """How late this host was [s] where the samples missing between those received are, if every gap falls
    where it was late (it may not have read them in time), else 0.
    """
    link.merge_host_timing()
    worst = 0.0
    for a, b in zip(samples, samples[1:], strict=False):
        if b.seq > a.seq + 1:
            late = explains(link.trace.host_late, a.t, b.t, 0.5 * (b.t - a.t))
            if not late:
                return 0.0
            worst = max(worst, late)
    return worst


def _judge_buffer(link, t0: float, t1: float):
    """CTRL-ST-4: the buffer level the status reports is what the host has queued beyond the last sample."""
    link.merge_host_timing()
    with link.lock:
        log = list(link.sent_log)
    errors, host = [], []        # host: this host's lateness [s] while each level that is off was counted
    for t, state, _, last, level in link._states_since(t0):
        if t > t1 or state != 'running':
            continue
        # counted at most: every frame whose send had begun by t; at least: every frame logged as sent
        # BUFFER_IN_FLIGHT before t
        sent_end = max((f + n for started, _, f, n in log if started <= t), default=None)
        sent_before = max((f + n for _, logged, f, n in log if logged <= t - BUFFER_IN_FLIGHT), default=None)
        if sent_end is None or sent_before is None:
            continue
        full_last = unwrap(last, sent_end, 1 << 16)
        hi, lo = sent_end - 1 - full_last, sent_before - 1 - full_last - link.frames.setpoints_per_frame
        errors.append(0 if lo <= level <= hi else min(abs(level - lo), abs(level - hi)))
        if errors[-1]:
            # setpoints a controller on this host had not read yet because it waited for a CPU: it could not read
            # those of the last `need` seconds (the stream's rate) only if this host was late that long meanwhile
            need = max(errors[-1] - link.frames.setpoints_per_frame, 0) / link.fs
            late = late_total(link.trace.host_late, t - BUFFER_IN_FLIGHT - need - 0.05, t)
            host.append(late if late >= need else 0.0)
    if not errors:
        link.results.put('CTRL-ST-4', NOT_TESTED, '', 'no status frame while running')
        return
    bad, own = sum(1 for e in errors if e), sum(1 for x in host if not x)
    ok = bad <= BUFFER_OUTLIERS * len(errors)
    measured = (f'{len(errors)} status frames while running, {bad} with a level off the queued setpoints (by up '
                f'to {max(errors)})')
    why = f'ST_BufferLevel must count the setpoints queued (at most {BUFFER_OUTLIERS * 100:g} % of the status ' \
          'frames off)'
    if not ok and own <= BUFFER_OUTLIERS * len(errors):
        link.results.put('CTRL-ST-4', NOT_TESTED, measured + f', {bad - own} of them by no more than this host '
                         'was late just before', not_judged(max(host), why))
        return
    link.results.put('CTRL-ST-4', PASS if ok else FAIL, measured, '' if ok else why)


@judges('CTRL-STREAM-2')
def s_stale(link):
    """Setpoints of the old stream after the ramp, without HostStreamStart (CTRL-STREAM-2)."""
    t = link.now()
    with link.lock:
        last = max(link.sent) if link.sent else 0
    link.heartbeat = True
    for k in range(10):
        link.send_setpoints(last + 1 + 19 * k, [link.position] * 19, record=False)
    link._sleep(0.3)
    got = link._samples_since(t)
    states = {s[1] for s in link._states_since(t)}
    ok = not got and states <= {'idle'}
    link.results.put('CTRL-STREAM-2', PASS if ok else FAIL, f'{len(got)} samples taken, states {sorted(states)}',
                     '' if ok else 'a controller at rest must take no setpoint before the next HostStreamStart')
    link.to_rest(link.position)
