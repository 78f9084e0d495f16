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


"""The online conformance run: drive a controller through the scenarios of the specification with small motion
inside a displacement envelope the operator states, and judge every requirement from what it did.

The host side here is deliberately not the driver: it must send what a driver never would (corrupted, foreign
and stale frames, a setpoint outside the limits, one too fast, silence). Every frame sent and received goes into
one Trace; the requirements a trace alone can show are then judged by the same code as the offline mode
(passive.check_offline). Safety: every measured displacement and applied command is checked against the
envelope as it arrives; a sample outside it, or a tracking error above a third of it, commands ABORT at once and
ends the run (Aborted). Motion is slow (a few mm/s) and at most 80 % of the envelope.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass

import can

from ...safety import DECEL_MAX
from ..can.frames import SampleFrames
from ..can.protocol import (
    CMD_ABORT,
    CMD_HOLD,
    CMD_IDENTIFY,
    CMD_RESET,
    FAULT_DISPLACEMENT_LIMIT,
    FAULT_VELOCITY_LIMIT,
    FAULT_WATCHDOG,
    PROTOCOL_VERSION,
    STATES,
    Protocol,
    cycle_time,
    fault_names,
    unwrap,
)
from .passive import check_offline
from .report import FAIL, NOT_TESTED, PASS, Results
from .requirements import REQUIREMENTS
from .trace import Trace

LSB = 1e-7                  # [m] displacement resolution of the frames
LEAD = 0.1                  # [s] setpoints streamed ahead of the controller (covers this host's pauses)
IDENTIFY_TIMEOUT = 0.1      # [s] CTRL-ID-1
RAMP_VELOCITY = 0.002       # [m/s] commanded velocity of the ramps the run asks for
WAVE_FREQUENCY = 2.0        # [Hz] of the motion the run streams
DEFAULT_HOST_TIMEOUT = 0.5  # [s] assumed when the controller states none
BUFFER_IN_FLIGHT = 0.05     # [s] setpoints sent this recently may not be counted in ST_BufferLevel yet
BUFFER_OUTLIERS = 0.02      # share of status frames whose level may be off (a controller busy for a moment)
REST_TIMEOUT = 15.0         # [s] longest wait for the controller to come to rest


class Aborted(RuntimeError):
    """The run left the operator's envelope (or could not continue safely): ABORT was commanded."""


@dataclass
class Envelope:
    """The displacement range [m] the operator allows the run to use: lower < 0 < upper."""

    lower: float
    upper: float

    def __post_init__(self):
        if not (math.isfinite(self.lower) and math.isfinite(self.upper) and self.lower < 0.0 < self.upper):
            raise ValueError(f'envelope {self.lower * 1e3:g}..{self.upper * 1e3:g} mm: it must contain the rest '
                             'position 0 mm (lower < 0 < upper)')

    @property
    def half(self) -> float:
        return min(-self.lower, self.upper)


@dataclass
class Sample:
    t: float
    seq: int
    x: float
    u: float
    state: str


