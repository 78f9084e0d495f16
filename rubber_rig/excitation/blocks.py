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

"""One program block: its fields (SI), validation with errors naming block and field, and evaluation."""
import math
from dataclasses import dataclass, field

import numpy as np

from rubber_rig.units import to_si

from . import waveforms as wf
from .detectors import DetectorError, parse_detectors


class ProgramError(ValueError):
    """A test program is invalid; the message names the block (index and name) and the field."""


# field -> dimension of its value (None: plain number / text); the allowed fields per waveform follow
_FIELDS = {
    'name': None, 'waveform': None, 'frequency': 'frequency', 'f_start': 'frequency', 'f_end': 'frequency',
    'amplitude': 'length', 'mean': 'length', 'cycles': None, 'taper_cycles': None, 'duration': 'time',
    'rate': 'velocity', 'target': 'length',
}
_ALLOWED = {
    'sine': {'frequency', 'amplitude', 'mean', 'cycles', 'taper_cycles'},
    'triangle': {'frequency', 'rate', 'amplitude', 'mean', 'cycles', 'taper_cycles'},
    'square': {'frequency', 'rate', 'amplitude', 'mean', 'cycles', 'taper_cycles'},
    'sweep_lin': {'f_start', 'f_end', 'duration', 'amplitude', 'mean', 'taper_cycles'},
    'sweep_log': {'f_start', 'f_end', 'duration', 'amplitude', 'mean', 'taper_cycles'},
    'hold': {'duration'},
    'ramp': {'target', 'rate', 'duration'},
}
DEFAULT_TAPER_CYCLES = 1.0
# The longest program (and so the longest block) accepted [s]: 24 h of rig time. Durations, cycle counts and
# frequencies are refused on load when a block would run longer, so everything computed from a program
# (sample counts, setpoint generation, the pre-start limit check) has a bounded cost: a request of
# `cycles: 1e8` or `frequency: 1e-9 Hz` is an error naming the field, not an executor busy for hours.
MAX_PROGRAM_DURATION = 24 * 3600.0
# The lowest frequency of a periodic block [Hz]: one cycle must fit into the longest program.
MIN_FREQUENCY = 1.0 / MAX_PROGRAM_DURATION
# The highest frequency of a periodic block relative to the sample rate it runs at (checked where the rate is
# known: Program.check_sample_rate, called by Limits.check_program and so by every ProgramRunner). A
# servo-hydraulic rig sampled at fs cannot sensibly follow sines above fs/10: at 10 samples per cycle the
# setpoint staircase already misses the peak by up to 5 % (1 - cos(pi/10)), the cycle detector needs at least
# 8 samples per cycle, and closer to fs/2 the command aliases (990 Hz at 1 kHz is a 10 Hz wave).
MAX_FREQUENCY_FRACTION = 0.1


