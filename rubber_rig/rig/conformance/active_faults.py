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

"""Conformance scenarios of what a controller must refuse or survive: corrupt and foreign frames, the host's
limits, setpoints out of limits or too fast, a silent host and the sequence wrap (scenarios of
active.SCENARIOS: each a function of the run's link).
"""
from __future__ import annotations

import math

import can

from ...safety import DECEL_MAX
from ..can.protocol import (
    CMD_ABORT,
    CMD_RESET,
    FAULT_DISPLACEMENT_LIMIT,
    FAULT_VELOCITY_LIMIT,
    FAULT_WATCHDOG,
    fault_names,
    unwrap,
)
from .host_timing import explains, not_judged
from .link import (
    APPROACH_VELOCITY,
    LATCH_TIME,
    LEAD,
    LSB,
    RAMP_VELOCITY,
    REACTION,
    RESET_TIME,
    REST_TIMEOUT,
    TOO_FAST_FACTOR,
    judges,
)
from .report import FAIL, NOT_TESTED, PASS, Stretch
from .shape import OWN_RAMP_VELOCITY, ramp_shape


@judges('CTRL-FRAME-2', 'CTRL-FRAME-3')
def s_bad_frames(link):
    """Malformed and foreign frames while running (CTRL-FRAME-2, CTRL-FRAME-3)."""
    a = 0.2 * link.env.half
    p0 = link.position
    first = link.next_sequence() + 1000
    wild = 20e-6
    injected = {}
    phase = {}

    def inject(k):
        seq = first + k - int(LEAD * link.fs / 2)          # sent, and still queued at the controller
        good = link.sent.get(seq)
        if good is None:
            return
        if k == int(0.3 * link.fs):
            phase['frame2'] = link.now()
            msg = link.frames.encode_setpoints(seq, [good + wild])[0]
            data = bytearray(msg.data)
            data[-1] ^= 0x5A
            link._tx(can.Message(arbitration_id=msg.arbitration_id, data=data, is_fd=msg.is_fd,
                                 bitrate_switch=msg.bitrate_switch, is_extended_id=False, check=False))
            injected[seq] = 'CTRL-FRAME-2'
            msg = link.frames.encode_setpoints(seq + 1, [good + wild])[0]
            link._tx(can.Message(arbitration_id=msg.arbitration_id, data=bytes(msg.data[:len(msg.data) // 2]),
                                 is_fd=msg.is_fd, is_extended_id=False, check=False))
            injected[seq + 1] = 'CTRL-FRAME-2'
            bad = link.proto.encode('HostCommand', {'CMD_Code': CMD_ABORT, 'CMD_Counter': 0,
                                                    'CMD_Argument': 0.0, 'CMD_RampVelocity': 0.0})
            bad.data = bytearray(bad.data)
            bad.data[-1] ^= 0xFF
            link._tx(bad)
        elif k == int(0.7 * link.fs):
            phase['frame3'] = link.now()
            msg = link.frames.encode_setpoints(seq, [good + wild])[0]
            link._tx(can.Message(arbitration_id=msg.arbitration_id, data=msg.data, is_fd=msg.is_fd,
                                 bitrate_switch=msg.bitrate_switch, is_extended_id=True, check=False))
            injected[seq] = 'CTRL-FRAME-3'
            abort = link.proto.encode('HostCommand', {'CMD_Code': CMD_ABORT, 'CMD_Counter': 0,
                                                      'CMD_Argument': 0.0, 'CMD_RampVelocity': 0.0})
            link._tx(can.Message(arbitration_id=abort.arbitration_id, data=abort.data, is_extended_id=True))
            link._tx(can.Message(arbitration_id=abort.arbitration_id, is_remote_frame=True, dlc=8,
                                 is_extended_id=False))
            link._tx(can.Message(arbitration_id=0x7FE, data=bytes(8), is_extended_id=False))
        elif k == int(0.9 * link.fs):
            # HostLimits that would exclude the motion, with a wrong CRC: applied, it would fault the stream
            phase['limits_crc'] = link.now()
            bad = link.proto.encode('HostLimits', {'HL_DisplacementMin': -1e-5, 'HL_DisplacementMax': 1e-5,
                                                   'HL_Deceleration': DECEL_MAX})
            bad.data = bytearray(bad.data)
            bad.data[-1] ^= 0xA5
            link._tx(bad)

    base = link.smooth(p0, -a if p0 > 0 else a)

    def wave(k):
        inject(k)
        return base(k)
    started = link.now()
    end = link.stream(first, wave, 1.1)
    link._sleep(LEAD + 0.05)
    samples = [s for s in link._samples_since(phase.get('frame2', 0.0)) if s.seq < end]
    # the frames are injected while the stream is sent LEAD ahead, possibly before the controller has taken its
    # first sample (all at once on simulated time): a status from before it ran is not one that left running
    running = min((s[0] for s in link._states_since(started) if s[1] == 'running'), default=math.inf)
    for rid, since, until in (('CTRL-FRAME-2', 'frame2', 'frame3'), ('CTRL-FRAME-3', 'frame3', 'limits_crc'),
                              ('CTRL-FRAME-2', 'limits_crc', None)):
        t0, t1 = max(phase.get(since, math.inf), running), phase.get(until, math.inf) if until else math.inf
        applied_wrong = [seq for seq, who in injected.items() if who == rid and any(
            s.seq == seq and abs(s.u - link.sent[seq]) > 1.5 * LSB for s in samples)]
        stopped = [s for s in link._states_since(t0) if s[0] < t1 and s[1] != 'running'
                   and unwrap(s[3], end, 1 << 16) < end - 1]
        ok = not applied_wrong and not stopped and bool(samples)
        link.results.put(rid, PASS if ok else FAIL, f'{since}: {len(applied_wrong)} injected setpoints applied, '
                         f'{len(stopped)} status frames out of running',
                         '' if ok else 'such frames must change nothing')
    link.to_rest(link.position)


@judges('CTRL-LIM-1')
def s_host_limits(link):
    """HostLimits bound the controller's own ramp, upwards and downwards (CTRL-LIM-1)."""
    for side in (+1, -1):
        _limited_abort(link, side)


def _limited_abort(link, side: int):
    """HL_DisplacementMax (side +1) or HL_DisplacementMin (side -1) at half the envelope on that side, then
    ABORT to 0.9 x the envelope there: the ramp must stop at the limit.
    """
    edge = link.env.upper if side > 0 else link.env.lower
    hl = 0.5 * edge
    begun = link.now()
    link.limits(*((link.env.lower, hl) if side > 0 else (hl, link.env.upper)))
    p0 = min(link.position, 0.0) if side > 0 else max(link.position, 0.0)
    first = link.next_sequence() + 1000
    link.stream(first, link.ramp_to(link.position, p0, RAMP_VELOCITY), 0.2)
    link._sleep(LEAD + REACTION)
    t = link.now()
    target = 0.9 * edge
    link.command(CMD_ABORT, target, 5 * RAMP_VELOCITY)
    link._wait(lambda: link.state in ('idle', 'fault'), REST_TIMEOUT)
    link._sleep(0.05)
    u = [s.u for s in link._samples_since(t)]
    far = max((x * side for x in u), default=link.position * side) * side
    ok = bool(u) and far * side <= hl * side + 1.5 * LSB and abs(u[-1] - hl) <= 1e-6
    name = 'HL_DisplacementMax' if side > 0 else 'HL_DisplacementMin'
    link.results.put('CTRL-LIM-1', PASS if ok else FAIL,
                     f'ABORT to {target * 1e3:.4f} mm with {name} {hl * 1e3:.4f} mm: farthest {far * 1e3:.4f} '
                     f'mm, stopped at {u[-1] * 1e3 if u else math.nan:.4f} mm',
                     '' if ok else f"the controller's ramp must stop at {name}",
                     Stretch(begun, link.now(), tolerance=math.inf if far * side > hl * side + 1.5 * LSB else None))
    link.limits(link.env.lower, link.env.upper)
    link.to_rest(link.position)


@judges('CTRL-LIM-2', 'CTRL-FAULT-1', 'CTRL-FAULT-2')
def s_out_of_limits(link):
    """A setpoint above HL_DisplacementMax, then one below HL_DisplacementMin (CTRL-LIM-2, CTRL-FAULT-1,
    CTRL-FAULT-2).
    """
    for side in (+1, -1):
        _outside_limits(link, side, judge_latch=side > 0)


def _outside_limits(link, side: int, judge_latch: bool):
    edge = link.env.upper if side > 0 else link.env.lower
    hl = 0.5 * edge
    link.limits(*((link.env.lower, hl) if side > 0 else (hl, link.env.upper)))
    first = link.next_sequence() + 1000
    target = 0.8 * edge
    p0 = link.position
    t = link.now()
    try:
        # slow enough that the controller is well on its way (LEAD x this short of the limit) when the first
        # setpoint beyond the limit reaches it: its fault ramp then starts from motion, whose shape is judged
        # (and no longer than until the controller stops: a fault's latch is timed from there)
        link.stream(first, link.ramp_to(p0, target, APPROACH_VELOCITY),
                    abs(target - p0) / APPROACH_VELOCITY + 0.1,
                    until=lambda: link.state in ('ramping_down', 'fault'))
    finally:
        link.heartbeat = True
    link._wait(lambda: link.state in ('idle', 'fault'), REST_TIMEOUT)
    link._sleep(0.05)
    samples = link._samples_since(t)
    u = [s.u for s in samples]
    far = max((x * side for x in u), default=p0 * side) * side
    faults = _fault_bits_since(link, t)
    shape = _own_ramp_shape(link, samples, 0.0)
    ok = far * side <= hl * side + 1.5 * LSB and bool(faults) and link.state == 'fault' and shape.ok
    name = 'HL_DisplacementMax' if side > 0 else 'HL_DisplacementMin'
    link.results.put('CTRL-LIM-2', PASS if ok else FAIL,
                     f'setpoints to {target * 1e3:.4f} mm with {name} {hl * 1e3:.4f} mm: farthest applied '
                     f'{far * 1e3:.4f} mm, faults {fault_names(faults)}, state {link.state}; fault ramp: '
                     f'{shape.describe()}',
                     '' if ok else shape.why() or f'a setpoint beyond {name} must never be applied, and must '
                     'fault the rig',    # beyond the limit: no delay of this host applies a setpoint
                     Stretch(t, link.now(), tolerance=math.inf if far * side > hl * side + 1.5 * LSB else None))
    _judge_fault_bits(link, f'beyond {name}', faults, FAULT_DISPLACEMENT_LIMIT, t)
    if judge_latch:
        _judge_latch(link)
    link.limits(link.env.lower, link.env.upper)
    link.to_rest(link.position)


def _own_ramp_shape(link, samples: list, target: float):
    """The shape (shape.ramp_shape) of the controller's own ramp among `samples`: from a little before the
    first sample reported ramping down (status lags by up to a period) to the end, at OWN_RAMP_VELOCITY.
    """
    k = next((i for i, s in enumerate(samples) if s.state in ('ramping_down', 'fault', 'idle')), len(samples))
    k = max(0, k - int(0.02 * link.fs))
    u = [s.u for s in samples[k:]]
    if len(u) < 2:
        return ramp_shape(u, link.fs, target, OWN_RAMP_VELOCITY)
    v0 = (u[1] - u[0]) * link.fs
    return ramp_shape(u, link.fs, target, OWN_RAMP_VELOCITY, v0, DECEL_MAX)


def _fault_bits_since(link, t: float) -> int:
    bits = 0
    for s in link._states_since(t):
        bits |= s[2]
    return bits


def _judge_fault_bits(link, cause: str, bits: int, expected: int, since: float):
    """CTRL-FAULT-1: judged only where a fault was raised (a missing fault fails the scenario's own
    requirement), on the fault bits since `since` [s]. A silence of this host as long as the stated host timeout
    trips the controller's watchdog, another bit: the FAIL's time tolerance (host_excuse).
    """
    if not bits:
        return
    ok = bits == expected
    link.results.put('CTRL-FAULT-1', PASS if ok else FAIL, f'{cause}: {fault_names(bits)}',
                     '' if ok else f'expected exactly {fault_names(expected)}',
                     Stretch(since, link.now(), tolerance=link.host_timeout))


def _judge_latch(link):
    """CTRL-FAULT-2: the fault stays for LATCH_TIME without RESET; RESET returns to idle without fault bits."""
    if link.state != 'fault':
        return
    t = link.now()
    link._sleep(LATCH_TIME)
    states = link._states_since(t)
    cleared = [s for s in states if s[1] != 'fault' or not s[2]]
    latched = bool(states) and not cleared
    t_reset = link.now()
    link.command(CMD_RESET)
    # idle is timed by the status frame's arrival on the bus, not by when this run read it (its view may lag)
    link._wait(lambda: link.state == 'idle' and not link.faults, 1.0)
    idle_at = next((s[0] for s in link._states_since(t_reset) if s[1] == 'idle' and not s[2]), None)
    idle = idle_at is not None and idle_at - t_reset <= RESET_TIME
    ok = latched and idle
    held = f'{cleared[0][0] - t:.3f} s' if cleared else f'{LATCH_TIME:g} s'
    link.results.put('CTRL-FAULT-2', PASS if ok else FAIL,
                     f'fault held {held} without RESET ({len(states)} status frames); idle without faults '
                     + (f'{idle_at - t_reset:.3f} s after RESET (at most {RESET_TIME:g} s)' if idle_at is not None
                        else f'not within {link.now() - t_reset:.3f} s of RESET'),
                     '' if ok else f'a fault must latch until RESET (checked for {LATCH_TIME:g} s), which '
                     'clears it',      # a fault that clears itself is no delay; a slow RESET by its excess only
                     Stretch(t, link.now(), excess=None if not latched else (
                         idle_at if idle_at is not None else link.now()) - t_reset - RESET_TIME, tolerance=math.inf))


@judges('CTRL-LIM-3', 'CTRL-FAULT-1')
def s_too_fast(link):
    """A setpoint faster than the rated velocity, upwards and downwards (CTRL-LIM-3, CTRL-FAULT-1)."""
    stated = float(link.identity[1]['CI_VelocityMax']) if link.identity else 0.0
    plausible = 0.0 < stated <= link.env.velocity_max
    vmax = stated if plausible else link.env.test_velocity(link.fs, TOO_FAST_FACTOR)
    basis = (f'rated {vmax:g} m/s' if plausible else f'stated {stated:g} m/s is implausible (CTRL-ID-3): tested '
             f'at the envelope value {vmax:g} m/s')
    step = TOO_FAST_FACTOR * vmax / link.fs
    if step > 0.8 * link.env.half:
        link.results.put('CTRL-LIM-3', NOT_TESTED, f'a step of {step * 1e3:.3f} mm is needed ({basis})',
                         'the envelope is too small for a step above the rated velocity')
        return
    for side in (+1, -1):
        _too_fast(link, side, vmax, step, basis)


def _too_fast(link, side: int, vmax: float, step: float, basis: str):
    """One step of `step` [m] in one sample, upwards (side +1) or downwards (-1), from rest at 0."""
    p0 = link.position
    end_pos = p0 + side * step
    first = link.next_sequence() + 1000
    t = link.now()
    # a controller that wrongly applies the step lags it for a moment: that is this requirement's FAIL, not a
    # reason to abort the run (the envelope itself still holds every sample)
    link.tracking_allowance = step
    try:
        link.stream(first, lambda k: p0 if k < int(0.2 * link.fs) else end_pos, 0.4)
        link.heartbeat = True
        link._wait(lambda: link.state in ('idle', 'fault'), 3.0)
        link._sleep(0.05)
    finally:
        link.tracking_allowance = 0.0
    samples = link._samples_since(t)
    u = [p0] + [s.u for s in samples]
    fastest = max((abs(b - a) * link.fs for a, b in zip(u, u[1:], strict=False)), default=0.0)
    faults = _fault_bits_since(link, t)
    shape = _own_ramp_shape(link, samples, 0.0)
    ok = fastest <= vmax * 1.02 + 2 * LSB * link.fs and bool(faults) and link.state == 'fault' and shape.ok
    link.results.put('CTRL-LIM-3', PASS if ok else FAIL,
                     f'a step of {side * step * 1e3:+.3f} mm in one sample ({step * link.fs:.3f} m/s, {basis}): '
                     f'fastest applied {fastest:.4f} m/s, faults {fault_names(faults)}; fault ramp: '
                     f'{shape.describe()}',
                     '' if ok else shape.why() if fastest <= vmax * 1.02 + 2 * LSB * link.fs and faults else
                     'a setpoint above the rated velocity must never be applied, and must fault',
                     Stretch(t, link.now(), tolerance=math.inf if fastest > vmax * 1.02 + 2 * LSB * link.fs else None))
    _judge_fault_bits(link, 'too fast', faults, FAULT_VELOCITY_LIMIT, t)
    link.to_rest(0.0)


@judges('CTRL-WD-1', 'CTRL-FAULT-1')
def s_host_silence(link):
    """Host silence (CTRL-WD-1, CTRL-FAULT-1)."""
    a = 0.4 * link.env.half
    p0 = link.position
    first = link.next_sequence() + 1000
    link.stream(first, link.smooth(p0, -a if p0 > 0 else a), 0.6)
    link.heartbeat = False
    link.foreign_traffic = True     # another node goes on talking: it must not keep the watchdog quiet
    link._sleep(0.01)
    with link.lock:   # the controller's host watchdog runs on HostHeartbeat
        t_silent = max(f.t for f in link.trace.frames if f.name == 'HostHeartbeat')
    timeout = link.host_timeout
    ramped = link._wait(lambda: link.state in ('ramping_down', 'fault', 'idle'), timeout + 1.0)
    t_ramp = next((s[0] for s in link._states_since(t_silent) if s[1] in ('ramping_down', 'fault', 'idle')),
                  None)
    if not ramped:
        link.merge_host_timing()
        late = explains(link.trace.host_late, t_silent, link.now(), 1.0)
        measured = f'still {link.state} {timeout + 1.0:.2f} s after the host fell silent (stated host timeout ' \
                   f'{timeout:g} s)'
        if late:     # the simulator on this host does not count time it was not scheduled
            link.results.put('CTRL-WD-1', NOT_TESTED, measured, not_judged(late, 'after the host fell silent'))
        else:
            link.results.put('CTRL-WD-1', FAIL, measured, 'the controller must ramp to rest on host silence')
        link.to_rest(0.0)
        return
    link._wait(lambda: link.state in ('idle', 'fault'), REST_TIMEOUT)
    link._sleep(0.05)
    delay = t_ramp - t_silent
    faults = _fault_bits_since(link, t_silent)
    rest = link.position
    shape = _own_ramp_shape(link, link._samples_since(t_silent), 0.0)
    ok = delay <= timeout + 0.1 and abs(rest) <= 1e-6 and link.state == 'fault' and bool(faults) and shape.ok
    link.merge_host_timing()
    late = explains(link.trace.host_late, t_silent, t_ramp, delay - (timeout + 0.1))
    if delay > timeout + 0.1 and late and abs(rest) <= 1e-6 and shape.ok and bool(faults):
        # late only where this host was late: the controller's watchdog cannot be judged by it
        link.results.put('CTRL-WD-1', NOT_TESTED, f'ramp began {delay:.3f} s after the last HostHeartbeat '
                         f'(stated host timeout {timeout:g} s), rest at {rest * 1e3:.4f} mm, faults '
                         f'{fault_names(faults)}', not_judged(late, 'between the last heartbeat and the ramp'))
        _judge_fault_bits(link, 'host silence', faults, FAULT_WATCHDOG, t_silent)
        link.to_rest(0.0)
        return
    link.results.put('CTRL-WD-1', PASS if ok else FAIL,
                     f'ramp began {delay:.3f} s after the last HostHeartbeat (stated host timeout {timeout:g} s), '
                     f'rest at {rest * 1e3:.4f} mm, state {link.state}, faults {fault_names(faults)}; ramp: '
                     f'{shape.describe()}',
                     '' if ok else shape.why() or 'host silence must ramp the rig to rest within the host '
                     'timeout, faulted')
    _judge_fault_bits(link, 'host silence', faults, FAULT_WATCHDOG, t_silent)
    link.to_rest(0.0)


@judges('CTRL-SEQ-2')
def s_wrap(link):
    """Streams across a 2^16 boundary and the field's wrap (CTRL-SEQ-2)."""
    starts = [(1 << 16) - int(0.3 * link.fs)]
    if link.trace.modulus[link.frames.feedback_names[0]] > (1 << 16):
        starts.append((1 << 32) - int(0.3 * link.fs))
    for first in starts:
        p0 = link.position
        link.stream(first, lambda k, p=p0: p, 0.6)
        link._sleep(LEAD + 0.1)
        link.to_rest(0.0)
