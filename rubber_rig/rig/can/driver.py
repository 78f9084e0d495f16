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

"""Host driver over any python-can Bus: streams setpoints, assembles measured samples, counts bad frames,
checks limits and sensors, and runs the watchdog. poll() is non-blocking and never raises on bad frames.
"""
import collections
import itertools
import math
import time

import can
import numpy as np

from ...safety import abort_ramp_velocity, setpoint_violation
from .frames import SampleFrames
from .protocol import (
    CMD_ABORT,
    CMD_HOLD,
    CMD_IDENTIFY,
    CMD_RESET,
    FAULT_BUS,
    FAULT_DISPLACEMENT_LIMIT,
    FAULT_FORCE_LIMIT,
    FAULT_SENSOR,
    FAULT_STREAM,
    FAULT_VELOCITY_LIMIT,
    FAULT_WATCHDOG,
    PROTOCOL_VERSION,
    STATES,
    STATUS_SEQ_MOD,
    MalformedFrame,
    Protocol,
    fault_names,
    unwrap,
)
from .sensor_check import SensorCheck
from .stream import DriverStatus, GrantedStream, SampleBlock, StreamGrant, StreamRefused

__all__ = ['DriverStatus', 'RigDriver', 'SampleBlock', 'StreamGrant', 'StreamRefused']


