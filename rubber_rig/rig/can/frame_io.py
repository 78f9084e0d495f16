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

"""The host driver's frame I/O: encodes and sends host frames (in order, through an outbox when the bus's
transmit queue is full), receives and decodes controller frames, unwraps feedback sequence numbers and counts
the samples lost, late or malformed on the way, and assembles the contiguous samples into SampleBlocks.

It judges nothing: what the frames mean for safety (bad-frame rates, lost bursts, measurements, the
controller's status frames) it reports to its `listener`, the Supervisor.
"""
import collections
import math

import can
import numpy as np

from .protocol import MalformedFrame, meet, unwrap
from .receiver import BusReceiver
from .stream import SampleBlock


class FrameIO:
    """Frames to and from the controller on python-can `bus` at sample rate fs [Hz].

    listener (set before the first frame arrives) provides: controller_sequence, controller_faults,
    temperature, event(level, text), on_frame(name, signals) -> bool (False: not a frame the host consumes),
    bad_frames(n), samples_lost(n), jumped(sequence) and measured(xs, fs, us).
    """

    def __init__(self, bus, proto, frames, fs: float, heartbeat_every: int, clock):
        self.bus, self.proto, self.frames, self.fs = bus, proto, frames, fs
        self._clock = clock
        self.listener = None
        self._feedback_ids = {frames.codecs[n].frame_id for n in frames.feedback_names}
        self._setpoint_ids = {frames.codecs[n].frame_id for n in frames.setpoint_names}
        self.counters = dict(samples_received=0, frames_lost=0, frames_late=0, frames_malformed=0,
                             frames_unknown=0, setpoints_sent=0, setpoints_refused=0, heartbeats_received=0,
                             tx_queue_full=0)
        # frames the bus did not take yet (its transmit queue was full), sent in order by drain_outbox()
        self.outbox = collections.deque()
        self._outbox_since = None        # when the oldest of them was first refused
        self.sent_end = 0                # after the last setpoint ever sent: a new stream starts at or after it
        self.expected = None             # next feedback sequence expected
        self.jump_to = None              # a stream on an idle rig starts at this sequence: the jump is no loss
        self.last_applied = 0.0          # last command the controller reported applying [m]
        self.prev_applied = 0.0
        self._pend = ([], [], [])        # x, f, u of the contiguous samples not yet returned
        self._pend_first, self._pend_t0, self._pend_lost = None, None, 0   # first sequence, its frame time
        self._ready = collections.deque()
        self._host_hb_counter = 0
        self.last_host_heartbeat = clock()   # clock time of the latest HostHeartbeat
        self._hb_every = heartbeat_every     # samples between the heartbeats that ride with a stream
        self._next_hb_seq = None
        self.measured_load = None        # callable -> busy fraction of the last second, when the bus can tell
        self.receiver = None             # receiver.BusReceiver reading the bus in a thread, or None: polled
        self._load_at, self._load = -math.inf, None

    # ---- host -> controller
    def send(self, msg):
        """Send a frame in order: when the bus's transmit queue is full (python-can CanOperationError, e.g.
        SocketCAN ENOBUFS on an overloaded bus) it waits in the outbox with every later frame, and
        drain_outbox() sends them as room frees up.
        """
        if not self.outbox:
            try:
                self.bus.send(msg)
                return
            except can.CanOperationError:
                self.counters['tx_queue_full'] += 1
                self._outbox_since = self._clock()
        self.outbox.append(msg)

    def drain_outbox(self):
        """Send what waits in the outbox; None when it is empty, else how long [s] its oldest frame waited."""
        box = self.outbox
        while box:
            try:
                self.bus.send(box[0])
            except can.CanOperationError:
                return self._clock() - self._outbox_since
            box.popleft()
            self._outbox_since = self._clock()
        self._outbox_since = None
        return None

    def drop_setpoints(self):
        """Forget the setpoints still waiting for room (a ramp command goes first; the controller flushes them)."""
        self.outbox = collections.deque(m for m in self.outbox if m.arbitration_id not in self._setpoint_ids)

    def send_limits(self, lim):
        """HostLimits: the displacement range [m] and the deceleration [m/s^2] of the controller's ramps."""
        self.send(self.proto.encode('HostLimits', {
            'HL_DisplacementMin': lim.displacement_min, 'HL_DisplacementMax': lim.displacement_max,
            # multiples of 2 m/s^2, never above the limit, and never 0 (which would mean the controller's default)
            'HL_Deceleration': max(2.0, min(510.0, math.floor(lim.deceleration_max / 2) * 2.0))}))

    def send_command(self, code: int, argument: float = 0, ramp_velocity: float = 0):
        """A HostCommand: argument [m] (a ramp's target), ramp_velocity [m/s]."""
        self.send(self.proto.encode('HostCommand', {'CMD_Code': code, 'CMD_Counter': 0, 'CMD_Argument': argument,
                                                    'CMD_RampVelocity': ramp_velocity}))

    def send_host_heartbeat(self):
        self._host_hb_counter = (self._host_hb_counter + 1) % 256
        self.send(self.proto.encode('HostHeartbeat', {'HH_Counter': self._host_hb_counter}))
        self.last_host_heartbeat = self._clock()

    def announce_stream(self, first: int):
        """HostStreamStart: the controller takes setpoints from `first` on (and, after a ramp, no older ones)."""
        self.send(self.proto.encode('HostStreamStart', {'HS_FirstSequence': first % (1 << 32)}))

    def send_setpoints(self, first_sequence: int, values: list):
        """Setpoints [m] for samples first_sequence.. in frames, with the host heartbeats due among them."""
        if self._next_hb_seq is None or self._next_hb_seq < first_sequence - self._hb_every:
            self._next_hb_seq = first_sequence
        send, per = self.send, self.frames.setpoints_per_frame
        for i, msg in enumerate(self.frames.encode_setpoints(first_sequence, values)):
            last = first_sequence + min((i + 1) * per, len(values)) - 1
            if last >= self._next_hb_seq:
                # heartbeats ride with the stream so the controller sees them at the right sample in fast mode
                self.send_host_heartbeat()
                self._next_hb_seq = last + self._hb_every
            send(msg)
        self.sent_end = max(self.sent_end, first_sequence + len(values))
        self.counters['setpoints_sent'] += len(values)

    def measured_bus_load(self):
        """The bus's busy fraction over the last second, when the bus can tell (the simulated bus), read at most
        every 0.1 s (status is read often).
        """
        if self.measured_load is None:
            return None
        now = self._clock()
        if now - self._load_at > 0.1:
            self._load_at, self._load = now, self.measured_load()
        return self._load

    # ---- controller -> host
    def receive_all(self):
        """Drain the bus without blocking (or take what the receiving thread read, when one reads it:
        receiver.BusReceiver); the contiguous samples received go to the ready blocks.
        """
        if self.receiver is not None:
            for msg in self.receiver.take():
                self._receive(msg)
            if self.receiver.error is not None and not self.receiver.said:   # said once, from the owner's thread
                self.receiver.said = True
                self.listener.event('error', f'CAN receive stopped: {self.receiver.error!r} (nothing is read now: '
                                             'the watchdog judges the silence)')
        else:
            recv = self.bus.recv
            msg = recv(0)
            while msg is not None:
                self._receive(msg)
                msg = recv(0)
        self.flush_pending()

    def receive_in_thread(self, wake, samples_per_wake: int, on_error=lambda exc: None, on_start=None):
        """From now on a thread reads the bus (receiver.BusReceiver: ``on_error``, ``on_start``) and calls ``wake()``
        (thread-safe) whenever ``samples_per_wake`` samples have arrived since it last did; receive_all() then takes
        what it read. The BusReceiver, or None when the bus is already read in a thread.
        """
        if self.receiver is not None:
            return None
        measured = self.frames.codecs[self.frames.feedback_names[-1]].frame_id   # one frame per sample group
        self.receiver = BusReceiver(self.bus, {measured}, 1, wake, on_error, on_start)
        self.wake_after(samples_per_wake)
        return self.receiver.start()

    def wake_after(self, samples: int):
        """The receiving thread wakes its owner once per ``samples`` samples from now on (a new batch size)."""
        if self.receiver is not None:
            self.receiver.frames_per_wake = max(1, math.ceil(samples / self.frames.feedback_per_frame))

    def stop_receiving(self):
        """Stop the receiving thread, if one runs (before the bus is shut down), and take what it read; from now on
        receive_all() reads the bus itself (a ramp to rest at shutdown is watched that way).
        """
        receiver, self.receiver = self.receiver, None
        if receiver is not None:
            receiver.stop()
            for msg in receiver.take():
                self._receive(msg)

    def next_block(self):
        """The oldest SampleBlock not yet returned, or None."""
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
        # None: unknown; a host frame echoed back or from another host is not ours to consume either
        if decoded is None or not self.listener.on_frame(*decoded):
            self.counters['frames_unknown'] += 1

    def _on_samples(self, seq, xs, fs, us, timestamp):
        """Contiguous measured samples from sequence number seq (modulo the profile's): displacement xs [m],
        force fs [N], applied command us [m] (lists); timestamp: the frame's arrival time.
        """
        ref = self.jump_to if self.jump_to is not None and self.expected is None else (
            self.expected if self.expected is not None else max(self.listener.controller_sequence, 0))
        seq = unwrap(seq, ref, self.frames.feedback_modulus)
        n = len(xs)
        if self.jump_to is not None and seq + n - 1 >= self.jump_to - 1:
            if seq <= self.jump_to < seq + n and (self.expected is None or self.jump_to > self.expected):
                self.expected = self.jump_to   # an idle rig started the new stream here: a jump, not a loss
                self.listener.jumped(self.jump_to)
            self.jump_to = None
        late, lost = meet(self.expected, seq, n)
        if late:
            self.counters['frames_late'] += late    # delayed or duplicated: their slots are already past
            self.listener.bad_frames(late)
            if late == n:
                return
            seq, xs, fs, us, n = seq + late, xs[late:], fs[late:], us[late:], n - late
        if lost:
            self.count_lost(lost)
            self.listener.samples_lost(lost)
        if self._pend_first is None:
            # the first sample's time: its frame arrived at `timestamp`, after the later samples it packs
            self._pend_first, self._pend_t0 = seq, timestamp - (n - 1) / self.fs
        px, pf, pu = self._pend
        px.extend(xs)
        pf.extend(fs)
        pu.extend(us)
        self.prev_applied, self.last_applied = (us[-2] if n > 1 else self.last_applied), us[-1]
        self.expected = seq + n
        self.counters['samples_received'] += n
        self.listener.measured(xs, fs, us)

    def _malformed(self):
        """A frame with a wrong length or CRC: counted, and a bad frame for the listener."""
        self.counters['frames_malformed'] += 1
        self.listener.bad_frames(1)

    def count_lost(self, lost: int):
        """`lost` samples before the next one received: counted, and carried by the next SampleBlock."""
        self.counters['frames_lost'] += lost
        self.flush_pending()
        self._pend_lost += lost

    def flush_pending(self):
        px, pf, pu = self._pend
        if px:
            lst = self.listener
            self._ready.append(SampleBlock(self._pend_first, self._pend_t0, 1.0 / self.fs, np.array(px),
                                           np.array(pf), np.array(pu), lst.temperature, lst.controller_faults,
                                           self._pend_lost))
            self._pend = ([], [], [])
            self._pend_first, self._pend_t0, self._pend_lost = None, None, 0
