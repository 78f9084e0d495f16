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

"""Host driver over any python-can Bus: the one safety authority between the hosts' setpoint streams and the
rig controller. RigDriver composes FrameIO (frames, outbox, sequences, sample blocks) and Supervisor
(controller state, measurement and sensor checks, watchdog, faults) and keeps the stream itself: who owns it,
that its batches continue the queue and fit the limits, and what ends it. poll() is non-blocking and never
raises on bad frames.
"""
import itertools
import time

import numpy as np

from ...safety import setpoint_violation
from .frame_io import FrameIO
from .frames import SampleFrames
from .protocol import (
    CMD_ABORT,
    CMD_HOLD,
    CMD_IDENTIFY,
    CMD_RESET,
    FAULT_BUS,
    FAULT_DISPLACEMENT_LIMIT,
    FAULT_STREAM,
    FAULT_VELOCITY_LIMIT,
    Protocol,
)
from .stream import DriverStatus, GrantedStream, SampleBlock, StreamGrant, StreamRefused
from .supervisor import Supervisor

__all__ = ['DriverStatus', 'RigDriver', 'SampleBlock', 'StreamGrant', 'StreamRefused']


def _read(part: str, name: str, doc: str) -> property:
    """A read-only attribute of the driver that one of its parts keeps."""
    return property(lambda self: getattr(getattr(self, part), name), doc=doc)


