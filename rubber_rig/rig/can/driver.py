"""Host driver over any python-can Bus: streams setpoints, assembles measured samples, counts bad frames,
checks limits and sensors, and runs the watchdog. poll() is non-blocking and never raises on bad frames."""
import collections
import math
import time
from dataclasses import dataclass, field
from typing import List

import numpy as np

from .protocol import (CMD_ABORT, CMD_RESET, FAULT_BUS, FAULT_DISPLACEMENT_LIMIT, FAULT_FORCE_LIMIT,
                       FAULT_SENSOR, FAULT_VELOCITY_LIMIT, FAULT_WATCHDOG, SEQ_MOD, STATES,
                       MalformedFrame, Protocol, unwrap_sequence)


@dataclass
class SampleBlock:
    """Consecutive measured samples: sample i has sequence first_sequence + i and was taken at
    t0 + i * sample_period (t0: bus timestamp of the first sample's frame [s]). SI units. `setpoint` is the
    command the controller applied (the host setpoint, or its own ramp after an abort). frames_lost: samples
    lost on the bus just before this block."""
    first_sequence: int
    t0: float
    sample_period: float
    displacement: np.ndarray
    force: np.ndarray
    setpoint: np.ndarray
    temperature: float
    status_flags: int
    frames_lost: int

    def __len__(self):
        return int(self.displacement.size)

    @property
    def sequence(self) -> np.ndarray:
        return np.arange(self.first_sequence, self.first_sequence + len(self), dtype=np.int64)


@dataclass
class RigStatus:
    """Snapshot of the driver (fields as msg_defs/RigStatus; faults is the FAULT_* bit mask)."""
    state: str
    faults: int
    fault_messages: List[str]
    sample_rate: float
    samples_received: int
    frames_lost: int
    frames_late: int
    frames_malformed: int
    frames_unknown: int
    temperature: float
    controller_state: str
    controller_faults: int
    controller_sequence: int
    setpoints_sent: int
    limits: object = None
    extra: dict = field(default_factory=dict)


