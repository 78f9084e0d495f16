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


"""The waveform registry: one :class:`WaveformType` per waveform a program block may use.

Each entry says everything the rest of the package asks of a waveform, so adding one is one entry here (plus
its shape in waveforms.py and its tests): the fields a block may give (parse_block refuses others), how they
become a Block (``parse``) and back (``to_fields``), the unit shape it generates, bounds of that shape for
the pre-start limit check (limits.py), how a measured cycle's amplitude is read (amplitude control, the
online summary, the cycle detectors) and which summary rows it gets.

Families: 'periodic' blocks run whole ``cycles`` of period 1/frequency between a taper in and out (they
resume after a hold, learn amplitude compensation, count towards the program's cycles); a 'sweep' changes
its frequency over ``duration``; 'hold' and 'ramp' move (or not) between levels. Units: m, s, Hz.
"""
import math
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from . import waveforms as wf

OSCILLATING_FIELDS = frozenset({'amplitude', 'mean', 'taper_cycles'})
# highest line of a multisine as a multiple of its base frequency: bounds the peak search (64 x this grid)
MAX_MULTISINE_HARMONIC = 4096


@dataclass(frozen=True)
class WaveformType:
    """One waveform: its fields, generation, limit-check bounds, amplitude measurement and summary.

    parse(block, values, need, err): set the block's own fields from the SI `values` (need(key, positive=True)
    returns a required value, err(field, message) makes the ProgramError); the amplitude, mean and taper of
    oscillating blocks are parsed before, for every waveform alike. shape(block, phase): unit shape at phase
    [cycles]. slope(block): sup |d shape / d phase| [1/cycle]. span: (low, high) bounds of the unit shape.
    step(block, fs): bound of |x[i+1] - x[i]| fs / amplitude over the full-amplitude part sampled at fs [1/s].
    sine_like: the taper bound is the sine's and a gentle block (acceleration below deceleration_max) needs
    no braking margin. dc: mean of the unit shape (a haversine's is 0.5). measure: how a cycle's amplitude
    is read, in the program's sense - 'harmonic' (first harmonic), 'half_range' (half peak-to-valley) or
    'full_range' (peak-to-valley: one-sided pulses). controlled: amplitude control and compensation memory
    apply. judged: cycle detectors judge its measured cycles. summary: 'steady' (one row at its frequency),
    'bands' (a row per frequency band) or None. top_harmonic(block): highest harmonic of the base frequency
    the shape contains (for the element force model). frequency_fields(block): (field, frequency [Hz]) it runs
    at, for the lowest-frequency and sample-rate rules. log_sweep: a sweep's frequency rises exponentially.
    taper_slope(block, env, d_env): bound of |d/dphase (env shape)| given the taper envelope and its slope
    (arrays; default: sine_like -> hypot(d_env, slope env), else max|span| d_env + slope env). cost(block):
    generating one of its samples, in samples of a sine (the pre-start check's exact budget counts it).
    """

    name: str
    family: str
    fields: frozenset
    parse: Callable
    to_fields: Callable
    shape: Optional[Callable] = None
    slope: Optional[Callable] = None
    span: Callable = lambda block: (-1.0, 1.0)
    step: Optional[Callable] = None
    sine_like: bool = False
    dc: float = 0.0
    measure: str = 'harmonic'
    controlled: bool = True
    judged: bool = True
    summary: Optional[str] = None
    top_harmonic: Callable = lambda block: 1
    log_sweep: bool = False
    taper_slope: Optional[Callable] = None
    cost: Callable = lambda block: 1.0
    frequency_fields: Callable = lambda block: [('frequency', block.frequency)]
    aliases: tuple = ()

    @property
    def oscillating(self) -> bool:
        """An amplitude and cycles about a mean (periodic blocks and sweeps)."""
        return self.family in ('periodic', 'sweep')

    @property
    def periodic(self) -> bool:
        """Whole cycles at one base frequency, between tapers."""
        return self.family == 'periodic'

    def cycle_rate(self, block) -> float:
        """Highest rate [Hz] its phase advances at (the shape's slope is per cycle of it)."""
        return max(block.frequency, block.frequency_end) if self.family == 'sweep' else block.frequency

    def velocity_per_metre(self, block) -> float:
        """Bound of |dx/dt| per metre of amplitude [1/s] of the full-amplitude part."""
        return self.cycle_rate(block) * self.slope(block)

    def fit_cycle(self, phase, x):
        """(amplitude, mean) [m] of one measured cycle x [m] at commanded phases [cycles], in the program's sense.

        'harmonic': least-squares fit of mean + a sin + b cos at the commanded phases (exact for any samples per
        cycle, robust to noise); 'half_range': half the peak-to-valley and its midpoint; 'full_range': the
        peak-to-valley and the valley (the base a one-sided pulse rises from).
        """
        if self.measure == 'half_range':
            return 0.5 * float(x.max() - x.min()), 0.5 * float(x.max() + x.min())
        if self.measure == 'full_range':
            return float(x.max() - x.min()), float(x.min())
        w = 2 * math.pi * phase
        basis = np.column_stack([np.ones_like(w), np.sin(w), np.cos(w)])
        coef = np.linalg.lstsq(basis, x, rcond=None)[0]
        return float(math.hypot(coef[1], coef[2])), float(coef[0])

    def cycle_amplitude(self, amplitude: float, peak_amplitude: float) -> float:
        """A measured cycle's amplitude [m] in the program's sense, from the cycle metrics' first-harmonic
        `amplitude` and `peak_amplitude` (half the peak-to-peak).
        """
        return {'harmonic': amplitude, 'half_range': peak_amplitude, 'full_range': 2.0 * peak_amplitude}[self.measure]

    def frequencies(self, block) -> list:
        """(field, frequency [Hz]) a block runs at, named as the program gives them (none for hold and ramp)."""
        return self.frequency_fields(block)


