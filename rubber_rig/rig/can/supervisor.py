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

"""The host driver's supervisor: what the controller says of itself (status, heartbeat, identity,
temperature), the checks on what it measures (limits, stuck sensors, bad-frame rate, lost bursts), the
watchdog over feedback and heartbeats, and the faults with their log of events.

A fault is recorded here and the safe ramp commanded through `on_fault` (RigDriver.abort), which also
releases the stream: the supervisor never touches the stream itself.
"""
import collections
import math

from ...safety import abort_ramp_velocity
from .liveness import ControllerLiveness, silence_limits
from .protocol import (
    CMD_HOLD,
    FAULT_BUS,
    FAULT_DISPLACEMENT_LIMIT,
    FAULT_FORCE_LIMIT,
    FAULT_SENSOR,
    FAULT_WATCHDOG,
    PROTOCOL_VERSION,
    STATES,
    STATUS_SEQ_MOD,
    fault_names,
    temperature_reading,
    unwrap,
)
from .sensor_check import SensorCheck
from .stream import DriverStatus


class Supervisor:
    """Watches the controller behind FrameIO `io` for RigConfig `config`; the listener of `io`.

    limits (the current Limits) is set by the driver. aborting: a ramp the host commanded is under way;
    ramp_pending: commanded to a moving controller that has not reported the ramp yet; host_stop: a stop the
    host commanded (abort, hold, limits) stays the headline while the controller's ramp, its consequence, runs.
    """

    def __init__(self, config, io, on_fault, clock):
        self.cfg, self.io, self.limits = config, io, config.limits
        self.fs = io.fs
        self._on_fault, self._clock = on_fault, clock
        self.events = collections.deque(maxlen=1000)   # (level 'info'|'warn'|'error', text)
        self.last_event = ''
        self.faults, self.fault_messages = 0, []
        self.controller_state, self.controller_faults, self.controller_sequence = 'unconfigured', 0, -1
        self.temperature = math.nan
        # what the controller said of itself (ControllerIdentity): protocol, device, firmware, host_timeout [s],
        # velocity_max [m/s]; None until it did
        self.controller_identity = None
        self.aborting = self.ramp_pending = self.host_stop = False
        self._sensor = SensorCheck(self.fs)
        self._bad = collections.deque()  # (sample position, count) of bad-frame events, 1 s window
        now = clock()
        self.last_feedback = self._last_poll_wall = now   # clock times
        # the embedded simulator's lag (callable: now [s] -> how far [s] this host keeps its output behind its
        # schedule, LatenessLedger.lag); None for a real controller
        self.host_lateness = None
        # a silence judged by the wall clock [s]; not paced (as fast as possible) a host turn may take longer
        self.wd_wall = config.watchdog_timeout if config.paced else max(config.watchdog_timeout, 2.0)
        # heartbeat, status and identity: each owed from the controller's first word on (liveness)
        self.liveness = ControllerLiveness(silence_limits(config.watchdog_timeout, config.require_identity),
                                           self.fs, config.paced)
        self._handlers = {'ControllerStatus': self._on_status, 'ControllerHeartbeat': self._on_heartbeat,
                          'Temperature': self._on_temperature, 'ControllerIdentity': self._on_identity}

    # ---- events and faults
    def event(self, level: str, text: str, headline: bool = True):
        self.events.append((level, text))
        if headline:
            self.last_event = text

    def take_events(self) -> list:
        """The (level, text) events not yet taken, oldest first (for the caller's log); they leave the queue."""
        taken = list(self.events)
        self.events.clear()
        return taken

    def record_fault(self, bit: int, message: str):
        """Record a fault (the caller commands what follows)."""
        self.faults |= bit
        self.fault_messages.append(message)
        self.event('error', f'fault {fault_names(bit)[0]}: {message}')

    def fault(self, bit: int, message: str):
        """Record a fault and command the safe ramp."""
        self.record_fault(bit, message)
        self._on_fault(message)

    def command_ramp(self, code: int, target, text: str):
        """Command the controller's ramp (CMD_ABORT to target [m], default rest_position, clamped into the
        limits; CMD_HOLD: to a stop) at the travel speed the limits allow; `text` says why, for the log.
        """
        lim, io = self.limits, self.io
        target = lim.clamp_position(self.cfg.rest_position if target is None else float(target))
        # the travel speed, in whole mm/s as the frame carries it (velocity_max >= 2 mm/s: >= 1 mm/s)
        ramp_v = max(0.001, math.floor(abort_ramp_velocity(lim) * 1000) / 1000)
        # the command goes before any setpoint still waiting for room (the controller would flush them anyway)
        io.drop_setpoints()
        io.send_command(code, target, ramp_v)
        # until the controller reports its ramp, status says ramping_down (not idle/fault while still moving)
        self.ramp_pending = self.controller_state in ('running', 'holding')
        self.host_stop = True
        if not self.aborting:
            self.event('warn', f'{text}; ramp to {"a stop" if code == CMD_HOLD else f"{target * 1e3:.4f} mm"} '
                               f'from {io.last_applied * 1e3:.4f} mm')
        # an idle controller has nothing to ramp (it ignores the command): waiting for its ramp to end would
        # block every later stream
        self.aborting = self.aborting or self.controller_state in ('running', 'holding', 'ramping_down')

    def clear(self):
        """Faults acknowledged (reset): the sensor history starts anew."""
        if self.faults or self.fault_messages:
            self.event('info', 'reset: cleared ' + ('; '.join(self.fault_messages[-3:]) or 'faults'))
        self.faults, self.fault_messages, self.aborting, self.ramp_pending = 0, [], False, False
        self._sensor.clear()
        # the controller's silence is judged afresh from the reset (a controller still silent faults again)
        self.liveness.rearm(self._clock(), self.io.expected)

    def why_not_ready(self) -> str:
        """'' when a stream can open now, else why not."""
        if self.faults:
            return 'rig fault: ' + '; '.join(self.fault_messages[-3:]) + ' (reset to acknowledge)'
        if self.controller_state == 'unconfigured':
            return 'the controller has not announced itself'
        why = self.why_not_heard() or self.identity_mismatch()
        if why:
            return why
        if self.aborting or self.controller_state == 'ramping_down':
            return 'the rig is ramping to rest'
        if self.controller_state == 'fault' or self.controller_faults:
            return f'controller fault {fault_names(self.controller_faults)} (reset to acknowledge)'
        return ''

    def why_not_heard(self) -> str:
        """'' when heartbeat, status and (require_identity) identity have each been received within their silence
        limits (liveness.silence_limits), else which one was not.
        """
        return self.liveness.why_not_heard(self.controller_now(self._clock()), self.io.expected)

    def why_not_reset(self) -> str:
        """'' when the controller is at rest (faults may be cleared), else why not."""
        if self.controller_state == 'ramping_down':
            return 'the rig is still ramping to rest: reset when it is at rest'
        if self.controller_state == 'running':      # ('holding' is a controller at rest on its last command)
            return ('the rig is moving (running its queued setpoints): stop the program first (excitation/abort '
                    'or rig_driver/abort); reset clears the faults of a rig at rest')
        return ''

    @property
    def state(self) -> str:
        """The rig's state as status reports it: ramping_down from the command on, fault, else the controller's."""
        if self.controller_state == 'ramping_down' or (self.ramp_pending and not self.faults & FAULT_WATCHDOG):
            return 'ramping_down'
        if self.faults or self.controller_faults:
            return 'fault'
        return self.controller_state

    def snapshot(self, extra: dict) -> DriverStatus:
        """The status of the rig as the supervisor and the frame counts see it; extra: the driver's part."""
        c = self.io.counters
        return DriverStatus(self.state, self.faults | self.controller_faults, list(self.fault_messages), self.fs,
                            c['samples_received'], c['frames_lost'], c['frames_late'], c['frames_malformed'],
                            c['frames_unknown'], self.temperature, self.controller_state, self.controller_faults,
                            self.controller_sequence, c['setpoints_sent'], self.limits, extra)

    # ---- controller frames (FrameIO listener)
    def on_frame(self, name: str, sig: dict) -> bool:
        """A decoded controller frame; False if it is not one the host consumes (e.g. a host frame echoed)."""
        handler = self._handlers.get(name)
        if handler is None:
            return False
        self.liveness.heard(name, self._clock(), self.io.expected)
        handler(sig)
        return True

    def _on_status(self, sig):
        code = int(sig['ST_State'])
        self._set_controller_state(STATES[code] if code < len(STATES) else 'fault')
        self.controller_faults = int(sig['ST_Faults'])
        io = self.io
        ref = self.controller_sequence if self.controller_sequence >= 0 else (io.expected or 0)
        self.controller_sequence = unwrap(int(sig['ST_LastSequence']), ref, STATUS_SEQ_MOD)
        if self.controller_state in ('idle', 'fault') and io.expected is not None \
                and self.controller_sequence + 1 > io.expected:
            # the controller stopped ticking after samples whose frames never arrived (feedback goes out before
            # this status: its identifier wins arbitration): they are lost, not merely late
            io.count_lost(self.controller_sequence + 1 - io.expected)
            io.expected = self.controller_sequence + 1

    def _on_heartbeat(self, sig):
        code = int(sig['HB_State'])
        self._set_controller_state(STATES[code] if code < len(STATES) else 'fault')
        self.io.counters['heartbeats_received'] += 1

    def _set_controller_state(self, state):
        old = self.controller_state
        if state == old:
            return
        self.controller_state = state
        self.ramp_pending = False
        at = f'{self.io.last_applied * 1e3:.4f} mm'
        if state == 'ramping_down':
            self.event('warn', f'controller ramping to rest from {at}', headline=not self.host_stop)
        elif old == 'ramping_down' and state in ('idle', 'fault'):
            self.aborting = False
            self.event('info', f'rig at rest at {at} (controller {state})')
        elif state == 'fault':
            self.event('error', f'controller reports a fault: {", ".join(fault_names(self.controller_faults))}')

    def identity_mismatch(self) -> str:
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

    def _on_identity(self, sig):
        ident = {'protocol': int(sig['CI_Protocol']), 'device': int(sig['CI_Device']),
                 'firmware': int(sig['CI_Firmware']), 'host_timeout': float(sig['CI_HostTimeout']),
                 'velocity_max': float(sig['CI_VelocityMax'])}
        if ident != self.controller_identity:
            self.controller_identity = ident
            why = self.identity_mismatch()
            self.event('error' if why else 'info', why or (
                f"controller 0x{ident['device']:04x} firmware {ident['firmware']}, rig protocol version "
                f"{ident['protocol']}, host timeout {ident['host_timeout']:g} s, rated velocity "
                f"{ident['velocity_max']:g} m/s"), headline=bool(why))

    def _on_temperature(self, sig):
        self.temperature = temperature_reading(float(sig['TEMP_Specimen']))     # NaN: the controller has none

    # ---- feedback checks (FrameIO listener)
    def bad_frames(self, n: int):
        """Bad frames (n lost, late or malformed samples): more than bus_error_max within 1 s of samples fault."""
        pos = self.io.expected or 0
        self._bad.append((pos, n))
        while self._bad and self._bad[0][0] < pos - self.fs:
            self._bad.popleft()
        total = sum(c for _, c in self._bad)
        if total > self.cfg.bus_error_max and not self.faults & FAULT_BUS:
            self.fault(FAULT_BUS, f'{total} bad frames (lost/late/malformed) within 1 s of samples '
                                  f'(> {self.cfg.bus_error_max})')

    def samples_lost(self, lost: int):
        """`lost` consecutive samples never arrived: bad frames, and a fault beyond lost_burst_max."""
        self.bad_frames(lost)
        if lost / self.fs > self.cfg.lost_burst_max:
            self.fault(FAULT_BUS, f'{lost} consecutive samples lost ({lost / self.fs * 1e3:.1f} ms > '
                                  f'{self.cfg.lost_burst_max * 1e3:g} ms)')

    def jumped(self, sequence: int):
        """An idle rig started a new stream at `sequence`: no sample passed, so no heartbeat silence either."""
        self.liveness.jumped(sequence)

    def measured(self, xs, fs, us):
        """Samples arrived (lists of displacement [m], force [N], applied command [m]): check them."""
        self.last_feedback = self._clock()
        self.liveness.connected(self.last_feedback, self.io.expected)
        self._check_measurements(xs, fs)
        if self.controller_state in ('running', 'ramping_down') and not self.faults & FAULT_SENSOR:
            add = self._sensor.add
            for u, x, f in zip(us, xs, fs, strict=True):
                why = add(u, x, f)
                if why:
                    self.fault(FAULT_SENSOR, why)
                    break

    def _check_measurements(self, xs, fs):
        """Force and displacement limits on measured samples (lists)."""
        lim = self.limits
        x_lo, x_hi, f_peak = min(xs), max(xs), max(max(fs), -min(fs))
        if not (math.isfinite(x_lo) and math.isfinite(x_hi) and math.isfinite(f_peak)):
            if not self.faults & FAULT_SENSOR:
                self.fault(FAULT_SENSOR, f'non-finite measurement (displacement {xs}, force {fs})')
            return
        if f_peak > lim.force_max and not self.faults & FAULT_FORCE_LIMIT:
            f = max(fs, key=abs)
            self.fault(FAULT_FORCE_LIMIT, f'measured force {f:.6g} N above force_max {lim.force_max:g} N')
        margin = 0.02 * (lim.displacement_max - lim.displacement_min)
        if not (lim.displacement_min - margin <= x_lo and x_hi <= lim.displacement_max + margin) \
                and not self.faults & FAULT_DISPLACEMENT_LIMIT:
            x = x_lo if x_lo < lim.displacement_min - margin else x_hi
            self.fault(FAULT_DISPLACEMENT_LIMIT, f'measured displacement {x:.6g} m outside the limits')

    # ---- watchdog
    @property
    def tick_period(self) -> float:
        """The longest [s] the host may leave between polls when no frame arrives (a silent bus wakes nobody): a
        quarter of the wall-clock watchdog limit, so a poll late by one whole period is still not taken for a
        starved host (starved(): half the limit), and paced at most half the host heartbeat period (the controller
        hears the host at least every heartbeat_period and a half).
        """
        quarter = 0.25 * self.wd_wall
        return min(quarter, 0.5 * self.cfg.heartbeat_period) if self.cfg.paced else quarter

    def starved(self) -> float:
        """Called at the start of every poll: how long [s] this host was not scheduled (0 if it was on time).

        Silence is judged only over time the host was awake, so a starved host never blames the controller for
        its own absence.
        """
        now = self._clock()
        late = now - self._last_poll_wall if now - self._last_poll_wall > 0.5 * self.wd_wall else 0.0
        if late:
            self.last_feedback += late
            self.liveness.shift(late)
        self._last_poll_wall = now
        return late

    def controller_now(self, now: float) -> float:
        """The moment [s] the controller's schedule has reached at `now` [s]: `now` for a real controller (its own
        CPU); for the embedded simulator (``host_lateness``, its LatenessLedger.lag) `now` less how far this host
        has kept its output behind, so its silence is judged on its schedule, never on the host's lateness.
        """
        return now if self.host_lateness is None else now - self.host_lateness(now)

    def watchdog(self, streaming: bool, read_at: float = None):
        """Host heartbeat when due; faults when feedback or the controller's heartbeat falls silent.

        streaming: setpoints are queued that the rig has not yet played. read_at [s]: when the bus was last read
        (default now): silence is judged up to then, as this host may have been descheduled since (the soak saw
        'no feedback for 0.35 s' with the controller on time: frames waiting unread are not silence).
        """
        now = self._clock()
        cfg, io = self.cfg, self.io
        if cfg.paced and now - io.last_host_heartbeat >= cfg.heartbeat_period:
            io.send_host_heartbeat()
        if self.faults & FAULT_WATCHDOG:
            return
        read = now if read_at is None else min(read_at, now)
        sched = self.controller_now(read)       # silence is judged on the controller's schedule
        if streaming and not self.aborting and sched - self.last_feedback > self.wd_wall:
            self.fault(FAULT_WATCHDOG, f'no feedback for {sched - self.last_feedback:.3f} s with setpoints queued'
                       + self._excused(now, read, sched))
            return
        if io.expected is not None and not self.aborting:
            # an idle rig starting a new stream jumps to its first sample: the samples before it are not owed
            expected = max(io.expected, io.jump_to or 0)
            lag = (self.controller_sequence + 1 - expected) / self.fs
            if lag > cfg.watchdog_timeout:
                self.fault(FAULT_WATCHDOG, f'feedback {lag:.3f} s behind the controller (stalled or delayed)')
                return
        # every periodic frame is owed from the controller's first word on, heard or not (liveness): paced by
        # the clock, as fast as possible in samples of feedback (on a busy bus the lowest-priority heartbeat may
        # trail many samples legitimately, so paced the clock judges it)
        quiet = self.liveness.silent(sched, io.expected)
        if quiet is not None:
            name, seconds, ever = quiet
            what = {'ControllerHeartbeat': 'heartbeat', 'ControllerStatus': 'status',
                    'ControllerIdentity': 'identity'}[name]
            unit = 's' if cfg.paced else 's of samples'
            self.fault(FAULT_WATCHDOG, f'controller {what} silent for {seconds:.3f} {unit}'
                       + ('' if ever else f' (no {name} received since the controller was first heard)')
                       + self._excused(now, read, sched))

    def _excused(self, now: float, read: float, sched: float) -> str:
        """What a watchdog fault says of the host lateness it excused: since the bus was read at `read` [s], and how
        far behind this host kept an embedded simulator ('' when neither): a fault under load names it.
        """
        parts = [f'{(now - read) * 1e3:.0f} ms since the bus was read'] if now - read >= 0.001 else []
        if self.host_lateness is not None:
            parts.append(f'embedded simulator {(read - sched) * 1e3:.0f} ms behind')
        return f' (host lateness excused: {", ".join(parts)})' if parts else ''
