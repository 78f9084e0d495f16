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

"""The pre-start check of a program against the safe envelope (safety.Limits), block by block.

The pre-start check (check_program) has a bounded cost for every program that loads (at most 24 h, see
blocks.MAX_PROGRAM_DURATION): it generates and checks the setpoints exactly, block by block, as long as the
program has generated at most EXACT_SAMPLES of them (a sample of a costlier waveform counts as
WaveformType.cost samples: a multisine's lines); a block beyond that budget is checked from closed-form
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
from typing import Callable, Optional

import numpy as np

from rubber_rig.models import ZenerBergParams, load_parameter_set
from rubber_rig.models.fractional import zener_complex_stiffness
from rubber_rig.models.friction import berg_peak_force

from ..safety import LimitError, Limits

# setpoints the pre-start check generates at most per program (about 0.1 s of numpy); the rest is bounded
EXACT_SAMPLES = 1 << 21
_CHUNK = 1 << 18


def check_program(limits: Limits, program, sample_rate: float, force_model: Optional[Callable] = None):
    """Check `program` (open loop) at sample_rate [Hz] before it starts, block by block, so the error names
    the block: the sample-rate rule (ProgramError, see Program.check_sample_rate), displacement, velocity,
    and the peak force predicted by stiffness_estimate and by `force_model` (default: limits.force_model), a
    callable block -> predicted peak |force| [N]. Bounded cost (module docstring).
    """
    program.check_sample_rate(sample_rate)
    fs = float(sample_rate)
    model = force_model if force_model is not None else limits.force_model
    starts = program.block_starts(fs)
    prev = program.initial_position
    if not limits.displacement_min <= prev <= limits.displacement_max:
        raise LimitError(f'program {program.name!r}: initial_position {prev:g} m outside the limits')
    if not limits.displacement_min <= program.rest_position <= limits.displacement_max:
        raise LimitError(f'program {program.name!r}: rest_position {program.rest_position:g} m outside '
                         f'the limits')
    budget = EXACT_SAMPLES
    for i, blk in enumerate(program.blocks):
        where = f"program {program.name!r} block {i} '{blk.name}'"
        n = int(starts[i + 1] - starts[i])
        cost = blk.type.cost(blk)
        if n * cost <= budget:
            budget -= n * cost
            for lo in range(0, n, _CHUNK):
                x = blk.evaluate(np.arange(lo, min(lo + _CHUNK, n)) / fs)
                limits.check_setpoints(x, fs, prev, where)
                limits.check_stiffness_force(float(np.max(np.abs(x))), where)
                prev = float(x[-1])
        else:
            prev, budget = _check_block_bounds(limits, blk, fs, n, prev, budget, where)
        if model is not None:
            _check_model_force(limits, model, blk, where)


def _check_model_force(limits: Limits, model, blk, where: str):
    try:
        f = model(blk)
    except (ValueError, ArithmeticError) as exc:
        raise LimitError(f'{where}: the force model cannot predict the force: {exc}') from None
    if f is None:
        return
    f = float(f)
    if not math.isfinite(f):
        raise LimitError(f'{where}: the force model predicts a non-finite force ({f})')
    if f > limits.force_max:
        what = (f'{_max_frequency(blk):g} Hz, {blk.amplitude * 1e3:g} mm amplitude, {blk.mean * 1e3:g} mm mean'
                if blk.oscillating else f'{blk.waveform} to {blk.end_level * 1e3:g} mm')
        raise LimitError(f'{where}: predicted peak force {f:.6g} N (element model, {what}) above force_max '
                         f'{limits.force_max:g} N')


def _check_block_bounds(limits: Limits, blk, fs: float, n: int, prev: float, budget: float, where: str):
    """Check a block of n samples (more than the exact budget) from closed-form bounds on its samples.

    Returns (its last setpoint, the budget left). The taper in and out (and the step from `prev` into the
    block) are generated exactly if they fit the budget; the rest is bounded by the supremum of its samples.
    """
    first = blk.start_level if not blk.oscillating else blk.mean          # every block starts at its level
    limits.check_setpoints([first], fs, prev, where)                    # the step into the block
    last = None
    if blk.oscillating:
        kind, a, f_top = blk.type, blk.amplitude, _max_frequency(blk)
        low, high = kind.span(blk)
        lo, hi = blk.mean + low * a, blk.mean + high * a
        steady = a * kind.step(blk, fs)                                # sampled full-amplitude part
        f_out = blk.frequency_end if kind.family == 'sweep' else blk.frequency
        k_in = min(n, int(math.ceil(blk.taper_cycles / blk.frequency * fs)) + 2)
        k_out = min(n, int(math.ceil(blk.taper_cycles / f_out * fs)) + 2)
        cost = kind.cost(blk)
        if (k_in + k_out) * cost <= budget:                            # the tapers sample by sample
            budget -= (k_in + k_out) * cost
            limits.check_setpoints(blk.evaluate(np.arange(k_in) / fs), fs, prev, where)
            tail = blk.evaluate(np.arange(n - k_out, n) / fs)
            limits.check_setpoints(tail, fs, None, where)
            last, v = float(tail[-1]), steady
        else:
            v = max(steady, a * kind.cycle_rate(blk) * _taper_slope(blk))
    elif blk.type.family == 'ramp':
        d = abs(blk.target - blk.start_level)
        lo, hi = min(blk.start_level, blk.target), max(blk.start_level, blk.target)
        # raised cosine sampled every 1/(D fs) of its length: steps <= d sin(pi / (2 D fs))
        v = d * fs * math.sin(0.5 * math.pi * min(1.0, 1.0 / (blk.duration * fs))) if blk.duration > 0 else 0.0
    else:                                                              # hold
        lo = hi = blk.start_level
        v = 0.0
    if blk.oscillating and not (blk.type.sine_like and (2 * math.pi * f_top) ** 2 * a <= limits.deceleration_max):
        # where an abort can stop: a sine whose acceleration stays below deceleration_max stops inside its
        # own peaks; otherwise allow for the braking distance at the peak speed
        brake = v * v / (2 * limits.deceleration_max) + v / fs
        lo, hi = lo - brake, hi + brake
    limits.check_range(lo, hi, where)
    limits.check_velocity(v, where)
    limits.check_stiffness_force(max(abs(lo), abs(hi)), where)
    if last is None:
        last = float(blk.evaluate(np.array([(n - 1) / fs]))[0])
    return last, budget


_U = np.linspace(0.0, 1.0, 1025)


def _taper_slope(blk) -> float:
    """Bound of |d/dphase [env(phase) shape(phase)]| over a taper of a periodic block (per cycle).

    In the taper env = (1 - cos(pi u)) / 2 with u = phase / taper_cycles, so |env'| = pi sin(pi u) / (2 T);
    with |shape| <= p and |shape'| <= s (waveform_types: p from its span, s its slope - 2 pi sine, 4 triangle, 4
    square_slope): |env' shape + env shape'| <= p |env'| + s env, and for a sine sqrt(env'^2 + (2 pi env)^2)
    (Cauchy-Schwarz on sin, cos). Maximised over u on a fine grid (+1e-4 for the grid); 0.8 % above 2 pi for
    a sine with one taper cycle.
    """
    env = 0.5 - 0.5 * np.cos(np.pi * _U)
    d_env = 0.5 * np.pi * np.sin(np.pi * _U) / blk.taper_cycles
    kind = blk.type
    if kind.taper_slope is not None:
        g = kind.taper_slope(blk, env, d_env)
    elif kind.sine_like:
        g = np.hypot(d_env, kind.slope(blk) * env)
    else:
        g = max(abs(v) for v in kind.span(blk)) * d_env + kind.slope(blk) * env
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
    |K_ev(j 2 pi f)| A; other shapes summed over `harmonics` harmonics, or up to a multisine's highest line), at
    the block's highest frequency (|K_ev| grows with frequency, so that covers a sweep), plus |K_ev(f)| dc A
    for a shape with a mean of its own (dc: 0.5 for a haversine), F_f0 Berg's steady peak friction force (Eq. 17; rate
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

    def k_ev(frequency):
        return zener_complex_stiffness(2 * np.pi * np.asarray(frequency, float), p.k0, p.k_inf, p.tau, p.alpha)

    def peak_force(block) -> float:
        if not block.oscillating:
            level = max(abs(block.start_level), abs(block.end_level))
            return float(p.k0 * level + p.f_fmax)
        kind, a = block.type, block.amplitude
        if kind.sine_like:
            linear = float(abs(k_ev(_max_frequency(block)))) * a
        else:
            top = max(harmonics, kind.top_harmonic(block))
            grid = max(n_grid, 8 * top)
            coef = np.fft.rfft(kind.shape(block, np.arange(grid) / grid))[:top + 1]
            n = np.arange(coef.size)
            coef[0] = 0.0                                                  # k0 carries the mean and the shape's dc
            coef[1:] *= k_ev(n[1:] * block.frequency)
            linear = float(np.max(np.abs(np.fft.irfft(coef, grid)))) * a
        # a shape's own mean (dc) builds up within its taper, too fast to relax to k0: carried at |K_ev(f)|;
        # friction at amplitude A: a one-sided shape travels A, and a loop of 2 A bounds that (Berg is monotone)
        static = p.k0 * abs(block.mean) + kind.dc * a * float(abs(k_ev(block.frequency)))
        return float(static + linear + berg_peak_force(p.f_fmax, p.x2, a))

    return peak_force