# ---- per-waveform parsing and fields
def _parse_periodic(blk, values, need, err):
    blk.cycles = int(need('cycles'))
    blk.frequency = need('frequency')


def _parse_triangle(blk, values, need, err):
    blk.cycles = int(need('cycles'))
    if 'rate' in values:
        if 'frequency' in values:
            raise err('rate', "give either 'frequency' or 'rate' for a triangle, not both")
        blk.rate = need('rate')
        blk.frequency = blk.rate / (4.0 * blk.amplitude)
    else:
        blk.frequency = need('frequency')


def _parse_square(blk, values, need, err):
    _parse_periodic(blk, values, need, err)
    blk.rate = need('rate')
    slope = blk.rate / (4.0 * blk.amplitude * blk.frequency)
    if slope < 1.0:
        raise err('rate', f'{blk.rate:g} m/s is too slow for a square wave at {blk.frequency:g} Hz and '
                          f'{blk.amplitude:g} m (needs >= {4 * blk.amplitude * blk.frequency:g} m/s; use a triangle)')
    blk.square_slope = slope


def _parse_sweep(blk, values, need, err):
    blk.frequency = need('f_start')
    blk.frequency_end = need('f_end')
    blk.duration = need('duration')


def _parse_hold(blk, values, need, err):
    blk.duration = need('duration')


def _parse_ramp(blk, values, need, err):
    blk.target = need('target', positive=False)
    if ('rate' in values) == ('duration' in values):
        raise err('rate', "give exactly one of 'rate' (peak velocity) or 'duration'")
    if 'rate' in values:
        # raised-cosine ramp: peak velocity = pi/2 * distance / duration
        blk.rate = need('rate')
        blk.duration = max(math.pi / 2 * abs(blk.target - blk.start_level) / blk.rate, 0.0)
    else:
        blk.duration = need('duration')


def _parse_multisine(blk, values, need, err):
    _parse_periodic(blk, values, need, err)
    blk.frequency_start, blk.frequency_end = need('f_start'), need('f_end')
    blk.seed = int(values.get('seed', 0))
    first, last = multisine_harmonics(blk)
    if last > MAX_MULTISINE_HARMONIC:
        raise err('f_end', f'{blk.frequency_end:g} Hz is {last} times the line spacing {blk.frequency:g} Hz, more '
                           f'than the {MAX_MULTISINE_HARMONIC} accepted')
    if last - first < 1:
        raise err('f_end', f'the band {blk.frequency_start:g}-{blk.frequency_end:g} Hz holds {max(last - first + 1, 0)}'
                           f' line(s) at multiples of {blk.frequency:g} Hz; a multisine needs at least 2')


def multisine_harmonics(blk):
    """(first, last) harmonic of a multisine's base frequency inside its band f_start..f_end."""
    return (int(math.ceil(blk.frequency_start / blk.frequency - 1e-9)),
            int(math.floor(blk.frequency_end / blk.frequency + 1e-9)))


def _multisine_bounds(blk):
    return wf.multisine_lines(*multisine_harmonics(blk), blk.seed)[3]


def _cycles_and_frequency(blk):
    return {'cycles': int(blk.cycles), 'frequency': blk.frequency}


def _triangle_fields(blk):
    # given by its rate: the frequency follows
    return {'cycles': int(blk.cycles), **({'rate': blk.rate} if blk.rate > 0 else {'frequency': blk.frequency})}


def _ramp_fields(blk):
    return {'target': blk.target, **({'rate': blk.rate} if blk.rate > 0 else {'duration': blk.duration})}


