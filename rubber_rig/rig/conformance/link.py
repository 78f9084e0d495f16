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

"""The host end of a conformance run: frames to and from the controller, the envelope watch on every sample
that arrives, waits and streams in the controller's sample time, and the results. It is the context every
scenario (active_power, active_stream, reference_specimen, active_faults: functions of the link) works on, and
the run (active.ConformanceRun) holds one; it is deliberately not the driver (see active).
"""
from __future__ import annotations

import math
import os
import threading
import time
from typing import TYPE_CHECKING

import can

from ...safety import DECEL_MAX
from ..can.frames import SampleFrames
from ..can.protocol import (
    CMD_ABORT,
    CMD_RESET,
    STATES,
    Protocol,
    cycle_time,
    unwrap,
)
from .envelope import Envelope, Sample
from .host_timing import HostTiming
from .kernel_counts import KernelCounts
from .marks import Aborted, judges  # noqa: F401 - the scenarios import them from here too
from .report import Results
from .trace import Trace

if TYPE_CHECKING:
    from .in_process import SimulatedTime

LSB = 1e-7                  # [m] displacement resolution of the frames
LEAD = 0.3                  # [s] setpoints streamed ahead of the controller: covers pauses of this host (a
#                             loaded 2-core host stalls the run for 100-300 ms; a stream that fell behind made the
#                             controller hold, then step to where the wave had moved on, and tripped the
#                             tracking watch)
IDENTIFY_TIMEOUT = 0.1      # [s] CTRL-ID-1
REACTION = 0.1              # [s] a controller is given to react to a command (a ramp's start, the watchdog's ramp)
RESET_TIME = 0.2            # [s] RESET is given to return a latched fault to idle (CTRL-FAULT-2)
IDENTIFY_REPEATS = 5        # CTRL-ID-1: IDENTIFY is asked this many times, each must be answered
RAMP_VELOCITY = 0.002       # [m/s] commanded velocity of the ramps the run asks for
APPROACH_VELOCITY = 0.0005  # [m/s] of the stream towards a limit (CTRL-LIM-2): LEAD of it is 0.15 mm
WAVE_FREQUENCY = 2.0        # [Hz] of the motion the run streams
DEFAULT_HOST_TIMEOUT = 0.5  # [s] assumed when the controller states none
BUFFER_IN_FLIGHT = 0.05     # [s] setpoints sent this recently may not be counted in ST_BufferLevel yet
BUFFER_OUTLIERS = 0.02      # share of status frames whose level may be off (a controller busy for a moment)
REST_TIMEOUT = 15.0         # [s] longest wait for the controller to come to rest
TOO_FAST_FACTOR = 1.5       # CTRL-LIM-3 steps at this multiple of the rated velocity in one sample
LATCH_TIME = 3.0            # [s] a fault must stay latched this long without RESET (CTRL-FAULT-2)
FOREIGN_ID = 0x7FE          # an identifier the DBC does not define: another node's traffic
FOREIGN_PERIOD = 0.01       # [s] of that traffic while the host is silent (CTRL-WD-1)
SCENARIO_THREAD = 'scenario thread'   # host_timing source: the run's thread that streams, commands and waits


