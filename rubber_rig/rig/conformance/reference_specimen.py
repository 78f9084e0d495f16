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

"""Measured values have a requirement (issue 36): the reference-specimen scenario. The way a lab verifies a
testing machine's force measuring system against a calibrated proving device (cf. ISO 7500-1, ASTM E4), the
operator puts a reference spring of declared stiffness and uncertainty on the rig; the run moves it and judges
from the feedback the stiffness (force sign, unit and scale, displacement gain: CTRL-MEAS-1), the delay between
force and displacement of one sample (CTRL-MEAS-2) and, against a declared ambient, the temperature (CTRL-MEAS-3).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .link import LEAD, judges
from .report import FAIL, NOT_TESTED, PASS, Stretch

REFERENCE_FREQUENCY = 2.0       # [Hz] of the reference motion


REFERENCE_CYCLES = 4            # cycles of it judged


REFERENCE_RISE = 0.25           # [s] its amplitude rises smoothly from 0 over this long


COVERAGE = 2.0                  # coverage factor of the expanded uncertainties (about 95 %, GUM)


TEMPERATURE_NOT_AVAILABLE = -327.68   # [degC] TEMP_Specimen's lowest raw value: the controller has no reading


@dataclass(frozen=True)
class ReferenceSpring:
    """The reference specimen on the rig: stiffness [N/m] > 0 and its relative expanded uncertainty (k = 2) from
    its calibration certificate, e.g. 0.01 for +-1 %.
    """

    stiffness: float
    uncertainty: float

    def __post_init__(self):
        if not (math.isfinite(self.stiffness) and self.stiffness > 0):
            raise ValueError(f'reference spring stiffness {self.stiffness!r} N/m: must be > 0')
        if not (math.isfinite(self.uncertainty) and 0 <= self.uncertainty < 0.5):
            raise ValueError(f'reference spring uncertainty {self.uncertainty!r}: must be 0 .. 50 %')

    def describe(self) -> str:
        return f'{self.stiffness * 1e-6:g} kN/mm +- {self.uncertainty * 100:g} % (k = 2)'


@dataclass(frozen=True)
class Ambient:
    """The specimen temperature the operator declares [degC] and how far a reading may be from it [K]."""

    temperature: float
    tolerance: float = 5.0

    def __post_init__(self):
        if not (math.isfinite(self.temperature) and -60 <= self.temperature <= 200):
            raise ValueError(f'ambient {self.temperature!r} degC: must be -60 .. 200 degC')
        if not (math.isfinite(self.tolerance) and self.tolerance > 0):
            raise ValueError(f'ambient tolerance {self.tolerance!r} K: must be > 0')


@dataclass
class SpringFit:
    """Least squares F = k x + c v + F0 over the samples of the reference motion: k [N/m] and its standard
    uncertainty, the delay d = -c / k [s] of force after displacement and its standard uncertainty, n samples.
    """

    k: float
    u_k: float
    delay: float
    u_delay: float
    n: int


def fit_spring(x, force, fs: float, seq=None) -> SpringFit:
    """Fit a spring to displacement x [m] and force [N] sampled at fs [Hz] (equal length, >= 10 samples), of the
    sample sequences `seq` (shape like x, increasing; None: contiguous).

    A pure spring read one sample late gives F(t) = k x(t - d) ~ k x(t) - k d v(t): the velocity's coefficient
    is -k d. v is the central difference of x, so only samples whose both neighbours were received are fitted
    (the end samples, and those next to a sample this host never received, are left out: a difference across a
    lost sample would be twice the velocity).
    """
    x, f = np.asarray(x, float), np.asarray(force, float)
    seq = np.arange(len(x)) if seq is None else np.asarray(seq)
    inner = (seq[1:-1] - seq[:-2] == 1) & (seq[2:] - seq[1:-1] == 1)
    v = ((x[2:] - x[:-2]) * fs / 2.0)[inner]
    x, f = x[1:-1][inner], f[1:-1][inner]
    a = np.column_stack([x, v, np.ones_like(x)])
    coef, *_ = np.linalg.lstsq(a, f, rcond=None)
    resid = f - a @ coef
    dof = max(1, len(f) - 3)
    cov = np.linalg.pinv(a.T @ a) * float(resid @ resid) / dof
    k, c = float(coef[0]), float(coef[1])
    u_k, u_c = math.sqrt(max(cov[0, 0], 0.0)), math.sqrt(max(cov[1, 1], 0.0))
    delay = -c / k if k else math.inf
    u_delay = abs(delay) * math.hypot(u_c / c if c else 0.0, u_k / k if k else 0.0) if k else math.inf
    return SpringFit(k, u_k, delay, max(u_delay, u_c / abs(k) if k else math.inf), len(f))


def judge_stiffness(fit: SpringFit, ref: ReferenceSpring) -> tuple[bool, str, str]:
    """CTRL-MEAS-1: (ok, measured, why) for the stiffness measured against the declared reference. Bound: the
    declared expanded uncertainty and COVERAGE x the fit's standard uncertainty, combined (GUM).
    """
    ratio = fit.k / ref.stiffness
    bound = math.hypot(ref.uncertainty, COVERAGE * fit.u_k / ref.stiffness)
    measured = (f'measured {fit.k * 1e-6:.4g} kN/mm +- {COVERAGE * fit.u_k * 1e-6:.2g} (k = 2, {fit.n} samples) '
                f'for the reference {ref.describe()}: ratio {ratio:.4g} (allowed 1 +- {bound:.3g})')
    if abs(ratio - 1.0) <= bound:
        return True, measured, ''
    if ratio < 0:
        why = 'force of the opposite sign to the displacement: load cell or its wiring inverted (docs/protocol.md: ' \
              'a spring reads F = k x, k > 0)'
    elif abs(math.log10(ratio) + 3) < 0.05:
        why = 'a thousandth of the reference: force sent in kN where the DBC says N?'
    else:
        why = (f'stiffness off by {(ratio - 1) * 100:+.1f} %: a gain error of the load cell or the displacement '
               'transducer')
    return False, measured, why


def judge_delay(fit: SpringFit, fs: float) -> tuple[bool, str, str]:
    """CTRL-MEAS-2: force and displacement of one feedback sample must be of the same tick: |delay| at most half
    a sample period, with COVERAGE x the fit's standard uncertainty of the delay.
    """
    bound = 0.5 / fs + COVERAGE * fit.u_delay
    measured = (f'force {fit.delay * 1e3:+.3f} ms after displacement ({fit.delay * fs:+.2f} samples) +- '
                f'{COVERAGE * fit.u_delay * 1e3:.2g} ms (k = 2); allowed +-{bound * 1e3:.3f} ms')
    ok = abs(fit.delay) <= bound
    return ok, measured, '' if ok else 'force and displacement of a sample must be measured at the same tick'


@judges('CTRL-MEAS-1', 'CTRL-MEAS-2', 'CTRL-MEAS-3')
def s_reference(link):
    """Reference specimen: stiffness, delay and temperature (CTRL-MEAS-1/2/3)."""
    _judge_temperature(link)
    if link.reference is None:
        for rid in ('CTRL-MEAS-1', 'CTRL-MEAS-2'):
            link.results.put(rid, NOT_TESTED, '', 'no reference spring declared on the rig (--reference-spring '
                             'STIFFNESS+-U, e.g. 10kN/mm+-1%): measured values cannot be judged')
        return
    link.limits(link.env.lower, link.env.upper)
    a, p0 = 0.4 * link.env.half, link.position
    w, rise = 2 * math.pi * REFERENCE_FREQUENCY / link.fs, REFERENCE_RISE * link.fs
    first = link.next_sequence() + 1000
    duration = REFERENCE_CYCLES / REFERENCE_FREQUENCY + REFERENCE_RISE

    def wave(k):
        envelope = 0.5 * (1 - math.cos(math.pi * min(k / rise, 1.0)))
        return p0 + a * envelope * math.sin(w * k)
    begun = link.now()
    end = link.stream(first, wave, duration)
    link._sleep(LEAD + 0.1)
    with link.lock:
        got = sorted({s.seq: (s.seq, s.x, s.force) for s in link.samples
                      if first + rise <= s.seq < end and math.isfinite(s.force)}.values())
    link.to_rest(0.0)
    expected = end - int(first + rise) if end > first + rise else 0
    lost = f'{expected - len(got)} of {expected} samples never received by this host, left out' \
        if len(got) < expected else ''
    if len(got) < 0.5 * REFERENCE_CYCLES / REFERENCE_FREQUENCY * link.fs:
        for rid in ('CTRL-MEAS-1', 'CTRL-MEAS-2'):
            # a motion not taken is a time: this host late LEAD or more underran the stream (its heartbeat as late
            # as the host timeout faults the controller), and the FAIL is not judged then (host_excuse)
            link.results.put(rid, FAIL, f'{len(got)} samples of the reference motion received',
                             'the controller did not take the reference motion', Stretch(begun, link.now(),
                                                                                         tolerance=LEAD))
        return
    fit = fit_spring([g[1] for g in got], [g[2] for g in got], link.fs, [g[0] for g in got])
    for rid, (ok, measured, why) in (('CTRL-MEAS-1', judge_stiffness(fit, link.reference)),
                                     ('CTRL-MEAS-2', judge_delay(fit, link.fs))):
        link.results.put(rid, PASS if ok else FAIL, f'{measured}; {lost}' if lost else measured, why)


def _judge_temperature(link):
    """CTRL-MEAS-3: every Temperature frame so far within the declared ambient's tolerance."""
    with link.lock:
        temps = [float(f.signals['TEMP_Specimen']) for f in link.trace.frames
                 if f.name == 'Temperature' and f.host is False and not f.malformed]
    if link.ambient is None:
        link.results.put('CTRL-MEAS-3', NOT_TESTED, f'{len(temps)} Temperature frames', 'no ambient declared '
                         '(--ambient T+-TOL, e.g. 23degC+-5K): the temperature cannot be judged')
        return
    if not temps or all(t <= TEMPERATURE_NOT_AVAILABLE + 0.005 for t in temps):
        link.results.put('CTRL-MEAS-3', NOT_TESTED, f'{len(temps)} Temperature frames, none with a reading',
                         'the controller reports no temperature (-327.68 degC: not available)')
        return
    read = [t for t in temps if t > TEMPERATURE_NOT_AVAILABLE + 0.005]
    worst = max(read, key=lambda t: abs(t - link.ambient.temperature))
    ok = abs(worst - link.ambient.temperature) <= link.ambient.tolerance
    link.results.put('CTRL-MEAS-3', PASS if ok else FAIL,
                     f'{len(read)} readings {min(read):.2f} .. {max(read):.2f} degC, declared ambient '
                     f'{link.ambient.temperature:g} +- {link.ambient.tolerance:g} K',
                     '' if ok else f'{worst:.2f} degC is not plausible for the declared ambient (byte order, '
                     'scale or offset of TEMP_Specimen?)')