@dataclass
class Block:
    """A validated program block. SI units: m, Hz, s, m/s.

    For periodic blocks (sine, triangle, square) `cycles` counts full-amplitude cycles; the taper in and out
    add `taper_cycles` each. For sweeps, `frequency` is the start and `frequency_end` the end frequency and
    `duration` the sweep time at full amplitude. `start_level` is where the block starts (previous block's end).
    """

    index: int
    name: str
    waveform: str
    frequency: float = 0.0
    amplitude: float = 0.0
    mean: float = 0.0
    cycles: int = 0
    taper_cycles: float = 0.0
    frequency_end: float = 0.0
    duration: float = 0.0
    rate: float = 0.0
    target: float = 0.0
    start_level: float = 0.0
    square_slope: float = field(default=1.0, repr=False)
    detectors: list = field(default_factory=list, repr=False)   # DetectorSpecs of this block only

    # ---- classification
    @property
    def oscillating(self) -> bool:
        """True for blocks with an amplitude and cycles about a mean: the periodic waveforms (``waveforms.PERIODIC``:
        sine, triangle, square) and the sweeps (``waveforms.SWEEPS``, whose frequency changes, so not periodic).
        """
        return self.waveform in wf.PERIODIC + wf.SWEEPS

    def to_dict(self) -> dict:
        """The block as program YAML fields in SI (the inverse of :func:`parse_block`: parsing the result at the
        same start level gives an equal block), for programs rewritten by tools such as ``rubber-rig bench``.
        """
        d = {'name': self.name, 'waveform': self.waveform}
        if self.detectors:
            d['detectors'] = [x.to_dict() for x in self.detectors]
        if self.oscillating:
            d.update(amplitude=self.amplitude, mean=self.mean, taper_cycles=self.taper_cycles)
        if self.waveform in wf.PERIODIC:
            d['cycles'] = int(self.cycles)
            if self.waveform == 'triangle' and self.rate > 0:     # given by its rate: the frequency follows
                d['rate'] = self.rate
            else:
                d['frequency'] = self.frequency
            if self.waveform == 'square':
                d['rate'] = self.rate
        elif self.waveform in wf.SWEEPS:
            d.update(f_start=self.frequency, f_end=self.frequency_end, duration=self.duration)
        elif self.waveform == 'hold':
            d['duration'] = self.duration
        elif self.waveform == 'ramp':
            d['target'] = self.target
            d.update({'rate': self.rate} if self.rate > 0 else {'duration': self.duration})
        return d

    @property
    def end_level(self) -> float:
        """Displacement [m] the block ends at."""
        if self.waveform == 'ramp':
            return self.target
        if self.waveform == 'hold':
            return self.start_level
        return self.mean

    @property
    def total_cycles(self) -> float:
        """Phase [cycles] at the end of a periodic block, taper included."""
        if self.waveform in wf.SWEEPS:
            return wf.sweep_phase(np.array(0.0), self.frequency, self.frequency_end, self.taper_cycles,
                                  self.duration, self.waveform == 'sweep_log')[1]
        return self.cycles + 2 * self.taper_cycles

    def seconds(self) -> float:
        """Duration of the block [s]."""
        if self.waveform in wf.PERIODIC:
            return self.total_cycles / self.frequency
        if self.waveform in wf.SWEEPS:
            return self.taper_cycles / self.frequency + self.duration + self.taper_cycles / self.frequency_end
        return self.duration

    def n_samples(self, sample_rate: float) -> int:
        """Number of samples the block takes at sample_rate [Hz] (ramps include their end point)."""
        n = int(math.ceil(self.seconds() * sample_rate - 1e-9))
        return max(1, n + 1 if self.waveform == 'ramp' else n)

    # ---- evaluation
    def phase(self, t):
        """Phase [cycles] at local times t [s] (periodic blocks)."""
        if self.waveform in wf.SWEEPS:
            return wf.sweep_phase(t, self.frequency, self.frequency_end, self.taper_cycles, self.duration,
                                  self.waveform == 'sweep_log')[0]
        return self.frequency * t

    def frequency_at(self, t):
        """Instantaneous frequency [Hz] at local times t [s] (0 for hold and ramp)."""
        if self.waveform in wf.SWEEPS:
            return wf.sweep_frequency(t, self.frequency, self.frequency_end, self.taper_cycles, self.duration,
                                      self.waveform == 'sweep_log')
        return np.full_like(np.asarray(t, dtype=float), self.frequency if self.oscillating else 0.0)

    def unit(self, phase):
        """Tapered unit waveform (-1..1) at phase [cycles]: envelope x shape."""
        return (wf.envelope(phase, self.total_cycles, self.taper_cycles)
                * wf.shape(self.waveform, phase, self.square_slope))

    def evaluate_phase(self, phase, gain=1.0, offset=0.0):
        """Setpoint [m] of a periodic block at phase [cycles] (= phase(t)), with gain and offset as evaluate()."""
        return self.mean + offset + gain * self.amplitude * self.unit(phase)

    def evaluate(self, t, gain=1.0, offset=0.0, start_level=None):
        """Setpoint [m] at local times t [s] (array).

        gain scales the amplitude and offset shifts the mean (amplitude control); start_level overrides
        where a ramp starts (resume after hold).
        """
        t = np.asarray(t, dtype=float)
        if self.oscillating:
            return self.evaluate_phase(self.phase(t), gain, offset)
        start = self.start_level if start_level is None else start_level
        if self.waveform == 'hold':
            return np.full_like(t, start)
        return start + (self.target - start) * wf.smoothstep(t / self.duration if self.duration > 0 else 1.0)