class ConformanceLink:
    """The bus side of a run on `bus` (any python-can Bus) at sample_rate [Hz] with frame `profile`, inside
    `envelope`: sending, receiving and judging what arrives against the envelope.
    """

    def __init__(self, bus: can.BusABC, sample_rate: float, envelope: Envelope, profile: str = 'packed',
                 log=print, power_up=None, host_timing_files=(), reference=None, ambient=None, only=None,
                 simulated: SimulatedTime | None = None):
        self.bus, self.fs, self.env, self.log = bus, float(sample_rate), envelope, log
        # None: the wall clock of this host, a receive thread reading the bus (a controller on a bus of its own);
        # a SimulatedTime: the controller in this process, stepped with the run (deterministic, faster than real time)
        self.simulated = simulated
        # the declared reference specimen (reference_specimen.ReferenceSpring) and ambient temperature
        # (reference_specimen.Ambient) the measured values are judged against (CTRL-MEAS-1..3); None: not declared
        self.reference, self.ambient = reference, ambient
        # names of the scenarios to run (a short run of a few; None: all): the run is then incomplete
        self.only = None if only is None else frozenset(only)
        # power_up: callable that switches the controller on (or asks the operator to) once the run listens;
        # None: the controller is already on and CTRL-PWR-1 is not tested
        self.power_up = power_up
        self.proto = Protocol()
        self.frames = SampleFrames(profile, self.proto.db, self.fs)
        self.trace = Trace(self.fs)
        # this host's own lateness (host_timing): the receive loop and the heartbeat sender record theirs; files
        # of other processes of this host (the simulator with --sim) are merged in before a timing verdict
        self.host_timing = HostTiming()
        self.trace.host_late = self.host_timing.windows
        self.host_timing_files = tuple(host_timing_files)
        # the kernel's count of this host's lateness, sampled by the receive loop (kernel_counts): the waits for a
        # CPU of the processes standing for the controller (kernel.pids: the simulator with --sim) and of this
        # run's own, and the frames the socket under this run's bus dropped
        self.kernel = KernelCounts(self.host_timing, bus if simulated is None else None,
                                   os.getpid() if simulated is None else None)
        self.results = Results()
        self.lock = threading.RLock()
        self.state, self.faults, self.identity = 'unconfigured', 0, None
        self.samples = []           # Sample per feedback sample received
        self.status_log = []        # (t, state, faults, last sequence, buffer level) per ControllerStatus
        self.sent = {}              # sequence -> setpoint sent (valid frames only)
        self.sent_log = []          # (t send called, t logged, first, count) per valid setpoint frame sent
        self.sent_at = {}           # sequence -> time its setpoint was sent
        self.deviation = ''
        self.tracking_allowance = 0.0   # [m] tracking error tolerated beyond a third of the envelope (a test step)
        self.heartbeat = False
        # another node on the bus: while set, the receive loop sends a frame of an identifier the DBC does not
        # define every FOREIGN_PERIOD (CTRL-WD-1: only HostHeartbeat may keep a controller's watchdog quiet)
        self.foreign_traffic = False
        self._next_foreign = 0.0
        self._fb_ref = 0
        self._hb_counter = 0
        self._next_hb = 0.0
        self._last_rx = -math.inf     # arrival time [s] of the latest controller frame read (catch_up)
        self._stop = threading.Event()
        self.position = 0.0         # last applied command reported [m]
        self._rx = threading.Thread(target=self._receive_loop, name='conformance-rx', daemon=True)

    @property
    def host_timeout(self) -> float:
        """The host timeout [s] the controller stated (ControllerIdentity), else DEFAULT_HOST_TIMEOUT."""
        if self.identity and float(self.identity[1]['CI_HostTimeout']) > 0:
            return float(self.identity[1]['CI_HostTimeout'])
        return DEFAULT_HOST_TIMEOUT

    def start(self):
        """Start listening: the receive loop (envelope watch, heartbeat, foreign traffic) runs until stop() (on
        simulated time there is no thread: each _pause reads what arrived).
        """
        if self.simulated is None:
            self._rx.start()

    def stop(self):
        """Heartbeat off, then the receive loop ends (after 0.1 s in which the last frames still arrive)."""
        self.heartbeat = False
        self._pause(0.1)
        self._stop.set()
        if self._rx.is_alive():
            self._rx.join(timeout=2.0)

    # ---- bus
    def _tx(self, msg: can.Message):
        with self.lock:
            self.trace.add(msg, self.now())
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
            # the frame is on its way from before send() is called: a status received after that may count it,
            # even while this thread still waits for the lock the receive thread holds
            started = self.now()
            self._tx(msg)
            if record:
                with self.lock:
                    self.sent_log.append((started, self.now(), first + i * per, len(chunk)))
                    now = self.now()
                    for k, v in enumerate(chunk):
                        self.sent[first + i * per + k] = v
                        self.sent_at[first + i * per + k] = now

    def _heartbeat(self):
        self._hb_counter = (self._hb_counter + 1) % 256
        self.send('HostHeartbeat', {'HH_Counter': self._hb_counter})

    def now(self) -> float:
        """The run's time [s]: this host's wall clock (time.time(), the time base of a CAN log), or simulated."""
        return self.simulated.t if self.simulated is not None else time.time()

    def _pause(self, seconds: float) -> None:
        """Let `seconds` pass: sleep (the receive thread reads the bus meanwhile), or on simulated time step the
        controller and read what it sent, one step at a time.
        """
        sim = self.simulated
        if sim is None:
            # the scenario thread woke later than it asked: what it then sent or saw was late by this host
            due = time.time() + seconds
            time.sleep(seconds)
            self.host_timing.due(due, time.time(), SCENARIO_THREAD)
            return
        for _ in range(max(1, int(round(seconds / sim.step)))):
            sim.t += sim.step
            if sim.powered:
                sim.poll(sim.t)
            self._send_due(sim.t)
            msg = self.bus.recv(0)
            while msg is not None:
                self._on_frame(msg, msg.timestamp)   # its arrival on the simulated bus, on the simulated clock
                msg = self.bus.recv(0)

    def _send_due(self, now: float) -> bool:
        """Send the host heartbeat and the foreign traffic when due at `now`; True when a heartbeat went out."""
        beat = self.heartbeat and now >= self._next_hb
        if beat:
            self._heartbeat()
            self._next_hb = max(self._next_hb + cycle_time('HostHeartbeat'), now)
        if self.foreign_traffic and now >= self._next_foreign:
            self._tx(can.Message(arbitration_id=FOREIGN_ID, data=bytes(8), is_extended_id=False))
            self._next_foreign = now + FOREIGN_PERIOD
        return beat

    def _receive_loop(self):
        """The receive thread of a run on the wall clock: read the bus, send what is due, and record every time this
        thread ran late (host_timing: not the controller's lateness).
        """
        wait, back, beating = 0.005, None, False
        while not self._stop.is_set():
            asked = time.time()
            if back is not None:        # the loop comes round at once after a frame: a pause here is this host's
                self.host_timing.due(back, asked)
            msg = self.bus.recv(wait)
            now = back = time.time()
            # back later than the wait asked for: this host did not run this loop (nor read the bus) meanwhile
            self.host_timing.due(asked + wait, back)
            due = self._next_hb
            if self._send_due(now) and beating:
                # due since the last one: a send later than due is this host's lateness
                self.host_timing.due(due, now)
            beating = self.heartbeat
            if msg is not None:
                self._on_frame(msg, msg.timestamp or now)
            self.kernel.sample(now)

    def _on_frame(self, msg: can.Message, t: float):
        """One frame the controller sent, seen at `t` [s]: into the trace, and the link's view of the controller."""
        with self.lock:
            fr = self.trace.add(msg, t)
            if fr.malformed or fr.host is not False:
                return
            self._last_rx = max(self._last_rx, t)
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
        raw, xs, fs, us = fr.samples
        first = unwrap(int(raw), self._fb_ref, self.trace.modulus[fr.name])
        self._fb_ref = first + len(xs)
        for i, (x, f, u) in enumerate(zip(xs, fs, us, strict=False)):
            self.samples.append(Sample(fr.t, first + i, float(x), float(u), self.state, float(f)))
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
        elif abs(x - u) > self.env.half / 3 + self.tracking_allowance:
            why = f'tracking error {abs(x - u) * 1e3:.4f} mm at sample {seq}'
        if why:
            self.deviation = why
            self.command(CMD_ABORT, 0.0)

    def merge_host_timing(self):
        """Read the lateness other processes of this host recorded (host_timing_files) into the windows."""
        for path in self.host_timing_files:
            self.host_timing.add_from_file(path)

    # ---- helpers
    def _check(self):
        if self.deviation:
            raise Aborted(self.deviation)

    def _wait(self, predicate, timeout: float) -> bool:
        end = self.now() + timeout
        while self.now() < end:
            self._check()
            with self.lock:
                if predicate():
                    return True
            self._pause(0.002 if self.simulated is None else self.simulated.step)
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

    def stream(self, first: int, wave, duration: float, start: bool = True, until=None) -> int:
        """Stream wave(k) [m] (k: samples since `first`) for `duration` [s] of samples, LEAD ahead, with the host
        heartbeat on, or until until() is true; returns the sequence after the last setpoint sent.
        """
        if start:
            self.send('HostStreamStart', {'HS_FirstSequence': first % (1 << 32)})
        with self.lock:
            self._fb_ref = first
        self.heartbeat = True
        total = int(round(duration * self.fs))
        per = self.frames.setpoints_per_frame
        t0, sent = self.now(), first
        while sent < first + total and not (until is not None and until()):
            self._check()
            due = first + int((self.now() - t0 + LEAD) * self.fs)
            while sent < min(due, first + total):
                n = min(per, first + total - sent)
                self.send_setpoints(sent, [wave(k - first) for k in range(sent, sent + n)])
                sent += n
            self._pause(0.001)
        return sent

    def catch_up(self, timeout: float = 1.0) -> bool:
        """Wait until a controller frame that arrived (kernel time stamp) after now was read, so every one before
        it was (the queue is read in order): the view scenarios act on lags the bus while this host starves the
        receive thread. False if none came within `timeout` [s]; on simulated time the view is always current.
        """
        if self.simulated is not None:
            return True
        t = self.now()
        return self._wait(lambda: self._last_rx >= t, timeout)

    def next_sequence(self, lead: float = LEAD) -> int:
        """A sequence LEAD ahead of the last sample the controller reported (after catching up with the bus)."""
        self.catch_up()
        with self.lock:
            last = self.samples[-1].seq if self.samples else 0
        return last + 1 + int(lead * self.fs)

    def to_rest(self, target: float = 0.0):
        """Bring the controller to rest at target (ABORT if it ticks), clear faults (RESET), wait for idle."""
        self.heartbeat, self.foreign_traffic = True, False
        end = self.now() + REST_TIMEOUT
        while True:
            # ABORT again every second while the controller still ticks: a frame lost on a loaded host (a full
            # receive queue) must not leave the rig running
            if self.state in ('running', 'holding'):
                self.command(CMD_ABORT, target)
            if self._wait(lambda: self.state in ('idle', 'fault'), min(1.0, max(0.0, end - self.now()))):
                break
            if self.now() >= end:
                raise Aborted(f'the controller did not come to rest within {REST_TIMEOUT:g} s (state {self.state})')
        if self.state == 'fault' or self.faults:
            self.command(CMD_RESET)
            self._wait(lambda: self.state == 'idle' and not self.faults, 1.0)
        self.catch_up()        # the next scenario starts from where the controller is, not from a lagging view
        self.heartbeat = False

    def smooth(self, start: float, amplitude: float, frequency: float = WAVE_FREQUENCY):
        """Start + amplitude (1 - cos 2 pi f t) / 2: begins at rest, never leaves [start, start + amplitude]."""
        w = 2 * math.pi * frequency / self.fs
        return lambda k: start + amplitude * (1.0 - math.cos(w * k)) / 2.0

    def ramp_to(self, start: float, end: float, velocity: float):
        """A constant-velocity move from start to end [m] at velocity [m/s], then holding end."""
        n = max(1, int(abs(end - start) / velocity * self.fs))
        return lambda k: start + (end - start) * min(k, n) / n