class RigDriver:
    """Driver for the rig controller on python-can `bus` with RigConfig `config`; the one safety authority.

    Only the owner of the open stream commands the rig (open_stream -> queue_setpoints with its id ->
    end_stream); every batch is checked against the limits as the continuation of what is already queued,
    including that the rig can still stop inside the displacement range at limits.deceleration_max. Faults,
    aborts, holds and a stream that stops (no batch for stream_timeout, or the controller running dry before
    the owner's last batch) end in the controller's own ramp, inside the limits. `events` collects one
    (level, text) line per transition for the caller's log.

    Call poll() often (at least every watchdog_timeout / 2): it drains the bus without blocking, updates the
    watchdog and returns the next block of contiguous samples or None.
    """

    MAX_LEAD_SAMPLES = 16384     # a stream may start at most this far ahead (16-bit sequences stay unambiguous)
    # a granted stream whose owner has sent nothing yet has moved nothing: it is withdrawn (no fault, nothing to
    # ramp) after this long, so a client that died or stalled between its grant and its first batch cannot fault
    # the rig, and one that is merely slow to hear the grant (the first service reply on a fresh DDS link) is not
    # judged by stream_timeout, which is for a stream that stops while it moves the rig
    FIRST_BATCH_TIMEOUT = 2.0    # [s]

    def __init__(self, bus, config, protocol: Protocol = None, clock=time.monotonic):
        self.bus, self.cfg = bus, config
        self.proto = protocol or Protocol()
        self.fs = float(config.sample_rate)
        # the protocol's share of the configured bus at this rate (worst-case stuffing; RigConfig refused more
        # than its max_bus_load): what status and diagnostics report as bus load
        self.bus_load = config.bus_load().load
        self.measured_load = None        # callable -> busy fraction of the last second, when the bus can tell
        self._load_at, self._load = -math.inf, None
        self.limits = config.limits
        self._clock = clock
        # the frames that carry samples (config.frame_profile) take a fast path; the rest go through cantools
        self.frames = SampleFrames(config.frame_profile, self.proto.db, self.fs)
        self._feedback_ids = {self.frames.codecs[n].frame_id for n in self.frames.feedback_names}
        self._setpoint_ids = {self.frames.codecs[n].frame_id for n in self.frames.setpoint_names}
        # frames the bus did not take yet (its transmit queue was full), sent in order by poll()
        self._outbox = collections.deque()
        self._outbox_since = None        # when the oldest of them was first refused
        self._sent_end = 0               # after the last setpoint ever sent: a new stream starts at or after it
        self._handlers = {'ControllerStatus': self._on_status, 'ControllerHeartbeat': self._on_heartbeat,
                          'Temperature': self._on_temperature, 'ControllerIdentity': self._on_identity}
        # what the controller said of itself (ControllerIdentity): protocol, device, firmware, host_timeout [s],
        # velocity_max [m/s]; None until it did
        self.controller_identity = None
        # stream bookkeeping
        self._stream = None              # GrantedStream of the owner, or None
        self._stream_ids = itertools.count(int(clock() * 1000) % 1_000_000 * 1000 + 1)
        self._jump_to = None             # a stream on an idle rig starts at this sequence: the jump is no loss
        self._last_applied = 0.0         # last command the controller reported applying [m]
        self._prev_applied = 0.0
        self._expected = None            # next feedback sequence expected
        self._pend = ([], [], [])        # x, f, u of the contiguous samples not yet returned
        self._pend_first, self._pend_t0, self._pend_lost = None, None, 0   # first sequence, its frame time
        self._ready = collections.deque()
        self._sensor = SensorCheck(self.fs)
        self._bad = collections.deque()  # (sample position, count) of bad-frame events, 1 s window
        self.events = collections.deque(maxlen=1000)   # (level 'info'|'warn'|'error', text)
        self.last_event = ''
        # a stop the host commanded (abort, hold, limits) stays the headline while the controller's ramp, its
        # consequence, runs: a status published in between must say why the stream ended, not 'ramping'
        self._host_stop = False
        self.refusal = ''                # why the latest batch was refused
        # counters and state
        self.counters = dict(samples_received=0, frames_lost=0, frames_late=0, frames_malformed=0,
                             frames_unknown=0, setpoints_sent=0, setpoints_refused=0, heartbeats_received=0,
                             tx_queue_full=0)
        self.faults, self.fault_messages = 0, []
        self.controller_state, self.controller_faults, self.controller_sequence = 'unconfigured', 0, -1
        self.temperature = math.nan
        self._aborting = False           # a ramp commanded by the host is under way
        self._ramp_pending = False       # commanded to a moving controller that has not yet reported the ramp
        now = clock()
        self._last_fb_wall = self._last_hb_wall = self._last_host_hb_wall = self._last_poll_wall = now
        self._hb_sample = None           # feedback position at the last controller heartbeat
        self._host_hb_counter = 0
        self._hb_every = max(1, round(config.heartbeat_period * self.fs))
        self._next_hb_seq = None
        self._wd_wall = config.watchdog_timeout if config.paced else max(config.watchdog_timeout, 2.0)
        self.pump = None                 # callable run at the start of poll() (in-process fast simulator)
        self._send_host_heartbeat()
        self.send_limits()
        self._send_command(CMD_IDENTIFY)   # HOST-ID-1: ask who is there before anything streams

    # ---- events
    def _event(self, level: str, text: str, headline: bool = True):
        self.events.append((level, text))
        if headline:
            self.last_event = text

    # ---- limits
    def set_limits(self, limits):
        """Apply new limits at once: the controller's ramps follow them, and if the rig or what is queued lies
        outside them the rig ramps into them now (a fault: the program no longer fits).
        """
        self.limits = limits
        self.send_limits()
        self._event('info', f'limits: displacement {limits.displacement_min * 1e3:g}..{limits.displacement_max * 1e3:g}'
                            f' mm, velocity {limits.velocity_max:g} m/s, force {limits.force_max:g} N, deceleration '
                            f'{limits.deceleration_max:g} m/s^2')
        s = self._stream
        inside = limits.displacement_min <= self._last_applied <= limits.displacement_max
        if s is not None and not s.held and (s.queued_end > self.next_sequence or not inside):
            self._fault(FAULT_DISPLACEMENT_LIMIT, 'limits changed while streaming: the queued setpoints were '
                                                  'checked against the old limits')
        elif not inside:
            self.abort('limits changed: the rig is outside the new displacement limits')

    def send_limits(self):
        lim = self.limits
        self._send(self.proto.encode('HostLimits', {
            'HL_DisplacementMin': lim.displacement_min, 'HL_DisplacementMax': lim.displacement_max,
            # multiples of 2 m/s^2, never above the limit, and never 0 (which would mean the controller's default)
            'HL_Deceleration': max(2.0, min(510.0, math.floor(lim.deceleration_max / 2) * 2.0))}))

    # ---- streams
    @property
    def stream(self):
        """The open StreamGrant, or None."""
        return self._stream.grant if self._stream is not None else None

    def why_not_ready(self) -> str:
        """'' when a stream can open now, else why not."""
        if self.faults:
            return 'rig fault: ' + '; '.join(self.fault_messages[-3:]) + ' (reset to acknowledge)'
        if self.controller_state == 'unconfigured':
            return 'the controller has not announced itself'
        why = self._identity_mismatch()
        if why:
            return why
        if self._aborting or self.controller_state == 'ramping_down':
            return 'the rig is ramping to rest'
        if self.controller_state == 'fault' or self.controller_faults:
            return f'controller fault {fault_names(self.controller_faults)} (reset to acknowledge)'
        return ''

    def open_stream(self, owner: str, lead_samples: int = 0) -> StreamGrant:
        """Grant the setpoint stream to `owner` (StreamRefused says why not). The first setpoint is due at
        first_sequence, lead_samples after every sample the rig has taken or been sent; the rig holds until
        then. The owner of a held or ended stream may re-open it (resume).
        """
        why = self.why_not_ready()
        if why:
            raise StreamRefused(why)
        s = self._stream
        if s is not None:
            if s.grant.owner != owner:
                raise StreamRefused(f'the rig is streaming for {s.grant.owner or "another client"} '
                                    f'(stream {s.grant.stream_id})')
            if not (s.held or s.ended):
                raise StreamRefused(f'{owner} already has stream {s.grant.stream_id} open (end it first)')
        # a ticking (holding) controller needs the first setpoint `lead` ahead; an idle one starts on arrival
        ticking = self.controller_state in ('running', 'holding')
        lead = max(0, min(int(lead_samples), self.MAX_LEAD_SAMPLES)) if ticking else 0
        first = self.next_sequence + lead
        if self.controller_state in ('idle', 'fault') and (s is None or s.queued_end <= self.next_sequence):
            self._jump_to = first     # an idle controller starts at the first setpoint it gets
        v = (self._last_applied - self._prev_applied) * self.fs if self.controller_state == 'running' else 0.0
        grant = StreamGrant(next(self._stream_ids), owner, first, self._last_applied, v)
        self._announce_stream(first)
        self._stream = GrantedStream(grant, first, self._last_applied, v, self._clock())
        self._host_stop = False
        self._event('info', f'stream {grant.stream_id} opened for {owner or "a local client"}: first setpoint '
                            f'at sample {first}, from {grant.position * 1e3:.4f} mm')
        return grant

    def _announce_stream(self, first: int):
        """HostStreamStart: the controller takes setpoints from `first` on (and, after a ramp, no older ones)."""
        self._send(self.proto.encode('HostStreamStart', {'HS_FirstSequence': first % (1 << 32)}))

    def refuse(self, n: int, why: str):
        """Count n setpoints refused before they reached the queue (StreamGate: not the owner's channel)."""
        self.refusal = why
        self.counters['setpoints_refused'] += int(n)

    def count(self, name: str, n: int = 1):
        """Add n to the counter `name` (reported in status.extra)."""
        self.counters[name] = self.counters.get(name, 0) + int(n)

    def end_stream(self, stream_id: int):
        """The owner's last batch is queued: running dry afterwards is the end of the program."""
        s = self._stream
        if s is not None and s.grant.stream_id == stream_id and not s.ended:
            s.ended = True
            self._event('info', f'stream {stream_id} ended by {s.grant.owner or "its owner"} at sample '
                                f'{s.queued_end}')

    def queue_setpoints(self, first_sequence: int, displacement, stream_id: int = None) -> bool:
        """Stream setpoints [m] for samples first_sequence .. + n - 1 of stream `stream_id` (contiguous with its
        previous batch). Without stream_id a local caller (ROS-free runner, tests) gets a stream opened for it at
        first_sequence when none is open.

        The whole batch is checked before anything is sent: displacement range, velocity from the true end of
        the queue, and that every setpoint can still stop inside the range at deceleration_max; a violation
        faults the rig (safe ramp) and returns False. A batch of another stream, or a discontinuous one, is
        refused (False, counted, `refusal` says why) and changes nothing. Also False while faulted or
        ramping.
        """
        x = np.asarray(displacement, dtype=float)
        s = self._stream
        if stream_id is None and s is None and not self.why_not_ready():
            s = self._local_stream(first_sequence)
        why = self._refusal(s, first_sequence, stream_id, x.size)
        if why:
            self.refusal = why
            self.counters['setpoints_refused'] += int(x.size)
            return False
        bad = setpoint_violation(self.limits, x, self.fs, s.last_queued)
        if bad is not None and bad.kind == 'not_finite':
            # never a setpoint of a program (the excitation cannot make one): a corrupted or forged batch. It is
            # refused without a fault, so a forged one that copied the owner's stream id and name cannot end its
            # program; the owner's own next batch then continues the queue as if it never came (were it the
            # owner's, its next batch would not continue and the stream would be lost after stream_timeout)
            self.refusal = f'non-finite setpoint {float(x[bad.index])} at sample {first_sequence + bad.index}: ' \
                           f'batch refused'
            self.counters['setpoints_refused'] += int(x.size)
            return False
        s.last_rx_wall = self._clock()
        s.batches += 1
        if x.size == 0:
            return True
        if bad is not None:
            code = FAULT_VELOCITY_LIMIT if bad.kind == 'velocity' else FAULT_DISPLACEMENT_LIMIT
            self._fault(code, f'setpoints from sample {first_sequence} (continuing from {s.last_queued * 1e3:.4f} '
                              f'mm): {bad.message}')
            return False
        if first_sequence <= self.controller_sequence:
            self._fault(FAULT_STREAM, f'setpoints for sample {first_sequence} arrived after the rig passed it '
                                      f'(at {self.controller_sequence}): the stream is late')
            return False
        pipeline_empty = self._expected is None or self._expected >= s.queued_end or self._jump_to is not None
        if s.queued_end == s.grant.first_sequence and pipeline_empty:
            self._last_fb_wall = self._clock()   # pipeline was empty (or idle rig): the feedback clock starts now
        if self._next_hb_seq is None or self._next_hb_seq < first_sequence - self._hb_every:
            self._next_hb_seq = first_sequence
        send, per = self._send, self.frames.setpoints_per_frame
        values = x.tolist()
        for i, msg in enumerate(self.frames.encode_setpoints(first_sequence, values)):
            last = first_sequence + min((i + 1) * per, len(values)) - 1
            if last >= self._next_hb_seq:
                # heartbeats ride with the stream so the controller sees them at the right sample in fast mode
                self._send_host_heartbeat()
                self._next_hb_seq = last + self._hb_every
            send(msg)
        s.queued_end = first_sequence + x.size
        self._sent_end = max(self._sent_end, s.queued_end)
        before = float(x[-2]) if x.size > 1 else s.last_queued
        s.last_queued, s.last_velocity = float(x[-1]), (float(x[-1]) - before) * self.fs
        self.counters['setpoints_sent'] += int(x.size)
        return True

    def _local_stream(self, first_sequence):
        grant = self.open_stream('', 0)
        grant.first_sequence = first_sequence
        self._announce_stream(first_sequence)
        self._stream.queued_end = first_sequence
        if self._jump_to is not None:
            self._jump_to = first_sequence
        return self._stream

    def _refusal(self, s, first_sequence, stream_id, n) -> str:
        if self.faults or self._aborting:
            return 'the rig is faulted or ramping to rest'
        if s is None:
            return 'no stream is open (rig_driver/open_stream first)'
        if stream_id is not None and stream_id != s.grant.stream_id:
            return (f'stream {stream_id} is not the open stream {s.grant.stream_id} of '
                    f'{s.grant.owner or "a local client"}')
        if s.held or s.ended:
            return f'stream {s.grant.stream_id} is {"held" if s.held else "ended"} (open it again to resume)'
        if first_sequence != s.queued_end:
            return (f'batch starts at sample {first_sequence}, the stream continues at {s.queued_end} '
                    '(discontinuous streams are refused)')
        return ''

    def stop_stream(self, stream_id: int, target: float, reason: str, hold: bool = False) -> str:
        """The owner stops now: flush and ramp to target [m] (clamped into the limits). hold: the owner keeps
        the rig and resumes with open_stream. '' on success, else why not.
        """
        s = self._stream
        if s is None or s.grant.stream_id != stream_id:
            return f'stream {stream_id} is not open'
        if hold:
            s.held = True
            self._command_ramp(CMD_ABORT, target, f'hold: {reason}')
        else:
            self.abort(reason, target)
        return ''

    def abort(self, reason: str = 'abort requested', target: float = None):
        """Command the safe ramp: the controller flushes queued setpoints and ramps smoothly from where it is
        to target [m] (default rest_position, clamped into the limits). The stream is released.
        """
        self._command_ramp(CMD_ABORT, target, f'abort: {reason}')
        self._release_stream()

    def hold_here(self, reason: str):
        """Stop the motion where it can stop (braking within the limits) and hold there; the stream is
        released.
        """
        self._command_ramp(CMD_HOLD, None, f'hold: {reason}')
        self._release_stream()

    def _command_ramp(self, code, target, text):
        target = self.limits.clamp_position(self.cfg.rest_position if target is None else float(target))
        lim = self.limits
        # the travel speed, in whole mm/s as the frame carries it (velocity_max >= 2 mm/s: >= 1 mm/s)
        ramp_v = max(0.001, math.floor(abort_ramp_velocity(lim) * 1000) / 1000)
        # the command goes before any setpoint still waiting for room (the controller would flush them anyway)
        self._outbox = collections.deque(m for m in self._outbox if m.arbitration_id not in self._setpoint_ids)
        self._send(self.proto.encode('HostCommand', {'CMD_Code': code, 'CMD_Counter': 0,
                                                     'CMD_Argument': target, 'CMD_RampVelocity': ramp_v}))
        # until the controller reports its ramp, status says ramping_down (not idle/fault while still moving)
        self._ramp_pending = self.controller_state in ('running', 'holding')
        self._host_stop = True
        if not self._aborting:
            self._event('warn',
                        f'{text}; ramp to {"a stop" if code == CMD_HOLD else f"{target * 1e3:.4f} mm"} from '
                        f'{self._last_applied * 1e3:.4f} mm')
        # an idle controller has nothing to ramp (it ignores the command): waiting for its ramp to end would
        # block every later stream
        self._aborting = self._aborting or self.controller_state in ('running', 'holding', 'ramping_down')

    def _release_stream(self):
        if self._stream is not None:
            self._stream = None

    def reset(self) -> str:
        """Acknowledge and clear faults (driver and controller) so a new stream can open. '' on success, else
        why not: the rig still moves, or a stream has an owner. Reset never takes the rig from its owner: a
        reset that dropped a running stream left the controller playing its queue out and then standing loaded,
        held by nobody.
        """
        if self.controller_state == 'ramping_down':
            return 'the rig is still ramping to rest: reset when it is at rest'
        if self.controller_state == 'running':      # ('holding' is a controller at rest on its last command)
            return ('the rig is moving (running its queued setpoints): stop the program first (excitation/abort '
                    'or rig_driver/abort); reset clears the faults of a rig at rest')
        s = self._stream
        if s is not None and not s.ended and not self.faults:    # a fault has already taken the rig from it
            owner = s.grant.owner or 'a local program'
            return (f'stream {s.grant.stream_id} of {owner} is {"held" if s.held else "open"}: end that program '
                    'first (excitation/abort); reset clears the faults of a rig nobody drives')
        self._send_command(CMD_RESET)
        if self.faults or self.fault_messages:
            self._event('info', 'reset: cleared ' + ('; '.join(self.fault_messages[-3:]) or 'faults'))
        self.faults, self.fault_messages, self._aborting, self._ramp_pending = 0, [], False, False
        self._stream = None
        self._sensor.clear()
        self.send_limits()
        return ''

    def _send_command(self, code: int):
        """A HostCommand without argument (RESET, IDENTIFY)."""
        self._send(self.proto.encode('HostCommand', {'CMD_Code': code, 'CMD_Counter': 0, 'CMD_Argument': 0,
                                                     'CMD_RampVelocity': 0}))

    def _send_host_heartbeat(self):
        self._host_hb_counter = (self._host_hb_counter + 1) % 256
        self._send(self.proto.encode('HostHeartbeat', {'HH_Counter': self._host_hb_counter}))
        self._last_host_hb_wall = self._clock()

    # ---- host -> controller
    def _send(self, msg):
        """Send a frame in order: when the bus's transmit queue is full (python-can CanOperationError, e.g.
        SocketCAN ENOBUFS on an overloaded bus) it waits in the outbox with every later frame, and poll() sends
        them as room frees up. Frames that cannot leave for watchdog_timeout fault the bus.
        """
        if not self._outbox:
            try:
                self.bus.send(msg)
                return
            except can.CanOperationError:
                self.counters['tx_queue_full'] += 1
                self._outbox_since = self._clock()
        self._outbox.append(msg)

    def _drain_outbox(self):
        box = self._outbox
        while box:
            try:
                self.bus.send(box[0])
            except can.CanOperationError:
                waited = self._clock() - self._outbox_since
                if waited > self._wd_wall and not self.faults & FAULT_BUS:
                    self._fault(FAULT_BUS, f'{len(box)} frames could not be sent for {waited:.3f} s (transmit '
                                           'queue full: the bus is overloaded or disconnected)')
                return
            box.popleft()
            self._outbox_since = self._clock()
        self._outbox_since = None

    # ---- controller -> host
    def poll(self):
        """Drain received frames (non-blocking), run the watchdog and checks; return the next SampleBlock of
        contiguous samples, or None if there is none.
        """
        now = self._clock()
        if now - self._last_poll_wall > 0.5 * self._wd_wall:
            # this host was not scheduled (a loaded machine): silence is judged only over time it was awake,
            # so a starved host never blames the controller for its own absence
            late = now - self._last_poll_wall
            self._last_fb_wall += late
            self._last_hb_wall += late
            if self._stream is not None:
                self._stream.last_rx_wall += late
        self._last_poll_wall = now
        if self._outbox:
            self._drain_outbox()
        if self.pump is not None:
            self.pump()
        recv = self.bus.recv
        msg = recv(0)
        while msg is not None:
            self._receive(msg)
            msg = recv(0)
        self._flush_pending()
        self._watchdog()
        self._check_stream()
        return self._ready.popleft() if self._ready else None

    def _receive(self, msg):
        if msg.arbitration_id in self._feedback_ids and not msg.is_extended_id:
            try:
                samples = self.frames.decode_feedback(msg)
            except MalformedFrame:
                self._malformed()
                return
            if samples is not None:
                self._on_samples(*samples, msg.timestamp)
            return
        try:
            decoded = self.proto.decode(msg)
        except MalformedFrame:
            self._malformed()
            return
        if decoded is None:
            self.counters['frames_unknown'] += 1
            return
        handler = self._handlers.get(decoded[0])
        if handler is None:   # a host frame echoed back or from another host: not ours to consume
            self.counters['frames_unknown'] += 1
            return
        handler(decoded[1], msg)

    def _on_samples(self, seq, xs, fs, us, timestamp):
        """Contiguous measured samples from sequence number seq (modulo the profile's): displacement xs [m],
        force fs [N], applied command us [m] (lists); timestamp: the frame's arrival time.
        """
        ref = self._jump_to if self._jump_to is not None and self._expected is None else (
            self._expected if self._expected is not None else max(self.controller_sequence, 0))
        seq = unwrap(seq, ref, self.frames.feedback_modulus)
        n = len(xs)
        if self._jump_to is not None and seq + n - 1 >= self._jump_to - 1:
            if seq <= self._jump_to < seq + n and (self._expected is None or self._jump_to > self._expected):
                self._expected = self._jump_to   # an idle rig started the new stream here: a jump, not a loss
                if self._hb_sample is not None:   # nor heartbeat silence: no sample passed in between
                    self._hb_sample = self._jump_to
            self._jump_to = None
        if self._expected is None:
            self._expected = seq
        if seq < self._expected:
            skip = min(n, self._expected - seq)
            self.counters['frames_late'] += skip    # delayed or duplicated: their slots are already past
            self._bad_event(skip)
            if skip == n:
                return
            seq, xs, fs, us, n = seq + skip, xs[skip:], fs[skip:], us[skip:], n - skip
        if seq > self._expected:
            lost = seq - self._expected
            self._count_lost(lost)
            self._bad_event(lost)
            if lost / self.fs > self.cfg.lost_burst_max:
                self._fault(FAULT_BUS, f'{lost} consecutive samples lost ({lost / self.fs * 1e3:.1f} ms > '
                                       f'{self.cfg.lost_burst_max * 1e3:g} ms)')
        if self._pend_first is None:
            # the first sample's time: its frame arrived at `timestamp`, after the later samples it packs
            self._pend_first, self._pend_t0 = seq, timestamp - (n - 1) / self.fs
        px, pf, pu = self._pend
        px.extend(xs)
        pf.extend(fs)
        pu.extend(us)
        self._prev_applied, self._last_applied = (us[-2] if n > 1 else self._last_applied), us[-1]
        self._expected = seq + n
        self.counters['samples_received'] += n
        self._last_fb_wall = self._clock()
        self._check_measurements(xs, fs)
        if self.controller_state in ('running', 'ramping_down') and not self.faults & FAULT_SENSOR:
            add = self._sensor.add
            for u, x, f in zip(us, xs, fs, strict=True):
                why = add(u, x, f)
                if why:
                    self._fault(FAULT_SENSOR, why)
                    break

    def _malformed(self):
        """A frame with a wrong length or CRC: counted, and a bad-frame event."""
        self.counters['frames_malformed'] += 1
        self._bad_event(1)

    def _count_lost(self, lost: int):
        """`lost` samples before the next one received: counted, and carried by the next SampleBlock."""
        self.counters['frames_lost'] += lost
        self._flush_pending()
        self._pend_lost += lost

    def _on_status(self, sig, msg):
        code = int(sig['ST_State'])
        self._set_controller_state(STATES[code] if code < len(STATES) else 'fault')
        self.controller_faults = int(sig['ST_Faults'])
        ref = self.controller_sequence if self.controller_sequence >= 0 else (self._expected or 0)
        self.controller_sequence = unwrap(int(sig['ST_LastSequence']), ref, STATUS_SEQ_MOD)
        if self.controller_state in ('idle', 'fault') and self._expected is not None \
                and self.controller_sequence + 1 > self._expected:
            # the controller stopped ticking after samples whose frames never arrived (feedback goes out before
            # this status: its identifier wins arbitration): they are lost, not merely late
            self._count_lost(self.controller_sequence + 1 - self._expected)
            self._expected = self.controller_sequence + 1

    def _on_heartbeat(self, sig, msg):
        code = int(sig['HB_State'])
        self._set_controller_state(STATES[code] if code < len(STATES) else 'fault')
        self.counters['heartbeats_received'] += 1
        self._last_hb_wall = self._clock()
        self._hb_sample = self._expected

    def _set_controller_state(self, state):
        old = self.controller_state
        if state == old:
            return
        self.controller_state = state
        self._ramp_pending = False
        if state == 'ramping_down':
            self._event('warn', f'controller ramping to rest from {self._last_applied * 1e3:.4f} mm',
                        headline=not self._host_stop)
        elif old == 'ramping_down' and state in ('idle', 'fault'):
            self._aborting = False
            self._event('info', f'rig at rest at {self._last_applied * 1e3:.4f} mm (controller {state})')
        elif state == 'fault':
            self._event('error', f'controller reports a fault: {", ".join(fault_names(self.controller_faults))}')

    def _identity_mismatch(self) -> str:
        """'' when the controller may be streamed to (RigConfig.require_identity, controller_device), else why not."""
        if not self.cfg.require_identity:
            return ''
        ident = self.controller_identity
        if ident is None:
            return ('the controller has not identified itself (no ControllerIdentity frame: it may not speak rig '
                    f'protocol version {PROTOCOL_VERSION})')
        if ident['protocol'] != PROTOCOL_VERSION:
            return (f"the controller speaks rig protocol version {ident['protocol']}, this host version "
                    f'{PROTOCOL_VERSION} (rubber_rig.dbc): refusing to stream')
        if self.cfg.controller_device and ident['device'] != self.cfg.controller_device:
            return (f"the controller is device 0x{ident['device']:04x}, the configuration expects "
                    f'0x{self.cfg.controller_device:04x} (controller_device): refusing to stream')
        return ''

    def _on_identity(self, sig, msg):
        ident = {'protocol': int(sig['CI_Protocol']), 'device': int(sig['CI_Device']),
                 'firmware': int(sig['CI_Firmware']), 'host_timeout': float(sig['CI_HostTimeout']),
                 'velocity_max': float(sig['CI_VelocityMax'])}
        if ident != self.controller_identity:
            self.controller_identity = ident
            why = self._identity_mismatch()
            self._event('error' if why else 'info', why or (
                f"controller 0x{ident['device']:04x} firmware {ident['firmware']}, rig protocol version "
                f"{ident['protocol']}, host timeout {ident['host_timeout']:g} s, rated velocity "
                f"{ident['velocity_max']:g} m/s"), headline=bool(why))

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

    def _check_measurements(self, xs, fs):
        """Force and displacement limits on measured samples (lists)."""
        lim = self.limits
        x_lo, x_hi, f_peak = min(xs), max(xs), max(max(fs), -min(fs))
        if not (math.isfinite(x_lo) and math.isfinite(x_hi) and math.isfinite(f_peak)):
            if not self.faults & FAULT_SENSOR:
                self._fault(FAULT_SENSOR, f'non-finite measurement (displacement {xs}, force {fs})')
            return
        if f_peak > lim.force_max and not self.faults & FAULT_FORCE_LIMIT:
            f = max(fs, key=abs)
            self._fault(FAULT_FORCE_LIMIT, f'measured force {f:.6g} N above force_max {lim.force_max:g} N')
        margin = 0.02 * (lim.displacement_max - lim.displacement_min)
        if not (lim.displacement_min - margin <= x_lo and x_hi <= lim.displacement_max + margin) \
                and not self.faults & FAULT_DISPLACEMENT_LIMIT:
            x = x_lo if x_lo < lim.displacement_min - margin else x_hi
            self._fault(FAULT_DISPLACEMENT_LIMIT, f'measured displacement {x:.6g} m outside the limits')

    def _watchdog(self):
        now = self._clock()
        cfg = self.cfg
        if cfg.paced and now - self._last_host_hb_wall >= cfg.heartbeat_period:
            self._send_host_heartbeat()
        if self.faults & FAULT_WATCHDOG:
            return
        s = self._stream
        # a held stream has nothing queued: the controller flushed it and stands at rest until the owner resumes
        streaming = s is not None and not s.held and s.queued_end > s.grant.first_sequence and (
            self._expected is None or self._expected < s.queued_end)
        if streaming and not self._aborting and now - self._last_fb_wall > self._wd_wall:
            self._fault(FAULT_WATCHDOG, f'no feedback for {now - self._last_fb_wall:.3f} s with setpoints queued')
            return
        if self._expected is not None and not self._aborting:
            # an idle rig starting a new stream jumps to its first sample: the samples before it are not owed
            expected = max(self._expected, self._jump_to or 0)
            lag = (self.controller_sequence + 1 - expected) / self.fs
            if lag > cfg.watchdog_timeout:
                self._fault(FAULT_WATCHDOG, f'feedback {lag:.3f} s behind the controller (stalled or delayed)')
                return
        if not cfg.paced and self._hb_sample is not None and self._expected is not None:
            # as fast as possible there is no wall time: silence is counted in samples. Paced, the wall clock
            # judges it (below): on a busy bus the lowest-priority heartbeat may trail many samples legitimately
            silent = (self._expected - self._hb_sample) / self.fs
            if silent > cfg.watchdog_timeout:
                self._fault(FAULT_WATCHDOG, f'controller heartbeat silent for {silent:.3f} s of samples')
                return
        if cfg.paced and self.counters['heartbeats_received'] and now - self._last_hb_wall > self._wd_wall:
            self._fault(FAULT_WATCHDOG, f'controller heartbeat silent for {now - self._last_hb_wall:.3f} s')

    def _check_stream(self):
        """A stream that stops without its last batch is lost: ramp to rest (or hold, stream_loss_action)."""
        s = self._stream
        if s is None or s.held or self.faults or self._aborting:
            if s is not None and s.ended and self.controller_sequence + 1 >= s.queued_end:
                self._release_stream()   # the owner's program has run to its end: the rig is free again
            return
        if s.ended:
            if self.controller_sequence + 1 >= s.queued_end:
                self._event('info', f'stream {s.grant.stream_id} of {s.grant.owner or "a local client"} '
                                    f'completed at sample {s.queued_end}')
                self._release_stream()
            return
        why = ''
        silent = self._clock() - s.last_rx_wall
        if s.batches == 0:
            if silent > max(self.FIRST_BATCH_TIMEOUT, self.cfg.stream_timeout):
                self._event('warn', f'stream {s.grant.stream_id} of {s.grant.owner or "a local client"} withdrawn: '
                                    f'no batch within {silent:.3f} s of the grant (nothing was moved)')
                self._release_stream()
            return
        if self.cfg.paced and silent > self.cfg.stream_timeout:
            why = f'no setpoints from {s.grant.owner or "the stream owner"} for {silent:.3f} s'
        elif s.queued_end > s.grant.first_sequence and self.controller_sequence + 1 >= s.queued_end \
                and self.controller_state == 'holding':
            why = f'the rig ran out of setpoints at sample {s.queued_end} before the end of the stream'
        if why:
            self._stream_lost(why)

    def owner_lost(self, why: str) -> bool:
        """The stream's owner is gone or alive but silent (the node's liveness watch says so): the same as a
        lost stream (fault, then ramp or hold per stream_loss_action), also while the owner holds the rig - a
        held stream sends no setpoints, so nothing else would notice. False if no stream of an owner is open.
        """
        s = self._stream
        if s is None or s.ended or self.faults or self._aborting:
            return False
        self._stream_lost(why)
        return True

    def _stream_lost(self, why: str) -> None:
        self.faults |= FAULT_STREAM
        self.fault_messages.append(f'setpoint stream lost: {why}')
        self._event('error', f'fault stream: setpoint stream lost: {why}')
        if self.cfg.stream_loss_action == 'hold':
            self.hold_here('setpoint stream lost')
        else:
            self.abort('setpoint stream lost')

    def _fault(self, bit: int, message: str):
        """Record a fault and command the safe ramp."""
        self.faults |= bit
        self.fault_messages.append(message)
        self._event('error', f'fault {fault_names(bit)[0]}: {message}')
        self.abort(message)

    # ---- status
    @property
    def status(self) -> DriverStatus:
        """Snapshot of state, faults and counters."""
        if self.controller_state == 'ramping_down' or (self._ramp_pending and not self.faults & FAULT_WATCHDOG):
            state = 'ramping_down'
        elif self.faults or self.controller_faults:
            state = 'fault'
        else:
            state = self.controller_state
        c = self.counters
        s = self._stream
        extra = {'heartbeats_received': c['heartbeats_received'], 'setpoints_refused': c['setpoints_refused'],
                 'next_sequence': self.next_sequence, 'position': self._last_applied,
                 'stream_owner': s.grant.owner if s else '', 'stream_id': s.grant.stream_id if s else 0,
                 'stream_held': bool(s and s.held), 'last_event': self.last_event, 'bus_load': self.bus_load,
                 'bus_load_measured': self._measured_bus_load(),
                 'tx_queue_full': c['tx_queue_full'], 'tx_backlog': len(self._outbox)}
        return DriverStatus(state, self.faults | self.controller_faults, list(self.fault_messages), self.fs,
                            c['samples_received'], c['frames_lost'], c['frames_late'], c['frames_malformed'],
                            c['frames_unknown'], self.temperature, self.controller_state, self.controller_faults,
                            self.controller_sequence, c['setpoints_sent'], self.limits, extra)

    def _measured_bus_load(self):
        """The bus's busy fraction over the last second, when the bus can tell (the simulated bus), read at most
        every 0.1 s (status is read often).
        """
        if self.measured_load is None:
            return None
        now = self._clock()
        if now - self._load_at > 0.1:
            self._load_at, self._load = now, self.measured_load()
        return self._load

    @property
    def next_sequence(self) -> int:
        """The first sample index no setpoint or sample has used yet (where a new stream may start)."""
        s = self._stream
        return max(self._expected or 0, self.controller_sequence + 1, s.queued_end if s else 0,
                   self._jump_to or 0, self._sent_end)

    def close(self, ramp: bool = True):
        """Command the ramp to rest (unless ramp=False), then shut the bus down."""
        if ramp and self.controller_state in ('running', 'holding'):
            self.abort('driver shutting down')
        self.bus.shutdown()
