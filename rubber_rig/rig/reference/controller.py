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

"""A second controller, written from docs/protocol.md and rubber_rig.dbc alone (issue 36): the state machine,
the stream, the safety duties and the periodic frames of the controller side of the rig protocol, on any
python-can bus, with the deliberate defects of defects.py behind flags.

It shares no code with the simulated controller (rig/sim/) nor the host's codec (rig/can/): what it knows of
the bus comes from wire.py, its ramps and its rig (an ideal position loop on a reference spring) from plant.py.
`rubber-rig conformance --reference` runs it in-process; test_reference_controller shows that a conformance run
passes it and fails each defect on exactly the requirements the defect breaks.

Time is an input: poll(now) handles what arrived and takes every tick of its sample clock due by `now` [s];
start() runs it in a thread on time.monotonic.
"""
from __future__ import annotations

import math
import threading
import time

import can

from .defects import check_reference_defects
from .plant import OVERSHOOT_DEFECT, OWN_RAMP_VELOCITY, STEP_DEFECT, Plant, Ramp
from .transmit import FrameSender
from .wire import Wire

LSB = 1e-7                  # [m] displacement resolution of the frames (DBC scale)
DEFAULT_DECEL = 100.0       # [m/s^2] braking until HostLimits says otherwise (HL_Deceleration 0 too)
TICKING = ('running', 'holding', 'ramping_down')
PROFILES = {'packed': ('SetpointPacked', ('FeedbackPacked',)), 'single': ('Setpoint', ('Feedback',)),
            'classic': ('Setpoint', ('FeedbackApplied', 'FeedbackMeasured'))}


def unwrap(raw: int, near: int, bits: int) -> int:
    """The full index whose low `bits` are `raw`, nearest to `near` (docs/protocol.md "Sequences")."""
    half, mod = 1 << (bits - 1), 1 << bits
    return near + ((raw - near + half) % mod) - half