def _err(index, name, fld, msg):
    label = f"block {index}" + (f" '{name}'" if name else '')
    return ProgramError(f"{label}: field '{fld}': {msg}" if fld else f'{label}: {msg}')


def parse_block(raw, index: int, start_level: float, defaults: dict) -> Block:
    """Validate one block mapping (after grid expansion) and return a Block starting at start_level [m]."""
    if not isinstance(raw, dict):
        raise _err(index, '', None, f'expected a mapping of fields, got {type(raw).__name__}')
    data = {**defaults, **raw}
    name = data.get('name')
    wave = data.get('waveform')
    if wave is None:
        raise _err(index, name, 'waveform', f"missing (one of: {', '.join(wf.WAVEFORMS)})")
    wave = wf.ALIASES.get(wave, wave)
    if wave not in wf.WAVEFORMS:
        raise _err(index, name, 'waveform', f"unknown waveform {data['waveform']!r} "
                                            f"(one of: {', '.join(wf.WAVEFORMS)})")
    name = str(name) if name is not None else f'{wave}_{index}'
    for key in raw:
        if key == 'detectors':
            continue
        if key not in _FIELDS:
            raise _err(index, name, key, f"unknown field (known: {', '.join(sorted(_FIELDS))})")
        if key not in ('name', 'waveform') and key not in _ALLOWED[wave]:
            raise _err(index, name, key, f"not used by waveform '{wave}' "
                                         f"(allowed: {', '.join(sorted(_ALLOWED[wave]))})")
    values = {}
    for key in _ALLOWED[wave]:
        if key not in data or data[key] is None:
            continue
        dim = _FIELDS[key]
        try:
            if key == 'cycles':
                values[key] = _whole_cycles(data[key])
            elif key == 'taper_cycles':
                values[key] = to_si(data[key], 'number')
            else:
                values[key] = to_si(data[key], dim)
        except ValueError as exc:
            raise _err(index, name, key, str(exc)) from None

    def need(key, positive=True):
        if key not in values:
            raise _err(index, name, key, f"required for waveform '{wave}'")
        if positive and values[key] <= 0:
            raise _err(index, name, key, f'must be > 0, got {data[key]!r}')
        return values[key]

    blk = Block(index=index, name=name, waveform=wave, start_level=start_level)
    try:
        blk.detectors = parse_detectors(raw.get('detectors'), f"block {index} '{name}'", index)
    except DetectorError as exc:
        raise ProgramError(str(exc)) from None
    if blk.oscillating:
        blk.amplitude = need('amplitude')
        blk.mean = values.get('mean', start_level)
        if abs(blk.mean - start_level) > 1e-12:
            raise _err(index, name, 'mean', f'{blk.mean:g} m differs from the level the previous block ends at '
                                            f'({start_level:g} m): insert a ramp block so nothing steps')
        blk.taper_cycles = values.get('taper_cycles', DEFAULT_TAPER_CYCLES)
        if blk.taper_cycles <= 0:
            raise _err(index, name, 'taper_cycles', 'must be > 0 so the block starts and ends without a '
                                                    'velocity jump')
    if wave in wf.PERIODIC:
        blk.cycles = int(need('cycles'))
        if wave == 'triangle' and 'rate' in values:
            if 'frequency' in values:
                raise _err(index, name, 'rate', "give either 'frequency' or 'rate' for a triangle, not both")
            blk.rate = need('rate')
            blk.frequency = blk.rate / (4.0 * blk.amplitude)
        else:
            blk.frequency = need('frequency')
        if wave == 'square':
            blk.rate = need('rate')
            slope = blk.rate / (4.0 * blk.amplitude * blk.frequency)
            if slope < 1.0:
                raise _err(index, name, 'rate', f'{blk.rate:g} m/s is too slow for a square wave at '
                                                f'{blk.frequency:g} Hz and {blk.amplitude:g} m (needs >= '
                                                f'{4 * blk.amplitude * blk.frequency:g} m/s; use a triangle)')
            blk.square_slope = slope
    elif wave in wf.SWEEPS:
        blk.frequency = need('f_start')
        blk.frequency_end = need('f_end')
        blk.duration = need('duration')
    elif wave == 'hold':
        blk.duration = need('duration')
    elif wave == 'ramp':
        blk.target = need('target', positive=False)
        if ('rate' in values) == ('duration' in values):
            raise _err(index, name, 'rate', "give exactly one of 'rate' (peak velocity) or 'duration'")
        if 'rate' in values:
            # raised-cosine ramp: peak velocity = pi/2 * distance / duration
            blk.rate = need('rate')
            blk.duration = max(math.pi / 2 * abs(blk.target - start_level) / blk.rate, 0.0)
        else:
            blk.duration = need('duration')
    _check_duration(blk, values)
    return blk


