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


"""Conformance scenarios of ramps and braking: the ABORT or DISABLE ramp to a target (CTRL-RAMP-1), HOLD
(CTRL-RAMP-2) and RESET while the rig moves (CTRL-RESET-1) (scenarios of active.SCENARIOS: each a function of
the run's link).
"""
from __future__ import annotations

import math

from ...safety import DECEL_MAX
from ..can.protocol import CMD_ABORT, CMD_DISABLE, CMD_HOLD, CMD_RESET
from .link import LEAD, LSB, RAMP_VELOCITY, REACTION, REST_TIMEOUT, WAVE_FREQUENCY, judges
from .report import FAIL, PASS, Stretch
from .shape import ramp_shape

COMMAND = {CMD_ABORT: 'ABORT', CMD_DISABLE: 'DISABLE'}


def _judge_ramp(link, target: float, code: int = CMD_ABORT):
    """ABORT (or DISABLE, `code`) from holding to target at RAMP_VELOCITY (CTRL-RAMP-1). The ramp starts where
    the last sample that arrived before the command was (by its arrival time on the bus, read once the ramp is
    over: the run's view when it commanded may lag behind the bus on a busy host).
    """
    t = link.now()
    link.command(code, target, RAMP_VELOCITY)
    done = link._wait(lambda: link.state in ('idle', 'fault'), REST_TIMEOUT)
    link._sleep(0.05)
    ramp = link._samples_since(t)
    if not done or not ramp:
        link.results.put('CTRL-RAMP-1', FAIL, f'{COMMAND[code]}: state {link.state} after {REST_TIMEOUT:g} s',
                         'no ramp to rest', Stretch(t, link.now(), excess=REST_TIMEOUT, tolerance=math.inf))
        link.to_rest(link.position)
        return
    start = _last_before(link, t, ramp[0].seq)
    p0 = start.u if start is not None else ramp[0].u
    u = [p0] + [s.u for s in ramp]
    moving = [s for s, a, b in zip(ramp, u, u[1:], strict=False) if abs(b - a) > 0.5 * LSB]
    duration = (moving[-1].seq - ramp[0].seq + 1) / link.fs if moving else 0.0
    allowed = 1.5 * abs(target - p0) / RAMP_VELOCITY + REACTION
    # samples never received (between the start and the ramp, or within it): judged per sample
    seqs = [start.seq if start is not None else ramp[0].seq - 1] + [s.seq for s in ramp]
    shape = ramp_shape(u, link.fs, target, RAMP_VELOCITY, gaps=[b - a for a, b in zip(seqs, seqs[1:], strict=False)])
    ok = (abs(u[-1] - target) <= 1e-6 and shape.ok and duration <= allowed and not link.faults
          and link.state == 'idle')
    link.results.put('CTRL-RAMP-1', PASS if ok else FAIL,
                     f'{COMMAND[code]}: {p0 * 1e3:.4f} -> {u[-1] * 1e3:.4f} mm (target {target * 1e3:.4f}) '
                     f'in {duration:.3f} s '
                     f'(at most {allowed:.3f} s) at {RAMP_VELOCITY * 1e3:g} mm/s commanded: {shape.describe()}, '
                     f'state {link.state}',
                     '' if ok else shape.why() or 'the ramp must reach its target at the commanded velocity '
                     'without a step and end idle',
                     Stretch(t, ramp[-1].t, excess=duration - allowed if duration > allowed else None,
                             # too long, and nothing else wrong: only lateness of the excess explains it
                             tolerance=math.inf if shape.ok and abs(u[-1] - target) <= 1e-6 else None))
    link.to_rest()


def _last_before(link, t: float, seq: int):
    """The last Sample that arrived before `t` [s] with a sequence below `seq` (the stream the ramp went on from,
    within a second of samples), None if there is none.
    """
    with link.lock:
        return next((s for s in reversed(link.samples) if s.t < t and seq - link.fs <= s.seq < seq), None)