class ReferenceController:
    """The controller end of the rig protocol on python-can `bus` at `sample_rate` [Hz] with frame `profile`.

    stiffness [N/m]: the reference spring on its rig; ambient [degC]: the temperature it reports (None: not
    available); host_timeout [s] and velocity_max [m/s]: what it states in ControllerIdentity and keeps to;
    defects: names of defects.REFERENCE_DEFECTS.
    """

    def __init__(self, bus: can.BusABC, sample_rate: float = 1000.0, profile: str = 'packed', defects=(),
                 stiffness: float = 1.0e7, ambient: float | None = 23.45, host_timeout: float = 0.5,
                 velocity_max: float = 0.5, seed: int = 36):
        why = check_reference_defects(defects)
        if why:
            raise ValueError(why)
        if profile not in PROFILES:
            raise ValueError(f'unknown frame profile {profile!r} (one of: {", ".join(PROFILES)})')
        self.bus, self.fs, self.defects = bus, float(sample_rate), frozenset(defects)
        self.wire = Wire()
        self.setpoint_name, self.feedback_names = PROFILES[profile]
        self.plant = Plant(stiffness, self.defects, seed=seed)
        self.ambient, self.host_timeout, self.velocity_max = ambient, float(host_timeout), float(velocity_max)
        self.state, self.faults = 'idle', 0
        self.u, self.v = 0.0, 0.0             # applied command of the last tick [m] and its velocity [m/s]
        self.queue = {}                       # full sequence -> setpoint [m]
        self.next_seq, self.last_taken = 0, 0
        # no setpoint is taken before a HostStreamStart (CTRL-PWR-1), and none below its first sequence
        self.accept_from = 0 if 'setpoints_at_power_up' in self.defects else None
        self.lower, self.upper, self.decel = -math.inf, math.inf, DEFAULT_DECEL
        self.ramp = None
        self.last_host_heartbeat = None
        self.counters = {'frames_bad': 0, 'setpoints_stale': 0, 'tx_dropped': 0}
        self._pending = []                    # (sequence, x, force, u) not sent yet
        self._t0 = None                       # sample clock origin [s]; tick n at t0 + n / fs
        self._n = 0
        self._due = {}
        self.tx = FrameSender(bus, self.wire, self.feedback_names, self.defects, self.counters)
        self._identified = False
        self._fault_since = None
        self._stop = threading.Event()
        self._thread = None

    # ---- lifecycle
    def start(self, clock=time.monotonic, late=None, late_min: float = 0.002):
        """Run in a thread until stop(), on `clock` [s]. late(t_due, t_done) [wall-clock s], if given, is told of
        every tick taken `late_min` [s] or more after its time: run in a process of this host, its lateness is the
        host's, which a controller with a CPU of its own would not have (conformance/host_timing).
        """
        self._thread = threading.Thread(target=self._run, args=(clock, late, late_min), name='reference-controller',
                                        daemon=True)
        self._thread.start()

    def stop(self):
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)

    def _run(self, clock, late, late_min):
        woken = None          # when this thread asked to be back: later than that is this host's lateness
        while not self._stop.is_set():
            now = clock()
            self.poll(now)
            # late from when it asked to be back (or, woken by a frame, from when it began) until what it owed
            # is sent: a wake-up past its time, or a poll the thread was descheduled in
            start = woken if woken is not None and woken < now else now
            done = clock()
            if late is not None and done - start >= late_min:
                wall = time.time()
                late(wall - (done - start), wall)
            wait = min(0.001, max(0.0, self._t0 + (self._n + 1) / self.fs - clock()))
            woken = clock() + wait
            msg = self.bus.recv(timeout=wait)
            if msg is not None:
                self.receive(msg, clock())

    def poll(self, now: float):
        """Handle every frame waiting on the bus, take the ticks due by `now` [s], send what is due."""
        if self._t0 is None:
            self._power_up(now)
        msg = self.bus.recv(0)
        while msg is not None:
            self.receive(msg, now)
            msg = self.bus.recv(0)
        due = int((now - self._t0) * self.fs)
        while self._n < due:
            self._n += 1
            if self.state in TICKING:
                self._tick(self._t0 + self._n / self.fs)
        self._send_feedback(final=False)
        self._periodic(now)
        if 'fault_clears_after_500ms' in self.defects:
            self._clear_fault_by_itself(now)

    def _power_up(self, now: float):
        """Idle, at rest, every periodic frame at once (docs/protocol.md "Power-up")."""
        self._t0 = now
        for name in ('ControllerStatus', 'ControllerHeartbeat', 'Temperature', 'ControllerIdentity'):
            self._due[name] = now

    # ---- frames received
    def receive(self, msg: can.Message, now: float):
        if 'watchdog_rearmed_by_any_frame' in self.defects:
            self.last_host_heartbeat = now
        frame = self.wire.host_frame(msg)
        if frame is None:                     # foreign: changes nothing (CTRL-FRAME-3)
            return
        layout, sig = frame
        if sig is None:                       # malformed: discarded whole (CTRL-FRAME-2)
            self.counters['frames_bad'] += 1
            if not ('host_limits_crc_unchecked' in self.defects and layout.name == 'HostLimits'
                    and len(msg.data) == layout.length):
                return
            word = int.from_bytes(bytes(msg.data), 'little')
            sig = {name: f.unpack(word) for name, f in layout.fields.items()}
        if layout.name == 'HostHeartbeat':
            self.last_host_heartbeat = now
        elif layout.name == 'HostStreamStart':
            self.accept_from = 0 if 'first_sequence_ignored' in self.defects else int(sig['HS_FirstSequence'])
        elif layout.name == 'HostLimits':
            self._on_limits(sig)
        elif layout.name == 'HostCommand':
            self._on_command(int(sig['CMD_Code']), sig, now)
        elif layout.name == self.setpoint_name:
            self._on_setpoints(sig, now)

    def _on_limits(self, sig: dict):
        lower, upper = sig['HL_DisplacementMin'], sig['HL_DisplacementMax']
        if not lower < upper:                 # min >= max: discarded whole, the limits stay as they were
            self.counters['frames_bad'] += 1
            return
        self.upper = upper
        self.lower = -math.inf if 'ignore_lower_limit' in self.defects else lower
        self.decel = sig['HL_Deceleration'] or DEFAULT_DECEL
        # tighter limits bind the setpoints already queued as well: one outside them is refused now
        spared = self.defects & {'tighter_limits_spare_queued', 'queued_checked_when_applied'}
        if self.state in ('running', 'holding') and not spared and not all(map(self._inside, self.queue.values())):
            self._fault('displacement_limit')

    def _on_command(self, code: int, sig: dict, now: float):
        codes = self.wire.command_code
        if code == codes['IDENTIFY']:
            if not ('identify_answered_once' in self.defects and self._identified):
                self._send_identity()
            self._identified = True
        elif code in (codes['ABORT'], codes['DISABLE'], codes['HOLD']) and self.state in TICKING:
            if code == codes['DISABLE'] and 'ignore_disable' in self.defects:
                return
            velocity = sig['CMD_RampVelocity'] or OWN_RAMP_VELOCITY
            target = None if code == codes['HOLD'] else self._clamp(sig['CMD_Argument'])
            self.queue.clear()
            self.ramp = Ramp(self.u, self.v, target, velocity,
                             self.decel if target is None else min(self.decel, 20.0))
            self._set_state('ramping_down')
        elif code == codes['RESET'] and (self.state in ('fault', 'idle') or (
                'reset_while_ramping' in self.defects and self.state == 'ramping_down')):
            self.faults, self.ramp, self.accept_from = 0, None, None
            self.queue.clear()
            self._set_state('idle')

    def _on_setpoints(self, sig: dict, now: float):
        if self.setpoint_name == 'SetpointPacked':
            count = int(sig['SPP_Count'])
            if not 1 <= count <= 19:
                self.counters['frames_bad'] += 1
                return
            raw, bits = int(sig['SPP_Sequence']), 32
            values = [sig[f'SPP_Displacement_{i}'] for i in range(count)]
        else:
            raw, bits, values = int(sig['SP_Sequence']), 16, [sig['SP_Displacement']]
        if self.state not in ('idle', 'running', 'holding'):
            return                             # ramping down, fault, unconfigured: discarded
        if self.state == 'idle':
            if self.accept_from is None:      # no stream announced since power-up or the last ramp
                self.counters['setpoints_stale'] += 1
                return
            first = unwrap(raw, self.accept_from, bits)
            if first < self.accept_from:
                self.counters['setpoints_stale'] += 1
                return
            self.queue.clear()
            self.next_seq = first             # its first tick is the next tick of the sample clock
            self.last_host_heartbeat = now    # host silence is timed from the start of the stream
            self._set_state('running')
        else:
            first = unwrap(raw, self.next_seq, bits)
        before = self.queue.get(first - 1, self.u if first == self.next_seq else None)
        step_max = self.velocity_max * 1.02 / self.fs + 2 * LSB
        for value in values:
            if not self._inside(value):
                self._fault('displacement_limit')
                return
            step = value - before if before is not None else 0.0
            if abs(step) > step_max and (step > 0 or 'velocity_check_upward_only' not in self.defects):
                self._fault('velocity_limit')
                return
            before = value
        for i, value in enumerate(values):
            if first + i >= self.next_seq:
                self.queue[first + i] = value

    # ---- ticks
    def _tick(self, t: float):
        u_before = self.u
        if self.state in ('running', 'holding') and t - self.last_host_heartbeat > self.host_timeout:
            self._fault('watchdog')
        value = self.queue.pop(self.next_seq, None) if self.state in ('running', 'holding') else None
        if value is not None and 'queued_checked_when_applied' in self.defects and not self._inside(value):
            self._fault('displacement_limit')     # refused only when its tick comes, not when the limits came
        if self.state in ('running', 'holding'):
            if value is None:
                if self.state == 'running':
                    self._set_state('holding')
            else:
                self.u = value
                if self.state == 'holding':
                    self._set_state('running')
        else:
            self.u = self.ramp.step(self.fs)
        self.v = (self.u - u_before) * self.fs
        x, force = self.plant.measure(self.u)
        self._pending.append((self.next_seq, x, force, self.u))
        self.last_taken, self.next_seq = self.next_seq, self.next_seq + 1
        if self.state == 'ramping_down' and self.ramp.done:
            self.ramp, self.accept_from = None, None
            self.queue.clear()
            self._set_state('fault' if self.faults else 'idle')

    def _fault(self, name: str):
        """Refuse, flush and ramp to rest at 0 m (clamped into HostLimits) on the controller's own, fault bit set."""
        self.faults |= self.wire.fault_bit[name]
        self.queue.clear()
        self.ramp = Ramp(self.u, self.v, self._clamp(0.0), OWN_RAMP_VELOCITY, min(self.decel, 20.0),
                         first_step=STEP_DEFECT if 'fault_ramp_step' in self.defects else 0.0,
                         past=OVERSHOOT_DEFECT if 'fault_ramp_overshoot' in self.defects else 0.0)
        self._set_state('ramping_down')

    def _inside(self, value: float) -> bool:
        return self.lower - LSB <= value <= self.upper + LSB

    def _clamp(self, value: float) -> float:
        return min(max(value, self.lower), self.upper)

    def _clear_fault_by_itself(self, now: float):
        if self.state != 'fault':
            self._fault_since = None
        elif self._fault_since is None:
            self._fault_since = now
        elif now - self._fault_since > 0.5:
            self.faults = 0
            self._set_state('idle')

    # ---- frames sent
    def _set_state(self, state: str):
        """Change state; the feedback of the ticks before goes first, a status at once (docs/protocol.md
        "Heartbeats and watchdogs": the controller should report a change at once).
        """
        if state == self.state:
            return
        self._send_feedback(final=state not in TICKING)
        self.state = state
        self._send_status()

    def _send_status(self):
        level = sum(1 for seq in self.queue if seq >= self.next_seq)
        self.tx.status(self.state, self.faults, self.last_taken, level)

    def _send_identity(self):
        self.tx.identity(self.wire.version, self.host_timeout, self.velocity_max)

    def _send_feedback(self, final: bool):
        if self._pending:
            self._pending = self.tx.feedback(self._pending, final)

    def _periodic(self, now: float):
        """Status, heartbeat, temperature and identity at their DBC periods, in every state."""
        for name, due in self._due.items():
            if now < due:
                continue
            period = self.wire.by_name[name].period
            self._due[name] = due + period if now - due < period else now + period
            if name == 'ControllerStatus':
                self._send_status()
            elif name == 'ControllerHeartbeat':
                self.tx.heartbeat(self.state)
            elif name == 'Temperature':
                self.tx.temperature(self.ambient)
            else:
                self._send_identity()
