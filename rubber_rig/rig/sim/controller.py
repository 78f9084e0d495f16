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

"""The simulated actuator controller: the other end of the rig bus, speaking the same DBC as a real one.

Consumes one setpoint per sample tick, drives the actuator and specimen, sends measured samples, status,
temperature and heartbeat frames, ramps smoothly to rest on ABORT or when the host heartbeat goes silent.
Paced: ticks at wall-clock deadlines t0 + k / fs (no drift). Fast: ticks as soon as the setpoint for the next
tick is there, so it advances only as far as setpoints are queued; waveform and physics are identical.
"""
import math
import threading
import time
from typing import Callable

import numpy as np

from ...safety import RAMP_ACCEL, RAMP_VELOCITY, SafeRamp, stopping_positions
from ..can.frames import SampleFrames
from ..can.protocol import (
    FAULT_CONTROLLER,
    FAULT_SENSOR,
    FAULT_WATCHDOG,
    Protocol,
)
from .constants import IDLE_PERIOD, STREAMING
from .faults import FaultInjector
from .lateness import LatenessLedger, LatenessLog
from .plant import Actuator, DelayLine, Sensor, first_invalid
from .receive import CommandReceiver
from .specimen import build_specimen
from .state import ControllerState
from .transmit import FeedbackTransmitter


def _shared(name: str) -> property:
    """The controller's view of one field of its shared state (state.ControllerState)."""
    return property(lambda self: getattr(self.shared, name), lambda self, value: setattr(self.shared, name, value),
                    doc=f'ControllerState.{name}')


