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

"""Safety limits on displacement, velocity and force, checked before a program starts and on every setpoint.

The pre-start check (Limits.check_program) has a bounded cost for every program that loads (at most 24 h, see
blocks.MAX_PROGRAM_DURATION): it generates and checks the setpoints exactly, block by block, as long as the
program has generated at most EXACT_SAMPLES of them; a block beyond that budget is checked from closed-form
bounds instead (its taper in and out still sample by sample while the budget lasts). Those bounds are the
supremum of what the samples can reach - the sampled sine's peak velocity 2 A fs sin(pi f / fs) rather than
2 pi f A - so a long block is refused only where some of its samples would come arbitrarily close to the
limit. A 24 h program checks in milliseconds (benchmarks/bench_checks.py).

The peak force: with `stiffness_estimate` [N/m] the check predicts k |x|; with a `force_model` (a callable
block -> predicted peak |force| [N], e.g. element_force_model() from the element model's parameters) it
predicts each block's force, so a program whose force limit is exceeded only at its highest frequency is
refused before anything moves.
"""
import math
from dataclasses import dataclass, field, fields
from typing import Callable, Optional

import numpy as np

from rubber_rig.models import ZenerBergParams, load_parameter_set
from rubber_rig.models.fractional import zener_complex_stiffness
from rubber_rig.models.friction import berg_peak_force

from ..settings import setting
from . import waveforms as wf
from .ramp import stopping_positions

# setpoints the pre-start check generates at most per program (about 0.1 s of numpy); the rest is bounded
EXACT_SAMPLES = 1 << 21
_CHUNK = 1 << 18


class LimitError(ValueError):
    """A program or setpoint would leave the safe envelope; the message names the limit and where. `field`: the
    Limits field a bad configuration value concerns ('' for a program or setpoint outside the envelope).
    """

    def __init__(self, message: str, field: str = ''):
        super().__init__(message)
        self.field = field