def _whole_cycles(v) -> int:
    """A cycle count: a whole, finite number >= 1 (YAML .inf, 2.5 or '8' are refused before any int())."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f'expected a whole number of cycles, got {v!r}')
    if isinstance(v, float) and not math.isfinite(v):
        raise ValueError(f'must be a finite whole number of cycles, got {v!r}')
    if abs(v) > 1e15:      # far beyond any program that fits MAX_PROGRAM_DURATION; keeps int/float exact
        raise ValueError(f'{str(v)[:12]}{"..." if len(str(v)) > 12 else ""} cycles are far more than fit '
                         f'into the longest program ({MAX_PROGRAM_DURATION / 3600:g} h)')
    if v != int(v):
        raise ValueError(f'expected a whole number of cycles, got {v!r}')
    return int(v)


def _check_duration(blk: Block, values: dict) -> None:
    """Refuse a block that cannot run within MAX_PROGRAM_DURATION, naming the field that makes it too long."""
    hours = f'{MAX_PROGRAM_DURATION / 3600:g} h'
    if blk.waveform in wf.SWEEPS:
        frequencies = [('f_start', blk.frequency), ('f_end', blk.frequency_end)]
    elif blk.oscillating:
        frequencies = [('rate' if blk.waveform == 'triangle' and 'rate' in values else 'frequency', blk.frequency)]
    else:
        frequencies = []
    for key, f in frequencies:
        if f < MIN_FREQUENCY:
            raise _err(blk.index, blk.name, key, f'{f:.6g} Hz is below the lowest frequency {MIN_FREQUENCY:.6g} Hz: '
                                                 f'one cycle would take longer than the longest program ({hours})')
    seconds = blk.seconds()
    if math.isfinite(seconds) and seconds <= MAX_PROGRAM_DURATION:
        return
    if blk.waveform in wf.PERIODIC:        # the larger part of the block is to blame
        key = 'cycles' if blk.cycles >= 2 * blk.taper_cycles else 'taper_cycles'
    elif blk.waveform in wf.SWEEPS:
        tapers = blk.taper_cycles / blk.frequency + blk.taper_cycles / blk.frequency_end
        key = 'duration' if blk.duration >= tapers else 'taper_cycles'
    else:
        key = 'rate' if 'rate' in values else 'duration'
    raise _err(blk.index, blk.name, key, f'the block would run {seconds:.6g} s, longer than the longest program '
                                         f'({MAX_PROGRAM_DURATION:g} s = {hours})')