class SimController:
    """Simulated rig on python-can `bus` (any interface) at sample_rate [Hz] with SimOptions `options`, speaking
    the frame profile `profile` (rubber_rig.rig.can.frames) for setpoints and samples.

    Three parts share one explicit state (``shared``, a state.ControllerState): the receiver
    (receive.CommandReceiver) applies the host's frames to it, the tick here moves the actuator and specimen by
    it, the transmitter (transmit.FeedbackTransmitter) reports it.
    """

    MAX_BLOCK = 1024           # ticks computed at once (numpy) while nothing but the stream happens
    MIN_RUN = 32               # from this many ticks the specimen model's batch run beats its per-sample step

    state, fault_bits, ticks, next_seq, buffer = map(_shared, ('state', 'fault_bits', 'ticks', 'next_seq', 'buffer'))
    u, u_prev, counters, lower, upper, decel_max = map(_shared, ('u', 'u_prev', 'counters', 'lower', 'upper',
                                                                 'decel_max'))

    def __init__(self, bus, sample_rate: float, options, paced: bool, protocol: Protocol = None,
                 profile: str = 'packed', flood_bus=None, clock: Callable[[], float] = time.monotonic):
        self.bus, self.fs, self.opt, self.paced = bus, float(sample_rate), options, paced
        self._clock = clock               # paced: the time the rig runs on (a scenario's simulated clock in tests)
        self.proto = protocol or Protocol()
        self.defects = frozenset(options.defects)   # deliberate protocol defects (conformance testing only)
        self.frames = SampleFrames(profile, self.proto.db, self.fs)
        self.shared = ControllerState()
        # one stream per noise source, so idle-time draws (temperature) never shift the sensor noise and paced
        # and fast runs stay identical
        rng_x, rng_f, rng_t = (np.random.default_rng([options.seed, k]) for k in range(3))
        self.actuator = Actuator(options.actuator_frequency, options.actuator_damping,
                                 options.actuator_velocity_max, self.fs)
        self.specimen = build_specimen(options.specimen, 1.0 / self.fs, options.damage)
        self.disp_sensor = Sensor(options.displacement_noise, options.displacement_offset,
                                  options.displacement_resolution, rng_x)
        self.force_sensor = Sensor(options.force_noise, options.force_offset, options.force_resolution, rng_f,
                                   gain=options.force_gain, drift=options.force_drift / self.fs)
        # the load cell reads the true force of force_delay ago (None: no delay, the true force as it is)
        delay = options.force_delay * self.fs
        delay = float(round(delay)) if abs(delay - round(delay)) < 1e-9 else delay
        self.force_delay = DelayLine(delay) if delay > 0 else None
        self.faults = FaultInjector(options.faults, self.fs, options.seed)
        base = options.specimen.get('temperature', options.temperature)
        self.receiver = CommandReceiver(self.shared, bus, self.proto, self.frames, self.defects,
                                        options.actuator_velocity_max, self.fs, abort=self.abort,
                                        report=lambda: self.tx.housekeeping(force=True),
                                        identify=lambda: self.tx.send_identity())
        self.tx = FeedbackTransmitter(self.shared, bus, self.proto, self.frames, self.faults, self.fault_time,
                                      options, self.fs, float(base if isinstance(base, (int, float)) else
                                                              options.temperature), rng_t, self.defects, flood_bus)
        self.flood_bus = flood_bus
        # fault schedules run on rig time plus, paced, the wall time the rig stood idle after its first tick: a
        # fault window ends in real time even while the rig stands faulted (first program: sample = time * fs)
        self.idle_ticks, self._idle_since, self.ramp = 0, None, None
        self._ramp_then = None            # defect fault_ramp_overshoot: the target after the ramp past it
        self._fault_since = None          # defect fault_clears_after_500ms: when the fault state began (wall)
        self._stop = threading.Event()
        # paced: every deadline this process missed by SIM_LATE_MIN or more, when its file is set - its host was
        # late, which a real controller on its own CPU would not be
        self.timing_log = LatenessLog()
        self.lateness = LatenessLedger()   # how far its output lags its schedule now: for a driver in this process
        self._announced, self._thread = False, None
        self._deadline, self._idle_before, self._next_idle_hk = None, True, 0.0   # paced schedule (serve)

    # ---- lifecycle
    def start(self):
        """Run in a background thread (in-process rig)."""
        self._thread = threading.Thread(target=self.run_forever, name='sim-rig', daemon=True)
        self._thread.start()

    def stop(self):
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)

    def run_forever(self):
        """Serve the bus until stop(): announce, then receive frames and tick (paced: on the clock, waiting on the
        bus until the next tick or housekeeping is due; fast: as far as the queued setpoints allow).
        """
        self.announce(self._clock())
        try:
            while not self._stop.is_set():
                if self.paced:
                    wait = self.serve(self._clock())
                    asked = time.time()
                    msg = self.bus.recv(wait)   # wait for a frame until the next moment due
                    self.timing_log.woke(asked, wait, msg)
                    if msg is not None:
                        self.receiver.handle(msg)
                        self.receiver.receive_all()
                else:
                    msg = self.bus.recv(0.02)
                    while msg is not None:
                        self._handle_in_order(msg)
                        msg = self.bus.recv(0)
                    self._catch_up()   # ticks only as far as setpoints are queued (or while ramping down)
                    self.tx.send_feedback()
        finally:
            self.lateness.stopped()     # nothing it misses from now on is this host's lateness

    def announce(self, now: float):
        """Power-up at `now` [s] on the clock: status and identity go out, the idle periods start."""
        self.tx.start_periods(now)
        self._next_idle_hk = now
        self._announced = True

    def serve(self, now: float) -> float:
        """Paced: one wake-up at `now` [s] on the clock (time.monotonic, or a scenario's simulated clock): handle
        the frames received, tick every sample due (deadline based: no drift from late wake-ups) or do the idle
        housekeeping; returns how long [s] the controller may wait for a frame before anything is due.
        """
        sh = self.shared
        if not self._announced:
            self.announce(now)
        if self.flood_bus is not None:
            self.tx.flood(now)
        if sh.state not in STREAMING:
            self.receiver.receive_all()  # a HostStreamStart and the first setpoints start the stream
        if sh.state not in STREAMING:
            return self._serve_idle(now)
        if self._deadline is None:
            self._deadline = now
            # the identity keeps its period across the change from wall-clock to tick time
            due = self.tx.idle_due.get('ControllerIdentity', now)
            self.tx.id_next_tick = sh.ticks + max(0, round((due - now) * self.fs))
            if self._idle_since is not None:
                self.idle_ticks += int((now - self._idle_since) * self.fs)
                self._idle_since = None
        self.receiver.receive_all()      # frames that arrived meanwhile come before the ticks that are due
        n, deadline = 0, self._deadline
        due = int((now - deadline) * self.fs) + 1 if now >= deadline else 0
        behind = now - deadline if due > 1 else 0.0
        if due > 1:
            # this process was not scheduled for `due` ticks: neither was the host in it, so the host watchdog does
            # not count that time (a real controller has its own CPU)
            sh.last_host_hb += due - 1
        started = time.time()
        while now >= deadline and sh.state in STREAMING:
            done = self._tick_block(int((now - deadline) * self.fs) + 1) or self._tick()
            deadline += done / self.fs
            n += done
        self._deadline = deadline
        self.lateness.woke(now, behind, deadline)
        if behind:     # late from the missed deadline until the ticks due are caught up (a burst of frames)
            self.timing_log.missed(behind, started)
        if n > 1:
            sh.counters['overruns'] += n - 1
        self._idle_before = False
        return max(0.0, min(deadline - self._clock(), 0.01)) if sh.state in STREAMING else 0.0

    def _serve_idle(self, now: float) -> float:
        """Paced and not streaming: periodic frames on the clock; returns the wait [s] until they are next due."""
        if self._deadline is not None:   # stopped ticking: back to wall-clock time
            self.tx.idle_due['ControllerIdentity'] = now + max(0, self.tx.id_next_tick - self.ticks) / self.fs
        self._deadline = None
        if self._idle_since is None and self.ticks:
            self._idle_since = now
        if 'fault_clears_after_500ms' in self.defects:
            self._clear_fault_by_itself(now)
        late = now - self._next_idle_hk if self._idle_before and now >= self._next_idle_hk else 0.0
        if now >= self._next_idle_hk:
            self.timing_log.missed(late)     # due while idle: a late wake-up is this host's lateness
            self.tx.idle_housekeeping(now)
            self._next_idle_hk = max(self._next_idle_hk + IDLE_PERIOD, now)
        self.lateness.woke(now, late, self._next_idle_hk)
        self._idle_before = True
        return min(IDLE_PERIOD, max(0.0, self._next_idle_hk - now))

    def _clear_fault_by_itself(self, now: float):
        """Defect fault_clears_after_500ms: a fault that goes back to idle 0.5 s after it began, without RESET."""
        if self.state != 'fault':
            self._fault_since = None
        elif self._fault_since is None:
            self._fault_since = now
        elif now - self._fault_since > 0.5:
            self.fault_bits, self.state, self._fault_since = 0, 'idle', None
            self.tx.housekeeping(force=True)

    def pump(self):
        """Fast mode without a thread: handle every frame waiting on the bus and tick as far as the queued
        setpoints allow, then return. The in-process fast rig is driven this way from the driver's poll(), so
        the host and the simulator never fight over the GIL; frames still cross the bus both ways.
        """
        if not self._announced:
            self.announce(self._clock())
        msg = self.bus.recv(0)
        while msg is not None:
            self._handle_in_order(msg)
            msg = self.bus.recv(0)
        self._catch_up()
        self.tx.send_feedback()   # nothing more to tick now: the host gets what there is

    def _handle_in_order(self, msg):
        """Fast mode: setpoint frames queue up; any other frame (heartbeat, command) is handled after the ticks
        of the setpoints that came before it on the bus, as it would be in real time.
        """
        if not self.receiver.is_setpoint(msg):
            self._catch_up()
        self.receiver.handle(msg)

    def _catch_up(self):
        """Fast mode: tick as far as the queued setpoints allow (or while ramping down)."""
        while self._can_tick():
            self._tick_block(self.MAX_BLOCK) or self._tick()

    def _can_tick(self):
        if self.state == 'ramping_down':
            return True
        if self.state not in ('running', 'holding') or not self.buffer:
            return False
        # a stream that resumes further ahead is bridged by holding, as the paced controller does in real time
        return self.next_seq in self.buffer or min(self.buffer) > self.next_seq

    def abort(self, target: float = 0.0, fault_bits: int = 0, velocity_max: float = None):
        """Flush queued setpoints and ramp from the current command and velocity to target [m] (None: stop
        where the motion can stop, braking at the host's deceleration limit), at most velocity_max [m/s]
        (default safety.RAMP_VELOCITY; the host sends half its velocity limit), inside the host's limits
        (CTRL-RAMP-1, CTRL-RAMP-2, CTRL-LIM-1).
        """
        self.fault_bits |= fault_bits
        self.buffer.clear()
        if self.state in ('running', 'holding', 'ramping_down'):
            v = (self.u - self.u_prev) * self.fs
            if target is None:
                target = float(stopping_positions(self.u, v, self.decel_max, self.fs))
            velocity = min(velocity_max or RAMP_VELOCITY, RAMP_VELOCITY)
            if 'slow_ramp' in self.defects:
                velocity /= 5.0
            x0, self._ramp_then = self.u, None
            away = target - self.u
            if fault_bits and abs(away) > 1e-6:      # the controller's own (fault, host silence) ramps
                if 'fault_ramp_step' in self.defects:    # starts with a step of up to 0.1 mm
                    x0, v = self.u + math.copysign(min(0.1e-3, abs(away)), away), 0.0
                if 'fault_ramp_overshoot' in self.defects:   # passes its target by 0.2 mm, then comes back
                    self._ramp_then, target = target, target + math.copysign(0.2e-3, away)
            self.ramp = SafeRamp(x0, v, target, self.fs,
                                 velocity_max=velocity,
                                 accel_max=RAMP_ACCEL, decel_max=self.decel_max, lower=self.lower, upper=self.upper)
            self.state = 'ramping_down'
        elif self.fault_bits:
            self.state = 'fault'
        self.tx.housekeeping(force=True)

    # ---- many samples at once
    def _tick_block(self, limit: int) -> int:
        """Up to `limit` ticks of a running stream at once, the same samples and frames as as many _tick()
        calls; returns how many, 0 when the next tick needs the per-sample path (not running, a fault injection
        or delayed frame pending, the host watchdog about to expire, no setpoint queued).

        A block ends at the next housekeeping tick, so status, heartbeat and temperature frames go out at the
        same ticks as tick by tick.
        """
        sh = self.shared
        if sh.state != 'running' or self.faults.faults or self.tx.held:
            return 0
        ticks, seq, buffer = sh.ticks, sh.next_seq, sh.buffer
        n = min(limit, self.tx.ticks_to_periodic(), int(self.opt.host_timeout * self.fs - (ticks - sh.last_host_hb))
                + 1)
        if n < 2:
            return 0
        u = []
        for k in range(seq, seq + n):
            value = buffer.pop(k, None)
            if value is None:
                break
            u.append(value)
        n = len(u)
        if n == 0:
            return 0
        x, v = self.actuator.run(u)
        force = self.specimen.run(np.asarray(x)) if n >= self.MIN_RUN else [self.specimen.step(p) for p in x]
        bad = first_invalid(force)
        if bad >= 0:   # the load cell channel went invalid: the stream ends at that tick, as tick by tick
            n = bad + 1
            for k in range(n, len(u)):
                buffer[seq + k] = u[k]
            u, x, force = u[:n], x[:n], force[:n]
            self.actuator.x, self.actuator.v = x[-1], v[n - 1]
        if self.force_delay is not None:
            force = self.force_delay.run(force)
        # a frame cannot carry NaN: an invalid channel reads 0 and the status frame carries the sensor fault
        self.tx.queue_feedback(seq, self.disp_sensor.read_frame(x), self.force_sensor.read_frame(force), u)
        sh.u_prev, sh.u = (u[-2] if n > 1 else sh.u), u[-1]
        sh.next_seq += n
        sh.ticks += n
        if bad >= 0 and not sh.fault_bits & FAULT_SENSOR:
            self.abort(0.0, FAULT_SENSOR)
        else:
            self.tx.housekeeping()
        return n

    # ---- one sample
    def _tick(self) -> int:
        t = self.fault_time()
        self.tx.release_held()
        if self.state == 'ramping_down':
            u = self.ramp.step()
        else:
            u = self.buffer.pop(self.next_seq, None)
            if u is None:   # CTRL-STREAM-3: an underrun holds the last command
                u = self.u
                self.counters['underruns'] += 1
                self.state = 'holding'
            else:
                self.state = 'running'
            if self.ticks - self.shared.last_host_hb > self.opt.host_timeout * self.fs \
                    and 'keep_setpoint_on_host_silence' not in self.defects:
                # CTRL-WD-1: host gone, the controller brings the rig to rest itself
                self.abort(0.0, FAULT_CONTROLLER if 'wrong_fault_bit' in self.defects else FAULT_WATCHDOG)
        self.u_prev, self.u = self.u, u
        x = self.actuator.step(u)
        force = self.specimen.step(x)
        if not math.isfinite(force) and not self.fault_bits & FAULT_SENSOR:
            self.abort(0.0, FAULT_SENSOR)   # the load cell channel went invalid: a controller stops on that
        if self.force_delay is not None:
            force = self.force_delay.step(force)
        stuck = self.faults.stuck(t)
        for name, sensor in (('displacement', self.disp_sensor), ('force', self.force_sensor)):
            if name in stuck and sensor.stuck_value is None:
                sensor.stuck_value = sensor.read(x if name == 'displacement' else force)
            elif name not in stuck:
                sensor.stuck_value = None
        xm, fm = self.disp_sensor.read(x), self.force_sensor.read(force)
        # a frame cannot carry NaN: an invalid channel reads 0 and the status frame carries the sensor fault
        self.tx.queue_feedback(self.next_seq, [xm if math.isfinite(xm) else 0.0],
                               [fm if math.isfinite(fm) else 0.0], [u])
        self.next_seq += 1
        self.ticks += 1
        if self.state == 'ramping_down' and self.ramp.done and self._ramp_then is not None:
            # defect fault_ramp_overshoot: back from past the target
            self.ramp = SafeRamp(self.u, 0.0, self._ramp_then, self.fs, accel_max=RAMP_ACCEL,
                                 decel_max=self.decel_max, lower=self.lower, upper=self.upper)
            self._ramp_then = None
        if self.state == 'ramping_down' and self.ramp.done:
            self.tx.send_feedback()
            self.shared.accept_from = math.inf
            self.state = 'fault' if self.fault_bits else 'idle'
            self.buffer.clear()
            self.tx.release_all_held()   # delayed frames still go out once the rig stops ticking
            self.tx.housekeeping(force=True)
        else:
            self.tx.housekeeping()
        return 1

    def fault_time(self) -> float:
        """Time [s] on the fault schedule: rig time, plus (paced) the wall time stood idle after the first tick."""
        idle = self.idle_ticks
        if self._idle_since is not None:
            idle += int((self._clock() - self._idle_since) * self.fs)
        return (self.ticks + idle) / self.fs