def _sine_step(blk, fs):
    # sampled sine: |sin(p + d) - sin p| <= 2 sin(d / 2), d = 2 pi f / fs, f / fs <= 0.1 (check_sample_rate)
    return 2.0 * fs * math.sin(math.pi * min(TYPES[blk.waveform].cycle_rate(blk) / fs, 0.5))


def _sweep(name, log):
    return WaveformType(
        name, 'sweep', frozenset({'f_start', 'f_end', 'duration'}) | OSCILLATING_FIELDS, _parse_sweep,
        lambda b: {'f_start': b.frequency, 'f_end': b.frequency_end, 'duration': b.duration},
        shape=lambda b, p: wf.sine(p), slope=lambda b: 2 * math.pi, step=_sine_step, sine_like=True,
        summary='bands', aliases=('sweep', 'sine_sweep') if not log else (), log_sweep=log,
        frequency_fields=lambda b: [('f_start', b.frequency), ('f_end', b.frequency_end)])


_PERIODIC_FIELDS = frozenset({'frequency', 'cycles'}) | OSCILLATING_FIELDS
_ENTRIES = (
    WaveformType('sine', 'periodic', _PERIODIC_FIELDS, _parse_periodic, _cycles_and_frequency,
                 shape=lambda b, p: wf.sine(p), slope=lambda b: 2 * math.pi, step=_sine_step, sine_like=True,
                 summary='steady'),
    WaveformType('triangle', 'periodic', _PERIODIC_FIELDS | {'rate'}, _parse_triangle, _triangle_fields,
                 shape=lambda b, p: wf.triangle(p), slope=lambda b: 4.0, step=lambda b, fs: 4.0 * b.frequency,
                 measure='half_range', summary='steady',
                 frequency_fields=lambda b: [('rate' if b.rate > 0 else 'frequency', b.frequency)]),
    WaveformType('square', 'periodic', _PERIODIC_FIELDS | {'rate'}, _parse_square,
                 lambda b: {**_cycles_and_frequency(b), 'rate': b.rate},
                 shape=lambda b, p: wf.square(p, b.square_slope), slope=lambda b: 4.0 * b.square_slope,
                 step=lambda b, fs: min(4.0 * b.frequency * b.square_slope, 2.0 * fs), measure='half_range',
                 summary='steady', aliases=('trapezoid',)),
    _sweep('sweep_lin', False),
    _sweep('sweep_log', True),
    WaveformType('hold', 'hold', frozenset({'duration'}), _parse_hold, lambda b: {'duration': b.duration},
                 aliases=('dwell',), frequency_fields=lambda b: []),
    WaveformType('ramp', 'ramp', frozenset({'target', 'rate', 'duration'}), _parse_ramp, _ramp_fields,
                 frequency_fields=lambda b: []),
    # x = mean + amplitude (1 - cos(2 pi f t)) / 2: one-sided pulses from the mean up to mean + amplitude
    WaveformType('haversine', 'periodic', _PERIODIC_FIELDS, _parse_periodic, _cycles_and_frequency,
                 shape=lambda b, p: wf.haversine(p), slope=lambda b: math.pi, span=lambda b: (0.0, 1.0),
                 step=lambda b, fs: 0.5 * _sine_step(b, fs), dc=0.5, measure='full_range', summary='steady',
                 # env (1 - cos th) / 2 has slope env' / 2 - env' cos(th) / 2 + pi env sin(th) (Cauchy-Schwarz)
                 taper_slope=lambda b, env, d_env: 0.5 * d_env + np.hypot(0.5 * d_env, math.pi * env)),
    # x = mean + amplitude u(f t), u an equal-line random-phase multisine scaled to peak 1 (waveforms.py)
    WaveformType('multisine', 'periodic', _PERIODIC_FIELDS | {'f_start', 'f_end', 'seed'}, _parse_multisine,
                 lambda b: {**_cycles_and_frequency(b), 'f_start': b.frequency_start, 'f_end': b.frequency_end,
                            'seed': int(b.seed)},
                 shape=lambda b, p: wf.multisine(p, *multisine_harmonics(b), b.seed),
                 slope=lambda b: _multisine_bounds(b)[1],
                 span=lambda b: (-_multisine_bounds(b)[0], _multisine_bounds(b)[0]),
                 step=lambda b, fs: b.frequency * _multisine_bounds(b)[1], measure='half_range',
                 controlled=False, judged=False, top_harmonic=lambda b: multisine_harmonics(b)[1],
                 cost=lambda b: 1.0 + (multisine_harmonics(b)[1] - multisine_harmonics(b)[0] + 1) / 32,
                 frequency_fields=lambda b: [('frequency', b.frequency), ('f_end', b.frequency_end)]),
)
TYPES = {t.name: t for t in _ENTRIES}
WAVEFORMS = tuple(TYPES)
ALIASES = {a: t.name for t in _ENTRIES for a in t.aliases}