@dataclass
class Limits:
    """Safe envelope, SI: displacement_min/max [m], velocity_max [m/s], force_max [N] (absolute),
    deceleration_max [m/s^2]: the hardest braking an abort ramp may use, so every setpoint must be able to stop
    inside the displacement range at it (ramp.stopping_positions) - then an abort at any phase stays inside.

    stiffness_estimate [N/m], if given, lets the pre-start check predict the peak force k * |x|; force_model, if
    given, is a callable block -> predicted peak |force| [N] that the pre-start check asks for every block
    (see element_force_model); check_program(force_model=...) overrides it for one check.
    """

    displacement_min: float = setting(-5e-3, 'lowest allowed displacement', units='m', range=(-1.0, 1.0))
    displacement_max: float = setting(5e-3, 'highest allowed displacement', units='m', range=(-1.0, 1.0))
    velocity_max: float = setting(0.2, 'highest allowed velocity', units='m/s', range=(1e-6, 100.0))
    force_max: float = setting(60e3, 'highest allowed absolute force', units='N', range=(1.0, 1e7))
    deceleration_max: float = setting(100.0, 'hardest braking of a ramp; every setpoint must be able to stop inside '
                                      'the displacement limits at it', units='m/s^2', range=(0.1, 500.0))
    stiffness_estimate: Optional[float] = None
    force_model: Optional[Callable] = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        for name in ('displacement_min', 'displacement_max', 'velocity_max', 'force_max', 'deceleration_max'):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise LimitError(f"limits: field '{name}': expected a finite number, got {v!r}", name)
        if self.displacement_min >= self.displacement_max:
            raise LimitError(f"limits: field 'displacement_min': {self.displacement_min:g} m must be below "
                             f"displacement_max {self.displacement_max:g} m", 'displacement_min')
        for name in ('velocity_max', 'force_max', 'deceleration_max'):
            if getattr(self, name) <= 0:
                raise LimitError(f"limits: field '{name}': must be > 0", name)
        k = self.stiffness_estimate
        if k is not None and (isinstance(k, bool) or not isinstance(k, (int, float)) or not math.isfinite(k)
                              or k < 0):
            raise LimitError(f"limits: field 'stiffness_estimate': expected a finite stiffness >= 0 [N/m], "
                             f"got {k!r}", 'stiffness_estimate')
        if self.force_model is not None and not callable(self.force_model):
            raise LimitError(f"limits: field 'force_model': expected a callable block -> peak force [N], got "
                             f"{type(self.force_model).__name__}")

    @classmethod
    def from_dict(cls, data) -> 'Limits':
        """Build from a mapping; unknown keys are an error naming the key."""
        if data is None:
            return cls()
        if isinstance(data, Limits):
            return data
        if not isinstance(data, dict):
            raise LimitError(f'limits: expected a mapping, got {type(data).__name__}')
        known = set(cls.__dataclass_fields__)
        for key in data:
            if key not in known:
                raise LimitError(f"limits: field '{key}': unknown (known: {', '.join(sorted(known))})", key)
        return cls(**data)

    def to_dict(self) -> dict:
        """The numeric fields (not the force model)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != 'force_model'}

    def clamp_position(self, x: float) -> float:
        """X [m] moved inside the displacement range."""
        return min(max(x, self.displacement_min), self.displacement_max)

    def check_setpoints(self, x, sample_rate: float, previous: Optional[float] = None, where: str = 'setpoint'):
        """Raise LimitError if setpoints x [m] (shape (n,)) leave the displacement range or their velocity
        (finite difference at sample_rate [Hz], starting from `previous` if given) exceeds velocity_max.
        """
        x = np.asarray(x, dtype=float)
        if x.size == 0:
            return
        if not np.all(np.isfinite(x)):
            raise LimitError(f'{where}: not finite')
        lo, hi = float(x.min()), float(x.max())
        self._check_range(lo, hi, where)
        seq = x if previous is None else np.concatenate([[previous], x])
        if seq.size > 1:
            v = np.diff(seq) * sample_rate
            self._check_velocity(float(np.max(np.abs(v))), where)
            stop = stopping_positions(seq[1:], v, self.deceleration_max, sample_rate)
            k = int(np.argmax(np.maximum(self.displacement_min - stop, stop - self.displacement_max)))
            if stop[k] < self.displacement_min - 1e-9 or stop[k] > self.displacement_max + 1e-9:
                raise LimitError(f'{where}: at {seq[k + 1] * 1e3:.4f} mm and {v[k]:.4g} m/s an abort braking at '
                                 f'deceleration_max {self.deceleration_max:g} m/s^2 would stop at '
                                 f'{stop[k] * 1e3:.4f} mm, outside the limits {self.displacement_min * 1e3:g}..'
                                 f'{self.displacement_max * 1e3:g} mm')

    def _check_range(self, lo: float, hi: float, where: str):
        if lo < self.displacement_min - 1e-12 or hi > self.displacement_max + 1e-12:
            raise LimitError(f'{where}: displacement {lo:.6g}..{hi:.6g} m outside the limits '
                             f'{self.displacement_min:g}..{self.displacement_max:g} m')

    def _check_velocity(self, v: float, where: str):
        if not v <= self.velocity_max * (1 + 1e-9):
            raise LimitError(f'{where}: velocity {v:.6g} m/s above velocity_max {self.velocity_max:g} m/s')

    def _check_stiffness_force(self, peak_x: float, where: str):
        if self.stiffness_estimate:
            f = self.stiffness_estimate * peak_x
            if f > self.force_max:
                raise LimitError(f'{where}: predicted force {f:.6g} N (stiffness_estimate x |x|) above '
                                 f'force_max {self.force_max:g} N')

    def check_program(self, program, sample_rate: float, force_model: Optional[Callable] = None):
        """Check `program` (open loop) at sample_rate [Hz] before it starts, block by block, so the error names
        the block: the sample-rate rule (ProgramError, see Program.check_sample_rate), displacement, velocity,
        and the peak force predicted by stiffness_estimate and by `force_model` (default: self.force_model), a
        callable block -> predicted peak |force| [N]. Bounded cost (module docstring).
        """
        program.check_sample_rate(sample_rate)
        fs = float(sample_rate)
        model = force_model if force_model is not None else self.force_model
        starts = program.block_starts(fs)
        prev = program.initial_position
        if not self.displacement_min <= prev <= self.displacement_max:
            raise LimitError(f'program {program.name!r}: initial_position {prev:g} m outside the limits')
        if not self.displacement_min <= program.rest_position <= self.displacement_max:
            raise LimitError(f'program {program.name!r}: rest_position {program.rest_position:g} m outside '
                             f'the limits')
        budget = EXACT_SAMPLES
        for i, blk in enumerate(program.blocks):
            where = f"program {program.name!r} block {i} '{blk.name}'"
            n = int(starts[i + 1] - starts[i])
            if n <= budget:
                budget -= n
                for lo in range(0, n, _CHUNK):
                    x = blk.evaluate(np.arange(lo, min(lo + _CHUNK, n)) / fs)
                    self.check_setpoints(x, fs, prev, where)
                    self._check_stiffness_force(float(np.max(np.abs(x))), where)
                    prev = float(x[-1])
            else:
                prev, budget = self._check_block_bounds(blk, fs, n, prev, budget, where)
            if model is not None:
                self._check_model_force(model, blk, where)

    def _check_model_force(self, model, blk, where: str):
        try:
            f = model(blk)
        except (ValueError, ArithmeticError) as exc:
            raise LimitError(f'{where}: the force model cannot predict the force: {exc}') from None
        if f is None:
            return
        f = float(f)
        if not math.isfinite(f):
            raise LimitError(f'{where}: the force model predicts a non-finite force ({f})')
        if f > self.force_max:
            what = (f'{_max_frequency(blk):g} Hz, {blk.amplitude * 1e3:g} mm amplitude, {blk.mean * 1e3:g} mm mean'
                    if blk.oscillating else f'{blk.waveform} to {blk.end_level * 1e3:g} mm')
            raise LimitError(f'{where}: predicted peak force {f:.6g} N (element model, {what}) above force_max '
                             f'{self.force_max:g} N')

    def _check_block_bounds(self, blk, fs: float, n: int, prev: float, budget: int, where: str):
        """Check a block of n samples (more than the exact budget) from closed-form bounds on its samples.

        Returns (its last setpoint, the budget left). The taper in and out (and the step from `prev` into the
        block) are generated exactly if they fit the budget; the rest is bounded by the supremum of its samples.
        """
        first = blk.start_level if not blk.oscillating else blk.mean          # every block starts at its level
        self.check_setpoints([first], fs, prev, where)                    # the step into the block
        last = None
        if blk.oscillating:
            a, f_top = blk.amplitude, _max_frequency(blk)
            lo, hi = blk.mean - a, blk.mean + a
            h = f_top / fs                                                 # <= 0.1 (check_sample_rate)
            if blk.waveform == 'triangle':
                steady = 4.0 * blk.frequency * a                           # constant edge slope
            elif blk.waveform == 'square':
                steady = min(4.0 * blk.frequency * a * blk.square_slope, 2.0 * a * fs)
            else:                                                          # sine, sweeps: |sin(p + d) - sin p|
                steady = 2.0 * a * fs * math.sin(math.pi * min(h, 0.5))   # <= 2 sin(d / 2), d = 2 pi f / fs
            f_out = blk.frequency_end if blk.waveform in wf.SWEEPS else blk.frequency
            k_in = min(n, int(math.ceil(blk.taper_cycles / blk.frequency * fs)) + 2)
            k_out = min(n, int(math.ceil(blk.taper_cycles / f_out * fs)) + 2)
            if k_in + k_out <= budget:                                     # the tapers sample by sample
                budget -= k_in + k_out
                self.check_setpoints(blk.evaluate(np.arange(k_in) / fs), fs, prev, where)
                tail = blk.evaluate(np.arange(n - k_out, n) / fs)
                self.check_setpoints(tail, fs, None, where)
                last, v = float(tail[-1]), steady
            else:
                v = max(steady, a * f_top * _taper_slope(blk))
        elif blk.waveform == 'ramp':
            d = abs(blk.target - blk.start_level)
            lo, hi = min(blk.start_level, blk.target), max(blk.start_level, blk.target)
            # raised cosine sampled every 1/(D fs) of its length: steps <= d sin(pi / (2 D fs))
            v = d * fs * math.sin(0.5 * math.pi * min(1.0, 1.0 / (blk.duration * fs))) if blk.duration > 0 else 0.0
        else:                                                              # hold
            lo = hi = blk.start_level
            v = 0.0
        if blk.oscillating and not (blk.waveform != 'triangle' and blk.waveform != 'square'
                                    and (2 * math.pi * f_top) ** 2 * a <= self.deceleration_max):
            # where an abort can stop: a sine whose acceleration stays below deceleration_max stops inside its
            # own peaks; otherwise allow for the braking distance at the peak speed
            brake = v * v / (2 * self.deceleration_max) + v / fs
            lo, hi = lo - brake, hi + brake
        self._check_range(lo, hi, where)
        self._check_velocity(v, where)
        self._check_stiffness_force(max(abs(lo), abs(hi)), where)
        if last is None:
            last = float(blk.evaluate(np.array([(n - 1) / fs]))[0])
        return last, budget


_U = np.linspace(0.0, 1.0, 1025)


def _taper_slope(blk) -> float:
    """Bound of |d/dphase [env(phase) shape(phase)]| over a taper of a periodic block (per cycle).

    In the taper env = (1 - cos(pi u)) / 2 with u = phase / taper_cycles, so |env'| = pi sin(pi u) / (2 T);
    with |shape| <= 1 and |shape'| <= s (2 pi sine, 4 triangle, 4 square_slope): |env' shape + env shape'| <=
    |env'| + s env, and for a sine sqrt(env'^2 + (2 pi env)^2) (Cauchy-Schwarz on sin, cos). Maximised over u on
    a fine grid (+1e-4 for the grid); 0.8 % above 2 pi for a sine with one taper cycle.
    """
    env = 0.5 - 0.5 * np.cos(np.pi * _U)
    d_env = 0.5 * np.pi * np.sin(np.pi * _U) / blk.taper_cycles
    if blk.waveform in ('triangle', 'square'):
        slope = 4.0 * (blk.square_slope if blk.waveform == 'square' else 1.0)
        g = d_env + slope * env
    else:
        g = np.hypot(d_env, 2 * np.pi * env)
    return float(np.max(g)) * (1 + 1e-4)


def _max_frequency(blk) -> float:
    """Highest frequency [Hz] a block runs at (0 for hold and ramp)."""
    return max(blk.frequency, blk.frequency_end) if blk.oscillating else 0.0


def element_force_model(params='swing_arm_joint_20C', harmonics: int = 256) -> Callable:
    """A force model for Limits.check_program: block -> predicted peak |force| [N] of a fractional Zener + Berg element.

    params: a parameter-set name (default swing_arm_joint_20C: the simulated specimen), a ZenerBergParams or a
    mapping of its values. Steady state, analytic (seed 000 Eq. 11, 17):

        F_peak ~ k0 |mean| + max_t |F_ev(t)| + F_f0(A)

    with F_ev the fractional Zener's periodic steady force under the block's unit shape (sine: exactly
    |K_ev(j 2 pi f)| A; triangle and square summed over `harmonics` harmonics), at the block's highest frequency
    (|K_ev| grows with frequency, so that covers a sweep), F_f0 Berg's steady peak friction force (Eq. 17; rate
    independent, so the same for every shape) and the static stiffness k0 carrying the mean (preload). The peak
    of a time-domain run from rest is slightly higher (the start-up transient; test_input_hardening_excitation
    bounds the difference), well inside the margin force_max should keep anyway. Hold and ramp blocks:
    k0 |x| + F_fmax (quasi-static).
    """
    if isinstance(params, str):
        p = load_parameter_set(params)
    elif isinstance(params, dict):
        p = ZenerBergParams.from_dict(params)
    else:
        p = params
    if not isinstance(p, ZenerBergParams):
        raise ValueError(f'element_force_model needs fractional_zener_berg parameters, got {type(p).__name__}')
    n_grid = 8 * harmonics
    phase = np.arange(n_grid) / n_grid

    def k_ev(frequency):
        return zener_complex_stiffness(2 * np.pi * np.asarray(frequency, float), p.k0, p.k_inf, p.tau, p.alpha)

    def peak_force(block) -> float:
        if not block.oscillating:
            level = max(abs(block.start_level), abs(block.end_level))
            return float(p.k0 * level + p.f_fmax)
        a, f = block.amplitude, _max_frequency(block)
        if block.waveform in ('triangle', 'square'):
            coef = np.fft.rfft(wf.shape(block.waveform, phase, block.square_slope))[:harmonics + 1]
            n = np.arange(coef.size)
            coef[0] = 0.0                                                  # zero-mean shapes; k0 carries the mean
            coef[1:] *= k_ev(n[1:] * f)
            linear = float(np.max(np.abs(np.fft.irfft(coef, n_grid)))) * a
        else:
            linear = float(abs(k_ev(f))) * a
        return float(p.k0 * abs(block.mean) + linear + berg_peak_force(p.f_fmax, p.x2, a))

    return peak_force