class RigDriver:
    """Driver for the rig controller on python-can `bus` with RigConfig `config`; the one safety authority.

    Only the owner of the open stream commands the rig (open_stream -> queue_setpoints with its id ->
    end_stream); every batch is checked against the limits as the continuation of what is already queued,
    including that the rig can still stop inside the displacement range at limits.deceleration_max. Faults,
    aborts, holds and a stream that stops (no batch for stream_timeout, or the controller running dry before
    the owner's last batch) end in the controller's own ramp, inside the limits. `events` collects one
    (level, text) line per transition for the caller's log.

    Call poll() often (at least every tick_period, and when frames arrived: receive_in_thread): it drains the bus
    without blocking, updates the watchdog and returns the next block of contiguous samples or None.
    """

    MAX_LEAD_SAMPLES = 16384     # a stream may start at most this far ahead (16-bit sequences stay unambiguous)
    # a granted stream whose owner has sent nothing yet has moved nothing: it is withdrawn (no fault, nothing to
    # ramp) after this long, so a client that died or stalled between its grant and its first batch cannot fault
    # the rig, and one that is merely slow to hear the grant (the first service reply on a fresh DDS link) is not
    # judged by stream_timeout, which is for a stream that stops while it moves the rig
    FIRST_BATCH_TIMEOUT = 2.0    # [s]
    counters = _read('io', 'counters', 'Frame, sample and setpoint counts (status reports them).')
    faults = _read('supervisor', 'faults', 'FAULT_* bits the host has raised since the last reset.')
    fault_messages = _read('supervisor', 'fault_messages', 'Why, one line per fault since the last reset.')
    events = _read('supervisor', 'events', '(level, text) of every transition, for the caller\'s log.')
    last_event = _read('supervisor', 'last_event', 'The headline event (status.extra).')
    controller_state = _read('supervisor', 'controller_state', 'The state the controller last reported.')
    controller_faults = _read('supervisor', 'controller_faults', 'The fault bits the controller last reported.')
    controller_sequence = _read('supervisor', 'controller_sequence', 'The last sample the controller took.')
    controller_identity = _read('supervisor', 'controller_identity', 'ControllerIdentity as a dict, or None.')
    temperature = _read('supervisor', 'temperature', 'The specimen temperature last reported [degC].')
    limits = _read('supervisor', 'limits', 'The Limits in force (set_limits changes them).')
    tick_period = _read('supervisor', 'tick_period', 'Call poll() at least this often [s], frames or not.')
    receive_in_thread = _read('io', 'receive_in_thread', 'Read the bus in a thread of its own (FrameIO).')

    @property
    def measured_load(self):
        """Callable -> the bus's busy fraction of the last second, when the bus can tell (else None)."""
        return self.io.measured_load

    @measured_load.setter
    def measured_load(self, load):
        self.io.measured_load = load

    def __init__(self, bus, config, protocol: Protocol = None, clock=time.monotonic):
        self.bus, self.cfg = bus, config
        self.proto = protocol or Protocol()
        self.fs = float(config.sample_rate)
        # the protocol's share of the configured bus at this rate (worst-case stuffing; RigConfig refused more
        # than its max_bus_load): what status and diagnostics report as bus load
        self.bus_load = config.bus_load().load
        self._clock = clock
        # the frames that carry samples (config.frame_profile) take a fast path; the rest go through cantools
        self.frames = SampleFrames(config.frame_profile, self.proto.db, self.fs)
        self.io = FrameIO(bus, self.proto, self.frames, self.fs, max(1, round(config.heartbeat_period * self.fs)),
                          clock)
        self.supervisor = self.io.listener = Supervisor(config, self.io, self.abort, clock)
        self._event, self._fault = self.supervisor.event, self.supervisor.fault
        self.take_events = self.supervisor.take_events   # () -> the (level, text) events for the caller's log
        self._stream = None              # GrantedStream of the owner, or None
        self._stream_ids = itertools.count(int(clock() * 1000) % 1_000_000 * 1000 + 1)
        self.refusal = ''                # why the latest batch was refused
        self.pump = None                 # callable run at the start of poll() (in-process fast simulator)
        self.io.send_host_heartbeat()
        self.send_limits()
        self.io.send_command(CMD_IDENTIFY)   # HOST-ID-1: ask who is there before anything streams

    # ---- limits
    def set_limits(self, limits):
        """Apply new limits at once: the controller's ramps follow them, and if the rig or what is queued lies
        outside them the rig ramps into them now (a fault: the program no longer fits).
        """
        self.supervisor.limits = limits
        self.send_limits()
        self._event('info', f'limits: displacement {limits.displacement_min * 1e3:g}..{limits.displacement_max * 1e3:g}'
                            f' mm, velocity {limits.velocity_max:g} m/s, force {limits.force_max:g} N, deceleration '
                            f'{limits.deceleration_max:g} m/s^2')
        s = self._stream
        inside = limits.displacement_min <= self.io.last_applied <= limits.displacement_max
        if s is not None and not s.held and (s.queued_end > self.next_sequence or not inside):
            self._fault(FAULT_DISPLACEMENT_LIMIT, 'limits changed while streaming: the queued setpoints were '
                                                  'checked against the old limits')
        elif not inside:
            self.abort('limits changed: the rig is outside the new displacement limits')

    def send_limits(self):
        """Tell the controller the limits its own ramps keep to."""
        self.io.send_limits(self.limits)

    # ---- streams
    @property
    def stream(self):
        """The open StreamGrant, or None."""
        return self._stream.grant if self._stream is not None else None

    def why_not_ready(self) -> str:
        """'' when a stream can open now, else why not."""
        return self.supervisor.why_not_ready()

    def open_stream(self, owner: str, lead_samples: int = 0) -> StreamGrant:
        """Grant the setpoint stream to `owner` (StreamRefused says why not). The first setpoint is due at
        first_sequence, lead_samples after every sample the rig has taken or been sent; the rig holds until
        then. The owner of a held or ended stream may re-open it (resume).
        """
        why = self.why_not_ready()
        if why:
            raise StreamRefused(why)
        s = self._stream
        if s is not None and s.why_not_reopen(owner):
            raise StreamRefused(s.why_not_reopen(owner))
        # a ticking (holding) controller needs the first setpoint `lead` ahead; an idle one starts on arrival
        ticking = self.controller_state in ('running', 'holding')
        lead = max(0, min(int(lead_samples), self.MAX_LEAD_SAMPLES)) if ticking else 0
        first = self.next_sequence + lead
        io = self.io
        if self.controller_state in ('idle', 'fault') and (s is None or s.queued_end <= self.next_sequence):
            io.jump_to = first     # an idle controller starts at the first setpoint it gets
        v = (io.last_applied - io.prev_applied) * self.fs if self.controller_state == 'running' else 0.0
        grant = StreamGrant(next(self._stream_ids), owner, first, io.last_applied, v)
        io.announce_stream(first)
        self._stream = GrantedStream(grant, first, io.last_applied, self._clock())
        self.supervisor.host_stop = False
        self._event('info', f'stream {grant.stream_id} opened for {owner or "a local client"}: first setpoint '
                            f'at sample {first}, from {grant.position * 1e3:.4f} mm')
        return grant

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
        why = self._refusal(s, first_sequence, stream_id)
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
        io = self.io
        pipeline_empty = io.expected is None or io.expected >= s.queued_end or io.jump_to is not None
        if s.queued_end == s.grant.first_sequence and pipeline_empty:
            # pipeline was empty (or idle rig): the feedback clock starts now
            self.supervisor.last_feedback = self._clock()
        io.send_setpoints(first_sequence, x.tolist())
        s.queued(first_sequence, x, self.controller_sequence + 1, self.cfg.sample_rate)
        return True

    def _local_stream(self, first_sequence):
        grant = self.open_stream('', 0)
        grant.first_sequence = first_sequence
        self.io.announce_stream(first_sequence)
        self._stream.queued_end = first_sequence
        if self.io.jump_to is not None:
            self.io.jump_to = first_sequence
        return self._stream

    def _refusal(self, s, first_sequence, stream_id) -> str:
        if self.faults or self.supervisor.aborting:
            return 'the rig is faulted or ramping to rest'
        if s is None:
            return 'no stream is open (rig_driver/open_stream first)'
        return s.refusal(first_sequence, stream_id)

    def stop_stream(self, stream_id: int, target: float, reason: str, hold: bool = False) -> str:
        """The owner stops now: flush and ramp to target [m] (clamped into the limits). hold: the owner keeps
        the rig and resumes with open_stream. '' on success, else why not.
        """
        s = self._stream
        if s is None or s.grant.stream_id != stream_id:
            return f'stream {stream_id} is not open'
        if hold:
            s.held = True
            self.supervisor.command_ramp(CMD_ABORT, target, f'hold: {reason}')
        else:
            self.abort(reason, target)
        return ''

    def abort(self, reason: str = 'abort requested', target: float = None):
        """Command the safe ramp: the controller flushes queued setpoints and ramps smoothly from where it is
        to target [m] (default rest_position, clamped into the limits). The stream is released.
        """
        self.supervisor.command_ramp(CMD_ABORT, target, f'abort: {reason}')
        self._release_stream()

    def hold_here(self, reason: str):
        """Stop the motion where it can stop (braking within the limits) and hold there; the stream is
        released.
        """
        self.supervisor.command_ramp(CMD_HOLD, None, f'hold: {reason}')
        self._release_stream()

    def _release_stream(self):
        self._stream = None

    def reset(self) -> str:
        """Acknowledge and clear faults (driver and controller) so a new stream can open. '' on success, else
        why not: the rig still moves, or a stream has an owner. Reset never takes the rig from its owner: a
        reset that dropped a running stream left the controller playing its queue out and then standing loaded,
        held by nobody.
        """
        why = self.supervisor.why_not_reset()
        if why:
            return why
        s = self._stream
        if s is not None and not s.ended and not self.faults:    # a fault has already taken the rig from it
            owner = s.grant.owner or 'a local program'
            return (f'stream {s.grant.stream_id} of {owner} is {"held" if s.held else "open"}: end that program '
                    'first (excitation/abort); reset clears the faults of a rig nobody drives')
        self.io.send_command(CMD_RESET)
        self.supervisor.clear()
        self._stream = None
        self.send_limits()
        return ''

    # ---- the cycle
    def poll(self):
        """Drain received frames (non-blocking), run the watchdog and checks; the next SampleBlock or None."""
        late = self.supervisor.starved()
        if late and self._stream is not None:
            self._stream.last_rx_wall += late
        if self.io.outbox:
            self._drain_outbox()
        if self.pump is not None:
            self.pump()
        read_at = self._clock()     # silence is known up to this read, however late the checks below run
        self.io.receive_all()
        self.supervisor.watchdog(self._stream is not None and self._stream.playing(self.io.expected), read_at)
        self._check_stream()
        return self.io.next_block()

    def _drain_outbox(self):
        """Frames that cannot leave for the watchdog's time fault the bus."""
        waited = self.io.drain_outbox()
        if waited is not None and waited > self.supervisor.wd_wall and not self.faults & FAULT_BUS:
            self._fault(FAULT_BUS, f'{len(self.io.outbox)} frames could not be sent for {waited:.3f} s '
                                   '(transmit queue full: the bus is overloaded or disconnected)')

    # ---- checks
    def _check_stream(self):
        """A stream that stops without its last batch is lost: ramp to rest (or hold, stream_loss_action)."""
        s = self._stream
        if s is None:
            return
        played = self.controller_sequence + 1
        if s.ended or s.held or self.faults or self.supervisor.aborting:
            if s.ended and played >= s.queued_end:
                if not (s.held or self.faults or self.supervisor.aborting):
                    self._event('info', f'stream {s.grant.stream_id} of {s.name} completed at sample {s.queued_end}')
                self._release_stream()   # the owner's program has run to its end: the rig is free again
            return
        silent = self._clock() - s.last_rx_wall
        if s.batches == 0:
            if silent > max(self.FIRST_BATCH_TIMEOUT, self.cfg.stream_timeout):
                self._event('warn', f'stream {s.grant.stream_id} of {s.name} withdrawn: no batch within '
                                    f'{silent:.3f} s of the grant (nothing was moved)')
                self._release_stream()
            return
        why = s.lost(silent, played, self.controller_state == 'holding', self.cfg)
        if why:
            self._stream_lost(why)

    def owner_lost(self, why: str) -> bool:
        """The stream's owner is gone or alive but silent (the node's liveness watch says so): the same as a
        lost stream (fault, then ramp or hold per stream_loss_action), also while the owner holds the rig - a
        held stream sends no setpoints, so nothing else would notice. False if no stream of an owner is open.
        """
        s = self._stream
        if s is None or s.ended or self.faults or self.supervisor.aborting:
            return False
        self._stream_lost(why)
        return True

    def _stream_lost(self, why: str) -> None:
        self.supervisor.record_fault(FAULT_STREAM, f'setpoint stream lost: {why}')
        (self.hold_here if self.cfg.stream_loss_action == 'hold' else self.abort)('setpoint stream lost')

    # ---- status
    @property
    def status(self) -> DriverStatus:
        """Snapshot of state, faults and counters."""
        c, s = self.counters, self._stream
        return self.supervisor.snapshot({
            'heartbeats_received': c['heartbeats_received'], 'setpoints_refused': c['setpoints_refused'],
            'next_sequence': self.next_sequence, 'position': self.io.last_applied,
            'stream_owner': s.grant.owner if s else '', 'stream_id': s.grant.stream_id if s else 0,
            'stream_held': bool(s and s.held), 'last_event': self.last_event, 'bus_load': self.bus_load,
            'bus_load_measured': self.io.measured_bus_load(),
            'tx_queue_full': c['tx_queue_full'], 'tx_backlog': len(self.io.outbox)})

    @property
    def next_sequence(self) -> int:
        """The first sample index no setpoint or sample has used yet (where a new stream may start)."""
        s, io = self._stream, self.io
        return max(io.expected or 0, self.controller_sequence + 1, s.queued_end if s else 0, io.jump_to or 0,
                   io.sent_end)

    def close(self, ramp: bool = True):
        """Command the ramp to rest (unless ramp=False), stop a receiving thread, then shut the bus down."""
        if ramp and self.controller_state in ('running', 'holding'):
            self.abort('driver shutting down')
        self.io.stop_receiving()
        self.bus.shutdown()