@judges('CTRL-RAMP-2')
def s_hold(link):
    """HOLD while moving (CTRL-RAMP-2)."""
    a = 0.4 * link.env.half
    p0 = link.position
    first = link.next_sequence() + 1000
    box = {}
    base = link.smooth(p0, -a if p0 > 0 else a)
    k_hold = int((0.25 / WAVE_FREQUENCY + LEAD) * link.fs)    # the controller is at full speed then

    def wave(k):
        if k == k_hold and 'hold' not in box:
            box['hold'] = link.now()
            link.command(CMD_HOLD, 0.0, RAMP_VELOCITY)
        return base(k)
    t = link.now()
    link.stream(first, wave, k_hold / link.fs + 0.2)          # HOLD goes out at k_hold, mid-stream
    done = link._wait(lambda: link.state in ('idle', 'fault'), REST_TIMEOUT)
    link._sleep(0.05)
    t_hold = box.get('hold', t)
    before = [s for s in link._samples_since(t) if s.t < t_hold]
    after = link._samples_since(t_hold)
    u = [s.u for s in before[-3:] + after]
    v = [(b - a) * link.fs for a, b in zip(u, u[1:], strict=False)]
    acc = [abs(b - a) * link.fs for a, b in zip(v, v[1:], strict=False)]
    decel = DECEL_MAX
    still = bool(after) and len(v) >= 2 and abs(v[-1]) <= 2 * LSB * link.fs
    peak_v = max((abs(x) for x in v[:3]), default=0.0)
    ok = done and still and max(acc, default=0) <= decel * 1.1 + 4 * LSB * link.fs ** 2 and not link.faults \
        and link.state == 'idle'
    link.results.put('CTRL-RAMP-2', PASS if ok else FAIL,
                     f'from {peak_v * 1e3:.2f} mm/s to a stop at {(u[-1] if u else math.nan) * 1e3:.4f} mm in '
                     f'{len(after)} samples, '
                     f'peak deceleration {max(acc, default=0):.1f} m/s^2 (HostLimits {decel:g}), '
                     f'state {link.state}',
                     '' if ok else 'HOLD must brake to a stop without a step and end idle without a fault')
    link.to_rest(link.position)


@judges('CTRL-RESET-1', 'CTRL-RAMP-1')
def s_reset_moving(link):
    """RESET while running, DISABLE, RESET while ramping (CTRL-RESET-1, CTRL-RAMP-1)."""
    a = 0.4 * link.env.half
    p0 = link.position
    first = link.next_sequence() + 1000
    t = link.now()
    box = {}
    base = link.smooth(p0, -a if p0 > 0 else a)

    def wave(k):
        if k == int(0.5 * link.fs) and 'reset' not in box:
            box['reset'] = link.now()
            link.command(CMD_RESET)
        return base(k)
    end = link.stream(first, wave, 1.2)
    link._sleep(LEAD + 0.05)
    after = [s for s in link._samples_since(box.get('reset', t)) if s.seq < end]
    states = link._states_before(box.get('reset', t), end)
    ok = bool(after) and states <= {'running'} and all(abs(s.u - link.sent[s.seq]) <= 1.5 * LSB for s in after)
    link.results.put('CTRL-RESET-1', PASS if ok else FAIL,
                     f'after RESET while running: {len(after)} samples as streamed, states {sorted(states)}',
                     '' if ok else 'RESET while the rig moves must change nothing', Stretch(t, link.now()))
    # DISABLE from holding: a ramp like ABORT's (CTRL-RAMP-1)
    _judge_ramp(link, _ramp_target(link), CMD_DISABLE)
    _reset_while_ramping(link)


def _ramp_target(link) -> float:
    """A target 0.6 x the envelope's half from the present position, inside 0.8 x the envelope."""
    p0 = link.position
    return p0 - 0.6 * link.env.half if p0 > 0 else p0 + 0.6 * link.env.half


def _reset_while_ramping(link):
    """CTRL-RESET-1: RESET during an ABORT ramp changes nothing: the ramp goes on to its target."""
    p0 = link.position
    first = link.next_sequence() + 1000
    link.stream(first, lambda k: p0, 0.2)
    link._sleep(LEAD + 0.1)                       # holding
    target = _ramp_target(link)
    t = link.now()
    link.command(CMD_ABORT, target, RAMP_VELOCITY)
    if not link._wait(lambda: link.state == 'ramping_down', 1.0):
        link.to_rest(link.position)               # no ramp: CTRL-RAMP-1's to judge, not this one
        return
    link._sleep(0.05)
    t_reset = link.now()
    link.command(CMD_RESET)
    link._wait(lambda: link.state in ('idle', 'fault'), REST_TIMEOUT)
    link._sleep(0.05)
    samples = link._samples_since(t)
    end = samples[-1].u if samples else link.position
    reached = abs(end - target) <= 1e-6
    moving_until = max((s.t for a, s in zip(samples, samples[1:], strict=False) if abs(s.u - a.u) > 0.5 * LSB),
                       default=t_reset)
    early = [s for s in link._states_since(t_reset) if s[0] < moving_until and s[1] != 'ramping_down']
    ok = reached and not early
    link.results.put('CTRL-RESET-1', PASS if ok else FAIL,
                     f'RESET {t_reset - t:.3f} s into an ABORT ramp to {target * 1e3:.4f} mm: ended at '
                     f'{end * 1e3:.4f} mm, {len(early)} status frames out of ramping_down before it ended',
                     '' if ok else 'RESET while ramping must change nothing: the ramp must reach its target',
                     Stretch(t, link.now()))
    link.to_rest(link.position)