class ConformanceRun:
    """One conformance run of the controller on `bus` (any python-can Bus) at sample_rate [Hz] with frame
    `profile`, inside `envelope`. run() returns the Results of every CTRL requirement.
    """

    def __init__(self, bus: can.BusABC, sample_rate: float, envelope: Envelope, profile: str = 'packed',
                 log=print, power_up=None):
        self.bus, self.fs, self.env, self.log = bus, float(sample_rate), envelope, log
        # power_up: callable that switches the controller on (or asks the operator to) once the run listens;
        # None: the controller is already on and CTRL-PWR-1 is not tested
        self.power_up = power_up
        self.proto = Protocol()
        self.frames = SampleFrames(profile, self.proto.db, self.fs)
        self.trace = Trace(self.fs)
        self.results = Results()
        self.lock = threading.RLock()
        self.state, self.faults, self.identity = 'unconfigured', 0, None
        self.samples = []           # Sample per feedback sample received
        self.status_log = []        # (t, state, faults, last sequence, buffer level) per ControllerStatus
        self.sent = {}              # sequence -> setpoint sent (valid frames only)
        self.sent_log = []          # (t, first, count) per valid setpoint frame sent
        self.sent_at = {}           # sequence -> time its setpoint was sent
        self.deviation = ''
        self.heartbeat = False
        self._fb_ref = 0
        self._hb_counter = 0
        self._next_hb = 0.0
        self._stop = threading.Event()
        self.position = 0.0         # last applied command reported [m]
        self._rx = threading.Thread(target=self._receive_loop, name='conformance-rx', daemon=True)

    # ---- bus
    def _tx(self, msg: can.Message):
        with self.lock:
            self.trace.add(msg, time.time())
        self.bus.send(msg)

    def send(self, name: str, signals: dict):
        self._tx(self.proto.encode(name, dict(signals)))

    def command(self, code: int, argument: float = 0.0, ramp_velocity: float = 0.0):
        self.send('HostCommand', {'CMD_Code': code, 'CMD_Counter': 0, 'CMD_Argument': argument,
                                  'CMD_RampVelocity': ramp_velocity})

    def limits(self, lower: float, upper: float, decel: float = DECEL_MAX):
        self.send('HostLimits', {'HL_DisplacementMin': lower, 'HL_DisplacementMax': upper, 'HL_Deceleration': decel})

    def send_setpoints(self, first: int, values: list, record: bool = True):
        for i, msg in enumerate(self.frames.encode_setpoints(first, values)):
            per = self.frames.setpoints_per_frame
            chunk = values[i * per:(i + 1) * per]
            self._tx(msg)
            if record:
                with self.lock:
                    self.sent_log.append((time.time(), first + i * per, len(chunk)))
                    now = time.time()
                    for k, v in enumerate(chunk):
                        self.sent[first + i * per + k] = v
                        self.sent_at[first + i * per + k] = now

    def _heartbeat(self):
        self._hb_counter = (self._hb_counter + 1) % 256
        self.send('HostHeartbeat', {'HH_Counter': self._hb_counter})

    def _receive_loop(self):
        period = cycle_time('HostHeartbeat')
        while not self._stop.is_set():
            msg = self.bus.recv(0.005)
            now = time.monotonic()
            if self.heartbeat and now >= self._next_hb:
                self._heartbeat()
                self._next_hb = max(self._next_hb + period, now)
            if msg is None:
                continue
            with self.lock:
                fr = self.trace.add(msg)
                if fr.malformed or fr.host is not False:
                    continue
                if fr.samples is not None:
                    self._on_feedback(fr)
                elif fr.name == 'ControllerStatus':
                    s = fr.signals
                    code = int(s['ST_State'])
                    self.state = STATES[code] if code < len(STATES) else f'state {code}'
                    self.faults = int(s['ST_Faults'])
                    self.status_log.append((fr.t, self.state, self.faults, int(s['ST_LastSequence']),
                                            int(s['ST_BufferLevel'])))
                elif fr.name == 'ControllerIdentity':
                    self.identity = (fr.t, dict(fr.signals))

    def _on_feedback(self, fr):
        raw, xs, _, us = fr.samples
        first = unwrap(int(raw), self._fb_ref, self.trace.modulus[fr.name])
        self._fb_ref = first + len(xs)
        for i, (x, u) in enumerate(zip(xs, us, strict=False)):
            self.samples.append(Sample(fr.t, first + i, float(x), float(u), self.state))
            self.position = float(u)
            self._watch(float(x), float(u), first + i)

    def _watch(self, x: float, u: float, seq: int):
        """The operator's envelope: a sample outside it, or tracking worse than a third of it, aborts the run."""
        if self.deviation:
            return
        margin = 0.02 * self.env.half + 5e-6
        why = ''
        if not self.env.lower - LSB <= u <= self.env.upper + LSB:
            why = f'applied command {u * 1e3:.4f} mm at sample {seq} outside the envelope'
        elif not self.env.lower - margin <= x <= self.env.upper + margin:
            why = f'measured displacement {x * 1e3:.4f} mm at sample {seq} outside the envelope'
        elif abs(x - u) > self.env.half / 3:
            why = f'tracking error {abs(x - u) * 1e3:.4f} mm at sample {seq}'
        if why:
            self.deviation = why
            self.command(CMD_ABORT, 0.0)

    # ---- helpers
    def _check(self):
        if self.deviation:
            raise Aborted(self.deviation)

    def _wait(self, predicate, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            self._check()
            with self.lock:
                if predicate():
                    return True
            time.sleep(0.002)
        return False

    def _sleep(self, seconds: float):
        self._wait(lambda: False, seconds)

    def _samples_since(self, t: float) -> list:
        with self.lock:
            return [s for s in self.samples if s.t >= t]

    def _states_since(self, t: float) -> list:
        with self.lock:
            return [s for s in self.status_log if s[0] >= t]

    def _states_before(self, t: float, end: int) -> set:
        """States the status frames since t report while the controller had not yet taken sample end - 1 (by
        ST_LastSequence, not by arrival time: feedback may arrive later than the status of the same tick).
        """
        return {s[1] for s in self._states_since(t) if unwrap(s[3], end, 1 << 16) < end - 1}

    def stream(self, first: int, wave, duration: float, start: bool = True) -> int:
        """Stream wave(k) [m] (k: samples since `first`) for `duration` [s] of samples, LEAD ahead, with the host
        heartbeat on; returns the sequence after the last setpoint sent.
        """
        if start:
            self.send('HostStreamStart', {'HS_FirstSequence': first % (1 << 32)})
        with self.lock:
            self._fb_ref = first
        self.heartbeat = True
        total = int(round(duration * self.fs))
        per = self.frames.setpoints_per_frame
        t0, sent = time.monotonic(), first
        while sent < first + total:
            self._check()
            due = first + int((time.monotonic() - t0 + LEAD) * self.fs)
            while sent < min(due, first + total):
                n = min(per, first + total - sent)
                self.send_setpoints(sent, [wave(k - first) for k in range(sent, sent + n)])
                sent += n
            time.sleep(0.001)
        return sent

    def next_sequence(self, lead: float = LEAD) -> int:
        """A sequence LEAD ahead of the last sample the controller reported."""
        with self.lock:
            last = self.samples[-1].seq if self.samples else 0
        return last + 1 + int(lead * self.fs)

    def to_rest(self, target: float = 0.0):
        """Bring the controller to rest at target (ABORT if it ticks), clear faults (RESET), wait for idle."""
        self.heartbeat = True
        if self.state in ('running', 'holding'):
            self.command(CMD_ABORT, target)
        if not self._wait(lambda: self.state in ('idle', 'fault'), REST_TIMEOUT):
            raise Aborted(f'the controller did not come to rest within {REST_TIMEOUT:g} s (state {self.state})')
        if self.state == 'fault' or self.faults:
            self.command(CMD_RESET)
            self._wait(lambda: self.state == 'idle' and not self.faults, 1.0)
        self.heartbeat = False

    def smooth(self, start: float, amplitude: float, frequency: float = WAVE_FREQUENCY):
        """Start + amplitude (1 - cos 2 pi f t) / 2: begins at rest, never leaves [start, start + amplitude]."""
        w = 2 * math.pi * frequency / self.fs
        return lambda k: start + amplitude * (1.0 - math.cos(w * k)) / 2.0

    def ramp_to(self, start: float, end: float, velocity: float):
        """A constant-velocity move from start to end [m] at velocity [m/s], then holding end."""
        n = max(1, int(abs(end - start) / velocity * self.fs))
        return lambda k: start + (end - start) * min(k, n) / n

    # ---- the run
    def run(self) -> Results:
        """Every scenario in order; the offline-checkable requirements from the whole trace at the end."""
        self._rx.start()
        scenarios = ((self.s_power_up,) if self.power_up else ()) + (
            self.s_listen, self.s_identify, self.s_stream, self.s_stale, self.s_hold, self.s_reset_moving,
            self.s_bad_frames, self.s_host_limits, self.s_out_of_limits, self.s_too_fast, self.s_host_silence,
            self.s_wrap)
        try:
            for scenario in scenarios:
                self.log(f'conformance: {scenario.__doc__.splitlines()[0].rstrip(".")}')
                scenario()
        except Aborted as exc:
            self.command(CMD_ABORT, 0.0)
            self.log(f'conformance: ABORTED: {exc}')
            self.deviation = self.deviation or str(exc)
        finally:
            self.heartbeat = False
            time.sleep(0.1)
            self._stop.set()
            self._rx.join(timeout=2.0)
        if not self.deviation:
            passive = check_offline(self.trace)
            for rid, r in passive.items():
                if rid.startswith('CTRL'):
                    self.results.put(rid, r.status, r.measured, r.detail)
        why = (f'run aborted: {self.deviation}' if self.deviation else
               'needs the controller switched on during the run (--power-up)')
        return self.results.complete({r.id for r in REQUIREMENTS if r.id.startswith('CTRL')}, why)

    def s_power_up(self):
        """Power-up (CTRL-PWR-1)."""
        self.power_up()
        if not self._wait(lambda: any(f.host is False for f in self.trace.frames), 60.0):
            raise Aborted('the controller sent nothing within 60 s of power-up')
        with self.lock:
            t0 = next(f.t for f in self.trace.frames if f.host is False)
        self._sleep(1.5)
        with self.lock:
            first = [f for f in self.trace.frames if f.host is False and f.t <= t0 + 1.0 and not f.malformed]
        ident = [f for f in first if f.name == 'ControllerIdentity']
        states = {STATES[int(f.signals['ST_State'])] if int(f.signals['ST_State']) < len(STATES) else '?'
                  for f in first if f.name == 'ControllerStatus'}
        faults = [f for f in first if f.name == 'ControllerStatus' and int(f.signals['ST_Faults'])]
        ticking = [f for f in first if f.samples is not None]
        ok = (bool(ident) and int(ident[0].signals['CI_Protocol']) == PROTOCOL_VERSION and bool(states)
              and states <= {'idle', 'unconfigured'} and not faults and not ticking)
        self.results.put('CTRL-PWR-1', PASS if ok else FAIL,
                         f'first second after power-up: {len(ident)} ControllerIdentity, states {sorted(states)}, '
                         f'{len(faults)} status frames with faults, {len(ticking)} feedback frames',
                         '' if ok else 'at power-up the controller must identify itself, idle, at rest, unfaulted')

    def s_listen(self):
        """Listen 1.5 s to the idle controller."""
        self._sleep(1.5)
        if self.state not in ('idle', 'fault', 'unconfigured'):
            raise Aborted(f'the controller is {self.state}, not at rest: conformance starts from rest')
        self.to_rest()

    def s_identify(self):
        """IDENTIFY (CTRL-ID-1)."""
        t = time.time()
        self.command(CMD_IDENTIFY)
        got = self._wait(lambda: self.identity is not None and self.identity[0] >= t, 1.0)
        if not got:
            self.results.put('CTRL-ID-1', FAIL, 'no ControllerIdentity within 1 s of IDENTIFY', '')
            return
        at, sig = self.identity
        latency = at - t
        version = int(sig['CI_Protocol'])
        ok = latency <= IDENTIFY_TIMEOUT and version == PROTOCOL_VERSION
        self.results.put('CTRL-ID-1', PASS if ok else FAIL,
                         f'answered in {latency * 1e3:.1f} ms: protocol {version}, device '
                         f'0x{int(sig["CI_Device"]):04x}, firmware {int(sig["CI_Firmware"])}, host timeout '
                         f'{float(sig["CI_HostTimeout"]):g} s, rated velocity {float(sig["CI_VelocityMax"]):g} m/s',
                         '' if ok else f'expected protocol {PROTOCOL_VERSION} within {IDENTIFY_TIMEOUT * 1e3:.0f} ms')

    @property
    def host_timeout(self) -> float:
        if self.identity and float(self.identity[1]['CI_HostTimeout']) > 0:
            return float(self.identity[1]['CI_HostTimeout'])
        return DEFAULT_HOST_TIMEOUT

    def s_stream(self):
        """Stream, underrun, resume, underrun, ABORT (CTRL-STREAM-1/3/4, CTRL-ST-4, CTRL-RAMP-1)."""
        self.limits(self.env.lower, self.env.upper)
        a = 0.4 * self.env.half
        first, p0 = 1000, self.position
        t0 = time.time()
        end = self.stream(first, self.smooth(p0, a), 2.0)
        self._sleep(LEAD + 0.3)                       # underrun: the controller holds
        t_hold = time.time()
        self._sleep(0.3)
        held = self._samples_since(t_hold)
        samples = [s for s in self._samples_since(t0) if first <= s.seq < end]
        # CTRL-STREAM-1: started at the first setpoint with that setpoint
        starts = [s for s in self._samples_since(t0)]
        ok = bool(starts) and starts[0].seq == first and abs(starts[0].u - self.sent[first]) <= 1.5 * LSB
        self.results.put('CTRL-STREAM-1', PASS if ok else FAIL,
                         f'first sample {starts[0].seq if starts else None} (stream start {first})',
                         '' if ok else 'the first applied sample must be the first setpoint of the stream')
        self._judge_applied(samples, first, end, 'stream')
        self._judge_buffer(t0, t_hold)
        # CTRL-STREAM-3: held the last command without a fault
        last = self.sent[end - 1]
        still = held and all(abs(s.u - last) <= 1.5 * LSB for s in held)
        states = {s[1] for s in self._states_since(t_hold)}
        faults = [s[2] for s in self._states_since(t_hold) if s[2]]
        ok = bool(still) and 'holding' in states and not faults
        # resume from the held position, after the controller's current tick
        first2 = self.next_sequence()
        t1 = time.time()
        end2 = self.stream(first2, self.smooth(last, -0.5 * a), 0.5, start=False)
        self._sleep(LEAD + 0.2)
        resumed = [s for s in self._samples_since(t1) if first2 <= s.seq < end2]
        ok_resume = len(resumed) == end2 - first2 and all(abs(s.u - self.sent[s.seq]) <= 1.5 * LSB for s in resumed)
        self.results.put('CTRL-STREAM-3', PASS if ok and ok_resume else FAIL,
                         f'held {len(held)} samples at {last * 1e3:.4f} mm, states {sorted(states)}, resumed '
                         f'{len(resumed)} of {end2 - first2} setpoints',
                         '' if ok and ok_resume else 'an underrun must hold the last command without a fault and the '
                         'stream must resume with the setpoints that follow')
        self._judge_ramp(target=-a)

    def _judge_applied(self, samples: list, first: int, end: int, what: str):
        """CTRL-STREAM-4: every setpoint applied once, at its own sequence. A setpoint this host sent after the
        feedback of its sequence had arrived was late by the host's fault: not judged (counted).
        """
        seqs = [s.seq for s in samples]
        late = {s.seq for s in samples if self.sent_at.get(s.seq, -math.inf) > s.t - 1e-3}
        wrong = sum(1 for s in samples if s.seq not in late and abs(s.u - self.sent.get(s.seq, math.inf)) > 1.5 * LSB)
        ok = seqs == list(range(first, end)) and wrong == 0 and len(late) < 0.05 * len(samples)
        self.results.put('CTRL-STREAM-4', PASS if ok else FAIL,
                         f'{what}: {len(samples)} of {end - first} setpoints applied, {wrong} different from the '
                         f'setpoint of their sequence, {len(late)} sent too late by this host (not judged)',
                         '' if ok else 'each setpoint must be applied at its sequence')

    def _judge_buffer(self, t0: float, t1: float):
        """CTRL-ST-4: the buffer level the status reports is what the host has queued beyond the last sample."""
        with self.lock:
            log = list(self.sent_log)
        errors = []
        for t, state, _, last, level in self._states_since(t0):
            if t > t1 or state != 'running':
                continue
            sent_end = max((f + n for ts, f, n in log if ts <= t), default=None)
            sent_before = max((f + n for ts, f, n in log if ts <= t - BUFFER_IN_FLIGHT), default=None)
            if sent_end is None or sent_before is None:
                continue
            full_last = unwrap(last, sent_end, 1 << 16)
            hi, lo = sent_end - 1 - full_last, sent_before - 1 - full_last - self.frames.setpoints_per_frame
            errors.append(0 if lo <= level <= hi else min(abs(level - lo), abs(level - hi)))
        if not errors:
            self.results.put('CTRL-ST-4', NOT_TESTED, '', 'no status frame while running')
            return
        bad = sum(1 for e in errors if e)
        ok = bad <= BUFFER_OUTLIERS * len(errors)
        self.results.put('CTRL-ST-4', PASS if ok else FAIL, f'{len(errors)} status frames while running, {bad} with '
                         f'a level off the queued setpoints (by up to {max(errors)})',
                         '' if ok else f'ST_BufferLevel must count the setpoints queued (at most '
                         f'{BUFFER_OUTLIERS * 100:g} % of the status frames off)')

    def _judge_ramp(self, target: float):
        """ABORT from rest to target at RAMP_VELOCITY (CTRL-RAMP-1)."""
        p0 = self.position
        t = time.time()
        self.command(CMD_ABORT, target, RAMP_VELOCITY)
        done = self._wait(lambda: self.state in ('idle', 'fault'), REST_TIMEOUT)
        self._sleep(0.05)
        ramp = self._samples_since(t)
        if not done or not ramp:
            self.results.put('CTRL-RAMP-1', FAIL, f'state {self.state} after {REST_TIMEOUT:g} s', 'no ramp to rest')
            return
        u = [p0] + [s.u for s in ramp]
        steps = [abs(b - a) * self.fs for a, b in zip(u, u[1:], strict=False)]
        moving = [s for s, a, b in zip(ramp, u, u[1:], strict=False) if abs(b - a) > 0.5 * LSB]
        duration = (moving[-1].seq - ramp[0].seq + 1) / self.fs if moving else 0.0
        allowed = 1.5 * abs(target - p0) / RAMP_VELOCITY + 0.1
        vmax = max(steps)
        ok = (abs(u[-1] - target) <= 1e-6 and vmax <= RAMP_VELOCITY * 1.05 + 2 * LSB * self.fs
              and duration <= allowed and not self.faults and self.state == 'idle')
        self.results.put('CTRL-RAMP-1', PASS if ok else FAIL,
                         f'{p0 * 1e3:.4f} -> {u[-1] * 1e3:.4f} mm (target {target * 1e3:.4f}) in {duration:.3f} s '
                         f'(at most {allowed:.3f} s), peak {vmax * 1e3:.2f} mm/s (commanded {RAMP_VELOCITY * 1e3:g}), '
                         f'state {self.state}',
                         '' if ok else 'the ramp must reach its target at the commanded velocity without a step and '
                         'end idle')
        self.to_rest()

    def s_stale(self):
        """Setpoints of the old stream after the ramp, without HostStreamStart (CTRL-STREAM-2)."""
        t = time.time()
        with self.lock:
            last = max(self.sent) if self.sent else 0
        self.heartbeat = True
        for k in range(10):
            self.send_setpoints(last + 1 + 19 * k, [self.position] * 19, record=False)
        self._sleep(0.3)
        got = self._samples_since(t)
        states = {s[1] for s in self._states_since(t)}
        ok = not got and states <= {'idle'}
        self.results.put('CTRL-STREAM-2', PASS if ok else FAIL, f'{len(got)} samples taken, states {sorted(states)}',
                         '' if ok else 'a controller at rest must take no setpoint before the next HostStreamStart')
        self.to_rest(self.position)

    def s_hold(self):
        """HOLD while moving (CTRL-RAMP-2)."""
        a = 0.4 * self.env.half
        p0 = self.position
        first = self.next_sequence() + 1000
        box = {}
        base = self.smooth(p0, -a if p0 > 0 else a)
        k_hold = int((0.25 / WAVE_FREQUENCY + LEAD) * self.fs)    # the controller is at full speed then

        def wave(k):
            if k == k_hold and 'hold' not in box:
                box['hold'] = time.time()
                self.command(CMD_HOLD, 0.0, RAMP_VELOCITY)
            return base(k)
        t = time.time()
        self.stream(first, wave, 0.4)
        done = self._wait(lambda: self.state in ('idle', 'fault'), REST_TIMEOUT)
        self._sleep(0.05)
        t_hold = box.get('hold', t)
        before = [s for s in self._samples_since(t) if s.t < t_hold]
        after = self._samples_since(t_hold)
        u = [s.u for s in before[-3:] + after]
        v = [(b - a) * self.fs for a, b in zip(u, u[1:], strict=False)]
        acc = [abs(b - a) * self.fs for a, b in zip(v, v[1:], strict=False)]
        decel = DECEL_MAX
        still = bool(after) and len(v) >= 2 and abs(v[-1]) <= 2 * LSB * self.fs
        peak_v = max((abs(x) for x in v[:3]), default=0.0)
        ok = done and still and max(acc, default=0) <= decel * 1.1 + 4 * LSB * self.fs ** 2 and not self.faults \
            and self.state == 'idle'
        self.results.put('CTRL-RAMP-2', PASS if ok else FAIL,
                         f'from {peak_v * 1e3:.2f} mm/s to a stop at {u[-1] * 1e3:.4f} mm in {len(after)} samples, '
                         f'peak deceleration {max(acc, default=0):.1f} m/s^2 (HostLimits {decel:g}), '
                         f'state {self.state}',
                         '' if ok else 'HOLD must brake to a stop without a step and end idle without a fault')
        self.to_rest(self.position)

    def s_reset_moving(self):
        """RESET while running (CTRL-RESET-1)."""
        a = 0.4 * self.env.half
        p0 = self.position
        first = self.next_sequence() + 1000
        t = time.time()
        box = {}
        base = self.smooth(p0, -a if p0 > 0 else a)

        def wave(k):
            if k == int(0.5 * self.fs) and 'reset' not in box:
                box['reset'] = time.time()
                self.command(CMD_RESET)
            return base(k)
        end = self.stream(first, wave, 1.2)
        self._sleep(LEAD + 0.05)
        after = [s for s in self._samples_since(box.get('reset', t)) if s.seq < end]
        states = self._states_before(box.get('reset', t), end)
        ok = bool(after) and states <= {'running'} and all(abs(s.u - self.sent[s.seq]) <= 1.5 * LSB for s in after)
        self.results.put('CTRL-RESET-1', PASS if ok else FAIL,
                         f'after RESET: {len(after)} samples as streamed, states {sorted(states)}',
                         '' if ok else 'RESET while the rig moves must change nothing')
        self.to_rest(self.position)

    def s_bad_frames(self):
        """Malformed and foreign frames while running (CTRL-FRAME-2, CTRL-FRAME-3)."""
        a = 0.2 * self.env.half
        p0 = self.position
        first = self.next_sequence() + 1000
        wild = 20e-6
        injected = {}
        phase = {}

        def inject(k):
            seq = first + k - int(LEAD * self.fs / 2)          # sent, and still queued at the controller
            good = self.sent.get(seq)
            if good is None:
                return
            if k == int(0.3 * self.fs):
                phase['frame2'] = time.time()
                msg = self.frames.encode_setpoints(seq, [good + wild])[0]
                data = bytearray(msg.data)
                data[-1] ^= 0x5A
                self._tx(can.Message(arbitration_id=msg.arbitration_id, data=data, is_fd=msg.is_fd,
                                     bitrate_switch=msg.bitrate_switch, is_extended_id=False, check=False))
                injected[seq] = 'CTRL-FRAME-2'
                msg = self.frames.encode_setpoints(seq + 1, [good + wild])[0]
                self._tx(can.Message(arbitration_id=msg.arbitration_id, data=bytes(msg.data[:len(msg.data) // 2]),
                                     is_fd=msg.is_fd, is_extended_id=False, check=False))
                injected[seq + 1] = 'CTRL-FRAME-2'
                bad = self.proto.encode('HostCommand', {'CMD_Code': CMD_ABORT, 'CMD_Counter': 0,
                                                        'CMD_Argument': 0.0, 'CMD_RampVelocity': 0.0})
                bad.data = bytearray(bad.data)
                bad.data[-1] ^= 0xFF
                self._tx(bad)
            elif k == int(0.7 * self.fs):
                phase['frame3'] = time.time()
                msg = self.frames.encode_setpoints(seq, [good + wild])[0]
                self._tx(can.Message(arbitration_id=msg.arbitration_id, data=msg.data, is_fd=msg.is_fd,
                                     bitrate_switch=msg.bitrate_switch, is_extended_id=True, check=False))
                injected[seq] = 'CTRL-FRAME-3'
                abort = self.proto.encode('HostCommand', {'CMD_Code': CMD_ABORT, 'CMD_Counter': 0,
                                                          'CMD_Argument': 0.0, 'CMD_RampVelocity': 0.0})
                self._tx(can.Message(arbitration_id=abort.arbitration_id, data=abort.data, is_extended_id=True))
                self._tx(can.Message(arbitration_id=abort.arbitration_id, is_remote_frame=True, dlc=8,
                                     is_extended_id=False))
                self._tx(can.Message(arbitration_id=0x7FE, data=bytes(8), is_extended_id=False))

        base = self.smooth(p0, -a if p0 > 0 else a)

        def wave(k):
            inject(k)
            return base(k)
        end = self.stream(first, wave, 1.1)
        self._sleep(LEAD + 0.05)
        samples = [s for s in self._samples_since(phase.get('frame2', 0.0)) if s.seq < end]
        for rid, since, until in (('CTRL-FRAME-2', 'frame2', 'frame3'), ('CTRL-FRAME-3', 'frame3', None)):
            t0, t1 = phase.get(since, math.inf), phase.get(until, math.inf) if until else math.inf
            applied_wrong = [seq for seq, who in injected.items() if who == rid and any(
                s.seq == seq and abs(s.u - self.sent[seq]) > 1.5 * LSB for s in samples)]
            stopped = [s for s in self._states_since(t0) if s[0] < t1 and s[1] != 'running'
                       and unwrap(s[3], end, 1 << 16) < end - 1]
            ok = not applied_wrong and not stopped and bool(samples)
            self.results.put(rid, PASS if ok else FAIL, f'{len(applied_wrong)} injected setpoints applied, '
                             f'{len(stopped)} status frames out of running',
                             '' if ok else 'such frames must change nothing')
        self.to_rest(self.position)

    def s_host_limits(self):
        """HostLimits bound the controller's own ramp (CTRL-LIM-1)."""
        hl_max = 0.5 * self.env.upper
        self.limits(self.env.lower, hl_max)
        p0 = min(self.position, 0.0)
        first = self.next_sequence() + 1000
        self.stream(first, self.ramp_to(self.position, p0, RAMP_VELOCITY), 0.2)
        self._sleep(LEAD + 0.1)
        t = time.time()
        target = 0.9 * self.env.upper
        self.command(CMD_ABORT, target, 5 * RAMP_VELOCITY)
        self._wait(lambda: self.state in ('idle', 'fault'), REST_TIMEOUT)
        self._sleep(0.05)
        u = [s.u for s in self._samples_since(t)]
        top = max(u, default=self.position)
        ok = bool(u) and top <= hl_max + 1.5 * LSB and abs(u[-1] - hl_max) <= 1e-6
        self.results.put('CTRL-LIM-1', PASS if ok else FAIL,
                         f'ABORT to {target * 1e3:.4f} mm with HL_DisplacementMax {hl_max * 1e3:.4f} mm: highest '
                         f'{top * 1e3:.4f} mm, stopped at {u[-1] * 1e3 if u else math.nan:.4f} mm',
                         '' if ok else "the controller's ramp must stop at HL_DisplacementMax")
        self.to_rest(self.position)

    def s_out_of_limits(self):
        """A setpoint outside HostLimits (CTRL-LIM-2, CTRL-FAULT-1, CTRL-FAULT-2)."""
        hl_max = 0.5 * self.env.upper
        self.limits(self.env.lower, hl_max)
        first = self.next_sequence() + 1000
        target = 0.8 * self.env.upper
        p0 = self.position
        t = time.time()
        try:
            self.stream(first, self.ramp_to(p0, target, RAMP_VELOCITY), abs(target - p0) / RAMP_VELOCITY + 0.1)
        finally:
            self.heartbeat = True
        self._wait(lambda: self.state in ('idle', 'fault'), REST_TIMEOUT)
        self._sleep(0.05)
        u = [s.u for s in self._samples_since(t)]
        top = max(u, default=p0)
        faults = self._fault_bits_since(t)
        ok = top <= hl_max + 1.5 * LSB and bool(faults) and self.state == 'fault'
        self.results.put('CTRL-LIM-2', PASS if ok else FAIL,
                         f'setpoints up to {target * 1e3:.4f} mm with HL_DisplacementMax {hl_max * 1e3:.4f} mm: '
                         f'highest applied {top * 1e3:.4f} mm, faults {fault_names(faults)}, state {self.state}',
                         '' if ok else 'a setpoint beyond HostLimits must never be applied, and must fault the rig')
        self._judge_fault_bits('outside HostLimits', faults, FAULT_DISPLACEMENT_LIMIT)
        self._judge_latch()
        self.limits(self.env.lower, self.env.upper)
        self.to_rest(self.position)

    def _fault_bits_since(self, t: float) -> int:
        bits = 0
        for s in self._states_since(t):
            bits |= s[2]
        return bits

    def _judge_fault_bits(self, cause: str, bits: int, expected: int):
        """CTRL-FAULT-1: judged only where a fault was raised (a missing fault fails the scenario's own
        requirement).
        """
        if not bits:
            return
        ok = bits == expected
        self.results.put('CTRL-FAULT-1', PASS if ok else FAIL, f'{cause}: {fault_names(bits)}',
                         '' if ok else f'expected exactly {fault_names(expected)}')

    def _judge_latch(self):
        """CTRL-FAULT-2: the fault stays until RESET; RESET returns to idle without fault bits."""
        if self.state != 'fault':
            return
        t = time.time()
        self._sleep(0.3)
        latched = all(s[1] == 'fault' and s[2] for s in self._states_since(t))
        t_reset = time.time()
        self.command(CMD_RESET)
        cleared = self._wait(lambda: self.state == 'idle' and not self.faults, 0.2)
        self.results.put('CTRL-FAULT-2', PASS if latched and cleared else FAIL,
                         f'fault held 0.3 s: {latched}; idle without faults {time.time() - t_reset:.3f} s after RESET: '
                         f'{cleared}', '' if latched and cleared else 'a fault must latch until RESET, which clears it')

    def s_too_fast(self):
        """A setpoint faster than the rated velocity (CTRL-LIM-3, CTRL-FAULT-1)."""
        if not self.identity or float(self.identity[1]['CI_VelocityMax']) <= 0:
            self.results.put('CTRL-LIM-3', NOT_TESTED, '', 'the controller states no rated velocity')
            return
        vmax = float(self.identity[1]['CI_VelocityMax'])
        step = 1.5 * vmax / self.fs
        p0 = self.position
        end_pos = p0 + step if p0 + step <= 0.8 * self.env.upper else p0 - step
        if not 0.8 * self.env.lower <= end_pos <= 0.8 * self.env.upper:
            self.results.put('CTRL-LIM-3', NOT_TESTED, f'a step of {step * 1e3:.3f} mm is needed',
                             'the envelope is too small for a step above the rated velocity')
            return
        first = self.next_sequence() + 1000
        t = time.time()
        self.stream(first, lambda k: p0 if k < int(0.2 * self.fs) else end_pos, 0.4)
        self.heartbeat = True
        self._wait(lambda: self.state in ('idle', 'fault'), REST_TIMEOUT)
        self._sleep(0.05)
        u = [p0] + [s.u for s in self._samples_since(t)]
        fastest = max((abs(b - a) * self.fs for a, b in zip(u, u[1:], strict=False)), default=0.0)
        faults = self._fault_bits_since(t)
        ok = fastest <= vmax * 1.02 + 2 * LSB * self.fs and bool(faults) and self.state == 'fault'
        self.results.put('CTRL-LIM-3', PASS if ok else FAIL,
                         f'a step of {step * 1e3:.3f} mm in one sample ({step * self.fs:.3f} m/s, rated '
                         f'{vmax:g} m/s): fastest applied {fastest:.4f} m/s, faults {fault_names(faults)}',
                         '' if ok else 'a setpoint above the rated velocity must never be applied, and must fault')
        self._judge_fault_bits('too fast', faults, FAULT_VELOCITY_LIMIT)
        self.to_rest(self.position)

    def s_host_silence(self):
        """Host silence (CTRL-WD-1, CTRL-FAULT-1)."""
        a = 0.4 * self.env.half
        p0 = self.position
        first = self.next_sequence() + 1000
        self.stream(first, self.smooth(p0, -a if p0 > 0 else a), 0.6)
        self.heartbeat = False
        self._sleep(0.01)
        with self.lock:   # the controller's host watchdog runs on HostHeartbeat
            t_silent = max(f.t for f in self.trace.frames if f.name == 'HostHeartbeat')
        timeout = self.host_timeout
        ramped = self._wait(lambda: self.state in ('ramping_down', 'fault', 'idle'), timeout + 1.0)
        t_ramp = next((s[0] for s in self._states_since(t_silent) if s[1] in ('ramping_down', 'fault', 'idle')),
                      None)
        if not ramped:
            self.results.put('CTRL-WD-1', FAIL, f'still {self.state} {timeout + 1.0:.2f} s after the host fell silent '
                             f'(stated host timeout {timeout:g} s)', 'the controller must ramp to rest on host silence')
            self.to_rest(0.0)
            return
        self._wait(lambda: self.state in ('idle', 'fault'), REST_TIMEOUT)
        self._sleep(0.05)
        delay = t_ramp - t_silent
        faults = self._fault_bits_since(t_silent)
        rest = self.position
        ok = delay <= timeout + 0.1 and abs(rest) <= 1e-6 and self.state == 'fault' and bool(faults)
        self.results.put('CTRL-WD-1', PASS if ok else FAIL,
                         f'ramp began {delay:.3f} s after the last HostHeartbeat (stated host timeout {timeout:g} s), '
                         f'rest at {rest * 1e3:.4f} mm, state {self.state}, faults {fault_names(faults)}',
                         '' if ok else 'host silence must ramp the rig to rest within the host timeout, faulted')
        self._judge_fault_bits('host silence', faults, FAULT_WATCHDOG)
        self.to_rest(0.0)

    def s_wrap(self):
        """Streams across a 2^16 boundary and the field's wrap (CTRL-SEQ-2)."""
        starts = [(1 << 16) - int(0.3 * self.fs)]
        if self.trace.modulus[self.frames.feedback_names[0]] > (1 << 16):
            starts.append((1 << 32) - int(0.3 * self.fs))
        for first in starts:
            p0 = self.position
            self.stream(first, lambda k, p=p0: p, 0.6)
            self._sleep(LEAD + 0.1)
            self.to_rest(0.0)

    def trace_to_log(self, path):
        """Write every frame of the run, with the times it was judged by, to the raw CAN log `path` (.blf, .asc,
        .log): the offline mode then reads what this run saw.
        """
        with self.lock:
            frames = list(self.trace.frames)
        frames.sort(key=lambda f: f.t)
        with can.Logger(str(path)) as writer:
            for f in frames:
                m = f.msg
                writer.on_message_received(can.Message(
                    timestamp=f.t, arbitration_id=m.arbitration_id, data=m.data, dlc=m.dlc, is_fd=m.is_fd,
                    bitrate_switch=m.bitrate_switch, is_extended_id=m.is_extended_id,
                    is_remote_frame=m.is_remote_frame, is_rx=not f.host, channel=0, check=False))