class RigDriver:
    """Driver for the rig controller on python-can `bus` with RigConfig `config`.

    Call poll() often (at least every watchdog_timeout / 2): it drains the bus without blocking, updates the
    watchdog and returns the next block of contiguous samples or None."""

    def __init__(self, bus, config, protocol: Protocol = None, clock=time.monotonic):
        self.bus, self.cfg = bus, config
        self.proto = protocol or Protocol()
        self.fs = float(config.sample_rate)
        self.limits = config.limits
        self._clock = clock
        self._handlers = {'Feedback': self._on_feedback, 'ControllerStatus': self._on_status,
                          'ControllerHeartbeat': self._on_heartbeat, 'Temperature': self._on_temperature}
        # stream bookkeeping
        self._queued_end = None          # sequence after the last queued setpoint
        self._last_queued = None         # last queued setpoint [m]
        self._last_applied = None        # last command the controller reported applying [m]
        self._expected = None            # next feedback sequence expected
        self._pend = ([], [], [])        # x, f, u of the contiguous samples not yet returned
        self._pend_first, self._pend_t0, self._pend_lost = None, None, 0   # first sequence, its frame time
        self._ready = collections.deque()
        self._recent = collections.deque(maxlen=max(20, int(0.05 * self.fs)))   # (u, x, f) for sensor checks
        self._bad = collections.deque()  # (sample position, count) of bad-frame events, 1 s window
        # counters and state
        self.counters = dict(samples_received=0, frames_lost=0, frames_late=0, frames_malformed=0,
                             frames_unknown=0, setpoints_sent=0, heartbeats_received=0)
        self.faults, self.fault_messages = 0, []
        self.controller_state, self.controller_faults, self.controller_sequence = 'unconfigured', 0, -1
        self.temperature = math.nan
        self._aborting = False
        now = clock()
        self._last_fb_wall = self._last_hb_wall = self._last_host_hb_wall = now
        self._hb_sample = None           # feedback position at the last controller heartbeat
        self._host_hb_counter = 0
        self._hb_every = max(1, round(config.heartbeat_period * self.fs))
        self._next_hb_seq = None
        self._wd_wall = config.watchdog_timeout if config.paced else max(config.watchdog_timeout, 2.0)
        self.pump = None                 # callable run at the start of poll() (in-process fast simulator)
        self._send_host_heartbeat()

    # ---- host -> controller
    def queue_setpoints(self, first_sequence: int, displacement) -> bool:
        """Stream setpoints [m] for samples first_sequence .. + n - 1 (contiguous with the previous call).

        The whole batch is checked against the limits before anything is sent; a violation faults the rig
        (safe ramp) and returns False. Also returns False while faulted or ramping down."""
        x = np.asarray(displacement, dtype=float)
        if self.faults or self._aborting:
            return False
        if self._queued_end is not None and first_sequence != self._queued_end:
            raise ValueError(f'queue_setpoints: first_sequence {first_sequence} is not contiguous with the '
                             f'stream (next is {self._queued_end})')
        if x.size == 0:
            return True
        lim = self.limits
        lo, hi = float(np.min(x)), float(np.max(x))
        if not (np.all(np.isfinite(x)) and lim.displacement_min <= lo and hi <= lim.displacement_max):
            self._fault(FAULT_DISPLACEMENT_LIMIT, f'setpoints {lo:.6g}..{hi:.6g} m outside the displacement '
                                                  f'limits {lim.displacement_min:g}..{lim.displacement_max:g} m')
            return False
        # a new stream continues from where the controller is (its last applied command), never with a step
        prev = self._last_queued if self._queued_end is not None else (
            self._last_applied if self._last_applied is not None else x[0])
        v = float(np.max(np.abs(np.diff(np.concatenate([[prev], x]))))) * self.fs
        if v > lim.velocity_max * (1 + 1e-9):
            self._fault(FAULT_VELOCITY_LIMIT, f'setpoint velocity {v:.6g} m/s above {lim.velocity_max:g} m/s')
            return False
        if self._queued_end is None or self._expected is not None and self._expected >= self._queued_end:
            self._last_fb_wall = self._clock()   # pipeline was empty: the feedback clock starts now
        if self._next_hb_seq is None:
            self._next_hb_seq = first_sequence
        encode, send = self.proto.encode, self.bus.send
        for i, value in enumerate(x.tolist()):
            seq = first_sequence + i
            if seq >= self._next_hb_seq:
                # heartbeats ride with the stream so the controller sees them at the right sample in fast mode
                self._send_host_heartbeat()
                self._next_hb_seq = seq + self._hb_every
            send(encode('Setpoint', {'SP_Sequence': seq % SEQ_MOD, 'SP_Displacement': value}))
        self._queued_end = first_sequence + x.size
        self._last_queued = float(x[-1])
        self.counters['setpoints_sent'] += int(x.size)
        return True

    def abort(self, reason: str = 'abort requested', target: float = 0.0):
        """Command the safe ramp: the controller flushes queued setpoints and ramps smoothly from where it is
        to target [m] (clamped into the limits). Further setpoints are refused until reset()."""
        target = self.limits.clamp_position(target)
        # ramp at most half the velocity limit (and 50 mm/s), in whole mm/s as the frame carries it
        ramp_v = max(0.001, math.floor(min(0.5 * self.limits.velocity_max, 0.05) * 1000) / 1000)
        self.bus.send(self.proto.encode('HostCommand', {'CMD_Code': CMD_ABORT, 'CMD_Counter': 0,
                                                        'CMD_Argument': target, 'CMD_RampVelocity': ramp_v}))
        if not self._aborting:
            self.fault_messages.append(f'abort: {reason}')
        self._aborting = True

    def reset(self):
        """Clear faults (driver and controller) so a new stream can start."""
        self.bus.send(self.proto.encode('HostCommand', {'CMD_Code': CMD_RESET, 'CMD_Counter': 0,
                                                        'CMD_Argument': 0, 'CMD_RampVelocity': 0}))
        self.faults, self.fault_messages, self._aborting = 0, [], False
        self._queued_end = self._last_queued = None

    def _send_host_heartbeat(self):
        self._host_hb_counter = (self._host_hb_counter + 1) % 256
        self.bus.send(self.proto.encode('HostHeartbeat', {'HH_Counter': self._host_hb_counter}))
        self._last_host_hb_wall = self._clock()

    # ---- controller -> host
    def poll(self):
        """Drain received frames (non-blocking), run the watchdog and checks; return the next SampleBlock of
        contiguous samples, or None if there is none."""
        if self.pump is not None:
            self.pump()
        recv = self.bus.recv
        msg = recv(0)
        while msg is not None:
            self._receive(msg)
            msg = recv(0)
        self._flush_pending()
        self._watchdog()
        return self._ready.popleft() if self._ready else None

    def _receive(self, msg):
        try:
            decoded = self.proto.decode(msg)
        except MalformedFrame:
            self.counters['frames_malformed'] += 1
            self._bad_event(1)
            return
        if decoded is None:
            self.counters['frames_unknown'] += 1
            return
        handler = self._handlers.get(decoded[0])
        if handler is None:   # a host frame echoed back or from another host: not ours to consume
            self.counters['frames_unknown'] += 1
            return
        handler(decoded[1], msg)

    def _on_feedback(self, sig, msg):
        ref = self._expected if self._expected is not None else (
            self._queued_end - 1 if self._queued_end is not None else 0)
        seq = unwrap_sequence(int(sig['FB_Sequence']), ref)
        if self._expected is None:
            self._expected = seq
        if seq < self._expected:
            self.counters['frames_late'] += 1    # delayed or duplicated: its slot is already past
            self._bad_event(1)
            return
        if seq > self._expected:
            lost = seq - self._expected
            self.counters['frames_lost'] += lost
            self._bad_event(lost)
            self._flush_pending()
            self._pend_lost += lost
            if lost / self.fs > self.cfg.lost_burst_max:
                self._fault(FAULT_BUS, f'{lost} consecutive samples lost ({lost / self.fs * 1e3:.1f} ms > '
                                       f'{self.cfg.lost_burst_max * 1e3:g} ms)')
        if self._pend_first is None:
            self._pend_first, self._pend_t0 = seq, msg.timestamp
        x, f, u = float(sig['FB_Displacement']), float(sig['FB_Force']), float(sig['FB_Setpoint'])
        px, pf, pu = self._pend
        px.append(x)
        pf.append(f)
        pu.append(u)
        self._recent.append((u, x, f))
        self._last_applied = u
        self._expected = seq + 1
        self.counters['samples_received'] += 1
        self._last_fb_wall = self._clock()
        self._check_measurement(x, f)

    def _on_status(self, sig, msg):
        code = int(sig['ST_State'])
        self.controller_state = STATES[code] if code < len(STATES) else 'fault'
        self.controller_faults = int(sig['ST_Faults'])
        ref = self.controller_sequence if self.controller_sequence >= 0 else (self._expected or 0)
        self.controller_sequence = unwrap_sequence(int(sig['ST_LastSequence']), ref)

    def _on_heartbeat(self, sig, msg):
        code = int(sig['HB_State'])
        self.controller_state = STATES[code] if code < len(STATES) else 'fault'
        self.counters['heartbeats_received'] += 1
        self._last_hb_wall = self._clock()
        self._hb_sample = self._expected

    def _on_temperature(self, sig, msg):
        self.temperature = float(sig['TEMP_Specimen'])

    def _flush_pending(self):
        px, pf, pu = self._pend
        if px:
            self._ready.append(SampleBlock(self._pend_first, self._pend_t0, 1.0 / self.fs, np.array(px),
                                           np.array(pf), np.array(pu), self.temperature, self.controller_faults,
                                           self._pend_lost))
            self._pend = ([], [], [])
            self._pend_first, self._pend_t0, self._pend_lost = None, None, 0

    # ---- checks
    def _bad_event(self, n):
        pos = self._expected or 0
        self._bad.append((pos, n))
        while self._bad and self._bad[0][0] < pos - self.fs:
            self._bad.popleft()
        total = sum(c for _, c in self._bad)
        if total > self.cfg.bus_error_max and not self.faults & FAULT_BUS:
            self._fault(FAULT_BUS, f'{total} bad frames (lost/late/malformed) within 1 s of samples '
                                   f'(> {self.cfg.bus_error_max})')

    def _check_measurement(self, x, f):
        lim = self.limits
        if abs(f) > lim.force_max and not self.faults & FAULT_FORCE_LIMIT:
            self._fault(FAULT_FORCE_LIMIT, f'measured force {f:.6g} N above force_max {lim.force_max:g} N')
        margin = 0.02 * (lim.displacement_max - lim.displacement_min)
        if not (lim.displacement_min - margin <= x <= lim.displacement_max + margin) \
                and not self.faults & FAULT_DISPLACEMENT_LIMIT:
            self._fault(FAULT_DISPLACEMENT_LIMIT, f'measured displacement {x:.6g} m outside the limits')

    def _watchdog(self):
        now = self._clock()
        cfg = self.cfg
        if cfg.paced and now - self._last_host_hb_wall >= cfg.heartbeat_period:
            self._send_host_heartbeat()
        if self.faults & FAULT_WATCHDOG:
            return
        streaming = self._queued_end is not None and (self._expected is None or self._expected < self._queued_end)
        if streaming and not self._aborting and now - self._last_fb_wall > self._wd_wall:
            self._fault(FAULT_WATCHDOG, f'no feedback for {now - self._last_fb_wall:.3f} s with setpoints queued')
            return
        if self._expected is not None and not self._aborting:
            lag = (self.controller_sequence + 1 - self._expected) / self.fs
            if lag > cfg.watchdog_timeout:
                self._fault(FAULT_WATCHDOG, f'feedback {lag:.3f} s behind the controller (stalled or delayed)')
                return
        if self._hb_sample is not None and self._expected is not None:
            silent = (self._expected - self._hb_sample) / self.fs
            if silent > cfg.watchdog_timeout:
                self._fault(FAULT_WATCHDOG, f'controller heartbeat silent for {silent:.3f} s of samples')
                return
        if cfg.paced and self.counters['heartbeats_received'] and now - self._last_hb_wall > cfg.watchdog_timeout:
            self._fault(FAULT_WATCHDOG, f'controller heartbeat silent for {now - self._last_hb_wall:.3f} s')
            return
        self._check_sensors()

    def _check_sensors(self):
        if len(self._recent) < self._recent.maxlen or self.controller_state != 'running' or self.faults & FAULT_SENSOR:
            return
        arr = np.array(self._recent)
        span = arr.max(axis=0) - arr.min(axis=0)
        if span[0] > 20e-6 and span[1] < 2.5e-7:
            self._fault(FAULT_SENSOR, f'displacement sensor stuck: command moved {span[0] * 1e3:.3f} mm, '
                                      'measurement did not')
        elif span[1] > 20e-6 and span[2] < 0.05:
            self._fault(FAULT_SENSOR, f'force sensor stuck: displacement moved {span[1] * 1e3:.3f} mm, force '
                                      'did not')
        self._recent.clear()   # judge disjoint windows: cheap and enough

    def _fault(self, bit: int, message: str):
        """Record a fault and command the safe ramp."""
        self.faults |= bit
        self.fault_messages.append(message)
        self.abort(message)

    # ---- status
    @property
    def status(self) -> RigStatus:
        """Snapshot of state, faults and counters."""
        if self.controller_state == 'ramping_down':
            state = 'ramping_down'
        elif self.faults or self.controller_faults:
            state = 'fault'
        else:
            state = self.controller_state
        c = self.counters
        return RigStatus(state, self.faults | self.controller_faults, list(self.fault_messages), self.fs,
                         c['samples_received'], c['frames_lost'], c['frames_late'], c['frames_malformed'],
                         c['frames_unknown'], self.temperature, self.controller_state, self.controller_faults,
                         self.controller_sequence, c['setpoints_sent'], self.limits,
                         {'heartbeats_received': c['heartbeats_received']})

    @property
    def next_sequence(self) -> int:
        """Sequence the next queued setpoint must have (0 before the first)."""
        return 0 if self._queued_end is None else self._queued_end

    def close(self):
        """Shut the bus down (the caller decides whether to abort first)."""
        self.bus.shutdown()
